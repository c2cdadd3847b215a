"""The sensor node as an SLCAN (Lawicel) USB-CAN adapter on a pseudo-terminal: a host
attaches to :attr:`SlcanPtyBus.path` as to a real adapter (docs/can.md); the node waits until
the host opens the channel (:meth:`SlcanPtyBus.wait_open`).
"""
from __future__ import annotations

import errno
import fcntl
import os
import queue
import select
import struct
import termios
import threading
import time
import tty
from typing import Any, Optional

import can

_BITRATES = {"S0": 10000, "S1": 20000, "S2": 50000, "S3": 100000, "S4": 125000,
             "S5": 250000, "S6": 500000, "S7": 750000, "S8": 1000000, "S9": 83300}
#: version, software version, serial number and status flags
_REPLIES = {"V": "V1013\r", "v": "v0107\r", "N": "NSUSP\r", "F": "F00\r"}


class SlcanPtyBus(can.BusABC):
    """python-can bus of a simulated SLCAN adapter on a pseudo-terminal (:attr:`path`).

    A frame that finds no room in the pty for ``write_timeout`` s is dropped and counted in
    :attr:`overflows`, one sent while the channel is closed in :attr:`dropped_closed`;
    :attr:`host_frames` counts the host's frames. ``timestamps``: SLCAN timestamps on.
    """

    def __init__(self, channel: Any = "pty", write_timeout: float = 5.0, timestamps: bool = False,
                 **kwargs: Any) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self.write_timeout = write_timeout
        self.timestamps = timestamps
        self.listen_only = False
        self.bitrate: Optional[int] = None
        self.overflows = 0
        self.dropped_closed = 0
        self.host_frames = 0
        self._opened = threading.Event()
        #: set when the host closes the channel (``C``), cleared when it opens it again
        self.closed_by_host = threading.Event()
        self._stop = threading.Event()
        self._wlock = threading.Lock()
        self._rx: "queue.SimpleQueue[can.Message]" = queue.SimpleQueue()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._serve, name=f"slcan-pty {self.path}",
                                        daemon=True)
        self._thread.start()
        self.channel_info = f"SLCAN adapter on {self.path}"
        super().__init__(channel=self.path, **kwargs)

    @property
    def is_open(self) -> bool:
        return self._opened.is_set()

    def wait_open(self, timeout: Optional[float] = None) -> bool:
        """Block until the host opens the channel; ``False`` on timeout."""
        return self._opened.wait(timeout)

    def _serve(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.05)
            except (OSError, ValueError):
                return
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 4096)
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno == errno.EIO:  # no process has the slave open
                    time.sleep(0.02)
                    continue
                return
            if not chunk:
                continue
            buf.extend(chunk)
            while True:
                cut = [i for i in (buf.find(b"\r"), buf.find(b"\n")) if i >= 0]
                if not cut:
                    break
                i = min(cut)
                line = bytes(buf[:i]).decode("ascii", errors="replace")
                del buf[: i + 1]
                self._write(self._command(line).encode("ascii"), urgent=True)

    def _command(self, line: str) -> str:
        """Execute one host command; return the reply."""
        if line == "":
            return "\r"
        c = line[0]
        if c in "OL":
            # python-can sends 'O' twice when it sets a bitrate; accept a repeated open
            self.listen_only = c == "L"
            self.closed_by_host.clear()
            self._opened.set()
            return "\r"
        if c == "C":
            self._opened.clear()
            self.closed_by_host.set()
            return "\r"
        if c == "S":
            if line[:2] not in _BITRATES or self.is_open:
                return "\a"
            self.bitrate = _BITRATES[line[:2]]
            return "\r"
        if c in "sYMm":
            return "\a" if self.is_open and c in "sY" else "\r"
        if c in _REPLIES:
            return _REPLIES[c]
        if c == "Z":
            self.timestamps = line[1:2] == "1"
            return "\r"
        if c in "tTrR":
            if not self.is_open or self.listen_only:
                return "\a"
            msg = self._parse_frame(line)
            if msg is None:
                return "\a"
            self.host_frames += 1
            self._rx.put(msg)
            return "z\r" if c in "tr" else "Z\r"
        return "\a"

    @staticmethod
    def _parse_frame(line: str) -> Optional[can.Message]:
        try:
            c = line[0]
            ext = c in "TR"
            n = 8 if ext else 3
            can_id = int(line[1:1 + n], 16)
            dlc = int(line[1 + n], 16)
            if dlc > 8:
                return None
            if c in "rR":
                return can.Message(arbitration_id=can_id, is_extended_id=ext, is_remote_frame=True,
                                   dlc=dlc, timestamp=time.time(), check=False)
            data = bytes.fromhex(line[2 + n: 2 + n + 2 * dlc])
            if len(data) != dlc:
                return None
            return can.Message(arbitration_id=can_id, is_extended_id=ext, data=data,
                               timestamp=time.time(), check=False)
        except (ValueError, IndexError):
            return None

    def _write(self, data: bytes, urgent: bool = False) -> bool:
        deadline = time.monotonic() + (self.write_timeout if not urgent else 1.0)
        view = memoryview(data)
        with self._wlock:
            while view:
                try:
                    n = os.write(self._master, view)
                    view = view[n:]
                    continue
                except BlockingIOError:
                    pass
                except OSError:
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                try:
                    select.select([], [self._master], [], min(left, 0.05))
                except (OSError, ValueError):
                    return False
        return True

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        """Write one frame as an SLCAN line (dropped and counted while the channel is closed)."""
        if not self.is_open:
            self.dropped_closed += 1
            return
        if msg.is_extended_id:
            head = f"{'R' if msg.is_remote_frame else 'T'}{msg.arbitration_id:08X}{msg.dlc:d}"
        else:
            head = f"{'r' if msg.is_remote_frame else 't'}{msg.arbitration_id:03X}{msg.dlc:d}"
        line = head if msg.is_remote_frame else head + msg.data.hex().upper()
        if self.timestamps:
            # the node stamps every frame with its data time (0.0 for the first sample)
            ms = int(round(msg.timestamp * 1000))
            line += f"{ms % 60000:04X}"
        if not self._write((line + "\r").encode("ascii")):
            self.overflows += 1

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        try:   # a timeout of 0 (or less) polls
            return self._rx.get(timeout=None if timeout is None else max(timeout, 0.0)), False
        except queue.Empty:
            return None, False

    def pending(self) -> int:
        """Bytes written to the host that it has not read yet."""
        try:
            raw = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
            return int(struct.unpack("i", raw)[0])
        except OSError:
            return 0

    def drain(self, timeout: float = 5.0) -> bool:
        """Wait until the host has read everything (or closed the channel); ``False`` on timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.pending() == 0 or self.closed_by_host.is_set():
                return True
            time.sleep(0.01)
        return False

    def wait_closed(self, timeout: Optional[float] = None) -> bool:
        """Block until the host closes the channel (``C``); ``False`` on timeout."""
        return self.closed_by_host.wait(timeout)

    def shutdown(self) -> None:
        """Stop the adapter and close the pseudo-terminal."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        super().shutdown()
