"""Dask: a local cluster and a real ``dask scheduler`` + two ``dask worker`` processes on
127.0.0.1 give exactly the in-process results."""
from __future__ import annotations

import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import pytest
from distributed import Client

from tests.conftest import REPO, suspid_env
from tests.fleet.conftest import FIX, Fleet, fleet_json

BIN = Path(sys.executable).parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _dask_cli() -> list[str]:
    exe = BIN / "dask"
    return [str(exe)] if exe.exists() else [shutil.which("dask") or "dask"]


def _stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for p in reversed(procs):
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in reversed(procs):
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=30)


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    """A real scheduler and two single-thread worker processes on 127.0.0.1 (torn down)."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(suspid_env(), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    procs: list[subprocess.Popen[bytes]] = []
    log = open(tmp_path / "dask.log", "wb")
    try:
        procs.append(subprocess.Popen([*_dask_cli(), "scheduler", "--host", "127.0.0.1", "--port",
                                       str(port), "--no-dashboard"], stdout=log, stderr=log,
                                      env=env, cwd=tmp_path))
        for i in range(2):
            procs.append(subprocess.Popen([*_dask_cli(), "worker", address, "--host", "127.0.0.1",
                                           "--nthreads", "1", "--no-dashboard", "--name",
                                           f"w{i}", "--local-directory", str(tmp_path / f"w{i}")],
                                          stdout=log, stderr=log, env=env, cwd=tmp_path))
        deadline = time.monotonic() + 240
        while True:
            try:
                with Client(address, timeout=20) as c:
                    c.wait_for_workers(2, timeout=max(1.0, deadline - time.monotonic()))
                    workers = c.scheduler_info()["workers"]
                    assert len(workers) == 2
                break
            except OSError:
                if time.monotonic() > deadline or any(p.poll() is not None for p in procs):
                    raise
                time.sleep(1.0)
        yield address
    finally:
        _stop(procs)
        log.close()


def _same(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert a["drives"] == b["drives"]
    assert a["vehicles"] == b["vehicles"]
    assert a["failed"] == b["failed"]


@pytest.mark.slow
def test_real_scheduler_and_workers_equal_the_local_run(fleet: Fleet, inprocess: dict[str, Any],
                                                        dask_cluster: str) -> None:
    out = fleet_json("--model", "quarter2", "--input", str(fleet.root), *FIX,
                     "--scheduler", dask_cluster)
    _same(out, inprocess)
    with Client(dask_cluster, timeout=20) as c:     # both workers took drives
        done = c.run(lambda dask_worker: len(dask_worker.data) + dask_worker.state.transition_counter)
    assert len(done) == 2 and all(v > 0 for v in done.values())


@pytest.mark.slow
def test_local_cluster_equals_in_process(fleet: Fleet, inprocess: dict[str, Any]) -> None:
    out = fleet_json("--model", "quarter2", "--input", str(fleet.root), *FIX, "--workers", "2")
    _same(out, inprocess)


@pytest.mark.slow
def test_unreachable_scheduler_is_one_error_line(fleet: Fleet) -> None:
    port = _free_port()
    proc = subprocess.run([sys.executable, "-m", "suspid", "fleet", "--model", "quarter2",
                           "--input", str(fleet.root / "VAN-OK" / "extra.csv"), *FIX,
                           "--scheduler", f"tcp://127.0.0.1:{port}", "--json"],
                          capture_output=True, text=True, env=dict(suspid_env(),
                          DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="3s"), cwd=REPO, timeout=300)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("error: --scheduler") and len(lines) == 1, proc.stderr


@pytest.mark.slow
def test_a_worker_that_dies_fails_only_its_drive(fleet: Fleet, monkeypatch: pytest.MonkeyPatch) -> None:
    """A drive whose task kills its worker process (as a crash in a native library would) is
    listed as failed with the reason; the other drives on the same cluster are identified."""
    import os

    from estimator.fleet import runner
    from estimator.fleet.drive import IdentifySettings, identify_drive

    logs = sorted((fleet.root / "VAN-OK").glob("drive-*.log"))[:2]
    poison = str(logs[1])

    def crashing(path: str, vehicle: str, settings: IdentifySettings,
                 digest: str | None = None) -> dict[str, Any]:
        if path == poison:
            os._exit(13)
        return identify_drive(path, vehicle, settings, digest)

    monkeypatch.setattr(runner, "identify_drive", crashing)
    settings = IdentifySettings(model="quarter2", fix={"m1": 300.0, "m2": 40.0})
    jobs: list[tuple[str, str, str | None]] = [(str(p), "VAN-OK", None) for p in logs]
    out = runner.execute(jobs, settings, workers=2)
    assert [r["path"] for r in out] == [str(p) for p in logs]
    assert out[0]["status"] == "ok" and out[0]["result"]["params"]["c1"] > 0
    assert out[1]["status"] == "failed"
    assert out[1]["error"].startswith(f"{poison}: the Dask task failed: KilledWorker")
    assert "\n" not in out[1]["error"]
