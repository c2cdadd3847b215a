"""The decoder's rules, one module each: :mod:`.e2e` (CRC and alive counter),
:mod:`.counters` (continuity, lost frames, period estimate), :mod:`.timebase` (which clock,
time order, tick of a frame), :mod:`.arrival` and :mod:`.arrival_live` (sample slots from
arrival times, for a whole log and causally). Per-frame and array forms give the same
result bit for bit (``tests/can/test_rules.py``).
"""
