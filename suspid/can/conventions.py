"""suspid's own DBC conventions, read from a loaded database without importing cantools.

The conventions of ``dbc/suspension.dbc`` (docs/can.md): ``E2EProfile = "P01"`` messages,
``SuspidChannel = "quarter1:x quarter2:x1"`` signal attributes, ``<Name>Valid`` validity bits,
and the ``SN_Sync``, ``SN_Status`` and ``SUSPID_Alert`` messages. Importing cantools costs
~0.4 s; a CSV-only ``suspid identify`` does not pay it.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from suspid.errors import InputError

if TYPE_CHECKING:
    from cantools.database.can import Database, Message

#: names of the special messages of suspension.dbc
SYNC_MESSAGE = "SN_Sync"
STATUS_MESSAGE = "SN_Status"
ALERT_MESSAGE = "SUSPID_Alert"
#: DBC attribute names used by suspid
ATTR_E2E = "E2EProfile"
ATTR_CHANNEL = "SuspidChannel"


def default_dbc_path() -> Path:
    """Path of suspid's ``suspension.dbc`` (package data; ``dbc/`` links to it)."""
    return Path(str(resources.files("suspid") / "data" / "suspension.dbc"))


def signal_attribute(signal: object, name: str, default: object = None) -> object:
    """Value of a DBC signal (or message) attribute (``default`` if unset)."""
    dbc = getattr(signal, "dbc", None)
    if dbc is None or name not in dbc.attributes:
        return default
    return dbc.attributes[name].value


def is_e2e(message: Message) -> bool:
    """``True`` if the message is E2E protected (``E2EProfile = "P01"``)."""
    return signal_attribute(message, ATTR_E2E, "") == "P01"


#: bit 31 of a DBC frame ID: the message is an extended (29-bit) frame
DBC_EXTENDED = 0x80000000
#: largest standard (11-bit) CAN ID
MAX_STANDARD_ID = 0x7FF


def _id_text(message: Message) -> str:
    """``0x100`` (standard) or ``0x80000100`` (extended, the DBC's bit 31) of a message."""
    if message.is_extended_frame:
        return f"{message.frame_id | DBC_EXTENDED:#x} (extended)"
    return f"{message.frame_id:#x} (standard)"


def find_message(db: Database, ref: str, where: str = "") -> Message:
    """Message by name, or by frame ID (decimal or ``0x`` hex), else an :class:`InputError`
    naming ``where`` (e.g. the map entry) and a few of the known messages.

    A frame ID is standard unless it has bit 31 set (``0x80000100``) or exceeds 11 bits; an
    ID only an extended message has finds it too. A name two messages share is an error.
    """
    lead = f"{where}{': ' if where else ''}"
    src = getattr(db, "suspid_path", "DBC")
    named = [m for m in db.messages if m.name == ref]
    if len(named) > 1:
        raise InputError(f"{lead}message name {ref!r} is ambiguous in {src}: "
                         f"{' and '.join(_id_text(m) for m in named)} share it; "
                         "give the frame ID instead of the name, e.g. "
                         f"{_id_text(named[0]).split()[0]}")
    if named:
        return named[0]
    try:
        fid = int(ref, 0)
    except ValueError:
        fid = None
    if fid is not None and fid >= 0:
        ext = bool(fid & DBC_EXTENDED) or fid > MAX_STANDARD_ID
        can_id = fid & ~DBC_EXTENDED
        same = [m for m in db.messages if m.frame_id == can_id]
        exact = [m for m in same if m.is_extended_frame == ext]
        if exact:
            return exact[0]
        if same and not fid & DBC_EXTENDED:   # 0x100 of an extended-only message
            return same[0]
    names = ", ".join(m.name for m in db.messages[:12])
    more = ", ..." if len(db.messages) > 12 else ""
    raise InputError(f"{lead}message {ref!r} is not in {src}; "
                     f"expected one of {names}{more}")


def channel_signals(db: Database, model_name: str) -> list[tuple[str, str, str]]:
    """``(channel, message, signal)`` triples that the ``SuspidChannel`` attributes give for a
    model; empty for a DBC without them."""
    out: list[tuple[str, str, str]] = []
    for msg in db.messages:
        for sig in msg.signals:
            attr = signal_attribute(sig, ATTR_CHANNEL, "") or ""
            for pair in str(attr).split():
                model, _, channel = pair.partition(":")
                if model == model_name and channel:
                    out.append((channel, msg.name, sig.name))
    return out


def has_suspid_channels(db: Database) -> bool:
    """``True`` if any signal carries a ``SuspidChannel`` attribute (i.e. suspid's own DBC)."""
    return any(signal_attribute(s, ATTR_CHANNEL, "") for m in db.messages for s in m.signals)
