"""Opening python-can buses the same way in the node and the estimator.

``--interface I --channel C`` becomes ``can.Bus(interface=I, channel=C)``, except:
``slcan`` + ``pty`` is the simulated node's adapter (registered in :data:`CHANNEL_FACTORIES`
by :mod:`firmware_sim.transport`); ``slcan`` + a device is :class:`BufferedSlcanBus` (chunked
serial reads, optionally the adapter's timestamps); ``virtual`` preserves the sender's
timestamps; ``udp_multicast`` is refused.

:class:`SocketcanReader` reads a SocketCAN socket itself, for what python-can does not pass
on: the kernel's drop count (``SO_RXQ_OVFL``) and the controller's error frames by class.
"""
from __future__ import annotations

import select
import socket
import struct
from collections import Counter, deque
from typing import Any, Callable, Optional

import can
import serial
from can.interfaces.slcan import slcanBus

from suspid.can import mmsg
from suspid.errors import UsageError

#: interfaces refused on purpose
REFUSED = {"udp_multicast": "a network transport; use virtual, slcan or socketcan"}

#: ``(interface, channel) -> bus factory`` for channels that are not python-can's (the
#: simulated node adapter registers ``("slcan", "pty")``)
CHANNEL_FACTORIES: dict[tuple[str, str], Callable[..., can.BusABC]] = {}

#: Lawicel frame letter -> characters before the payload (letter, ID, DLC digit)
_HEAD = {"t": 5, "r": 5, "T": 10, "R": 10}


def adapter_ms(line: str) -> Optional[int]:
    """The Lawicel timestamp (ms, 0..59999) at the end of a received frame line
    (``tIIIL<data><tttt>\r``), if any."""
    body = line.rstrip("\r\a")
    head = _HEAD.get(body[:1])
    if head is None or len(body) < head:
        return None
    try:
        pay = 0 if body[0] in "rR" else 2 * min(int(body[head - 1], 16), 8)
        return int(body[head + pay:], 16) if len(body) == head + pay + 4 else None
    except ValueError:
        return None


class BufferedSlcanBus(slcanBus):
    """python-can's SLCAN bus with a chunked serial reader (python-can reads byte by byte).

    ``timestamps`` switches the adapter's timestamp mode on (``Z1``): frame times are the host
    time of the first timestamped frame plus the adapter's elapsed time (its 60 s ms counter
    unwrapped); frames without one keep the host's arrival time. ``kwargs``: python-can's.
    """

    def __init__(self, *args: Any, timestamps: bool = False, **kwargs: Any) -> None:
        self._line = ""
        self._ts_on = timestamps
        self._ts_last = -1
        self._ts_wraps = 0
        self._ts_anchor: Optional[float] = None
        #: frames timed by the adapter / by the host
        self.adapter_timed = 0
        self.host_timed = 0
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        """Open the channel (``O``); with timestamps, ``Z1`` first (set while closed)."""
        if self._ts_on:
            self._write("Z1")
        super().open()

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        msg, filtered = super()._recv_internal(timeout)
        if msg is None:
            return msg, filtered
        ms = adapter_ms(self._line) if self._ts_on else None
        if ms is None:
            self.host_timed += 1
            return msg, filtered
        if self._ts_last >= 0 and ms < self._ts_last - 30000:
            self._ts_wraps += 1          # the 60 s counter wrapped
        self._ts_last = ms
        elapsed = (self._ts_wraps * 60000 + ms) / 1000.0
        if self._ts_anchor is None:
            self._ts_anchor = msg.timestamp - elapsed
        msg.timestamp = self._ts_anchor + elapsed
        self.adapter_timed += 1
        return msg, filtered

    def _read(self, timeout: Optional[float]) -> Optional[str]:
        """The next Lawicel line (kept in ``_line`` for its timestamp), read in chunks."""
        buf = self._buffer
        port = self.serialPortOrig
        deadline = serial.Timeout(timeout)
        while True:
            ends = [k for k in (buf.find(b"\r"), buf.find(b"\a")) if k >= 0]
            if ends:
                i = min(ends)
                self._line = buf[: i + 1].decode(errors="replace")
                del buf[: i + 1]
                return self._line
            try:
                chunk = port.read(max(1, port.in_waiting))
            except (OSError, serial.SerialException) as exc:
                raise can.CanOperationError(f"Could not read from serial device: {exc}") from exc
            if chunk:
                buf.extend(chunk)
                continue
            if deadline.expired():
                return None


#: ``SO_RXQ_OVFL`` (``SOL_SOCKET``): the kernel attaches its count of frames dropped at the
#: socket's full receive queue to each received frame
SO_RXQ_OVFL = 40
#: ``SO_TIMESTAMPNS`` (``SOL_SOCKET``): a ``struct timespec`` arrival time per frame
SO_TIMESTAMPNS = 35
#: ``SO_MEMINFO`` (``SOL_SOCKET``): the socket's memory counters, the 9th (``SK_MEMINFO_DROPS``)
#: being its drop count
SO_MEMINFO = 55
_MEMINFO_SIZE = 9 * 4
SOL_CAN_RAW = 101
CAN_RAW_ERR_FILTER = 2
CAN_EFF_FLAG = 0x80000000
CAN_RTR_FLAG = 0x40000000
CAN_ERR_FLAG = 0x20000000
#: every error class (``CAN_ERR_MASK``)
CAN_ERR_MASK = 0x1FFFFFFF
CANFD_MTU = 72
#: ``struct can_frame`` / ``canfd_frame`` head: ID, length, flags, (reserved), len8_dlc
_FRAME_HEAD = struct.Struct("=IBB1xB")
_TIMESPEC = struct.Struct("@ll")
_DROPS = struct.Struct("=I")
_ANC_SIZE = socket.CMSG_SPACE(_TIMESPEC.size) + socket.CMSG_SPACE(_DROPS.size)

#: error frame classes (bits of the CAN ID, ``linux/can/error.h``) by the name counted
ERROR_CLASSES = {0x001: "tx_timeout", 0x002: "lost_arbitration", 0x004: "controller",
                 0x008: "protocol", 0x010: "transceiver", 0x020: "no_ack", 0x040: "bus_off",
                 0x080: "bus_error", 0x100: "restarted", 0x200: "counters"}
#: controller problem details (``data[1]`` of a ``CAN_ERR_CRTL`` frame)
CONTROLLER_DETAILS = {0x01: "rx_overflow", 0x02: "tx_overflow", 0x04: "rx_warning",
                      0x08: "tx_warning", 0x10: "rx_passive", 0x20: "tx_passive",
                      0x40: "active"}
#: error-frame classes after which received frames may be missing (the controller dropped
#: frames, or it was off the bus)
LOSS_CLASSES = frozenset({"rx_overflow", "bus_off"})


def error_frame_classes(msg: can.Message) -> list[str]:
    """The classes an error frame reports (``ERROR_CLASSES``, ``CONTROLLER_DETAILS``)."""
    ident = int(msg.arbitration_id)
    out = [name for bit, name in ERROR_CLASSES.items() if ident & bit]
    if ident & 0x004 and len(msg.data) > 1:
        out += [name for bit, name in CONTROLLER_DETAILS.items() if msg.data[1] & bit]
    return out


class SocketcanReader:
    """Receive from a python-can SocketCAN bus with the kernel's drop count and error frames.

    Switches ``SO_RXQ_OVFL`` and every error class on the bus's raw socket and parses frames
    as python-can's ``capture_message`` does. Once behind, frames are taken in batches
    (``recvmmsg``, :mod:`suspid.can.mmsg`), each with its own ancillary data.

    ``bus`` is an open python-can SocketCAN bus. ``dropped``: frames the kernel dropped at the socket's
    full receive queue, as of the newest frame; ``error_frames``: error frames received
    (counted, not returned); ``errors``: by class (:func:`error_frame_classes`).
    """

    def __init__(self, bus: Any) -> None:
        sock = getattr(bus, "socket", None)
        if not isinstance(sock, socket.socket) or sock.family != getattr(socket, "AF_CAN", -1):
            raise TypeError(f"{type(bus).__name__} has no SocketCAN socket")
        self.sock: socket.socket = sock
        self.channel = getattr(bus, "channel", None) or None
        self.dropped = 0
        self.error_frames = 0
        self.errors: Counter[str] = Counter()
        #: the newest error frame's classes (until the next one)
        self.last_error: list[str] = []
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        sock.setsockopt(SOL_CAN_RAW, CAN_RAW_ERR_FILTER, CAN_ERR_MASK)
        self.multi = mmsg.make(sock, CANFD_MTU, _ANC_SIZE)
        self._pending: deque[tuple[bytes, list[tuple[int, int, bytes]], int]] = deque()
        self._full = False

    def kernel_drops(self) -> Optional[int]:
        """The socket's drop count now (``SO_MEMINFO``); ``None`` where not reported."""
        try:
            info = self.sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, _MEMINFO_SIZE)
        except OSError:
            return None
        if len(info) < _MEMINFO_SIZE:
            return None
        return int(_DROPS.unpack_from(info, _MEMINFO_SIZE - _DROPS.size)[0])

    def recv(self, timeout: Optional[float]) -> Optional[can.Message]:
        """The next frame or error frame (``None`` after ``timeout`` s without one); raises
        ``can.CanOperationError`` when the socket can no longer be read."""
        sock = self.sock
        pending = self._pending
        try:
            if not pending and self.multi is not None:
                if self._full:                        # behind: more is queued, no select
                    pending.extend(self.multi.recv())
                if not pending:
                    if not self._ready(timeout):
                        return None
                    pending.extend(self.multi.recv())
                self._full = len(pending) >= self.multi.batch
                if not pending:
                    return None
            if pending:
                frame, anc, flags = pending.popleft()
            else:
                if not self._ready(timeout):
                    return None
                frame, anc, flags, _ = sock.recvmsg(CANFD_MTU, _ANC_SIZE)
        except (OSError, ValueError) as exc:
            raise can.CanOperationError(f"Error receiving: {exc}") from exc
        stamp = 0.0
        for level, kind, data in anc:
            if level != socket.SOL_SOCKET:
                continue
            if kind == SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(data)
                stamp = sec + nsec * 1e-9
            elif kind == SO_RXQ_OVFL and len(data) >= _DROPS.size:
                self.dropped = _DROPS.unpack_from(data)[0]
        return self._message(frame, flags, stamp)

    def _ready(self, timeout: Optional[float]) -> bool:
        """Whether the socket is readable within ``timeout`` s (``None``: blocking read)."""
        return timeout is None or bool(select.select([self.sock], [], [], timeout)[0])

    def _message(self, frame: bytes, flags: int, stamp: float) -> can.Message:
        ident, size, fdflags, len8 = _FRAME_HEAD.unpack_from(frame)
        fd = len(frame) == CANFD_MTU
        dlc = size
        if not fd:
            fdflags = 0
            size = min(size, 8)
            if size == 8 and 8 < len8 <= 15:
                dlc = len8
        msg = can.Message(
            timestamp=stamp, channel=self.channel,
            arbitration_id=ident & (0x1FFFFFFF if ident & (CAN_EFF_FLAG | CAN_ERR_FLAG)
                                    else 0x7FF),
            is_extended_id=bool(ident & CAN_EFF_FLAG),
            is_remote_frame=bool(ident & CAN_RTR_FLAG),
            is_error_frame=bool(ident & CAN_ERR_FLAG), is_fd=fd,
            is_rx=not flags & socket.MSG_DONTROUTE, bitrate_switch=bool(fdflags & 0x01),
            error_state_indicator=bool(fdflags & 0x02), dlc=dlc, data=frame[8:8 + size])
        if msg.is_error_frame:
            self.error_frames += 1
            self.last_error = error_frame_classes(msg)
            self.errors.update(self.last_error)
        return msg


def open_bus(interface: str = "virtual", channel: str = "suspid", **kwargs: Any) -> can.BusABC:
    """Open a python-can bus for any suspid component (``interface`` and ``channel`` as
    python-can names them; ``kwargs`` go to the bus class); a :class:`UsageError` for an
    interface refused, unknown or unavailable, or a channel that cannot be opened."""
    if interface in REFUSED:
        raise UsageError(f"--interface {interface}: not supported ({REFUSED[interface]})")
    try:
        factory = CHANNEL_FACTORIES.get((interface, str(channel).lower().rstrip(":")))
        if factory is not None:
            return factory(**kwargs)
        if interface == "slcan" and str(channel).lower() in ("pty", "pty:"):
            raise UsageError("--interface slcan --channel pty is the simulated sensor node's "
                             "adapter (suspid node); a host opens the node's /dev/pts/N")
        if interface == "slcan":
            return BufferedSlcanBus(channel=channel, **kwargs)
        if interface == "virtual":
            kwargs.setdefault("preserve_timestamps", True)
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise UsageError(f"cannot open CAN interface {interface!r} channel {channel!r}: "
                         f"{' '.join(str(exc).split()) or type(exc).__name__}") from None
