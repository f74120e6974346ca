"""The WHOI Micro-Modem's conformance rows (``conformance_kit``): the sentences of WHOI's Micro-Modem Software
Interface Guide as far as it is public (its list as goby3's MMDriver gives it, "from Micro-Modem Software
Interface Guide v. 3.04", with WHOI's public ``libumutil.h`` for the fields and rates, a public v8
``$CACST`` capture, and ``acomms`` 3.1.1, WHOI's Python library, as second source).  The outside library is
``acomms`` (tests/peers/acomms_peer.py, driven by tests/test_micromodem.py and
tests/test_fuzz_bytes_micromodem.py).  The probes go to an emulated Micro-Modem at address 1, a second one
at address 2 10 m away."""

from conformance_kit import Row

T = rb"\d{6}"  # hhmmss
ERR = rb"\$CAERR," + T + rb",NMEA,1,Unsupported "


def unsupported(command: str, what: str, real: str, library: tuple[str, ...] = (), answers: str = "") -> Row:
    """A host command the emulator does not do: ``$CAERR,hhmmss,NMEA,1,Unsupported <command>``."""
    return Row(f"`${command}`{answers}", real, f"not emulated ({what}): `$CAERR,hhmmss,NMEA,1,Unsupported {command}`",
               "—", library, probe=f"${command},0\r\n".encode(), answer=ERR + command.encode())


ROWS = [
    Row("`$CCCFG,<name>,<value>` → `$CACFG`", "sets a configuration parameter, echoed", "kept and echoed; `SRC` "
        "moves the link in the simulation; `ALL,0` the factory values (the link keeps its address); an unknown "
        "name or value: `$CAERR`", "`$CCCFG,SRC,<address>` at start", ("Micromodem.set_config",),
        probe=b"$CCCFG,DTO,5\r\n$CCCFG,NOPE,1\r\n", answer=rb"\$CACFG,DTO,5\*[0-9A-F]{2}\r\n\$CAERR," + T + rb",CCCFG,3",
        keys=("CCCFG",), driver_code='sentence("CCCFG", "SRC"'),
    Row("`$CCCFQ,<name>` → `$CACFG`", "queries one parameter, `ALL` every one", "`SRC`, `AGN`, `ASD`, `BND`, `CST`, "
        "`CTO`, `DTO`, `PCM`, `REV`, `RXD`, `RXP`, `TAT`, `TXF`, `TXP`, `XST`; `ALL`; `info` → `info.firmware_version`",
        "—", ("Micromodem.get_config", "Micromodem.query_modem_info", "Micromodem.connect_serial"),
        probe=b"$CCCFQ,SRC\r\n", answer=rb"\$CACFG,SRC,1\*", keys=("CCCFQ",)),
    Row("settings `RXP`, `TXP`, `TXF`, `CST`, `RXD`", "whether the modem prints `$CARXP`, `$CATXP`, `$CATXF`, "
        "`$CACST`, `$CARXD`", "honoured, 1 by default (goby's driver sets `CST` and `RXP` to 1 at start)", "—",
        ("Micromodem.set_config",), probe=b"$CCCFQ,RXP\r\n", answer=rb"\$CACFG,RXP,1\*",
        tested=("test_micromodem.py", "wait_for_data_packet")),
    Row("settings `DTO`, `CTO`", "seconds the modem waits for a frame, for a cycle", "`DTO` 5 s of the host's "
        "time (whatever `--speed`); `CTO` bounds a cycle", "—", probe=b"$CCCFQ,CTO\r\n", answer=rb"\$CACFG,CTO,10\*",
        tested=("test_micromodem.py", "DTO is 5 s of the host's time")),
    Row("settings `ASD`, `BND`, `PCM`, `REV`, `TAT`, `XST`, `AGN`", "test data, band, channel mask, `$CAREV`, "
        "turnaround, `$CAXST`, analog gain", "kept and answered; `AGN` is `$CACST`'s gain (250 is 30 dB); the "
        "others change nothing in the model (`$CAXST` is not printed)", "—", probe=b"$CCCFQ,AGN\r\n",
        answer=rb"\$CACFG,AGN,250\*"),
    Row("`$CCCYC,0,src,dest,rate,ack,n` → `$CACYC`", "a cycle: the modem then asks for each frame", "echoed; "
        "`$CAERR` for a bad rate or count, a busy modem, an uplink request (`src` another modem)",
        "one cycle per GLI frame, at the link's `rate`", ("Micromodem.send_packet_data", "Micromodem.send_test_packet"),
        probe=b"$CCCYC,0,1,2,1,0,1\r\n$CCTXD,1,2,0,48454C4C4F\r\n",
        answer=rb"\$CACYC,0,1,2,1,0,1\*.*\$CADRQ," + T + rb",1,2,0,64,1\*.*\$CATXD,1,2,0,5\*.*\$CATXP,64\*.*\$CATXF,64\*",
        keys=("CCCYC",), driver_code='sentence("CCCYC"'),
    Row("`$CADRQ,hhmmss,src,dest,ack,bytes,frame`", "the modem asks for a frame", "the rate's frame size; "
        "`$CAERR,…,DATA_TIMEOUT,<frame>` if none comes within `DTO`: what was given goes, or the cycle ends",
        "answers with `$CCTXD`", ("Micromodem.send_packet_data",), tested=("test_micromodem.py", "DATA_TIMEOUT"),
        driver_code='"CADRQ": _request'),
    Row("`$CCTXD,src,dest,ack,<hex>` → `$CATXD`", "a frame's data, echoed with its size", "echoed; too long for "
        "the rate: as if not given (`DATA_TIMEOUT`); unasked: `$CAERR`", "each frame of the GLI frame",
        ("Micromodem.send_packet_data",), keys=("CCTXD",), tested=("test_fuzz_bytes_micromodem.py", "send_packet_data"),
        driver_code='sentence("CCTXD"'),
    unsupported("CCTXA", "ASCII data", "a frame's data as ASCII", answers=" → `$CATXA`"),
    Row("`$CATXP,<bytes>`", "start of the packet's transmission", "when the model puts it on air (`TXP`)", "ignored",
        tested=("test_micromodem.py", "CATXP")),
    Row("`$CATXF,<bytes>`", "end of the transmission", "when the model's transmission ends (`TXF`); `0` after "
        "a rate-0 cycle init and after a receiver's acknowledgement", "ends the cycle (a `tx` trace line)",
        ("Micromodem.send_packet_data",), tested=("test_micromodem.py", "CATXF"), driver_code='"CATXF": _transmitted'),
    Row("`$CARXP,<0 FSK|1 PSK>`", "a packet detected, before it is decoded", "when a packet begins to arrive, any "
        "packet the modem hears (`RXP`)", "ignored", ("Micromodem.wait_for_data_packet",),
        tested=("test_micromodem.py", "wait_for_data_packet")),
    Row("`$CACYC` at the receiver", "the cycle of an arriving packet", "when the model delivers a packet for this "
        "modem or broadcast (address 0); at rate 0 for the cycle-init minipacket", "starts the frames it joins",
        ("Micromodem.wait_for_data_packet",), tested=("test_micromodem.py", '"CACYC"'), driver_code='"CACYC": _cycle'),
    Row("`$CARXD,src,dest,ack,frame,<hex>`", "a received frame", "each frame as sent (a real modem's padding of a "
        "short last frame is not emulated) (`RXD`)", "joined and parsed by the packet class",
        ("Micromodem.attach_packetrx_queue", "Micromodem.wait_for_data_packet"),
        tested=("test_fuzz_bytes_micromodem.py", "receive"), driver_code='"CARXD": _received'),
    Row("`$CARXA`", "a received frame as ASCII", "never printed (`$CARXD` always)", "—"),
    Row("`$CACST` (version 8)", "cycle receive statistics: mode, time of arrival, matched filter, gain, shifts, "
        "rate, addresses, PSK error, packet type, frames, bad frames, SNRs, MSE, DQF, Doppler, noise, carrier, "
        "band; widths as a Micro-Modem 2 prints them", "after each packet and minipacket for this modem; mode 1 "
        "when the model lost it; the link budget's RSSI on the modem's scales (SPL = 185 dB re 1 µPa less the "
        "loss, SNR against 105 dB), DQF for FSK only (−1 for PSK), the closing speed as Doppler (`CST`)",
        "into the trace (`modem_stats`); mode 1 counted (`err`, `bad_crc`)", ("Micromodem.attach_incoming_cst_queue",),
        tested=("test_micromodem.py", "CACST_V8"), driver_code='"CACST": _statistics'),
    Row("`$CAACK,src,dest,frame,1`", "the receiver's acknowledgement of a frame that asked", "the model's ACK "
        "frame on the channel (`ack_bytes` 16, 50 ms turnaround); one `$CAACK` per frame that asked when it comes "
        "back, nothing when it does not", "traced `ack`; the frame `delivered` once every frame was, else `failed`",
        ("Micromodem.send_packet_data",), tested=("test_micromodem.py", "acks"), driver_code='"CAACK": _acknowledged'),
    Row("`$CCMPC,src,dest` → `$CAMPC`, `$CAMPA`, `$CAMPR,dest,src,<owtt>`", "a two-way ping; the one-way travel "
        "time", "the reply is the model's ACK; `owtt` what the model measured from the round trip (s, 4 "
        "decimals); a `$CACST` for the ping at the remote and for its reply", "—",
        ("Micromodem.send_ping", "Micromodem.wait_for_ping_reply"), keys=("CCMPC",),
        tested=("test_micromodem.py", "owtt")),
    Row("`$CCMUC,src,dest,<13 bits hex>` → `$CAMUC`, `$CAMUA` at the remote", "a user minipacket", "an FSK "
        "minipacket (0.5 s) on the channel; `$CAMUR` (its reply) is not emulated", "—",
        ("Micromodem.send_minipacket", "Micromodem.wait_for_minipacket"), probe=b"$CCMUC,1,2,1ABC\r\n",
        answer=rb"\$CAMUC,1,2,1ABC\*", keys=("CCMUC",)),
    Row("`$CCMEC,src,dest,line,mode,arg` → `$CAMEC`", "a hardware line, local or at a remote (`$CAMEA`, "
        "`$CAMER`)", "the local modem's only, echoed (no line modelled); a remote's: `$CAERR`", "—",
        ("Micromodem.change_gpio",), probe=b"$CCMEC,1,1,5,1,1\r\n", answer=rb"\$CAMEC,1,1,5,1,1\*", keys=("CCMEC",)),
    unsupported("CCEXL", "no hardware lines", "external hardware control, local modem only"),
    unsupported("CCMSC", "no sleep", "sleep, local or at a remote (`$CAMSC`, `$CAMSA`, `$CAMSR`)"),
    unsupported("CCRSP", "no sweeps", "an FM sweep ping", ("Micromodem.send_sweep",), " → `$CARSP`"),
    unsupported("CCPDT", "navigation pings", "ping REMUS digital transponders; `$SNTTA` travel times",
                ("Micromodem.ping_remus",)),
    unsupported("CCPNT", "navigation pings", "ping narrowband transponders; `$SNTTA`, `$SNMFD`",
                ("Micromodem.ping_narrow",)),
    Row("`$CCCLK,yyyy,MM,dd,HH,mm,ss` → `$CACLK`; `$CCCLQ`", "sets / reads the modem's clock (Micro-Modem 1)",
        "the modem's clock moves (every time it prints follows); answered with `$CACLK`", "—",
        probe=b"$CCCLQ,0\r\n", answer=rb"\$CACLK,\d{4},\d+,\d+,\d+,\d+,\d+\*", keys=("CCCLK", "CCCLQ")),
    Row("`$CCTMS,<ISO 8601>,<mode>` → `$CATMS,<timed out>,<time>`", "sets the clock (Micro-Modem 2)",
        "moved (`acomms`' `…ZZ` time taken); `$CATMS,0,<time>`", "—", ("Micromodem.set_time",), keys=("CCTMS",),
        tested=("test_micromodem.py", "set_time")),
    Row("`$CCTMQ` → `$CATMQ,<ISO 8601>,<clock source>,<PPS source>`", "reads the clock (Micro-Modem 2)",
        "the emulator's clock, `RTC`, `NONE`", "—", ("Micromodem.get_time_info",),
        probe=b"$CCTMQ,0\r\n", answer=rb"\$CATMQ,\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z,RTC,NONE\*", keys=("CCTMQ",)),
    Row("`$CCALQ` → `$CAALQ`", "the NMEA API level", "11", "—", ("Micromodem.query_nmea_api_level",),
        probe=b"$CCALQ,0\r\n", answer=rb"\$CAALQ,0,11\*", keys=("CCALQ",)),
    unsupported("CCAGC", "no gain control", "automatic gain control"),
    unsupported("CCCFR", "no noise measurement", "measures the noise; `$SNCFR`"),
    unsupported("CCTDP", "FDP packets", "a Flexible Data Protocol packet (Micro-Modem 2); `$CATDP`, `$CARDP`",
                ("Micromodem.send_tdp",)),
    unsupported("CCTFP", "FDP packets", "an FDP packet, newer firmware"),
    unsupported("CCCMD", "FDP pings", "an FDP ping (`$CACMD`, `$CACMA`, `$CACMR`)", ("Micromodem.send_fdp_ping",)),
    unsupported("CCTJN", "JANUS", "a JANUS packet (`$CATJN`, `$CAJRX`)", ("Micromodem.send_tjn",)),
    unsupported("CCSWP", "no sweeps", "an FM sweep"),
    unsupported("CCMSQ", "no sequences", "a maximal-length sequence"),
    unsupported("CCSST", "no statistics requests", "a single-shot `$CASST`", ("Micromodem.send_single_shot_sst",)),
    unsupported("CCPGT", "navigation pings", "ping generic transponders"),
    unsupported("CCHIB", "no hibernation", "hibernate (`$CAHIB`, `$CAHBR`)", ("Micromodem.start_hibernate",)),
    unsupported("CCRBR", "no modem log", "the modem's log (`$CARBR`, `$CARBS`)"),
    unsupported("CCPAS", "no pass-through", "a pass-through message"),
    unsupported("CCACM", "no acoustic commands", "an acoustic modem command"),
    unsupported("CCRST", "no firmware slots", "restarts into a firmware slot"),
    Row("`$CAXST`", "transmit statistics (`XST`)", "not printed (`XST` is kept, nothing more)", "ignored"),
    Row("`$CADQF`, `$CASHF`, `$CAMFD`, `$CASNR`, `$CADOP`, `$CATOA`", "one figure each of a reception (older "
        "firmware; `$CACST` holds them all)", "not printed: their figures are in `$CACST`", "ignored"),
    Row("`$CAMSG`", "transaction messages (`BAD_CRC`, `PACKET_TIMEOUT`)", "not printed: a packet the model lost "
        "is `$CACST` mode 1", "ignored"),
    Row("`$CAREV,hhmmss,AUV,<version>`", "the firmware, at start and periodically (`REV`)", "only after a cycle "
        "the model never put on air (the one sentence after which every host forgets its cycle)",
        "a restart: the frame goes again, the address is set again",
        tested=("test_micromodem.py", "refuses_ends_with_the_modems_restart_sentence"),
        driver_code='"CAREV": _restarted'),
    Row("`$CAERR,hhmmss,module,number,text`", "errors", "a bad checksum or no sentence: `NMEA,2`; an unknown "
        "sentence: `NMEA,1,Unsupported`; the cycle's refusals; `DATA_TIMEOUT`", "fails the cycle with the "
        "modem's words (`data_timeout`, `refused`)", ("Micromodem.send_packet_data",),
        probe=b"$CCCYC,0,1,2,1,0,1*00\r\n", answer=rb"\$CAERR," + T + rb",NMEA,2,Checksum", driver_code='"CAERR": _error'),
    Row("`$CADBG`, `$CABBD`, `$SNMFD`, `$SNTTA`, `$SNCFR`", "debug, baseband dumps, navigation", "never printed",
        "ignored"),
    Row("rates 0–6", "0: FH-FSK 80 bit/s, 1 × 32 B; 1: 250 bit/s, 3 × 64; 2: 500, 3 × 64; 3: 1200, 2 × 256; 4: 1300, "
        "2 × 256; 5: 5300, 8 × 256 (`libumutil.h`); 6: 490, 6 × 32 (WHOI's page)", "a packet is one frame of the model "
        "with its rate's air time: 0.3 s of probe (PSK) + its bytes at the rate; rate 0 after a 0.8 s cycle-init "
        "minipacket", "`rate` 0–5", ("Micromodem.send_packet_data",), tested=("test_micromodem.py", "/ 250")),
    Row("serial line", "19200 8N1 by default", "not paced", "`baud` 19200", ("Micromodem.connect_serial",),
        tested=("test_micromodem.py", "19200")),
]
