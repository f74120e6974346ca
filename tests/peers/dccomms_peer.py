#!/usr/bin/env python3
"""A dccomms application, reduced to its bytes: raw posix_ipc and its own VariableLength2BPacket code.

It does what ``CommsDeviceService`` does on the application side (IPHY_TYPE_DLINK) and nothing of
hilgate: open ``/X_tx_dlnk_phy`` and ``/X_rx_dlnk_phy`` with O_CREAT, say REQ_STATE, send FRAME
messages of the whole 2065-byte buffer (real packet + virtual area), read FRAME and CMD_STATE.
Prints one JSON line per event on stdout with CLOCK_MONOTONIC times, so a test can compare them.

    dccomms_peer.py LINK --send N --dst ADDR [--interval S] [--size B] [--receive N] [--timeout S] [--clear]
"""

import argparse
import binascii
import json
import os
import struct
import sys
import time

import posix_ipc

MAX_PAYLOAD = 2048
MAX_REAL = 1 + 2 + MAX_PAYLOAD + 2  # 2053
BODY = MAX_REAL + 12  # 2065


def encode_vl2b(payload: bytes, seq: int, src: int, dst: int) -> bytes:
    real = b"\x55" + len(payload).to_bytes(2, "big") + payload + binascii.crc_hqx(payload, 0).to_bytes(2, "big")
    return real.ljust(MAX_REAL, b"\xee") + struct.pack("<III", seq, src, dst)


def decode_vl2b(body: bytes) -> dict:
    length = int.from_bytes(body[1:3], "big")
    payload = body[3 : 3 + length]
    crc_ok = binascii.crc_hqx(body[3 : 3 + length + 2], 0) == 0 and body[0] == 0x55
    seq, src, dst = struct.unpack_from("<III", body, MAX_REAL)
    return {"payload": payload.decode("latin-1"), "crc_ok": crc_ok, "seq": seq, "src": src, "dst": dst,
            "body_len": len(body)}


def emit(**fields) -> None:
    print(json.dumps({"mono": time.monotonic(), **fields}), flush=True)


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("link")
    p.add_argument("--send", type=int, default=0)
    p.add_argument("--dst", type=int, default=255)
    p.add_argument("--src", type=int, default=0)
    p.add_argument("--interval", type=float, default=0.5)
    p.add_argument("--size", type=int, default=10)
    p.add_argument("--receive", type=int, default=0)
    p.add_argument("--timeout", type=float, default=10.0)
    p.add_argument("--raw", help="send this hex message as is (after the frames), for bad-input tests")
    p.add_argument("--clear", action="store_true",
                   help="empty the input queue before REQ_STATE, as CommsDeviceService::Init's ClearInputQueue does")
    a = p.parse_args()
    old = os.umask(0)
    tx = posix_ipc.MessageQueue(f"/{a.link}_tx_dlnk_phy", posix_ipc.O_CREAT, 0o777, 10, 8192)
    rx = posix_ipc.MessageQueue(f"/{a.link}_rx_dlnk_phy", posix_ipc.O_CREAT, 0o777, 10, 8192)
    os.umask(old)
    if a.clear:
        cleared = []
        while True:
            try:
                message, _ = rx.receive(0)
            except posix_ipc.BusyError:
                break
            cleared.append(message[0])
        emit(ev="cleared", types=cleared)
    tx.send(b"\x01")  # REQ_STATE
    emit(ev="req_state")
    for i in range(a.send):
        payload = f"{a.link}#{i:04d}".encode().ljust(a.size, b".")[: a.size]
        tx.send(b"\x00" + encode_vl2b(payload, i, a.src, a.dst))
        emit(ev="sent", seq=i, payload=payload.decode())
        if i + 1 < a.send:
            time.sleep(a.interval)
    if a.raw:
        for chunk in a.raw.split(","):
            tx.send(bytes.fromhex(chunk))
            emit(ev="sent_raw", length=len(chunk) // 2)
    received = 0
    deadline = time.monotonic() + a.timeout
    while received < a.receive and time.monotonic() < deadline:
        try:
            message, _ = rx.receive(max(0.01, deadline - time.monotonic()))
        except posix_ipc.BusyError:
            break
        if message[0] == 0:
            received += 1
            emit(ev="frame", **decode_vl2b(message[1:]))
        elif message[0] == 2:
            emit(ev="state", ready=message[1] == 1)
    emit(ev="done", received=received)
    return 0


if __name__ == "__main__":
    sys.exit(main())
