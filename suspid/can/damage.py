"""Where a binary CAN log (ASAM MDF4, Vector BLF) is damaged, found from its own structure.

A log cut short makes python-can's readers stop silently (BLF) or with an obscure exception
(asammdf). These functions read only block and object headers and name the first
inconsistency: the byte, what was expected and what is there. A last MDF4 data block of 24
bytes followed by data up to the end is the open-ended block a CANedge appends to, not damage.
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

#: an MDF4 block header: ``##XX``, reserved, length (u64), link count (u64)
_MDF_HEADER = struct.Struct("<4s4xQQ")
#: byte offset of the MDF4 header block (after the 64-byte identification block)
_MDF_HD = 64
#: more blocks than this are not walked (a damaged link table that loops is cut off)
_MDF_MAX_BLOCKS = 200_000
#: channel group flag: variable-length signal data group
_CG_VLSD = 1

#: a BLF object header base: ``LOBJ``, header size (u16), header version (u16), object size (u32),
#: object type (u32)
_BLF_OBJECT = struct.Struct("<4sHHLL")
#: the BLF file header: signature, header size, ..., file size (u64) at byte 16
_BLF_FILE_SIZE_AT = 16


def _block(fh: BinaryIO, at: int) -> tuple[bytes, int, list[int]] | None:
    """Block ID, length and links of the MDF4 block at byte ``at`` (``None``: no header)."""
    fh.seek(at)
    head = fh.read(_MDF_HEADER.size)
    if len(head) < _MDF_HEADER.size:
        return None
    bid, length, nlinks = _MDF_HEADER.unpack(head)
    if not bid.startswith(b"##") or nlinks > 1 << 20:
        return None
    raw = fh.read(8 * nlinks)
    links = list(struct.unpack(f"<{len(raw) // 8}Q", raw[:len(raw) // 8 * 8]))
    return bid, length, links


@dataclass(frozen=True)
class MdfDamage:
    """The first damage of an MDF4 file: ``what``, one line without the file name; the file's
    first ``whole_to`` bytes hold whole records only (0: its structure itself is damaged)."""

    what: str
    whole_to: int = 0


def _name(bid: bytes) -> str:
    return bid[2:].decode("ascii", "replace")


def mdf_damage(path: str | Path) -> MdfDamage | None:
    """The first structural damage of an ``.mf4`` file; ``None`` when it is whole or not MDF 4
    (the reader reports that itself)."""
    p = Path(path)
    size = os.path.getsize(p)
    with open(p, "rb") as fh:
        ident = fh.read(16)
        # "UnFinMF ": a file its logger has not finalised (a CANedge's, always)
        if not ident.startswith((b"MDF ", b"UnFinMF ")) or not ident[8:9] == b"4":
            return None
        blocks = _mdf_blocks(fh, size)
        return MdfDamage(blocks) if blocks is not None else _mdf_records(fh, size)


def _mdf_blocks(fh: BinaryIO, size: int) -> str | None:
    """Every block reachable from the header block lies inside the file."""
    todo: list[tuple[int, int, bytes]] = [(_MDF_HD, 0, b"##ID")]
    seen: set[int] = set()
    while todo and len(seen) < _MDF_MAX_BLOCKS:
        at, parent, pid = todo.pop()
        if at in seen:
            continue
        seen.add(at)
        origin = f" (linked from the {_name(pid)} block at byte {parent})" if parent else ""
        blk = _block(fh, at) if at + _MDF_HEADER.size <= size else None
        if blk is None:
            where = "beyond the end of the file" if at + _MDF_HEADER.size > size \
                else "not a block header"
            return (f"the block at byte {at}{origin} is {where} ({size} bytes): the file is cut "
                    "short or overwritten")
        bid, length, links = blk
        if at + length > size and not (bid == b"##DT" and length == _MDF_HEADER.size):
            return (f"the {_name(bid)} block at byte {at}{origin} declares {length} bytes, "
                    f"{size - at} are left before the end of the file: the file is cut short")
        todo.extend((link, at, bid) for link in links if link)
    return None


def _mdf_records(fh: BinaryIO, size: int) -> MdfDamage | None:
    """The last record of each unsorted data group held in one data block is whole."""
    hd = _block(fh, _MDF_HD)
    dg_at = hd[2][0] if hd is not None and hd[2] else 0
    groups = 0
    while dg_at and groups < _MDF_MAX_BLOCKS:
        groups += 1
        dg = _block(fh, dg_at)
        if dg is None or dg[0] != b"##DG" or len(dg[2]) < 3:
            return None
        next_dg, cg_at, data_at = dg[2][0], dg[2][1], dg[2][2]
        fh.seek(dg_at + _MDF_HEADER.size + 8 * len(dg[2]))
        id_size = fh.read(1)[0] if data_at else 0
        if id_size == 1 and data_at:
            found = _unsorted_tail(fh, size, cg_at, data_at)
            if found:
                return found
        dg_at = next_dg
    return None


def _unsorted_tail(fh: BinaryIO, size: int, cg_at: int, data_at: int) -> MdfDamage | None:
    """Walk the records (1-byte record ID) of one ``DT`` block; name a record cut short."""
    sizes: dict[int, int] = {}   # record ID -> record bytes after the ID; -1: VLSD
    while cg_at:
        cg = _block(fh, cg_at)
        if cg is None or cg[0] != b"##CG":
            return None
        fh.seek(cg_at + _MDF_HEADER.size + 8 * len(cg[2]))
        raw = fh.read(32)
        if len(raw) < 32:
            return None
        rec_id, _cycles, flags, _sep, data_bytes, inval_bytes = struct.unpack("<QQHH4xLL", raw)
        sizes[rec_id] = -1 if flags & _CG_VLSD else data_bytes + inval_bytes
        cg_at = cg[2][0]
    dt = _block(fh, data_at)
    if dt is None or dt[0] != b"##DT":
        return None   # a list of blocks or compressed data: the block walk covers it
    start = data_at + _MDF_HEADER.size
    end = size if dt[1] == _MDF_HEADER.size else data_at + dt[1]
    fh.seek(start)
    data = fh.read(end - start)
    pos = 0
    n = len(data)
    whole = 0   # end of the last whole record
    while pos < n:
        rid = data[pos]
        need = sizes.get(rid)
        if need is None:
            return MdfDamage(f"byte {start + pos}: record ID {rid} is no channel group of the "
                             f"data group (expected one of "
                             f"{', '.join(str(k) for k in sorted(sizes))}): the data is "
                             "overwritten", start + whole)
        if need < 0:
            if pos + 5 > n:
                need = 4
            else:
                need = 4 + int.from_bytes(data[pos + 1:pos + 5], "little")
        if pos + 1 + need > n:
            return MdfDamage(f"the file ends inside a record at byte {start + pos}: record ID "
                             f"{rid} needs {1 + need} bytes, {n - pos} are left: the file is "
                             "cut short", start + whole)
        pos += 1 + need
        whole = pos
    return None


def blf_damage(path: str | Path) -> str | None:
    """The first structural damage of a ``.blf`` file (header already checked), one line
    without the file name; ``None`` when it is whole."""
    p = Path(path)
    size = os.path.getsize(p)
    with open(p, "rb") as fh:
        head = fh.read(_BLF_FILE_SIZE_AT + 8)
        if len(head) < _BLF_FILE_SIZE_AT + 8:
            return None
        header_size = int.from_bytes(head[4:8], "little")
        announced = int.from_bytes(head[_BLF_FILE_SIZE_AT:_BLF_FILE_SIZE_AT + 8], "little")
        note = (f" (the header announces {announced} bytes, the file has {size})"
                if announced > size else "")
        at = header_size
        while at + _BLF_OBJECT.size <= size:
            fh.seek(at)
            sig, _hs, _hv, obj_size, _typ = _BLF_OBJECT.unpack(fh.read(_BLF_OBJECT.size))
            if sig != b"LOBJ" or obj_size < _BLF_OBJECT.size:
                return (f"byte {at}: expected an object ('LOBJ'), got {sig!r}{note}: the file "
                        "is overwritten or cut short")
            if at + obj_size > size:
                return (f"the object at byte {at} declares {obj_size} bytes, {size - at} are "
                        f"left{note}: the file is cut short")
            at += obj_size + obj_size % 4
        if at < size:
            return (f"the file ends inside an object header at byte {at} ({size - at} of "
                    f"{_BLF_OBJECT.size} bytes){note}: the file is cut short")
        if note:
            return f"the file ends at byte {size}{note}: the file is cut short"
    return None
