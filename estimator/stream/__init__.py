"""Streaming estimation: sliding-window identification of a suspension on a CAN stream
(``docs/monitoring.md``)."""
