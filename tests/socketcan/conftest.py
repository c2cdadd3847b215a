"""SocketCAN tests: a real kernel CAN stack (vcan0) with can-utils as the other end.

They run where vcan0 is up: natively on a host with SocketCAN, otherwise through
``tools/vcan_bench.sh`` (User-Mode Linux); ``tools/test.sh`` runs them that way. Elsewhere
they are skipped with the command that runs them.
"""
from __future__ import annotations

import shutil
import socket
from pathlib import Path

import pytest

CAN_UTILS = ("candump", "canplayer", "cangen", "cansend")


def vcan_unavailable() -> str | None:
    """Why the SocketCAN tests cannot run here (None: they can)."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError as exc:
        return f"kernel has no SocketCAN ({exc.strerror}); run: tools/vcan_bench.sh pytest -m socketcan"
    s.close()
    if not Path("/sys/class/net/vcan0").exists():
        return "no vcan0; run: tools/vcan_bench.sh pytest -m socketcan"
    missing = [p for p in CAN_UTILS if shutil.which(p) is None]
    if missing:
        return f"can-utils missing ({', '.join(missing)}): apt-get install can-utils"
    return None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    reason = vcan_unavailable()
    for item in items:
        if "socketcan" in item.keywords and reason is not None:
            item.add_marker(pytest.mark.skip(reason=reason))
