"""The decoder's rules, each in one module, the frame-by-frame and the array form side by side.

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

Each frame rule has a scalar function (the reference, used frame by frame) and an array function
over many frames (used by :class:`~estimator.decode.engine.DecodeEngine`'s batches) that
gives the same result bit for bit; ``tests/can/test_rules.py`` compares them directly.
"""
