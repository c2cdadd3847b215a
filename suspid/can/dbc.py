"""Loading DBC files with one-line errors; suspid's DBC conventions
(:mod:`suspid.can.conventions`, no cantools import) re-exported."""
from __future__ import annotations

import logging
from pathlib import Path

from cantools.database.can import Database

from suspid.can.conventions import (ALERT_MESSAGE, ATTR_CHANNEL, ATTR_E2E, STATUS_MESSAGE,
                                    SYNC_MESSAGE, channel_signals, default_dbc_path,
                                    find_message, has_suspid_channels, is_e2e)
from suspid.errors import InputError, require_file

__all__ = ["ALERT_MESSAGE", "ATTR_CHANNEL", "ATTR_E2E", "STATUS_MESSAGE", "SYNC_MESSAGE",
           "channel_signals", "default_dbc_path", "find_message", "has_suspid_channels",
           "is_e2e", "load_dbc"]

log = logging.getLogger(__name__)


def _not_a_name_overwrite(record: logging.LogRecord) -> bool:
    """Drop cantools' "Overwriting message" log line (two messages of one name):
    :func:`~suspid.can.conventions.find_message` names both IDs when a map uses the name."""
    return not str(record.msg).startswith("Overwriting message '%s' with '%s' in the name")


def load_dbc(path: str | Path | None = None) -> Database:
    """Load a DBC file (default :func:`default_dbc_path`) with cantools in strict mode; one
    failing only the strict checks is loaded non-strict with a logged warning. The database's
    ``suspid_path`` is the path it came from; an :class:`InputError` for a missing or unreadable
    file or a parse error."""
    p = require_file(path if path is not None else default_dbc_path(), "DBC file")
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"{p}: cannot read DBC: {exc.strerror}") from None
    db = Database(strict=True)
    cantools_log = logging.getLogger(Database.__module__)
    cantools_log.addFilter(_not_a_name_overwrite)
    try:
        db.add_dbc_string(text)
    except Exception as exc:  # cantools raises several types (ParseError, Error, ...)
        msg = " ".join(str(exc).split())
        if "Invalid syntax" not in msg:
            db = Database(strict=False)
            try:
                db.add_dbc_string(text)
            except Exception:
                raise InputError(f"{p}: cannot load DBC: {msg}") from None
            log.warning("%s: loaded without cantools strict checks (%s)", p, msg)
        else:
            raise InputError(f"{p}: cannot load DBC: {msg}") from None
    finally:
        cantools_log.removeFilter(_not_a_name_overwrite)
    if not db.messages:
        raise InputError(f"{p}: DBC defines no message (BO_), expected at least one")
    db.suspid_path = str(p)  # type: ignore[attr-defined]
    return db
