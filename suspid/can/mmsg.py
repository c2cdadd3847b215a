"""Many datagrams per system call: Linux ``recvmmsg(2)`` through ctypes.

Where a system call is dear (a loaded host, a virtual machine) a reader taking one frame per
``recvmsg`` falls behind and the kernel drops frames; ``recvmmsg`` takes every queued frame,
up to a batch, in one call, each with its ancillary data. Python's :mod:`socket` does not wrap
it; where the C library has none, :func:`available` is ``False`` and callers use ``recvmsg``.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import socket
import struct
from typing import Any, Optional

#: ``struct cmsghdr`` head: length (``size_t``), level, type
_CMSG_HEAD = struct.Struct("@Nii")
_ALIGN = ctypes.sizeof(ctypes.c_size_t)
_SIZE_T = struct.Struct("@N")
_INT = struct.Struct("@i")
_UINT = struct.Struct("@I")
#: ``MSG_DONTWAIT``: return what is queued now
MSG_DONTWAIT = getattr(socket, "MSG_DONTWAIT", 0x40)


class _IOVec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class _MsgHdr(ctypes.Structure):
    _fields_ = [("msg_name", ctypes.c_void_p), ("msg_namelen", ctypes.c_uint32),
                ("msg_iov", ctypes.POINTER(_IOVec)), ("msg_iovlen", ctypes.c_size_t),
                ("msg_control", ctypes.c_void_p), ("msg_controllen", ctypes.c_size_t),
                ("msg_flags", ctypes.c_int)]


class _MMsgHdr(ctypes.Structure):
    _fields_ = [("msg_hdr", _MsgHdr), ("msg_len", ctypes.c_uint)]


def _libc_recvmmsg() -> Any:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        fn = libc.recvmmsg
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.POINTER(_MMsgHdr), ctypes.c_uint, ctypes.c_int,
                   ctypes.c_void_p]
    fn.restype = ctypes.c_int
    return fn


_RECVMMSG = _libc_recvmmsg()


def available() -> bool:
    """``True`` where the C library has ``recvmmsg``."""
    return _RECVMMSG is not None


def _cmsg_align(n: int) -> int:
    return (n + _ALIGN - 1) & ~(_ALIGN - 1)


def parse_cmsgs(buf: bytes) -> list[tuple[int, int, bytes]]:
    """``(level, type, data)`` per control message in ``buf``, as ``socket.recvmsg`` lists
    them."""
    out = []
    off = 0
    head = _CMSG_HEAD.size
    while off + head <= len(buf):
        length, level, kind = _CMSG_HEAD.unpack_from(buf, off)
        if length < head:
            break
        out.append((level, kind, bytes(buf[off + _cmsg_align(head):off + length])))
        off += _cmsg_align(length)
    return out


class MultiReceiver:
    """Receive up to ``batch`` datagrams of a socket per system call.

    ``sock`` a datagram socket; ``size`` the largest datagram (bytes, longer ones truncated);
    ``ancsize`` the ancillary buffer per datagram (bytes). Raises ``OSError`` without
    ``recvmmsg`` (:func:`available`).
    """

    def __init__(self, sock: socket.socket, size: int, ancsize: int, batch: int = 64) -> None:
        if _RECVMMSG is None:
            raise OSError(errno.ENOSYS, "recvmmsg is not available")
        self.sock = sock
        self.size = int(size)
        self.ancsize = int(ancsize)
        self.batch = max(1, int(batch))
        n = self.batch
        self._data = ctypes.create_string_buffer(n * self.size)
        self._ctl = ctypes.create_string_buffer(max(1, n * self.ancsize))
        self._iov = (_IOVec * n)()
        self._vec = (_MMsgHdr * n)()
        base = ctypes.addressof(self._data)
        cbase = ctypes.addressof(self._ctl)
        for i in range(n):
            self._iov[i].iov_base = base + i * self.size
            self._iov[i].iov_len = self.size
            hdr = self._vec[i].msg_hdr
            hdr.msg_iov = ctypes.pointer(self._iov[i])
            hdr.msg_iovlen = 1
            hdr.msg_control = cbase + i * self.ancsize if self.ancsize else None
        self._mem = memoryview(self._vec).cast("B")
        self._stride = ctypes.sizeof(_MMsgHdr)
        self._ctl_off = _MsgHdr.msg_controllen.offset
        self._flags_off = _MsgHdr.msg_flags.offset
        self._len_off = _MMsgHdr.msg_len.offset
        self._used = n   # entries the last call filled (to reset)
        #: system calls made, datagrams received (for benchmarks)
        self.calls = 0
        self.received = 0

    def recv(self) -> list[tuple[bytes, list[tuple[int, int, bytes]], int]]:
        """Every datagram queued now, up to ``batch``: ``(data, ancdata, flags)`` each, as
        ``socket.recvmsg`` returns them; raises ``OSError`` when the socket cannot be read."""
        vec = self._vec
        mem = self._mem
        stride = self._stride
        ctl_off = self._ctl_off
        flags_off = self._flags_off
        anc = self.ancsize
        for i in range(self._used):                 # the kernel wrote these: reset
            base = i * stride
            _SIZE_T.pack_into(mem, base + ctl_off, anc)
            _INT.pack_into(mem, base + flags_off, 0)
        got = _RECVMMSG(self.sock.fileno(), vec, self.batch, MSG_DONTWAIT, None)
        self.calls += 1
        if got < 0:
            self._used = 0
            err = ctypes.get_errno()
            if err in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EINTR):
                return []
            raise OSError(err, os.strerror(err))
        self._used = got
        raw = self._data.raw
        ctl = self._ctl.raw
        len_off = self._len_off
        out = []
        size = self.size
        for i in range(got):
            base = i * stride
            n = min(_UINT.unpack_from(mem, base + len_off)[0], size)
            clen = min(_SIZE_T.unpack_from(mem, base + ctl_off)[0], anc)
            data = raw[i * size:i * size + n]
            cmsgs = parse_cmsgs(ctl[i * anc:i * anc + clen]) if clen else []
            out.append((data, cmsgs, _INT.unpack_from(mem, base + flags_off)[0]))
        self.received += got
        return out


def make(sock: socket.socket, size: int, ancsize: int) -> Optional[MultiReceiver]:
    """A :class:`MultiReceiver` on ``sock``, or ``None`` where ``recvmmsg`` is missing."""
    try:
        return MultiReceiver(sock, size, ancsize)
    except OSError:
        return None
