"""The decoder's rules, each in one module.

========================  ==================================================================
module                    rule
========================  ==================================================================
:mod:`.e2e`               E2E protection: CRC-8 J1850 over the data ID and payload, the
                          alive counter's place in the payload
:mod:`.counters`          alive counter continuity (stale, jump, lost frames), the
                          per-message period estimate that tells a silence from a jump
:mod:`.timebase`          which clock gives data time (sensor tick or arrival), the time
                          order check and its re-anchoring, the tick of a frame from its
                          counter, the stale-tick rule after a silence
:mod:`.arrival`           without a sensor clock: each frame's sample slot from the
                          arrival times of its message (a whole log at once)
========================  ==================================================================

:class:`~estimator.decode.engine.DecodeEngine` applies the array functions to the frames of a
batch and the per-frame functions (``CounterRules.step``, ``stale_tick``, ``tick_of_counter``,
``alive_counter``...) to the frames its array code does not cover (a time anomaly, a counter
jump, a silence, a short run); the two give the same result bit for bit, compared in
``tests/can/test_rules.py``. :mod:`.arrival_live` is the causal form of :mod:`.arrival` for
frames that arrive one at a time (it holds a few frames per message as look-ahead).
"""
