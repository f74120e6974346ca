"""The other hosts' transmissions, from Zenoh to this host's medium: handed over from Zenoh's thread to the
loop (bounded per host), checked on the loop (who says it, when, heard before?) and given to the medium as
a transmission of the sending link's modem here, late ones traced ``late``.

Kept apart from :mod:`.network` (which publishes this host's transmissions and holds what the parts share)
so that the hand-over's bounds and the checks, in their order, stay in one place.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from typing import Any

from .netcodec import MAX_TRANSMISSION, TIME_WINDOW_S, NetError, Transmission, decode_transmission, to_local
from .nethosts import HostView
from ..core.inbox import Inbox
from ..sim.live_vehicle import RemoteVehicle

log = logging.getLogger(__name__)

__all__ = ["Hearing", "remember"]

REMEMBERED_FRAMES = 4096  # frames a control frame of another host may still refer to (S-FAMA's RTS → CTS)
FIFO_DEPTH = 128
"""Transmissions Zenoh keeps for the thread that hands them to the loop (beyond that Zenoh holds back
its own reader): that thread takes them at once, and drops what the hand-over cannot hold, so this
queue stays short; at most FIFO_DEPTH × the size filter's 128 kB = 32 MB, only while the thread waits
for the GIL under a flood."""
TX_DEPTH = 2048
"""Transmissions of one host waiting for the loop (a frame's transmission is 0.1-4 kB) …"""
TX_BYTES = 4 << 20
"""… and their bytes, at most; beyond either, what the host sends is dropped until the loop has taken
some (counted ``inbox_full``, traced per host).  The hosts together: :data:`TX_TOTAL_BYTES`."""
TX_TOTAL_BYTES = 16 << 20
INBOX_BATCH = 256  # transmissions the loop takes per turn (then its other inputs get a turn)


def remember(cache: OrderedDict, key: tuple[str, int], frame: Any) -> None:
    """Keep ``frame`` under ``key``, forgetting the oldest past :data:`REMEMBERED_FRAMES`."""
    cache[key] = frame
    if len(cache) > REMEMBERED_FRAMES:
        cache.popitem(last=False)


class Hearing:
    """The others' transmissions (``network``: the daemon's :class:`~.network.Network`, whose session,
    hosts, scene, counters and frames sent it shares)."""

    def __init__(self, network: Any):
        self.network = network
        self.heard: OrderedDict[tuple[str, int], Any] = OrderedDict()

    def subscribe(self) -> Any:
        """The subscriber of the others' transmissions, its queue Zenoh's (:data:`FIFO_DEPTH`)."""
        import zenoh

        network = self.network
        return network.session.declare_subscriber(f"{network.prefix}/tx/**", zenoh.handlers.FifoChannel(FIFO_DEPTH))

    def hand_over(self, transmissions: Any) -> None:
        """Start the thread that moves what ``transmissions`` (the subscriber) hears to the loop."""
        handover = Inbox(self.network.scheduler.post, self._on_transmissions, TX_DEPTH, TX_BYTES, TX_TOTAL_BYTES,
                         batch=INBOX_BATCH)
        threading.Thread(target=self._drain, args=(transmissions.handler, handover), name="network-tx",
                         daemon=True).start()

    def _drain(self, handler: Any, handover: Inbox) -> None:
        """The others' transmissions, from Zenoh's queue to the loop's (``handover``: one queue per host,
        bounded in messages and bytes, taken in turns; one wake-up for all that came meanwhile, and each
        host's in its order).  What a host's queue cannot hold is dropped here, uncopied, and counted:
        this thread never waits for the loop, so Zenoh's queue stays short."""

        def copied(item: tuple[str, Any]) -> tuple[str, bytes]:
            return item[0], item[1].payload.to_bytes()

        key_host = self.network.key_host
        while True:
            try:
                sample = handler.recv()  # (waits with the GIL released)
            except Exception:  # the subscriber was undeclared: the daemon is stopping
                return
            while sample is not None:
                key, size = str(sample.key_expr), len(sample.payload)
                host = key_host(key, "tx")
                if size <= MAX_TRANSMISSION:
                    handover.put((key, sample), size, host, copied)
                else:  # (counted on the loop, never copied; Zenoh's filter refused longer ones)
                    handover.put((key, size), 0, host)
                sample = handler.try_recv()

    def _on_transmissions(self, batch: list[tuple[str, bytes | int]], dropped: dict[str, int]) -> None:
        network = self.network
        for host, n in dropped.items():  # what the hand-over could not hold: counted and traced per host
            network.counters["inbox_full"] += n
            network.recorder.event({"t": round(network.scheduler.now(), 9), "ev": "drop", "link": "*", "src": host,
                                    "cause": "inbox_full", "n": n})
        for key, data in batch:
            self._on_transmission(key, data)

    def _read(self, key: str, data: bytes | int) -> Transmission | None:
        """The transmission ``data`` is, if it is readable and its host is its key's (else counted)."""
        counters = self.network.counters
        if isinstance(data, int):
            counters["bad_message"] += 1
            log.debug("a transmission of %d bytes on %s: refused unread", data, key)
            return None
        try:
            message = decode_transmission(data)
        except NetError as exc:
            counters[exc.cause] += 1
            log.debug("unreadable transmission: %s", exc)
            return None
        if message.host != self.network.key_host(key, "tx"):
            counters["forged"] += 1  # a host speaking for another (possible only without credentials)
            return None
        return message

    def _on_transmission(self, key: str, data: bytes | int) -> None:
        message = self._read(key, data)
        if message is None:
            return
        network = self.network
        view = network.hosts.get(message.host)
        if view is None:  # this host, or one the scene does not name: nothing of it is judged here
            if message.host != network.host:
                network.counters["foreign_sender"] += 1
            return
        frame = message.frame
        world = network.router.world
        modem = world.modems.get(frame.src_link)
        if modem is None or modem.radio.listens or network.remote_links.get(frame.src_link) != message.host:
            network.counters["foreign_sender"] += 1  # not a link the scene gives that host: ignored
            network.settlement.refused(message)
            return
        now = network.scheduler.now()
        t = to_local(message.t, message.epoch_ns, network.epoch_ns)
        # A clock that far off (or a forged time) would schedule nonsense; and no host started later than
        # now (its epoch, the UNIX clock at its model time 0, is its start: 2**62 is no start, however its
        # t makes up for it)
        if abs(now - t) > TIME_WINDOW_S or message.epoch_ns - network.epoch_ns > (now + TIME_WINDOW_S) * 1e9:
            network.counters["out_of_time"] += 1
            network.settlement.refused(message)
            return
        # Only now, the message known good in every other way, may it move the replay window (a message
        # refused above moved it before issue 37: one forged epoch made the host's every frame a replay)
        verdict = view.window.admit(message.session, message.epoch_ns, message.number, message.session in view.zids)
        if isinstance(verdict, str):
            network.counters[verdict] += 1
            network.recorder.event({"t": round(now, 9), "ev": "drop", "link": "*", "src": message.host,
                                    "cause": verdict})
            return
        if verdict:
            view.gaps += verdict
            network.recorder.event({"t": round(now, 9), "ev": "drop", "link": "*", "src": message.host,
                                    "cause": "net_gap", "n": verdict})
        if message.ref_key is not None:
            mine = network.sent.get(message.ref_key) if message.ref_key[0] not in network.remote_links else None
            frame.ref = mine or self.heard.get(message.ref_key) or frame.ref
        remember(self.heard, (frame.src_link, frame.id), frame)
        if not network.settlement.hear(message, modem, t, now):
            return  # (reported as never heard: its sender traced it)
        view.heard += 1
        delay = now - t
        view.delay_sum += delay
        view.delay_max = max(view.delay_max, delay)
        pose = modem.pose
        if isinstance(pose, RemoteVehicle) and message.position is not None:
            pose.update_from(t, message.position, None)
        if now > t + message.duration:
            self._account_late(modem, frame, t, message.duration, now, view)
        world.medium.transmit(modem.radio, frame, t, message.duration)

    def _account_late(self, sender: Any, frame: Any, t: float, duration: float, now: float, view: HostView) -> None:
        """Arrivals here that should have ended before the transmission was heard: delivered at once
        (the medium cannot go back), traced ``late`` and counted per host."""
        medium = self.network.router.world.medium
        for receiver in medium.modems:
            radio = receiver.radio
            if not radio.listens or radio.rx_channel != sender.radio.tx_channel:
                continue
            tau = medium.propagation_delay(sender.radio, radio, t)
            if tau is None:
                continue
            lateness = now - (t + tau + duration)
            if lateness > 0:
                view.late += 1
                view.late_max = max(view.late_max, lateness)
                self.network.recorder.event({"t": round(now, 9), "ev": "late", "link": receiver.id,
                                             "src": frame.src_link, "pkt": frame.id, "host": view.name,
                                             "lateness_s": round(lateness, 9)})
