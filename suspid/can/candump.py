"""candump -L logs (SocketCAN) read fast: a column parser over the file's bytes.

Regular lines are parsed with array operations (~10x python-can's reader); the rest --
CAN FD, remote frames, odd spacing, bad lines -- go through python-can's
:class:`can.CanutilsLogReader` a block at a time, bad lines counted with their reason and
line number in :class:`~suspid.can.frames.ReadStats` and reading going on.
"""
from __future__ import annotations

import io
from bisect import bisect_left
from pathlib import Path
from typing import Callable, Iterable, Iterator, Optional

import can
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from suspid.can.frames import FrameArrays, LabelledFrames, ReadStats, select_arrays
from suspid.errors import InputError

_CAN_ERR_FLAG = 0x20000000
#: candump lines handed to python-can's reader at once
_ODD_BLOCK = 4096
#: characters of a hex payload
_HEX_DIGITS = "0123456789abcdefABCDEF"


def _line_fault(parts: list[str]) -> str | None:
    """Why the fields of a candump -L line are no frame (``None``: they may be one): the checks
    python-can's reader does not make, or makes with an unhelpful error."""
    ts_s = parts[0]
    if ts_s[0] != "(" or ts_s[-1] != ")":
        return f"expected '(seconds)' first, got {ts_s[:24]!r}"
    if len(parts) < 3:
        return "expected '(seconds) interface ID#DATA'"
    id_s, sep, data_s = parts[2].partition("#")
    if not sep:
        return f"expected ID#DATA, got {parts[2][:24]!r}"
    if data_s[:1] in ("R", "r"):
        return None
    payload = data_s[2:] if data_s[:1] == "#" else data_s
    if len(payload) % 2 or payload.strip(_HEX_DIGITS):
        return f"payload {data_s[:24]!r} is not hex"
    if data_s[:1] != "#" and len(payload) > 16:
        return f"{len(payload) // 2} data bytes in a classic CAN frame"
    return None


def _canutils(lines: list[str]) -> list[can.Message]:
    """python-can's :class:`can.CanutilsLogReader` over ``lines`` (one frame each)."""
    return list(can.CanutilsLogReader(io.StringIO("\n".join(lines))))


def _candump_odd(path: Path, numbered: Iterable[tuple[int, int, str]],
                 stats: ReadStats) -> Iterator[tuple[int, can.Message]]:
    """The lines the array parser leaves (CAN FD, remote, odd spacing, bad lines) through
    python-can's reader, a block at a time (a failing block line by line).

    ``numbered`` gives ``(tag, lineno, text)``; yields ``(tag, message)`` in line order, error
    frames made as the array parser makes them; a bad line is counted in ``stats``.
    """
    block: list[tuple[int, int, list[str], str | None]] = []
    it = iter(numbered)
    while True:
        block.clear()
        for tag, lineno, line in it:
            parts = line.split()
            if parts:
                block.append((tag, lineno, parts[:3] + [f for f in parts[3:4]
                                                        if f.lower() in ("r", "t")],
                              _line_fault(parts)))
                if len(block) >= _ODD_BLOCK:
                    break
        if not block:
            return
        good = [" ".join(p) for _, _, p, why in block if why is None]
        try:
            msgs = iter(_canutils(good))
            failed: dict[int, str] = {}
        except (ValueError, IndexError):   # the block line by line
            got: list[can.Message] = []
            failed = {}
            for k, (_, _, parts, why) in enumerate(block):
                if why is None:
                    try:
                        got.extend(_canutils([" ".join(parts)]))
                    except (ValueError, IndexError) as exc:
                        failed[k] = str(exc) or "unparseable line"
            msgs = iter(got)
        for k, (tag, lineno, parts, why) in enumerate(block):
            why = why or failed.get(k)
            if why is not None:
                stats.bad(f"{path}:{lineno}", why)
                continue
            msg = next(msgs)
            stats.frames += 1
            id_s = parts[2].partition("#")[0]
            if int(id_s, 16) & _CAN_ERR_FLAG and len(id_s) > 3:
                msg = can.Message(timestamp=msg.timestamp, is_error_frame=True, check=False)
            msg.channel = parts[1]
            yield tag, msg


def read_candump(path: Path, stats: ReadStats) -> Iterator[can.Message]:
    """candump -L lines as :class:`can.Message` (the array reader's frames, 64 KiB at a time),
    each with its interface as ``channel``."""
    for fa, codes, names in candump_batches(path, stats, 1 << 16):
        yield from fa.iter_messages(names, codes)



#: hex digit value per byte, 255 = not a hex digit
_HEXVAL = np.full(256, 255, dtype=np.uint8)
for _k, _c in enumerate(b"0123456789abcdef"):
    _HEXVAL[_c] = _k
for _k, _c in enumerate(b"ABCDEF"):
    _HEXVAL[_c] = 10 + _k
#: decimal digit value per byte, 255 = not a digit
_DIGVAL = np.full(256, 255, dtype=np.uint8)
_DIGVAL[48:58] = np.arange(10)
#: byte value of two hex digits read as a little-endian uint16; 0x100 = not two hex digits
_HEXPAIR = np.full(1 << 16, 0x100, dtype=np.uint16)
_hv = np.flatnonzero(_HEXVAL != 255)
_HEXPAIR[(_hv[:, None] | (_hv[None, :] << 8)).ravel()] = \
    ((_HEXVAL[_hv][:, None] << 4) | _HEXVAL[_hv][None, :]).ravel()
#: longest line (bytes) the array parser takes; longer ones go through the message parser
_MAX_FAST_LINE = 160
#: integers below this are exact in float64
_EXACT_INT = float(2 ** 53)
#: line layouts tried per line length before the rest of that length goes line by line
_MAX_LAYOUTS = 8


def _line_layout(line: bytes) -> tuple[int, int, int, int, int, int] | None:
    """Byte positions ``(close, dot, sp1, sp2, hash, sp3)`` of a regular candump line
    (``(DIGITS.DIGITS) IFACE HEXID#HEXDATA[ ...]``, single spaces, 1-8 ID digits, up to 8 data
    bytes), else ``None``. The characters are checked later, for every line of the layout.
    """
    if line[:1] != b"(":
        return None
    close = line.find(b")")
    sp1 = close + 1
    if close < 3 or line[sp1:sp1 + 1] != b" ":
        return None
    dot = line.find(b".", 1, close)
    if dot < 2 or dot > close - 2:
        return None
    sp2 = line.find(b" ", sp1 + 1)
    if sp2 <= sp1 + 1:
        return None
    sp3 = line.find(b" ", sp2 + 1)
    if sp3 < 0:
        sp3 = len(line)
    hs = line.find(b"#", sp2 + 1, sp3)
    if hs < 0 or not 1 <= hs - sp2 - 1 <= 8 or (sp3 - hs - 1) % 2 or sp3 - hs - 1 > 16:
        return None
    return close, dot, sp1, sp2, hs, sp3


def _digits_value(chars: np.ndarray, lut: np.ndarray, base: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``(value, ok)`` of rows of digit characters (decimal or hex by ``lut``/``base``).

    A ``value`` below 2**53 is exact (a rounded partial value never falls below 2**53).
    """
    d = lut[chars]
    acc = d[:, 0].astype(np.float64)
    bad = d[:, 0].copy()
    for j in range(1, chars.shape[1]):
        col = d[:, j]
        acc *= base
        acc += col
        bad |= col
    return acc, bad < 16   # digit values 0..15; 255 marks any other character


def _parse_layout(rows: np.ndarray, layout: tuple[int, int, int, int, int, int]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Parse lines of one layout (``rows`` (m, L) uint8): ``(good, timestamp, arbitration_id,
    data)``, ``good`` false for a row that does not fit (left to the message parser)."""
    close, dot, sp1, sp2, hs, sp3 = layout
    m, length = rows.shape
    good = (rows[:, 0] == 40) & (rows[:, close] == 41) & (rows[:, sp1] == 32)
    good &= (rows[:, dot] == 46) & (rows[:, sp2] == 32) & (rows[:, hs] == 35)
    if sp3 < length:
        good &= rows[:, sp3] == 32
    for j in range(sp1 + 1, sp2):                                   # interface: no blank
        good &= rows[:, j] > 32
    n_int, ok_int = _digits_value(rows[:, 1:dot], _DIGVAL, 10.0)
    n_frac, ok_frac = _digits_value(rows[:, dot + 1:close], _DIGVAL, 10.0)
    nf = close - dot - 1
    good &= ok_int & ok_frac
    # INT.FRAC = N / 10**nf with N exact below 2**53: one division rounds as float(text) does
    # (docs/can.md, Logs); the other rows are converted by float() itself
    if nf <= 22:
        p10 = float(10 ** nf)
        num = n_int * p10 + n_frac
        ts = num / p10
    else:   # 10**nf is not a float: every row by float()
        num = np.full(m, _EXACT_INT)
        ts = np.zeros(m)
    id_value, ok_id = _digits_value(rows[:, sp2 + 1:hs], _HEXVAL, 16.0)
    good &= ok_id
    ids = id_value.astype(np.int64)
    data = np.zeros((m, 8), dtype=np.uint8)
    nb = (sp3 - hs - 1) // 2
    if nb:
        pairs = _HEXPAIR[np.ascontiguousarray(rows[:, hs + 1:sp3]).view(np.uint16)]
        bad = pairs[:, 0] >> 8
        for j in range(1, nb):
            bad |= pairs[:, j] >> 8
        good &= bad == 0
        data[:, :nb] = pairs
    inexact = np.flatnonzero(good & ~(num < _EXACT_INT))
    if inexact.size:
        text = np.ascontiguousarray(rows[inexact, 1:close]).view(f"S{close - 1}").ravel()
        ts[inexact] = [float(t) for t in text.tolist()]
    return good, ts, ids, data


def _name_codes(iface: np.ndarray, code_of: Callable[[str], int]) -> np.ndarray | int:
    """The code (``code_of(name)``) of each interface name of ``iface`` (an ``S<n>`` array),
    names coded in order of appearance; one code when all are equal."""
    first = iface[0]
    if bool((iface == first).all()):
        return code_of(bytes(first).decode("ascii", errors="replace"))
    uniq, at, inv = np.unique(iface, return_index=True, return_inverse=True)
    codes = np.zeros(uniq.size, dtype=np.int32)
    for k in np.argsort(at).tolist():
        codes[k] = code_of(bytes(uniq[k]).decode("ascii", errors="replace"))
    return codes[inv.reshape(-1)]


def _candump_chunk(buf: bytes, path: Path, line0: int, stats: ReadStats
                   ) -> tuple[FrameArrays, int, np.ndarray, list[str]]:
    """Parse whole candump -L lines (``buf`` ends at a line end or at the file end).

    Lines are grouped by length; a group's first line gives the field positions and every
    line of that layout is parsed at once; the others go through :func:`_candump_odd`.
    Returns the frames in file order, the number of lines (a lone ``\\r`` counts as a line
    break), each frame's interface code and the interface names.
    """
    b = np.frombuffer(buf, dtype=np.uint8)
    nl = np.flatnonzero(b == 10)
    ends = nl if (b.size == 0 or b[-1] == 10) else np.append(nl, b.size)
    nlines = int(ends.size)
    starts = np.zeros(nlines, dtype=np.int64)
    starts[1:] = ends[:-1] + 1
    e = ends.astype(np.int64)
    nonempty = e > starts
    slow = np.zeros(nlines, dtype=bool)
    extra_at: list[tuple[int, int]] = []   # (line, lone "\\r" in it)
    if buf.find(b"\r") >= 0:
        # "\\r\\n" is one line break (universal newlines): the "\\r" is not part of the line
        cr = nonempty & (b[np.maximum(e - 1, 0)] == 13)
        e[cr] -= 1
        crs = np.flatnonzero(b == 13)
        li = np.searchsorted(starts, crs, side="right") - 1
        inner = crs < e[li]
        if inner.any():
            u, cnt = np.unique(li[inner], return_counts=True)
            slow[u] = True
            extra_at = list(zip(u.tolist(), cnt.tolist()))
    length = e - starts
    lt = np.zeros(nlines)
    lid = np.zeros(nlines, dtype=np.int64)
    lidlen = np.zeros(nlines, dtype=np.int64)
    lnb = np.zeros(nlines, dtype=np.int64)
    ldata = np.zeros((nlines, 8), dtype=np.uint8)
    ldata64 = ldata.view(np.uint64).reshape(nlines)    # one 8-byte store per row
    fast = np.zeros(nlines, dtype=bool)
    lcode = np.zeros(nlines, dtype=np.int32)
    name_code: dict[str, int] = {}   # interface name -> code, in order of appearance

    def code_of(name: str) -> int:
        return name_code.setdefault(name, len(name_code))

    cand = (length >= 10) & (length <= _MAX_FAST_LINE) & ~slow
    cidx = np.flatnonzero(cand)
    if cidx.size:
        clen = length[cidx]
        padded = np.concatenate((b, np.zeros(_MAX_FAST_LINE, dtype=np.uint8)))
        for L in np.flatnonzero(np.bincount(clen)).tolist():
            sel = clen == L
            idx = cidx if sel.all() else cidx[sel]
            rows = sliding_window_view(padded, L)[starts[idx]]
            left = np.arange(idx.size)
            for _ in range(_MAX_LAYOUTS):
                if not left.size:
                    break
                layout = _line_layout(rows[left[0]].tobytes())
                if layout is None:
                    left = left[1:]
                    continue
                part = rows if left.size == idx.size else rows[left]
                good, ts, ids, data = _parse_layout(part, layout)
                if not good.all():
                    part, ts, ids, data = part[good], ts[good], ids[good], data[good]
                at = idx[left[good]]
                fast[at] = True
                lt[at] = ts
                lid[at] = ids
                lidlen[at] = layout[4] - layout[3] - 1
                lnb[at] = (layout[5] - layout[4] - 1) // 2
                ldata64[at] = data.view(np.uint64).reshape(-1)
                sp1, sp2 = layout[2], layout[3]
                iface = np.ascontiguousarray(part[:, sp1 + 1:sp2]).view(f"S{sp2 - sp1 - 1}").reshape(-1)
                if iface.size:
                    lcode[at] = _name_codes(iface, code_of)
                left = left[~good]
    # every other non-empty line: the message parser, in file order, in one pass
    slow_msgs: list[can.Message] = []
    slow_line: list[int] = []     # per message: its line (index in this chunk)
    slow_lines = np.flatnonzero(nonempty & ~fast).tolist()
    per_line = fast.astype(np.int64) if slow_lines else fast
    if slow_lines:
        extra_lines = [x for x, _ in extra_at]
        extra_cum = np.cumsum([0] + [c for _, c in extra_at]).tolist()
        line_start = starts.tolist()
        line_end = e.tolist()
        def numbered() -> Iterator[tuple[int, int, str]]:
            for i in slow_lines:
                lineno = line0 + i + 1
                if extra_lines:
                    lineno += extra_cum[bisect_left(extra_lines, i)]
                text = buf[line_start[i]:line_end[i]].decode("ascii", errors="replace")
                if "\r" in text:
                    for k, sub in enumerate(text.split("\r")):
                        yield i, lineno + k, sub
                else:
                    yield i, lineno, text

        for i, msg in _candump_odd(path, numbered(), stats):
            slow_msgs.append(msg)
            slow_line.append(i)
    n_fast = int(np.count_nonzero(fast))
    stats.frames += n_fast
    total_lines = nlines + sum(c for _, c in extra_at)
    ext = lidlen > 3
    ft = ((lid & _CAN_ERR_FLAG) != 0) & ext
    lid[ft] = 0   # error frames: no identifier, no data (as the message reader makes them)
    lnb[ft] = 0
    ldata[ft] = 0
    regular = FrameArrays(lt, lid, ext, ft, lnb, ldata)
    if not slow_msgs:   # every frame from a regular line: in file order already
        if n_fast == nlines:
            return regular, total_lines, lcode, list(name_code)
        return regular.select(fast), total_lines, lcode[fast], list(name_code)
    where = np.array(slow_line, dtype=np.int64)
    np.add.at(per_line, where, 1)
    n = int(per_line.sum())
    offs = np.cumsum(per_line) - per_line
    out = FrameArrays.empty(n)
    codes = np.zeros(n, np.int32)
    codes[offs[fast]] = lcode[fast]
    out.put(offs[fast], regular.select(fast))
    # the line-by-line frames, converted at once
    extra = FrameArrays.from_messages(slow_msgs)
    first = np.flatnonzero(np.r_[True, where[1:] != where[:-1]])   # a line's first frame
    nth = np.arange(where.size) - np.repeat(first, np.diff(np.r_[first, where.size]))
    at = offs[where] + nth
    codes[at] = [code_of(str(m.channel)) for m in slow_msgs]
    out.put(at, extra)
    return out, total_lines, codes, list(name_code)


def read_candump_arrays(path: str | Path, stats: Optional[ReadStats] = None, *,
                        chunk_bytes: int = 1 << 19) -> Iterator[FrameArrays]:
    """The frames of a candump -L log as :class:`FrameArrays`, about ``chunk_bytes`` at a time.

    Same frames, malformed-line counts, reasons and line numbers as the message reader, ~10x
    faster; ``stats`` as :func:`~suspid.can.logs.read_log` fills it; the parse's temporaries
    are ~7x ``chunk_bytes``. Raises :class:`InputError` when the file cannot be opened.
    """
    p = Path(path)
    st = stats if stats is not None else ReadStats()
    return select_arrays(p, ".log", candump_batches(p, st, chunk_bytes), st, None)


def candump_batches(p: Path, st: ReadStats, chunk_bytes: int = 1 << 19) -> Iterator[LabelledFrames]:
    """:func:`read_candump_arrays` with each frame's interface (:data:`LabelledFrames`)."""
    try:
        fh = p.open("rb")
    except OSError as exc:
        raise InputError(f"{p}: cannot open CAN log: {exc.strerror}") from None
    with fh:
        rest = b""
        line0 = 0
        while True:
            blk = fh.read(max(1, chunk_bytes))
            if blk:
                buf = rest + blk
                cut = buf.rfind(b"\n") + 1
                if cut == 0:
                    rest = buf
                    continue
                buf, rest = buf[:cut], buf[cut:]
            else:
                buf, rest = rest, b""
                if not buf:
                    return
            fa, nlines, codes, names = _candump_chunk(buf, p, line0, st)
            line0 += nlines
            if len(fa):
                yield fa, codes, names
            if not blk:
                return

