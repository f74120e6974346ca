"""Payloads of every byte value, for the end-to-end property tests (``tests/test_fuzz_bytes_*.py``).

Each family's module runs one daemon (a module fixture) and sends many payloads through it, end to end
and both ways: an outside library (``wlmodem``, ``acomms``) or hilgate's driver → the emulated modem →
the simulated channel → the far emulated modem → an outside library or hilgate's driver, and compares
what comes out byte for byte.  What breaks protocols is in every payload hypothesis draws here: the
line ends (CR, LF), NUL, the separators of the modems' sentences (``*``, ``,``, ``$``, ``w``), an
EvoLogics escape (``+++``, ``AT``, ``+++AT``, a whole ``+++ATC`` line) and 0xFF; every size from one byte
to the largest the mode allows, the largest always among them (:func:`edges`).
"""

from __future__ import annotations

from contextlib import contextmanager

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from daemon_kit import HANG_GUARD_S, Daemon
from fuzzkit import examples

SPECIALS = (b"\r", b"\n", b"\r\n", b"\x00", b"*", b",", b"$", b"w", b"+++", b"AT", b"+++AT", b"+++ATC\r\n", b"\xff")
ALL_SPECIALS = b"".join(SPECIALS)


def fit(data: bytes, least: int, most: int, zero_free: bool = False) -> bytes:
    """``data`` cut to ``most`` bytes and padded with NUL to ``least``; ``zero_free``: never all NUL (the
    M64's all-zero packet is its sync packet, reserved by the modem)."""
    data = (data[:most] + bytes(max(0, least - len(data))))[:most]
    if zero_free and not any(data):
        data = data[:-1] + b"\x01"
    return data


def payloads(most: int, least: int = 1, zero_free: bool = False) -> st.SearchStrategy[bytes]:
    """Any bytes of ``least``..``most``, half of them made of :data:`SPECIALS` and short binary runs."""
    pieces = st.one_of(st.sampled_from(SPECIALS), st.binary(min_size=1, max_size=8))
    mixed = st.lists(pieces, max_size=max(1, most // 2)).map(b"".join)
    return st.one_of(mixed, st.binary(min_size=least, max_size=most)).map(
        lambda data: fit(data, least, most, zero_free))


def edges(most: int, least: int = 1) -> list[bytes]:
    """The sizes at the ends of the range, of the bytes that matter: every special, every byte value."""
    every = (ALL_SPECIALS + bytes(range(256))) * (most // (len(ALL_SPECIALS) + 256) + 1)
    return [fit(ALL_SPECIALS, least, most), every[:most], fit(b"\r", least, least)]


def many(count: int):
    """Hypothesis settings for a property test through a live daemon: ``count`` examples in ``make test``
    (more under ``make fuzz``), no per-example deadline (a modem takes the model's time), and the module's
    daemon a fixture of the module (hypothesis need not reset it between examples)."""
    return settings(max_examples=examples(count), deadline=None, derandomize=False, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@contextmanager
def running(tmp_path_factory, scene_text: str, links: list[str], *args: str):
    """One daemon for a whole module (the kit's :class:`~daemon_kit.Daemon`), up and READY, closed after."""
    daemon = Daemon(tmp_path_factory.mktemp("daemon"), scene_text, links, *args)
    try:
        daemon.wait_for("READY=1")
        yield daemon
    finally:
        daemon.close()


def crossed(sender, receiver, payload: bytes, dst: int, timeout: float = HANG_GUARD_S) -> bytes | None:
    """``payload`` sent by one GLI client (``hilgate.client.Link``) and what the other receives next."""
    sender.send(payload, dst=dst)
    message = receiver.recv(timeout=timeout)
    return None if message is None else message.data
