"""Issue 18 hand check (docs/dune-hand-check.md): drive two LSTS DUNE instances running the unmodified
Transports.Evologics task against hilgate's emulated modems, with IMC UamTxFrame over UDP, and count
what comes back (UamTxStatus, UamRxFrame, UamRxRange).  Needs a DUNE build; no test uses it.

usage: dune_drive.py DURATION_S
Instance 1: lauv-noptilus-1 (IMC 0x001A, EvoLogics address 1), UDP 16001, reports to 17001.
Instance 2: lauv-noptilus-2 (IMC 0x001B, EvoLogics address 2), UDP 16002, reports to 17002.
"""
import collections
import json
import select
import socket
import struct
import sys
import time

def crc16(data: bytes) -> int:
    crc = 0
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc

def imc(mgid: int, payload: bytes, src: int, dst: int, dst_ent: int = 255) -> bytes:
    header = struct.pack("<HHHdHBHB", 0xFE54, mgid, len(payload), time.time(), src, 0, dst, dst_ent)
    body = header + payload
    return body + struct.pack("<H", crc16(body))

def text(s: bytes) -> bytes:
    return struct.pack("<H", len(s)) + s

def parse_text(b: bytes, i: int):
    n = struct.unpack_from("<H", b, i)[0]
    return b[i + 2:i + 2 + n], i + 2 + n

SELF = 0x4000  # this script's IMC address
DUNES = {1: dict(imc=0x001A, name=b"lauv-noptilus-1", port=16001, listen=17001),
         2: dict(imc=0x001B, name=b"lauv-noptilus-2", port=16002, listen=17002)}
STATUS = {0: "DONE", 1: "FAILED", 2: "CANCELED", 3: "BUSY", 4: "INV_ADDR", 5: "IP", 6: "UNSUPPORTED", 7: "INV_SIZE"}

def main():
    duration = float(sys.argv[1])
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ins = {}
    for k, d in DUNES.items():
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", d["listen"]))
        ins[s] = k
    counts = collections.Counter()
    ranges = collections.Counter()
    statuses = collections.defaultdict(collections.Counter)
    rx = collections.Counter()
    payload_ok = collections.Counter()
    sent = {}
    seq = 0
    start = time.monotonic()
    next_send = start + 5
    kinds = ["ack", "noack", "burst"]
    while time.monotonic() - start < duration:
        now = time.monotonic()
        if now >= next_send:
            seq += 1
            frm = 1 if seq % 2 else 2
            to = 2 if frm == 1 else 1
            kind = kinds[(seq // 2) % 3]
            data = (b"hil%05d," % seq) + (b"x" * (100 if kind == "burst" else 20))
            flags = 1 if kind == "ack" else 0  # UTF_ACK
            msg = struct.pack("<H", seq) + text(DUNES[to]["name"]) + struct.pack("<B", flags) + text(data)
            out.sendto(imc(814, msg, SELF, DUNES[frm]["imc"]), ("127.0.0.1", DUNES[frm]["port"]))
            sent[seq] = (frm, to, kind, data)
            counts[f"sent_{kind}"] += 1
            next_send = now + 15
        r, _, _ = select.select(list(ins), [], [], 0.5)
        for s in r:
            b, _ = s.recvfrom(65535)
            sync, mgid, size = struct.unpack_from("<HHH", b, 0)
            p = b[20:20 + size]
            k = ins[s]
            if mgid == 816:
                sq, value = struct.unpack_from("<HB", p, 0)
                err, _ = parse_text(p, 3)
                if sq in sent:
                    statuses[sent[sq][2]][STATUS.get(value, value)] += 1
                    if value not in (5,):
                        print(f"{time.monotonic()-start:7.1f} dune{k} seq {sq} {sent[sq][2]} -> {STATUS.get(value)} {err.decode()}", flush=True)
            elif mgid == 815:
                src, i = parse_text(p, 0)
                dst, i = parse_text(p, i)
                flags = p[i]
                data, _ = parse_text(p, i + 1)
                rx[k] += 1
                sq = int(data[3:8]) if data[:3] == b"hil" else None
                if sq in sent and sent[sq][3] == data:
                    payload_ok[k] += 1
                print(f"{time.monotonic()-start:7.1f} dune{k} UamRxFrame from {src.decode()} {len(data)} B flags {flags}", flush=True)
            elif mgid == 817:
                sq = struct.unpack_from("<H", p, 0)[0]
                sysname, i = parse_text(p, 2)
                value = struct.unpack_from("<f", p, i)[0]
                ranges[f"{value:.2f}"] += 1
                print(f"{time.monotonic()-start:7.1f} dune{k} UamRxRange {sysname.decode()} {value:.2f} m", flush=True)
    print(json.dumps({"sent": counts, "status": statuses, "rx_frames": rx, "rx_payload_ok": payload_ok,
                      "ranges_m": ranges}, indent=1))

main()
