"""CAN front end of the estimator: frame validation, decoding, rolling buffer, log input.

Parts, by file
--------------
``listener.py`` :class:`~estimator.decode.listener.DecodeListener`
    the python-can Listener (a ``can.Notifier`` drives it, or a log replay): queues frames
    and hands them to the engine in batches (arrays); the results.
``engine.py`` :class:`~estimator.decode.engine.DecodeEngine`
    batches of frames as arrays -> validated, decoded samples in the buffer; the one
    entry (``process``) for a log and a live bus.
``rules/`` (``e2e.py``, ``counters.py``, ``timebase.py``, ``arrival.py``, ``arrival_live.py``)
    the checks: E2E CRC and alive counter, counter continuity and lost frames, which clock
    gives data time, sample slots from arrival times.
``routes.py``
    per CAN ID of the DBC: kind, length, E2E check, decoders, buffer ring.
``vector.py``
    signals of many payloads at once, bit for bit the per-frame decoder.
``buffer.py`` :class:`~estimator.decode.buffer.RollingBuffer`
    bounded preallocated store; :meth:`~estimator.decode.buffer.RollingBuffer.align`.
``log_input.py`` :func:`~estimator.decode.log_input.load_log_as_measurement`
    a CAN log as a Measurement plus frame statistics (``suspid identify --input LOG``).
``replay.py`` :func:`~estimator.decode.replay.feed_log`, :func:`~estimator.decode.replay.feed`,
:class:`~estimator.decode.replay.ReplayBus`
    a CAN log into a listener as arrays, messages into listeners directly or through
    ``can.Notifier``.
"""
from estimator.decode.buffer import Aligned, Gap, RollingBuffer
from estimator.decode.listener import REJECT_REASONS, DecodeListener
from estimator.decode.log_input import aligned_to_measurement, load_log_as_measurement
from estimator.decode.replay import ReplayBus, feed, feed_log, feed_with_notifier

__all__ = ["Aligned", "Gap", "RollingBuffer", "REJECT_REASONS", "DecodeListener",
           "aligned_to_measurement", "load_log_as_measurement", "ReplayBus", "feed",
           "feed_log", "feed_with_notifier"]
