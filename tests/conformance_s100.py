"""The WFS Seatooth S100's conformance rows (``conformance_kit``).  No WFS command set, manual or datasheet is
public; what is known comes from the one public driver, dccomms_utils' S100 bridge (it quotes the
distributor), and UWSim-NET's scenes (shared/protocols/s100-mavlink-aruco.md).  No outside S100 library
runs in Python (the bridge is C++): hilgate's driver at both ends is the outside view, and the emulated
modem is driven by pyserial with bytes of its own in tests/test_s100_emulator.py.  The S100 takes no
commands, so no row has a probe: each names its test."""

from conformance_kit import Row

ROWS = [
    Row("a transparent byte pipe", "no command set; addressing, acknowledgement and CRC are the application's",
        "the same: frames of the link's packet class go as frames, other bytes as they are (a raw frame, CR LF "
        "included), the far S100 writes them unchanged", "hilgate's frame (`A5 5A`, length, payload, CRC-16) for "
        "`raw` links, the class's own otherwise", tested=("test_s100_emulator.py", "transparent"),
        driver_code="wire_class"),
    Row("CR LF ends a packet", "every packet ends with CR LF (0x0D 0x0A); shorter than 45 B it waits for a "
        "timeout unless CR LF comes", "a frame goes on air when its CR LF has crossed the line; without one, "
        "0.1 s after the last byte (the timeout's real value is undocumented)", "CR LF after every frame, in the "
        "last piece", tested=("test_s100_emulator.py", "cr_lf_would_have_crossed")),
    Row("45 bytes without flow control", "at most 45 B, CR LF included, without RTS/CTS", "held and sent at the "
        "air bitrate, 45 at a time even without CR LF; what comes while full is lost (`drop`, `overflow`), judged "
        "within what a busy host's timing cannot rule out; a CR or LF of a long frame's payload passes", "45-byte "
        "pieces paced at `bitrate_bps`", tested=("test_s100_emulator.py", "holds_45_bytes"), driver_code="pieces("),
    Row("RTS/CTS", "hardware flow control recommended: no size limit", "`rtscts: true`: the host is never refused "
        "a byte, frames go whole (the signals themselves are not on the pty)", "`rtscts:`",
        tested=("test_fuzz_bytes_s100.py", "flow_control")),
    Row("`+++…` notices", "the modem's own lines, content undocumented (the bridge drops `+++…\\r\\n` ≤ 200 B)",
        "not emitted; a host's `+++` line crosses as bytes", "skipped and logged (`modem notice`)",
        tested=("test_s100_emulator.py", "+++NOTICE"), driver_code="Notice"),
    Row("serial line", "8N1, 9600 baud in the latest bridge (2400/19200 before), no XON/XOFF", "paced at the "
        "scene's `baud`, 10 bits a byte; reads at most 2 s of line time ahead", "`baud` 9600",
        tested=("test_s100_emulator.py", "ten_bits")),
    Row("bitrate, range, errors", "1800 bit/s (UWSim-NET); 0.5–6 m; BER 6e-13·d^13.7", "the `s100` preset's",
        "—", tested=("test_s100_emulator.py", "1000")),
    Row("configuration commands", "none published", "none: every byte is data", "none sent"),
]
