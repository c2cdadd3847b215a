"""What the decoder counts: frames accepted, ignored, lost, and rejected by reason."""
from __future__ import annotations

from dataclasses import dataclass, field

#: rejection reasons, in check order
REJECT_REASONS: tuple[str, ...] = ("malformed", "frame_type", "time", "unknown_id", "dlc", "crc",
                                   "counter_stale", "counter_jump", "no_sync")


@dataclass
class FrameCounts:
    """Frame counters of a decoder (see :mod:`estimator.decode.listener`).

    Attributes
    ----------
    accepted : int
        Frames validated and stored (data) or applied (SN_Sync, SN_Status, alerts).
    ignored : int
        Frames of DBC messages that carry no mapped channel.
    lost : int
        Frames the counters and the time say are missing.
    rejected : dict
        Reason (:data:`REJECT_REASONS`) -> frames rejected for it.
    """

    accepted: int = 0
    ignored: int = 0
    lost: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))
