"""The example of a user-defined MAC in docs/channel-models.md: TDMA, each node sends only in its own time slot.

List it in a scene (``plugins: [example_mac.py]``, relative to the scene's file) or give
``--plugin example_mac.py``, then name it by its ``name``, ``mac: {protocol: tdma, slot_s: 0.5, slots: 4}``,
or as ``plugin:Class``, ``mac: {protocol: "example_mac:Tdma"}``."""

from hilgate.models.mac import Mac, Param


class Tdma(Mac):
    name = "tdma"
    PARAMETERS = {"slot_s": Param("number", 1.0, minimum=0.001), "slots": Param("integer", 4, minimum=1)}

    def __init__(self, slot_s: float = 1.0, slots: int = 4):
        super().__init__()
        self.slot_s, self.slots = slot_s, slots
        self.timer = None

    def on_enqueue(self):          # told: a frame from the application waits in the FIFO
        self._wait_for_my_slot()

    def on_tx_done(self, frame):   # told: the PHY finished a frame
        self._wait_for_my_slot()

    def _wait_for_my_slot(self):
        modem = self.modem
        if self.timer is not None or modem.phy_busy or not modem.fifo:
            return
        cycle = self.slot_s * self.slots
        mine = (modem.address % self.slots) * self.slot_s
        now = modem.clock.now()
        start = now - now % cycle + mine
        if start < now - 1e-9:
            start += cycle
        self.timer = modem.clock.at(start, self._send)   # may: set a timer

    def _send(self):
        self.timer = None
        modem = self.modem
        if modem.fifo and not modem.phy_busy:
            modem.transmit(modem.fifo_pop())              # may: put a frame on air

    # on_frame is inherited: good frames addressed here are delivered up (modem.deliver)
