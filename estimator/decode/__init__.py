"""CAN front end of the estimator: frame validation, decoding, rolling buffer, log input.

``listener.py`` (the python-can Listener), ``engine.py`` (batches of frames -> samples),
``rules/`` (the checks), ``routes.py`` (per CAN ID: kind, checks, decoders), ``vector.py``
(array decoders), ``buffer.py`` (rolling store, alignment), ``log_input.py`` (a CAN log as a
Measurement), ``replay.py`` (logs into listeners).
"""
from estimator.decode.buffer import Aligned, Gap, RollingBuffer
from estimator.decode.listener import REJECT_REASONS, DecodeListener
from estimator.decode.log_input import aligned_to_measurement, load_log_as_measurement
from estimator.decode.replay import ReplayBus, feed, feed_log, feed_with_notifier

__all__ = ["Aligned", "Gap", "RollingBuffer", "REJECT_REASONS", "DecodeListener",
           "aligned_to_measurement", "load_log_as_measurement", "ReplayBus", "feed",
           "feed_log", "feed_with_notifier"]
