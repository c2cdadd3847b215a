"""The decoder's rules, one module each; per-frame and array forms give the same result bit
for bit (``tests/can/test_rules.py``)."""
