"""SAE J1939 frames matched to a DBC's messages by parameter group (PGN), whatever their sender
(the source address is no part of the PGN); one sender per PGN is decoded (docs/can.md
"J1939")."""
from __future__ import annotations

import can
import numpy as np
from cantools.database.can import Database
from cantools.j1939 import frame_id_unpack, pgn_from_frame_id

from suspid.can.logs import FrameArrays
from suspid.errors import UsageError

#: the largest J1939 source address a controller may have (254: null, 255: global)
MAX_SOURCE = 253
#: PGNs named in the error of a log without the mapped ones
TOP_PGNS = 5


def parse_source(text: str | int | None) -> int | None:
    """``can.j1939_source`` as an address 0..253 (``0x47``, ``71``; None: none); else UsageError."""
    if text is None or isinstance(text, int):
        value = text
    else:
        try:
            value = int(str(text).strip(), 0)
        except ValueError:
            raise UsageError(f"can.j1939_source {text!r}: expected a source address 0..253 "
                             "(decimal or 0x hex, e.g. 0x00)") from None
    if value is not None and not 0 <= value <= MAX_SOURCE:
        raise UsageError(f"can.j1939_source {text!r}: expected a source address 0..253, got "
                         f"{value}")
    return value


def j1939_messages(db: Database) -> dict[int, tuple[int, str]]:
    """PGN -> (DBC frame ID, message name) of the DBC's J1939 messages (``VFrameFormat J1939PG``, or all
    extended ones under ``ProtocolType "J1939"``)."""
    attrs = db.dbc.attributes if db.dbc is not None else {}
    proto = attrs.get("ProtocolType")
    whole = proto is not None and str(proto.value).strip().upper() == "J1939"
    out: dict[int, tuple[int, str]] = {}
    for msg in db.messages:
        if msg.is_extended_frame and (whole or getattr(msg, "protocol", None) == "j1939"):
            out.setdefault(pgn_from_frame_id(msg.frame_id), (msg.frame_id, msg.name))
    return out


class J1939Match:
    """Translate the extended frames of a stream to the DBC's J1939 identifiers by PGN
    (``table``: :func:`j1939_messages`), decoding only ``source`` when given.

    Counts: :attr:`pgns` (PGN -> frames seen), :attr:`senders` (message -> {address:
    frames}), :attr:`used` (message -> address decoded), :attr:`other_source`.
    """

    def __init__(self, table: dict[int, tuple[int, str]], source: int | None = None) -> None:
        self.table = table
        self.source = source
        self.pgns: dict[int, int] = {}
        self.senders: dict[str, dict[int, int]] = {}
        self.used: dict[str, int] = {}
        self.other_source = 0
        self._ids: dict[int, tuple[int, str] | None] = {}   # DBC J1939 frame ID -> (sa, name)
        self._pgn = {n: p for p, (_f, n) in table.items()}

    @classmethod
    def from_db(cls, db: Database, source: str | int | None = None) -> "J1939Match | None":
        """The match of a DBC's J1939 messages; ``None`` when it has none."""
        addr = parse_source(source)
        table = j1939_messages(db)
        if not table:
            if addr is not None:
                raise UsageError(f"can.j1939_source {source}: "
                                 f"{getattr(db, 'suspid_path', 'the DBC')} has no J1939 message "
                                 "(ProtocolType J1939 or VFrameFormat J1939PG)")
            return None
        return cls(table, addr)

    def _target(self, frame_id: int, count: int) -> int:
        """The DBC frame ID for ``count`` frames of ``frame_id`` (-1: another sender's), counted."""
        pgn = pgn_from_frame_id(frame_id)
        self.pgns[pgn] = self.pgns.get(pgn, 0) + count
        if frame_id not in self._ids:
            msg = self.table.get(pgn)
            self._ids[frame_id] = (frame_id_unpack(frame_id).source_address, msg[1]) if msg else None
        hit = self._ids[frame_id]
        if hit is None:
            return frame_id
        sa, name = hit
        per = self.senders.setdefault(name, {})
        per[sa] = per.get(sa, 0) + count
        want = self.source if self.source is not None else self.used.setdefault(name, sa)
        if self.source is not None:
            self.used.setdefault(name, self.source)
        if sa != want:
            self.other_source += count
            return -1
        return self.table[pgn][0]

    def message(self, msg: can.Message) -> can.Message | None:
        """The frame with the DBC's ID (itself when not J1939, None: another sender's)."""
        if not msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            return msg
        fid = self._target(msg.arbitration_id, 1)
        if fid == msg.arbitration_id:
            return msg
        if fid < 0:
            return None
        return can.Message(timestamp=msg.timestamp, arbitration_id=fid, is_extended_id=True,
                           data=msg.data, dlc=msg.dlc, channel=msg.channel, is_rx=msg.is_rx,
                           is_fd=msg.is_fd, check=False)

    def arrays(self, fa: FrameArrays) -> FrameArrays:
        """The frames with the DBC's IDs; another sender's frames left out (counted)."""
        ext = fa.is_extended & ~fa.frame_type
        if not ext.any():
            return fa
        ids = fa.arbitration_id[ext]
        uniq, first, inverse, counts = np.unique(ids, return_index=True, return_inverse=True,
                                                 return_counts=True)
        new = np.empty_like(uniq)
        for j in np.argsort(first, kind="stable").tolist():   # first senders first
            new[j] = self._target(int(uniq[j]), int(counts[j]))
        if bool((new == uniq).all()):
            return fa
        out_ids = fa.arbitration_id.copy()
        out_ids[ext] = new[inverse.reshape(-1)]
        out = FrameArrays(fa.timestamp, out_ids, fa.is_extended, fa.frame_type, fa.length,
                          fa.data, fa.long_data)
        if bool((new < 0).any()):
            out = out.select(out_ids >= 0)
        return out

    def stats(self) -> dict[str, object]:
        """``{"messages": {name: {"pgn", "source", "sources"}}, "other_source": n}``."""
        msgs: dict[str, object] = {}
        for pgn, (_fid, name) in self.table.items():
            per = self.senders.get(name, {})
            used = self.used.get(name)
            msgs[name] = {"pgn": pgn, "source": None if used is None else f"{used:#04x}",
                          "sources": {f"{sa:#04x}": n for sa, n in sorted(per.items())}}
        return {"messages": msgs, "other_source": self.other_source}

    def warnings(self, where: str, mapped: set[str]) -> list[str]:
        """One line per mapped message sent by several sources without ``can.j1939_source``."""
        out = []
        for name, per in self.senders.items():
            if name not in mapped or len(per) < 2 or self.source is not None:
                continue
            used = self.used[name]
            listed = ", ".join(f"{sa:#04x} ({n} frames)" for sa, n in sorted(per.items()))
            out.append(f"{where}: J1939 {name} (PGN {self._pgn[name]}) is sent by {len(per)} "
                       f"sources, {listed}; decoded {used:#04x} (the first), the others "
                       "not; choose one with the --config file's can.j1939_source")
        return out

    def hint(self, mapped: set[str]) -> str:
        """Why no frame of the mapped J1939 messages was decoded (``"; ..."``, for the error)."""
        parts = []
        for name in sorted(mapped):
            if name not in self.used and name not in self.senders:
                parts.append(f"{name} (PGN {self._pgn[name]}) not in the log")
            elif self.source is not None and self.source not in self.senders.get(name, {}):
                got = ", ".join(f"{sa:#04x} ({n} frames)"
                                for sa, n in sorted(self.senders[name].items()))
                parts.append(f"{name} (PGN {self._pgn[name]}) is sent by {got}, not by "
                             f"can.j1939_source {self.source:#04x}")
        top = sorted(self.pgns.items(), key=lambda kv: (-kv[1], kv[0]))[:TOP_PGNS]
        names = {p: n for p, (_f, n) in self.table.items()}
        have = ", ".join(f"{p} ({names[p] + ', ' if p in names else ''}{n} frames)"
                         for p, n in top) or "none (no extended frame)"
        more = f" of {len(self.pgns)}" if len(self.pgns) > TOP_PGNS else ""
        return f"; J1939: {'; '.join(parts) + '; ' if parts else ''}PGNs in the log{more}: {have}"
