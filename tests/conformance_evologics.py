"""The EvoLogics S2C's conformance rows (``conformance_kit``): the AT reference rebuilt from EvoLogics' public
drivers and stacks (shared/protocols/evologics-at.md: EVINS, DMAC, DUNE, BIR, DESERT, OSL, ACFR, GSO, DCC).
No outside EvoLogics library runs in Python: LSTS DUNE's ``Transports.Evologics`` task is the outside
driver, its start-up, polling and message exchange replayed by tests/test_emulator_dune.py and run by
hand (docs/dune-hand-check.md); the last column says what DUNE sends or needs.  The probes go to an
emulated S2C at address 1 (a second at address 2), lines ended by CR as on a serial line."""

from conformance_kit import Row

OK = rb"OK\r\n"
RANGED = ("AL", "AR", "AM", "L", "LC", "G", "C", "RI", "RC", "KO", "RT", "ZI", "ZH", "ZC", "ZP", "CA", "RP", "ZS",
          "ZX", "ZF", "ZU", "ZL")
DUNE = "test_emulator_dune.py"

ROWS = [
    Row("`AT*SENDIM[,p<pid>],<len>,<dst>,ack\\|noack\\|force,<data>`", "`OK`; with `ack`, `DELIVEREDIM,<dst>` or, "
        "after the `!RI` retries, `FAILEDIM,<dst>`; 255 broadcast", "`OK`; the far modem's acknowledgement is a frame "
        "on the channel (`ack_bytes`, `ack_turnaround_s`); `DELIVEREDIM` when it comes back, `FAILEDIM` after `!RI` "
        "retries; `BUSY DELIVERING` while an `ack` IM is pending; `ERROR WRONG FORMAT` for another flag",
        "a GLI frame ≤ 64 B (`im: true`, `ack:`); the next waits for the report", (),
        probe=b"AT*SENDIM,5,2,noack,hello\rAT*SENDIM,5,2,maybe,hello\r", answer=OK + rb"ERROR WRONG FORMAT\r\n",
        keys=("*SENDIM",), driver_code='self.command("*SENDIM"'),
    Row("`AT*SENDIMS,<len>,<dst>,<usec>,<data>`", "sent when the µs clock reaches `usec`", "sent at once (`usec` "
        "not honoured); `RECVIMS` at the far end", "—", probe=b"AT*SENDIMS,2,2,,hi\r", answer=OK, keys=("*SENDIMS",)),
    Row("`AT*SENDPBM,<len>,<dst>,<data>`", "rides in the next acknowledgement from `dst`", "sent at once as a "
        "frame of its own; `RECVPBM`", "—", probe=b"AT*SENDPBM,2,2,hi\r", answer=OK, keys=("*SENDPBM",)),
    Row("`AT*SEND,<len>,<dst>,<data>` (burst)", "over a D-MAC connection; then `AT?PC`, and `DELIVERED,<pc>,<dst>` / "
        "`FAILED,<pc>,<dst>`", "one frame, no connection set-up; acknowledged on the channel, retried `!RC` times, "
        "then `DELIVERED`/`FAILED`", "a GLI frame ≤ 1024 B (`im: false`)", probe=b"AT*SEND,3,2,abc\r", answer=OK,
        keys=("*SEND",), driver_code='self.command("*SEND"'),
    Row("`AT*SENDPROBE`", "a probe (EVINS only)", "not emulated: `ERROR UNKNOWN COMMAND`", "—",
        probe=b"AT*SENDPROBE,1,0,0\r", answer=rb"ERROR UNKNOWN COMMAND\r\n"),
    Row("payload sizes", "IM, IMS, PBM ≤ 64 B; burst ≤ 1024 B", "`ERROR OUT OF RANGE` beyond the link's `limits:` "
        "(those by default)", "refused when the application sends, with the simulated link's words",
        probe=b"AT*SENDIM,65,2,noack," + b"x" * 65 + b"\r", answer=rb"ERROR OUT OF RANGE\r\n",
        tested=("test_modem_limits.py", "ERROR OUT OF RANGE"), driver_code="def admit"),
    Row("`ATO`; `+++AT<cmd>` → `+++AT<cmd>:<n>:<reply>`; `+++ATC`", "data mode: raw bytes are burst data to `AR`; "
        "escape frames for commands and notifications", "yes; raw data goes to `AR` in pieces ≤ 1024 B; with `AR 0` "
        "it cannot be sent (dropped: `AT?ZD`, trace `no_remote_address`); a `+++AT` line in command mode: `ERROR "
        "WRONG FORMAT`", "—", probe=b"ATO\r+++AT?AL\r+++ATC\r", answer=rb"\+\+\+AT\?AL:1:1\r\n", keys=("O",),
        tested=("test_emulator_commands.py", "+++AT")),
    Row("`RECVIM`, `RECVIMS`, `RECVPBM`, `RECV` (`[,p<pid>]`)", "length-framed, with duration or bitrate, RSSI, "
        "integrity, velocity", "when the model delivers the frame; RSSI, integrity and velocity from "
        "`models/link_budget.py`", "delivered to the applications; RSSI and integrity into the trace", (),
        tested=("test_fuzz_bytes_evologics.py", "crossed"), driver_code='"RECVIM", "RECVIMS", "RECVPBM", "RECV"'),
    Row("`DELIVEREDIM`, `FAILEDIM`, `DELIVERED`, `FAILED`", "the outcome of an `ack` IM or a burst",
        "the model's acknowledgement outcome", "traced; then `AT?T`", (), tested=("test_emulator_acks.py", "FAILEDIM"),
        driver_code='"DELIVEREDIM", "FAILEDIM"'),
    Row("`CANCELEDIM`, `CANCELEDIMS`, `CANCELEDPBM`, `EXPIREDIMS`", "an IM cancelled or expired", "never printed "
        "(no queue of IMs is cancelled or expires in the model)", "—"),
    Row("`AT?T`", "the last one-way propagation time, µs", "from the model's round trip", "after every delivery",
        probe=b"AT?T\r", answer=rb"\d+\r\n", keys=("?T",), driver_code='self.command("?T"'),
    Row("`AT?MODE`", "`AT` or `NET` (the interpreter)", "`firmware.mode`, `NET` by default", "—",
        probe=b"AT?MODE\r", answer=rb"NET\r\n", keys=("?MODE",), tested=(DUNE, "?MODE")),
    Row("`ATI0`, `ATI1`, `ATI7` (`ATI` = `ATI0`)", "firmware, `phy: …, mac: v…`, maker", "from `firmware:`", "—",
        probe=b"ATI1\r", answer=rb"phy: [^,]+, mac: v[^\r]+\r\n", keys=("I",), tested=(DUNE, "I1")),
    Row("`AT?CLOCK`", "system clock", "whole seconds of the model clock", "—", probe=b"AT?CLOCK\r",
        answer=rb"\d+\r\n", keys=("?CLOCK",), tested=(DUNE, "?CLOCK")),
    Row("`AT?P`", "8 lines `<t> <integrity>`, bare LF between", "one path: `0 <integrity>`, 7 × `0 0`", "—",
        probe=b"AT?P\r", answer=rb"0 \d+(\n0 0){7}\r\n", keys=("?P",), tested=(DUNE, "?P")),
    Row("`AT!AL<n>`, `AT?AL`", "the local address, 1..`AM`", "range-checked; moves the link in the simulation",
        "`!AL<address>` at start", probe=b"AT!AL1\rAT?AL\r", answer=OK + rb"1\r\n", keys=("?AL",),
        driver_code='("!AL", str(self.address))'),
    Row("`!AR` 0..AM, `!AM` 2/6/14/30/62/126/254, `!L` 0–3, `!LC`, `!G` 0–1, `!C` 0–3, `!RI`/`!RC`/`!KO` 0–255, "
        "`!RT` 500–12000, `!ZI`/`!ZH` 0–3600, `!ZC` 1–31, `!ZP` 50–5000, `!CA` 1300–1700, `!RP`, `!ZS` 0–7, "
        "`@ZX`/`@ZF`/`@ZU` 0–1, `@ZL`; `?X` reads each", "settings within their ranges", "`ERROR OUT OF RANGE` / "
        "`ERROR WRONG FORMAT`; kept; only `!AR`, `@ZX`, `@ZU`, `@ZL`, `!RI`/`!RC` act on the model (`!L`/`!G`, "
        "`!RP`, `!CA` change nothing: the scene decides)", "`!L`, `!G`, `@ZX1`, `!RI` at start (its options)",
        probe=b"AT!L4\rAT!L3\rAT?L\r", answer=rb"ERROR OUT OF RANGE\r\nOK\r\n3\r\n",
        keys=tuple(f"{p}{k}" for k in RANGED for p in "!?@"), driver_code='("@ZX", "1")'),
    Row("`AT!DA`, `AT!DT`, `AT?ZSL`, `AT?NOISE`, `AT?ZE`, `%…`, `AT<key>$`", "wake-up, interfaces, noise, "
        "delivered bytes, service, help", "not emulated: `ERROR UNKNOWN COMMAND`", "—",
        probe=b"AT?ZSL\r", answer=rb"ERROR UNKNOWN COMMAND\r\n"),
    Row("`AT@ZX1`: `SENDSTART`, `SENDEND`", "around each transmission", "at the model's start and end (`type` "
        "im/ims/pbm/burst; `delay` from the command to the air)", "`@ZX1` at start (ignored after)",
        tested=("test_emulator_commands.py", "SENDSTART")),
    Row("`RECVSTART`, `RECVEND`, `RECVFAILED`", "around each reception", "at the model's start and end of an "
        "arrival for this modem (broadcast included); `RECVFAILED` when the model loses it", "ignored",
        tested=("test_emulator_commands.py", "RECVEND")),
    Row("`BITRATE,local\\|remote,<bps>`, `SRCLEVEL,<n>`", "link and power", "`BITRATE` before a burst's "
        "`SENDSTART` and its `RECV`; `SRCLEVEL` when `!L` changes", "ignored",
        tested=("test_emulator_commands.py", "SRCLEVEL")),
    Row("`USBLLONG`, `USBLANGLES` (`@ZU1`)", "a USBL's fixes", "from the positions hilgate knows, a link with "
        "`usbl:` (`models/usbl.py`); `USBLPHYD`/`USBLPHYP` not emitted", "ignored", tested=("test_emulator_acks.py", "USBLLONG")),
    Row("`PHYON`/`PHYOFF`, `RADDR`, `DROPCNT`, `RECVSRV`, `STATUS`, `ECLK`, `RTO`, `RECVPROBE`", "PHY power, "
        "service, status, clock", "not emitted (no PHY power, service or clock model)", "ignored"),
    Row("unsolicited `ERROR EFAULT`, `ERROR OVERLOAD`; `[*]OK`", "errors nobody asked for; accepted, applied later",
        "never printed (nothing is pending in the model)", "taken for what they are, not a reply", (),
        tested=("test_evologics_codec.py", "EFAULT")),
    Row("`ATZ0`", "reboot: no answer, TCP dropped", "stored settings run again (with `AL`), every buffer emptied, "
        "no answer, a TCP client is disconnected", "—", keys=("Z",), tested=("test_emulator_commands.py", "ATZ0")),
    Row("`ATZ1` / `ATZ3` / `ATZ4`; `ATZ2`", "drop bursts / IMs / the whole buffer; `ATZ2` used by no driver",
        "frames not yet on air leave the model's FIFO (trace `drop`, cause `cleared`, `AT?ZD`); `ATZ2`: `OK`, "
        "clears nothing", "`ATZ4` after `ERROR BUFFER FULL` or `ERROR INTERNAL`", probe=b"ATZ4\rATZ2\r",
        answer=OK + OK, driver_code='self.command("Z", "4")'),
    Row("`AT&W`, `AT&F`, `AT&V`", "store, factory, dump (`Key: value` lines)", "yes (`&V`: `KEY: value` lines, "
        "an empty line)", "—", probe=b"AT&W\r", answer=OK, keys=("&W", "&F", "&V"),
        tested=("test_emulator_commands.py", "&V")),
    Row("`AT?S`", "`<STATE> <SUB> [free bytes]` (AT interpreter)", "`ONLINE NORMAL <free>` or `ONLINE "
        "DELIVERING <free>`, one line", "—", probe=b"AT?S\r", answer=rb"ONLINE (NORMAL|DELIVERING) \d+\r\n", keys=("?S",)),
    Row("`AT?DI`", "EMPTY / DELIVERING / FAILED / EXPIRED", "EMPTY / DELIVERING", "—", probe=b"AT?DI\r",
        answer=rb"(EMPTY|DELIVERING)\r\n", keys=("?DI",)),
    Row("`AT?E`, `?I`, `?V`", "last reception's RSSI, integrity, velocity", "RSSI and integrity as in the last "
        "`RECV*`; `?V` `0.00`", "—", probe=b"AT?E\rAT?V\r", answer=rb"-?\d+\r\n0\.00\r\n", keys=("?E", "?I", "?V")),
    Row("`AT?BV`", "battery voltage", "`24.00` (no battery model)", "—", probe=b"AT?BV\r", answer=rb"24\.00\r\n",
        keys=("?BV",)),
    Row("`AT?UT`, `AT!UT<s>`", "system time", "whole seconds; `!UT` sets it (32 bits)", "—",
        probe=b"AT!UT100\rAT?UT\r", answer=OK + rb"\d+\r\n", keys=("?UT", "!UT")),
    Row("`AT?BL`, `?BR`", "last bitrates", "the link's bitrate", "—", probe=b"AT?BL\r", answer=rb"\d+\r\n",
        keys=("?BL", "?BR")),
    Row("`AT?ZD`/`@ZD`, `?ZO`/`@ZO`", "drop / overflow counters, reset", "frames dropped (cleared, `AR 0`) / "
        "refused `BUFFER FULL`", "—", probe=b"AT@ZD\rAT?ZD\r", answer=OK + rb"0\r\n",
        keys=("?ZD", "?ZO", "@ZD", "@ZO")),
    Row("`AT?PC`, `?PID`", "packet counter, protocol id", "bursts accepted; `ZS`", "—", probe=b"AT?PID\r",
        answer=rb"0\r\n", keys=("?PC", "?PID")),
    Row("`AT`, `ATA`, `ATN`, `ATS`, `ATP`, `ATH`, `ATD`, `ATC`, `AT@CTRL`", "is anyone there; states, connection",
        "`OK`; no state is modelled", "a bare `AT` at start", probe=b"AT\rATA\rATH0\r", answer=OK + OK + OK,
        keys=("", "A", "N", "S", "P", "H", "D", "C", "@CTRL"), tested=(DUNE, "@CTRL"), driver_code='[("", "")]'),
    Row("a malformed command; an unknown one", "`ERROR WRONG FORMAT`; `ERROR UNKNOWN COMMAND`", "the same; a "
        "number of more than 10 digits (or `AT!UT` past 32 bits) `ERROR OUT OF RANGE`", "fails the command in "
        "flight", probe=b"AT?QQ\rAT!AL12345678901\r", answer=rb"ERROR UNKNOWN COMMAND\r\nERROR OUT OF RANGE\r\n"),
    Row("line ends", "`\\r` on serial, `\\n` on TCP from the host; `\\r\\n` from the modem", "any of them from the "
        "host; `\\r\\n` back", "`eol: auto` (CR on serial, LF on TCP)", probe=b"AT?AL\n", answer=rb"1\r\n",
        driver_code="eol=options.eol_bytes()"),
    Row("serial line, TCP port", "19200 8N1; TCP 9200", "a pty (not paced) or a loopback TCP port, at most 8 "
        "clients", "`baud` 19200, `socket://HOST:9200`", tested=("test_modems_e2e.py", "evologics-tcp")),
]
