"""CAN front end of the estimator: frame validation, decoding, rolling buffer, log input.

Public entry points
-------------------
:class:`~estimator.decode.listener.DecodeListener`
    python-can Listener: validate (ID, DLC, CRC, counter, time), decode, buffer -- in
    NumPy batches, identical to frame by frame.
:class:`~estimator.decode.buffer.RollingBuffer`
    bounded preallocated store; :meth:`~estimator.decode.buffer.RollingBuffer.align`.
:func:`~estimator.decode.log_input.load_log_as_measurement`
    a CAN log as a Measurement plus frame statistics (``suspid identify --input LOG``).
:func:`~estimator.decode.replay.feed_log`
    a CAN log into a listener as arrays (candump: no message objects at all).
:func:`~estimator.decode.replay.feed`, :class:`~estimator.decode.replay.ReplayBus`
    messages into listeners, directly or through ``can.Notifier``.
"""
from estimator.decode.buffer import Aligned, Gap, RollingBuffer
from estimator.decode.listener import REJECT_REASONS, DecodeListener
from estimator.decode.log_input import aligned_to_measurement, load_log_as_measurement
from estimator.decode.replay import ReplayBus, feed, feed_log, feed_with_notifier

__all__ = ["Aligned", "Gap", "RollingBuffer", "REJECT_REASONS", "DecodeListener",
           "aligned_to_measurement", "load_log_as_measurement", "ReplayBus", "feed",
           "feed_log", "feed_with_notifier"]
