"""Receive cost per frame: one ``select`` + ``recvmsg`` per frame against ``recvmmsg`` batches.

Run natively::

    .venv/bin/python tools/bench_recv.py [--frames 200000] [--batch 64] [--repeat 5]

A 16-byte CAN frame is written ``--frames`` times into a Unix datagram socket pair (this
host's kernel has no AF_CAN; the socket layer's per-call cost is what is measured, and a
CAN_RAW socket's ``recvmsg`` works the same way), with the arrival-time ancillary data the
SocketCAN reader asks for. The queued frames are then read back as a lagging reader does:

* ``recvmsg``: ``select`` then ``recvmsg`` per frame (python-can's ``SocketcanBus``, and this
  project's reader before batching);
* ``recvmmsg``: :class:`suspid.can.mmsg.MultiReceiver`, up to ``--batch`` frames per call,
  ``select`` only when a batch came back short.

Printed: system calls per frame and microseconds per frame of each, and their ratio (best
of ``--repeat``). In a virtual machine or a User-Mode Linux guest a system call costs far
more than here, and the ratio of calls is what carries over.
"""
from __future__ import annotations

import argparse
import select
import socket
import struct
import time

from suspid.can import mmsg
from suspid.can.bus import _ANC_SIZE, CANFD_MTU, SO_TIMESTAMPNS

FRAME = struct.pack("=IB3x8s", 0x123, 8, bytes(range(8)))


def _fill(n: int) -> tuple[socket.socket, socket.socket]:
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    for s in (a, b):
        for opt in (getattr(socket, "SO_RCVBUFFORCE", 33), socket.SO_RCVBUF):
            try:
                s.setsockopt(socket.SOL_SOCKET, opt, 256 << 20)
                break
            except OSError:
                continue
        s.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_SNDBUFFORCE", 32), 256 << 20)
    b.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    for _ in range(n):
        a.send(FRAME)
    return a, b


def one_by_one(n: int) -> tuple[float, int]:
    a, b = _fill(n)
    with a, b:
        calls = 0
        t0 = time.perf_counter()
        for _ in range(n):
            select.select([b], [], [], 0.1)
            b.recvmsg(CANFD_MTU, _ANC_SIZE)
            calls += 2
        return time.perf_counter() - t0, calls


def batched(n: int, batch: int) -> tuple[float, int]:
    a, b = _fill(n)
    with a, b:
        rx = mmsg.MultiReceiver(b, CANFD_MTU, _ANC_SIZE, batch)
        got = 0
        selects = 0
        full = False
        t0 = time.perf_counter()
        while got < n:
            if not full:
                select.select([b], [], [], 0.1)
                selects += 1
            k = len(rx.recv())
            got += k
            full = k >= batch
        return time.perf_counter() - t0, rx.calls + selects


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    if not mmsg.available():
        raise SystemExit("error: no recvmmsg in this C library")
    one = min(one_by_one(a.frames) for _ in range(a.repeat))
    many = min(batched(a.frames, a.batch) for _ in range(a.repeat))
    n = a.frames
    print(f"frames {n}, batch {a.batch}, best of {a.repeat}")
    print(f"{'reader':<12}{'calls/frame':>12}{'us/frame':>10}")
    print(f"{'recvmsg':<12}{one[1] / n:>12.3f}{1e6 * one[0] / n:>10.3f}")
    print(f"{'recvmmsg':<12}{many[1] / n:>12.3f}{1e6 * many[0] / n:>10.3f}")
    print(f"ratio recvmsg/recvmmsg: calls {one[1] / many[1]:.1f}x, time {one[0] / many[0]:.2f}x")


if __name__ == "__main__":
    main()
