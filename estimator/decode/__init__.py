"""CAN front end of the estimator: frame validation (``listener``, ``engine``, ``rules/``),
decoding (``routes``, ``vector``, ``pages``), rolling buffer, log input and replay."""
from estimator.decode.buffer import Aligned, Gap, RollingBuffer
from estimator.decode.listener import REJECT_REASONS, DecodeListener
from estimator.decode.log_input import aligned_to_measurement, load_log_as_measurement
from estimator.decode.replay import ReplayBus, feed, feed_log, feed_with_notifier

__all__ = ["Aligned", "Gap", "RollingBuffer", "REJECT_REASONS", "DecodeListener",
           "aligned_to_measurement", "load_log_as_measurement", "ReplayBus", "feed",
           "feed_log", "feed_with_notifier"]
