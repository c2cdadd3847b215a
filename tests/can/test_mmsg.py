"""Batch receive (recvmmsg) gives what one recvmsg per datagram gives, in order."""
from __future__ import annotations

import socket
import struct

import pytest

from suspid.can import mmsg
from suspid.can.bus import _ANC_SIZE, CANFD_MTU, SO_TIMESTAMPNS

pytestmark = pytest.mark.skipif(not mmsg.available(), reason="no recvmmsg in this C library")


def _pair() -> tuple[socket.socket, socket.socket]:
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    b.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    return a, b


def _frames(n: int) -> list[bytes]:
    return [struct.pack("=IB3x8s", 0x100 + i, 8, bytes([i % 256]) * 8) for i in range(n)]


def test_batches_equal_recvmsg_one_by_one() -> None:
    frames = _frames(150)
    a, b = _pair()
    c, d = _pair()
    with a, b, c, d:
        for f in frames:
            a.send(f)
            c.send(f)
        rx = mmsg.MultiReceiver(b, CANFD_MTU, _ANC_SIZE, batch=64)
        got = []
        sizes = []
        while True:
            batch = rx.recv()
            if not batch:
                break
            sizes.append(len(batch))
            got += batch
        one = [d.recvmsg(CANFD_MTU, _ANC_SIZE)[:3] for _ in frames]
    assert sizes == [64, 64, 22]
    assert rx.calls == 4 and rx.received == 150
    assert [g[0] for g in got] == frames == [o[0] for o in one]
    assert [g[2] for g in got] == [o[2] for o in one]
    # the same ancillary layout (level, type, length) and a nanosecond arrival time each
    for g, o in zip(got, one):
        assert [(lv, k, len(x)) for lv, k, x in g[1]] == [(lv, k, len(x)) for lv, k, x in o[1]]
        assert g[1] and g[1][0][:2] == (socket.SOL_SOCKET, SO_TIMESTAMPNS)
    stamps = [struct.unpack("@ll", g[1][0][2]) for g in got]
    assert stamps == sorted(stamps)


def test_long_datagram_is_cut_and_flagged() -> None:
    a, b = _pair()
    with a, b:
        a.send(bytes(100))
        a.send(bytes(16))
        got = mmsg.MultiReceiver(b, CANFD_MTU, _ANC_SIZE, batch=8).recv()
    assert [len(g[0]) for g in got] == [CANFD_MTU, 16]
    assert got[0][2] & socket.MSG_TRUNC and not got[1][2] & socket.MSG_TRUNC


def test_nothing_queued_and_closed_socket() -> None:
    a, b = _pair()
    rx = mmsg.MultiReceiver(b, CANFD_MTU, _ANC_SIZE)
    assert rx.recv() == []
    a.close()
    b.close()
    with pytest.raises(OSError):
        rx.recv()


def test_control_messages_parsed_like_recvmsg() -> None:
    a, b = _pair()
    with a, b:
        r, w = socket.socketpair()
        with r, w:
            a.sendmsg([b"x" * 16], [(socket.SOL_SOCKET, socket.SCM_RIGHTS,
                                     struct.pack("i", r.fileno()))])
            got = mmsg.MultiReceiver(b, CANFD_MTU, 64, batch=4).recv()
    kinds = [(lv, k) for lv, k, _ in got[0][1]]
    assert (socket.SOL_SOCKET, socket.SCM_RIGHTS) in kinds
    assert (socket.SOL_SOCKET, SO_TIMESTAMPNS) in kinds
    for lv, k, data in got[0][1]:
        if k == socket.SCM_RIGHTS:
            socket.close(struct.unpack("i", data[:4])[0])
