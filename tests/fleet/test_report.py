"""``--report``: the static HTML page opened in a real headless Chromium; the ranked table,
the trend plots and the failed logs read back from the browser's DOM."""
from __future__ import annotations

import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

from estimator.fleet import runner
from estimator.fleet.drive import IdentifySettings
from estimator.fleet.report import vehicle_anchor
from suspid.errors import InputError
from tests.fleet.conftest import Fleet, HistoryRuns, fleet_json


class _Tables(HTMLParser):
    """Rows of the tables with an id, and the trend SVGs' (vehicle, parameter)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.svgs: list[tuple[str, str]] = []
        self.ids: list[str] = []
        self.links: list[str] = []
        self._table: str | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if a.get("id"):
            self.ids.append(str(a["id"]))
        if tag == "a" and (a.get("href") or "").startswith("#"):
            self.links.append(str(a["href"])[1:])
        if tag == "table" and a.get("id"):
            self._table = str(a["id"])
            self.tables[self._table] = []
        elif tag == "tr" and self._table:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
        elif tag == "svg" and "trend" in (a.get("class") or ""):
            self.svgs.append((str(a.get("data-vehicle")), str(a.get("data-parameter"))))

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None and self._table:
            self.tables[self._table].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        exe = shutil.which(name)
        if exe:
            return exe
    pytest.fail("headless Chromium not found: install the Debian package 'chromium' "
                "(bash tools/system_deps.sh installs tools/system-packages.txt)")


def _browser(args: list[str], profile: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([_chromium(), "--headless", "--no-sandbox", "--disable-gpu",
                           "--disable-dev-shm-usage", f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_report_in_headless_chromium(fleet: Fleet, history: HistoryRuns,
                                     tmp_path: Path) -> None:
    report = tmp_path / "report"
    out = fleet_json("--db", str(history.db), "--report", str(report))   # from the history
    page = report / "index.html"
    assert out["report"] == str(page)
    proc = _browser(["--dump-dom", page.resolve().as_uri()], tmp_path / "profile")
    assert proc.returncode == 0 and "<table" in proc.stdout, proc.stderr[-2000:]
    dom = _Tables()
    dom.feed(proc.stdout)
    header, *rows = dom.tables["vehicles"]
    assert header[:3] == ["Rank", "Vehicle", "Risk"]
    assert [r[1] for r in rows] == ["VAN-WORN", "VAN-WEAR", "VAN-OK"]      # ranked by risk
    assert [r[2] for r in rows] == ["alert", "forecast", "ok"]
    assert rows[0][header.index("Alerts")] == "c1"
    fc = {v["vehicle"]: v for v in out["vehicles"]}["VAN-WEAR"]["forecast"]["c1"]
    assert rows[1][header.index("First forecast crossing (90 %)")].startswith("c1: 2026-")
    assert fc["crossing_t_low"] < fc["crossing_t"]
    failed = dom.tables["failed"][1:]
    assert sorted(r[0] for r in failed) == sorted(str(p) for p in fleet.bad)
    assert len(rows) == 3 and int(rows[2][header.index("Drives")]) == 8
    assert all(r[1] == "VAN-OK" and r[2] for r in failed)
    assert sorted(dom.svgs) == sorted((v, k) for v in ("VAN-WORN", "VAN-WEAR", "VAN-OK")
                                      for k in ("c1", "k1", "c2", "k2"))
    # every vehicle link leads to its section: ids unique, without whitespace
    assert len(dom.links) == 3 and set(dom.links) <= set(dom.ids)
    assert len(set(dom.ids)) == len(dom.ids) and not any(c.isspace() for i in dom.ids for c in i)
    shot = tmp_path / "report.png"
    proc = _browser([f"--screenshot={shot}", "--window-size=1200,1600", page.resolve().as_uri()],
                    tmp_path / "profile2")
    assert proc.returncode == 0 and shot.stat().st_size > 20000, proc.stderr[-2000:]


def test_unusable_report_folder_fails_before_any_drive(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """``--report`` naming a file, or a folder whose index.html is a folder, is one error at
    the start of the run, not after every drive has been identified."""
    log = tmp_path / "V" / "d.csv"
    log.parent.mkdir()
    log.write_text("t,x\n0,0\n")
    (tmp_path / "a-file").write_text("x")
    (tmp_path / "r" / "index.html").mkdir(parents=True)

    def identified(*args: object) -> None:
        raise AssertionError("a drive was identified before the report folder was checked")

    monkeypatch.setattr(runner, "identify_drive", identified)
    settings = IdentifySettings(model="quarter2")
    for folder, words in (("a-file", "is a file"), ("r", "is a folder")):
        with pytest.raises(InputError, match=words):
            runner.run_fleet(runner.FleetConfig(inputs=[str(log)], settings=settings, workers=0,
                                                report=str(tmp_path / folder)))


def test_vehicle_anchors_are_valid_distinct_ids() -> None:
    """Vehicle names with spaces, markup or non-ASCII letters give HTML ids without
    whitespace or markup, one per name."""
    names = ["VAN 1", "VAN_1", "VAN-1", "VAN_20_1", "Lkw Ölwechsel", "<b>&\"'", "ö", "_f6_", ""]
    ids = [vehicle_anchor(n) for n in names]
    assert len(set(ids)) == len(ids)
    assert all(i.startswith("v-") and all((c.isascii() and c.isalnum()) or c in "-_" for c in i)
               for i in ids)
    assert vehicle_anchor("VAN-OK") == "v-VAN-OK"
