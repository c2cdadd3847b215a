"""suspid's own DBC conventions, read from a loaded database without importing cantools.

Conventions of ``dbc/suspension.dbc`` (see ``docs/can.md``):

* message attribute ``E2EProfile = "P01"``: byte 0 CRC-8 J1850, byte 1 low nibble alive
  counter (:mod:`suspid.can.crc`);
* signal attribute ``SuspidChannel = "quarter1:x quarter2:x1"``: the model channel each
  signal carries, per model;
* a signal ``<Name>Valid`` in the same message is the validity bit of signal ``<Name>``;
* message ``SN_Sync`` carries the sample tick; ``SN_Status`` the node status;
  ``SUSPID_Alert`` the estimator's maintenance alert.

Loading a DBC (:func:`suspid.can.dbc.load_dbc`) needs cantools, whose import loads
python-can and its log backends (about 0.4 s); this module only reads a database passed
in, so the signal map and a CSV-only ``suspid identify`` do not pay that import.
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
    """Path of suspid's ``suspension.dbc``, the one source of the bus definition.

    The file is the package data ``suspid/data/suspension.dbc`` (so an installed
    ``suspid`` finds it); the repository's ``dbc/suspension.dbc`` is a symbolic link to it
    for users who look in ``dbc/``.
    """
    return Path(str(resources.files("suspid") / "data" / "suspension.dbc"))


def message_attribute(message: Message, name: str, default: object = None) -> object:
    """Value of a DBC message attribute (``default`` if unset)."""
    dbc = message.dbc
    if dbc is None or name not in dbc.attributes:
        return default
    return dbc.attributes[name].value


def signal_attribute(signal: object, name: str, default: object = None) -> object:
    """Value of a DBC signal attribute (``default`` if unset)."""
    dbc = getattr(signal, "dbc", None)
    if dbc is None or name not in dbc.attributes:
        return default
    return dbc.attributes[name].value


def is_e2e(message: Message) -> bool:
    """``True`` if the message is E2E protected (``E2EProfile = "P01"``)."""
    return message_attribute(message, ATTR_E2E, "") == "P01"


def find_message(db: Database, ref: str, where: str = "") -> Message:
    """Message by name, or by frame ID (decimal or ``0x`` hex).

    Raises
    ------
    InputError
        Naming ``where`` (e.g. the map entry) and a few of the known messages.
    """
    try:
        return db.get_message_by_name(ref)
    except KeyError:
        pass
    try:
        fid = int(ref, 0)
    except ValueError:
        fid = None
    if fid is not None:
        try:
            return db.get_message_by_frame_id(fid)
        except KeyError:
            pass
    names = ", ".join(m.name for m in db.messages[:12])
    more = ", ..." if len(db.messages) > 12 else ""
    src = getattr(db, "suspid_path", "DBC")
    raise InputError(f"{where}{': ' if where else ''}message {ref!r} is not in {src}; "
                     f"expected one of {names}{more}")


def channel_signals(db: Database, model_name: str) -> list[tuple[str, str, str]]:
    """``(channel, message, signal)`` triples that the ``SuspidChannel`` attributes give for a model.

    Empty for a DBC without suspid attributes (then a signal map is needed).
    """
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
