"""What the decoder counts: frames accepted, ignored, lost, and rejected by reason."""
from __future__ import annotations

from dataclasses import dataclass, field

#: rejection reasons, in check order
REJECT_REASONS: tuple[str, ...] = ("malformed", "frame_type", "time", "unknown_id", "dlc", "crc",
                                   "counter_stale", "counter_jump", "no_sync")


@dataclass
class FrameCounts:
    """Frame counters of a decoder: ``accepted`` (stored or applied), ``ignored`` (DBC
    messages without a mapped channel), ``lost`` (missing by the counters and the time),
    ``rejected`` (reason -> frames)."""

    accepted: int = 0
    ignored: int = 0
    lost: int = 0
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0))
