"""The backend table: every real-modem driver hilgate knows, declared once (as gpsd's driver table).

One :class:`Driver` row per modem type says

- its **name**, the scene's ``backend:`` (and ``emulate: {protocol:}``);
- its **options**: a frozen dataclass whose fields are what the driver is given; a field made with
  :func:`option` is a scene key, with its default and its check (an :class:`Option`) as metadata; a
  field made with :func:`from_link` is filled from the link's own modem keys instead;
- how to **open** it: ``"module:Class"`` of its backend, built as
  ``Class(link_id, address, packet, options, scheduler, trace)`` by :func:`open_backend`;
- its **emulator**: ``"module:Class"`` of the emulated device that a simulated link can show, found by
  :func:`emulator_for`, and how the row's driver **reaches** it (:class:`Reach`: on a pty, on a loopback
  TCP port, and the driver's options that name it), which also says where the emulated device can be;
- its **limits**: what the modem accepts (:class:`ModemLimits`) when the link's preset says nothing:
  the driver and the emulator refuse beyond them, and so does a simulated link whose preset states them.

The scene loader (:mod:`hilgate.scene.backends`) reads the keys, the checks, the "only for backend X"
and the "did you mean" from this table, and the daemon opens backends and emulators through it:
adding a modem type means adding one options class and one row here, and its driver module.

Why here, and why by name: the scene loader must know every driver's keys to validate any scene
(also in the reload worker and in ``hilgate check``), yet must not import the drivers to do so —
they import pyserial and the codecs, and open ports.  This module imports only the standard library
and :mod:`hilgate.core.tables` (which adds the rows of installed packages: ``hilgate.drivers`` entry points);
driver and emulator classes are named as ``"module:attr"`` strings and imported only when the daemon
opens a link.  Declarations inside each driver module would force that import; a table inside
``hilgate/scene`` would make the daemon and the drivers depend on the loader's internals.  The checks
are plain data (kind and bounds, like a MAC's ``PARAMETERS``) for the same reason: ``drivers/``
imports only the core, and the scene turns the data into its own checkers.
"""

from __future__ import annotations

from dataclasses import MISSING, Field, dataclass, field, fields
from typing import Any, Callable, Iterator

from hilgate.core.packets import PacketError
from hilgate.core.tables import merge_entry_points, resolve

__all__ = [
    "Option", "Driver", "Reach", "BY_PTY", "DRIVERS", "ModemLimits", "MODES", "SEND_AS", "limits_for", "EvologicsOptions", "S100Options", "S100EmulatorOptions", "option", "from_link", "scene_options", "emulator_options",
    "M64Options", "M64EmulatorOptions", "MicromodemOptions", "UnetOptions", "UnetEmulatorOptions", "driver_names", "emulated_protocols", "open_backend", "emulator_for",
]

KINDS = ("port", "integer", "number", "boolean", "choice", "host")


@dataclass(frozen=True)
class Option:
    """How a scene gives one driver option: ``kind`` is port (a device path relative to the scene, or a
    URL hilgate can open), integer, number, boolean, choice or host (a host name or IP address), with
    its bounds; ``hint`` says what to give when a required option is missing."""

    kind: str
    minimum: float | None = None
    maximum: float | None = None
    above: float | None = None
    choices: tuple[str, ...] = ()
    hint: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"option kind {self.kind!r}: one of {', '.join(KINDS)}")


PORT = Option("port")
BOOLEAN = Option("boolean")
SCENE = "hilgate.scene"  # the metadata key of a field that is a scene option
LINK = "hilgate.link"    # the metadata key of a field filled from the link's modem keys
SPEC = "hilgate.spec"    # the metadata key of a field filled from the link's spec (its limits)


def option(check: Option, default: Any = MISSING) -> Any:
    """A field of an options class that the scene sets under its own name (required without a default)."""
    return field(default=default, metadata={SCENE: check})


def from_link(attribute: str, default: Any) -> Any:
    """A field that is no scene key of its own: the link's ``ModemParams.<attribute>`` fills it."""
    return field(default=default, metadata={LINK: attribute})


def from_limits(default: "ModemLimits | None") -> Any:
    """A field the link's ``limits:`` fills (its preset's, else ``default``, the driver's own)."""
    return field(default=default, metadata={SPEC: "limits"})


# -- what a modem accepts -------------------------------------------------------------------------------

MODES = {"im": "an instant message", "ims": "a synchronous instant message", "pbm": "a piggyback message",
         "burst": "a burst"}
"""The EvoLogics S2C's ways of sending, as a refusal names them (``AT*SENDIM``, ``AT*SENDIMS``,
``AT*SENDPBM``, ``AT*SEND``)."""
MICROMODEM_RATES = tuple(f"rate{n}" for n in range(6))
MODES.update({"packet": "a packet", "datagram": "a datagram",
              **{mode: f"a rate-{mode[4:]} packet" for mode in MICROMODEM_RATES}})
"""… the Modem-M64's 8-byte packet and the WlUDPSocket datagram its driver sends in them, the Micro-Modem's
packet of each rate."""
SEND_AS = ("im", "burst", "datagram", *MICROMODEM_RATES)
"""The modes GLI frames can go as: the EvoLogics driver's ``im: true`` and ``im: false``, the M64 driver's
datagrams, the Micro-Modem driver's ``rate`` (a simulated link's ``send_as``)."""
PLURALS = {"im": "instant messages", "ims": "synchronous instant messages", "pbm": "piggyback messages",
           "burst": "bursts", "packet": "packets", "datagram": "datagrams",
           **{mode: f"rate-{mode[4:]} packets" for mode in MICROMODEM_RATES}}


@dataclass(frozen=True)
class ModemLimits:
    """What a modem accepts, as a preset's ``limits:`` states it (``models/*.yaml`` say where each figure
    comes from), or as its driver assumes without one.

    - ``modes``: (mode, bytes) — the largest payload of one message of each mode (EvoLogics: ``im``,
      ``ims``, ``pbm``, ``burst``);
    - ``send_as``: the mode a *simulated* link's GLI frames are sent as (the driver's ``im:`` decides for
      a real one); None: a simulated link refuses nothing by size;
    - ``piece_bytes``: what an S100 holds at a time without flow control (longer frames cross in pieces
      of that size); ``flow_control``: the flow control the modem takes (``rtscts``: then whole frames
      of any size, as the link's ``rtscts: true`` asks);
    - ``baud``: the modem's serial line by default (its air bit rate is the preset's ``bitrate_bps``,
      its transmit pool ``fifo_bytes``).

    One :meth:`refusal` text serves the driver, the emulator's host-side checks and the simulated link,
    so an application sees the same error whichever backend the scene gives its link."""

    modem: str
    modes: tuple[tuple[str, int], ...] = ()
    send_as: str | None = None
    piece_bytes: int | None = None
    flow_control: str | None = None
    baud: int | None = None

    def most(self, mode: str) -> int | None:
        """The largest payload of one message of ``mode`` (None: the modem has no such mode)."""
        for name, size in self.modes:
            if name == mode:
                return size
        return None

    def refusal(self, size: int, mode: str | None = None) -> str | None:
        """Why ``size`` bytes cannot go as one message of ``mode`` (default ``send_as``), or None if they can."""
        mode = mode or self.send_as
        most = self.most(mode) if mode is not None else None
        if most is None or size <= most:
            return None
        title = DRIVERS[self.modem].title if self.modem in DRIVERS else self.modem
        hint = "use a smaller packet class"
        larger = [(name, n) for name, n in self.modes if n >= size and name in SEND_AS]
        if larger:
            name, n = larger[0]
            hint += f" or {PLURALS.get(name, name)} (at most {n})"
        return f"{size} bytes on air do not fit {MODES.get(mode, mode)} of the {title} (at most {most}); {hint}"

    def admit(self, size: int, mode: str | None = None) -> None:
        """Refuse (``PacketError`` "size", with :meth:`refusal`'s words) a message that does not fit ``mode``."""
        problem = self.refusal(size, mode)
        if problem is not None:
            raise PacketError("size", problem)

    def describe(self) -> str:
        """One line for ``hilgate check``."""
        parts = []
        if self.modes:
            parts.append(", ".join(f"{name} {n} B" for name, n in self.modes))
        if self.piece_bytes is not None:
            parts.append(f"pieces of {self.piece_bytes} B without flow control"
                         + (f", whole frames with {self.flow_control}" if self.flow_control else ""))
        if self.baud is not None:
            parts.append(f"serial {self.baud} baud")
        return "; ".join(parts)


# -- the drivers ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EvologicsOptions:
    """``backend: evologics`` (:mod:`hilgate.drivers.evologics`)."""

    port: str = option(Option("port", hint="a device such as /dev/ttyUSB0, or socket://HOST:9200"))
    baud: int = option(Option("integer", 50, 4_000_000), 19200)
    im: bool = option(BOOLEAN, True)  # instant messages; false: bursts (their sizes: ``limits``)
    ack: bool = option(BOOLEAN, True)
    source_level: int | None = option(Option("integer", 0, 3), None)
    gain: int | None = option(Option("integer", 0, 1), None)
    extended: bool = option(BOOLEAN, True)
    im_retries: int | None = option(Option("integer", 0, 255), None)
    command_timeout_s: float = option(Option("number", above=0), 2.0)
    delivery_timeout_s: float = option(Option("number", above=0), 30.0)
    queue_frames: int = option(Option("integer", 0, 100_000), 50)
    eol: str = option(Option("choice", choices=("auto", "cr", "lf", "crlf")), "auto")
    limits: "ModemLimits | None" = from_limits(None)  # None: EVOLOGICS_LIMITS

    def eol_bytes(self) -> bytes:
        if self.eol == "auto":
            return b"\n" if self.port.startswith("socket://") else b"\r"
        return {"cr": b"\r", "lf": b"\n", "crlf": b"\r\n"}[self.eol]


@dataclass(frozen=True)
class S100Options:
    """``backend: s100`` (:mod:`hilgate.drivers.s100`)."""

    port: str = option(Option("port", hint="a device such as /dev/ttyUSB0"))
    baud: int = option(Option("integer", 50, 4_000_000), 9600)
    rtscts: bool = option(BOOLEAN, False)
    air_bitrate_bps: float = from_link("bitrate_bps", 1800.0)  # pacing without RTS/CTS: the link's bitrate
    queue_frames: int = option(Option("integer", 0, 100_000), 50)
    limits: "ModemLimits | None" = from_limits(None)  # None: S100_LIMITS


@dataclass(frozen=True)
class S100EmulatorOptions:
    """``emulate: {protocol: s100}`` (:class:`hilgate.drivers.s100_emulator.S100Emulator`): the serial line
    the emulated S100 models, so that a pty (which takes no time per byte) behaves like the real line."""

    baud: int = option(Option("integer", 50, 4_000_000), 9600)  # 8N1: 10 bits on the line per byte
    rtscts: bool = option(BOOLEAN, False)  # without it, the modem takes at most 45 bytes at a time


@dataclass(frozen=True)
class M64Options:
    """``backend: m64`` (:mod:`hilgate.drivers.m64`): a Water Linked Modem-M64.  A pair talks when one is
    role ``a`` and the other ``b`` on the same ``modem_channel`` (1-7); frames cross as ``WlUDPSocket`` datagrams in
    8-byte packets, about one a second each way."""

    port: str = option(Option("port", hint="a device such as /dev/ttyUSB0"))
    role: str = option(Option("choice", choices=("a", "b"), hint="a or b: one modem of a pair is a, the other b"))
    modem_channel: int = option(Option("integer", 1, 7, hint="the pair's channel, 1 to 7 (Water Linked recommends 2 or 3)"))
    baud: int = option(Option("integer", 50, 4_000_000), 115200)
    queued_packets: int = option(Option("integer", 1, 1000), 2)  # kept in the modem's queue (as WlUDPSocket)
    poll_s: float = option(Option("number", above=0), 0.2)  # how often the queue is asked (wcl), as WlUDPSocket
    diagnostic_s: float = option(Option("number", minimum=0), 5.0)  # wcd into the trace (0: never)
    command_timeout_s: float = option(Option("number", above=0), 1.0)
    queue_frames: int = option(Option("integer", 0, 100_000), 50)
    limits: "ModemLimits | None" = from_limits(None)  # None: M64_LIMITS


@dataclass(frozen=True)
class M64EmulatorOptions:
    """``emulate: {protocol: m64}`` (:class:`hilgate.drivers.m64_emulator.M64Emulator`): the role and
    channel the modem has at power-on (a host's ``wcs`` changes them)."""

    role: str = option(Option("choice", choices=("a", "b")), "a")
    channel: int = option(Option("integer", 1, 7), 1)


@dataclass(frozen=True)
class MicromodemOptions:
    """``backend: micromodem`` (:mod:`hilgate.drivers.micromodem`): a WHOI Micro-Modem; each frame is one
    packet of ``rate`` (its frames sized as the rate allows), with the modem's acknowledgement if ``ack``."""

    port: str = option(Option("port", hint="a device such as /dev/ttyUSB0"))
    baud: int = option(Option("integer", 50, 4_000_000), 19200)
    rate: int = option(Option("integer", 0, 5), 1)
    ack: bool = option(BOOLEAN, False)
    command_timeout_s: float = option(Option("number", above=0), 2.0)
    cycle_timeout_s: float = option(Option("number", above=0), 60.0)
    ack_timeout_s: float = option(Option("number", above=0), 10.0)
    queue_frames: int = option(Option("integer", 0, 100_000), 50)
    limits: "ModemLimits | None" = from_limits(None)  # None: MICROMODEM_LIMITS


@dataclass(frozen=True)
class UnetOptions:
    """``backend: unet`` (:mod:`hilgate.drivers.unet`): a UnetStack modem (Subnero's) reached through its fjåge
    API at ``modem_host``:``port`` (1100 by default, fjåge's; ``host`` is the scene's key for the daemon
    that serves the link); the link's frames go as datagrams of ``unet_protocol`` and its received
    datagrams of that protocol come back as frames."""

    modem_host: str = option(Option("host", hint="the modem's address, such as 192.168.1.12"))
    port: int = option(Option("integer", 1, 65535), 1100)
    unet_protocol: int = option(Option("integer", 0, 63), 0)  # 0: DATA; 32-63: USER protocols
    command_timeout_s: float = option(Option("number", above=0), 5.0)
    send_timeout_s: float = option(Option("number", above=0), 60.0)  # a datagram's transmission, at most
    queue_frames: int = option(Option("integer", 0, 100_000), 50)
    limits: "ModemLimits | None" = from_limits(None)  # None: UNET_LIMITS


@dataclass(frozen=True)
class UnetEmulatorOptions:
    """``emulate: {protocol: unet}`` (:class:`hilgate.drivers.unet_emulator.UnetEmulator`): the protocol
    number the node gives received frames of other families, which carry none on air."""

    unet_protocol: int = option(Option("integer", 0, 63), 0)


WAYS = ("pty", "tcp")  # where an emulated device can be: its ``emulate:`` key


@dataclass(frozen=True)
class Reach:
    """One way a row's driver reaches an emulated device of its own row on the same machine (the whole HIL
    chain on one bench): the emulated link's ``emulate: {<way>: WHERE}`` (``pty``: a path, ``tcp``: a
    loopback port) and the driver link's scene ``options`` that name it, ``{where}`` standing for WHERE.

    Why data in the row: a driver names its modem in its own keys (a serial row's ``port`` is the pty, an
    EvoLogics modem's may also be ``socket://HOST:PORT``, a UnetStack modem's is ``modem_host`` and
    ``port``), and whatever builds such a bench (the driver-table suite, ``tests/bench_kit.py``) reads it
    here: a test that knew it by the row's name would miss the next row."""

    way: str
    options: tuple[tuple[str, str], ...]

    def __post_init__(self) -> None:
        if self.way not in WAYS:
            raise ValueError(f"reach way {self.way!r}: one of {', '.join(WAYS)}")

    def driver_options(self, where: Any) -> dict[str, str]:
        """The driver link's scene options (as text) that reach the emulated device at ``where``."""
        return {key: value.format(where=where) for key, value in self.options}


BY_PTY = (Reach("pty", (("port", "{where}"),)),)
"""A serial row's: its driver's ``port`` is the emulated device's pty."""


@dataclass(frozen=True)
class Driver:
    """One row of the table (see the module's docstring)."""

    name: str
    title: str      # the device as messages name it: "the {title} is serial"
    options: type   # a frozen dataclass made of option() and from_link() fields
    backend: str    # "module:Class" of the backend
    emulator: str | None = None  # "module:Class" of the emulated device, if there is one
    reach: tuple[Reach, ...] = BY_PTY  # where the emulated device can be, and how the driver reaches it there
    emulator_options: type | None = None  # the emulated device's own ``emulate:`` keys (option() fields)
    limits: ModemLimits | None = None  # what the modem accepts when the link's preset does not say

    @property
    def emulator_pty(self) -> bool:
        """The emulated device can be on a pty (a UnetStack modem's API is TCP only)."""
        return any(r.way == "pty" for r in self.reach)

    @property
    def emulator_tcp(self) -> bool:
        """The emulated device can listen on a loopback TCP port."""
        return any(r.way == "tcp" for r in self.reach)


EVOLOGICS_LIMITS = ModemLimits("evologics", (("im", 64), ("ims", 64), ("pbm", 64), ("burst", 1024)),
                               send_as="im", baud=19200)
"""The S2C's sizes as public drivers agree on them (shared/protocols/evologics-at.md, "Size limits");
``models/evologics-*.yaml`` state them with their sources."""

S100_LIMITS = ModemLimits("s100", piece_bytes=45, flow_control="rtscts", baud=9600)
"""The Seatooth S100 as dccomms_utils' bridge drives it (shared/protocols/s100-mavlink-aruco.md);
``models/s100.yaml`` states it with its source."""

M64_LIMITS = ModemLimits("m64", (("packet", 8), ("datagram", 4000)), send_as="datagram", baud=115200)
"""The Modem-M64: 8-byte packets (its protocol's ``wrn,8``), 115200 baud; a GLI frame goes as one
WlUDPSocket datagram, at most 4000 bytes (hilgate's bound: its framing stays within the 4096 bytes the
receiving driver holds; WlUDPSocket has none, and at 8 bytes a second 4000 take eight minutes)."""

MICROMODEM_LIMITS = ModemLimits("micromodem", tuple((f"rate{n}", size) for n, size in
                                                    enumerate((32, 192, 192, 512, 512, 2048))),
                                send_as="rate1", baud=19200)
"""The Micro-Modem's packet of each rate, frames × frame bytes (``drivers/micromodem_codec.py``'s
RATES, WHOI's software interface guide); 19200 baud, its default serial rate; GLI frames go as one packet
of the driver's ``rate`` (1 by default)."""

UNET_LIMITS = ModemLimits("unet", (("datagram", 64),), send_as="datagram")
"""A UnetStack modem's DATA frame as hilgate assumes it without a preset (the modem's own ``phy[2].MTU``
decides; ``models/unet-m25m.yaml`` says where its figures come from)."""

DRIVERS: dict[str, Driver] = {driver.name: driver for driver in (
    Driver("evologics", "EvoLogics modem", EvologicsOptions, "hilgate.drivers.evologics:EvologicsBackend",
           "hilgate.drivers.evologics_emulator:EvologicsEmulator", limits=EVOLOGICS_LIMITS,
           reach=(*BY_PTY, Reach("tcp", (("port", "socket://127.0.0.1:{where}"),)))),
    Driver("s100", "S100", S100Options, "hilgate.drivers.s100:S100Backend",
           "hilgate.drivers.s100_emulator:S100Emulator", emulator_options=S100EmulatorOptions, limits=S100_LIMITS),
    Driver("m64", "Modem-M64", M64Options, "hilgate.drivers.m64:M64Backend",
           "hilgate.drivers.m64_emulator:M64Emulator", emulator_options=M64EmulatorOptions, limits=M64_LIMITS),
    Driver("micromodem", "Micro-Modem", MicromodemOptions, "hilgate.drivers.micromodem:MicromodemBackend",
           "hilgate.drivers.micromodem_emulator:MicromodemEmulator", limits=MICROMODEM_LIMITS),
    Driver("unet", "UnetStack modem", UnetOptions, "hilgate.drivers.unet:UnetBackend",
           "hilgate.drivers.unet_emulator:UnetEmulator", emulator_options=UnetEmulatorOptions, limits=UNET_LIMITS,
           reach=(Reach("tcp", (("modem_host", "127.0.0.1"), ("port", "{where}"))),)),
)}


def limits_for(modem: str, limits: ModemLimits | None) -> ModemLimits | None:
    """The limits a ``modem`` driver or emulator works by: the link's own when they are that modem's,
    else the driver's (the scene refuses a preset's limits of another modem on a driver link)."""
    if limits is not None and limits.modem == modem:
        return limits
    driver = DRIVERS.get(modem)
    return driver.limits if driver is not None else None


# -- reading the table -----------------------------------------------------------------------------------


def scene_options(driver: Driver) -> Iterator[tuple[str, Option, bool]]:
    """(key, check, required) of each scene option of ``driver``, in the order its class declares them."""
    for f in fields(driver.options):
        if SCENE in f.metadata:
            yield f.name, f.metadata[SCENE], _required(f)


def _required(f: Field) -> bool:
    return f.default is MISSING and f.default_factory is MISSING


def emulator_options(driver: Driver) -> Iterator[tuple[str, Option, Any]]:
    """(key, check, default) of each ``emulate:`` option of ``driver``'s emulated device."""
    if driver.emulator_options is not None:
        for f in fields(driver.emulator_options):
            if SCENE in f.metadata:
                yield f.name, f.metadata[SCENE], f.default


def driver_names() -> tuple[str, ...]:
    return tuple(DRIVERS)


def emulated_protocols() -> tuple[str, ...]:
    """The ``emulate: {protocol:}`` values: drivers with an emulated device."""
    return tuple(name for name, driver in DRIVERS.items() if driver.emulator)


def open_backend(spec: Any, scheduler: Any, trace: Callable[[dict], Any]) -> Any:
    """The backend of a real-modem link (a validated ``LinkSpec``), opened: its driver module is
    imported now, its options are the scene's (``spec.options``) plus those filled from the link."""
    from hilgate.core.packets import packet_class

    driver = DRIVERS[spec.backend]
    options = dict(spec.options)
    for f in fields(driver.options):
        if LINK in f.metadata:
            # by name: the field's metadata names the spec's attribute
            options.setdefault(f.name, getattr(spec.params, f.metadata[LINK]))
        elif SPEC in f.metadata:
            # by name: the field's metadata names the spec's attribute
            options.setdefault(f.name, limits_for(spec.backend, getattr(spec, f.metadata[SPEC], None)))
    return resolve(driver.backend)(spec.id, spec.params.address, packet_class(spec.packet),
                                    driver.options(**options), scheduler, trace)


def emulator_for(protocol: str) -> type:
    """The emulated-device class of ``emulate: {protocol: ...}`` (its module imported now)."""
    reference = DRIVERS[protocol].emulator
    if reference is None:
        raise KeyError(f"backend {protocol!r} has no emulator")
    return resolve(reference)


# last: a plug-in's row module imports this one (its row class, its options), complete by now
merge_entry_points("hilgate.drivers", DRIVERS, lambda row: isinstance(row, Driver))  # a lab's own modems
