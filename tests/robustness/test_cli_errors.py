"""Every bad input or option value of every subcommand: exit 2, one ``error:`` line, no traceback.

The CLI runs in-process (``suspid.cli.main``) to stay fast; a few subprocess checks make
sure the installed console script behaves the same.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from suspid.cli import main
from suspid.excitation import make_scenario
from suspid.io.csvio import write_measurement
from suspid.models import get_model
from suspid.simulate import simulate


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory with a good CSV and log and a zoo of bad files."""
    d = tmp_path_factory.mktemp("cli")
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "bump", duration=0.4, fs=500.0)
    out = simulate(m, m.defaults(), t, road, x0)
    write_measurement(d / "q2.csv", t, {k: out[k] for k in ("r", "r_dot", "x1", "x2")})
    assert main(["encode", "--input", str(d / "q2.csv"), "--out", str(d / "q2.log")]) == 0
    (d / "adir").mkdir()
    (d / "adir.log").mkdir()
    (d / "empty.csv").write_text("")
    (d / "empty.log").write_text("")
    (d / "empty.dbc").write_text("")
    (d / "tonly.csv").write_text("t\n0\n0.1\n")
    (d / "dupt.csv").write_text("t,x1\n0,1\n0,2\n")
    (d / "inf.csv").write_text("t,x1\n0,1\n0.1,inf\n")
    (d / "bin.csv").write_bytes(b"\x00\xff\xfe\x01garbage")
    (d / "bad.dbc").write_text("garbage here\nBO_ x\n")
    (d / "foreign.dbc").write_text('VERSION ""\nBO_ 1 Foo: 8 X\n SG_ A : 0|8@1+ (1,0) [0|1] "" X\n')
    (d / "junk.blf").write_bytes(b"x" * 10)
    (d / "junk.mf4").write_bytes(b"x" * 10)
    (d / "bad.json").write_text("{bad json")
    (d / "q2.xyz").write_text("t,x1\n0,0\n")
    (d / "huge.csv").write_text("t,x1,x2\n0,1e300,0\n0.01,-2e300,0\n"
                                + "".join(f"0.0{k},0,1\n" for k in range(2, 9)))
    # plain `candump can0` output (not -L) saved as .log
    plain = [ln.split() for ln in (d / "q2.log").read_text().splitlines()[:50]]
    (d / "plain.log").write_text("".join(
        f"  {f[1]}  {f[2].split('#')[0]}   [{len(f[2].split('#')[1]) // 2}]  "
        + " ".join(f[2].split("#")[1][i:i + 2] for i in range(0, len(f[2].split("#")[1]), 2)) + "\n"
        for f in plain))
    # a missing sample (0.015 s), not jitter: more than a quarter step off any uniform grid
    (d / "jitroad.csv").write_text("t,r\n0,0\n0.005,0\n0.01,0.001\n0.02,0.002\n0.025,0.002\n")
    (d / "hugeroad.csv").write_text("t,r,x1\n0,1e300,0\n0.01,-2e300,0\n0.02,0,1\n")
    # --config files: a short fit, bad values, not TOML
    (d / "fast.toml").write_text("[fit]\nrestarts = 0\n")
    (d / "lowpass.toml").write_text("[window]\nroad_lowpass_hz = -1\n")
    (d / "fusion.toml").write_text("[window]\nroad_fusion_hz = nan\n")
    (d / "bad.toml").write_text("[fit\nrestarts = 0\n")
    (d / "x0short.toml").write_text("[fit]\nx0 = [1, 2]\n")
    (d / "x0inf.toml").write_text("[fit]\nx0 = [0, inf, 0, 0]\n")
    (d / "roadclass.toml").write_text('[simulate]\nroad_class = "Z"\n')
    return d


IDENT = ["identify", "--model", "quarter2", "--json", "--maxfev", "5", "--config", "fast.toml"]
#: compare on its own scenario: the bad value must stop it before any simulation
COMPARE = ["compare", "--model", "quarter2", "--json"]
NODE = ["node", "--scenario", "bump", "--duration", "0.05", "--speed", "0", "--log", "n.log"]
#: (argv, text the error line must contain); file names are relative to the work dir
CASES: list[tuple[list[str], str]] = [
    # input files
    (IDENT + ["--input", "missing.csv"], "missing.csv: no such file"),
    (IDENT + ["--input", "adir"], "adir: is a directory, expected a file"),
    (IDENT + ["--input", "empty.csv"], "empty.csv: empty file"),
    (IDENT + ["--input", "tonly.csv"], "tonly.csv:1: no measured channel"),
    (IDENT + ["--input", "dupt.csv"], "dupt.csv:3: column 't': expected increasing"),
    (IDENT + ["--input", "inf.csv"], "inf.csv:3: column 'x1': expected a finite number"),
    (IDENT + ["--input", "bin.csv"], "bin.csv:1: not a CSV text file"),
    (IDENT + ["--input", "q2.xyz"], "q2.xyz: unknown input format '.xyz'"),
    (IDENT + ["--input", "huge.csv"], "huge.csv: column 'x1': values up to 2e+300 overflow"),
    (IDENT + ["--input", "hugeroad.csv"], "hugeroad.csv: column 'r': values up to 2e+300 overflow"),
    (["diagnose", "--model", "quarter2", "--input", "huge.csv"], "huge.csv: column 'x1'"),
    (IDENT + ["--input", "missing.log"], "missing.log: no such CAN log file"),
    (IDENT + ["--input", "adir.log"], "adir.log: no such CAN log file"),
    (IDENT + ["--input", "empty.log"], "empty.log: no accepted frame"),
    (IDENT + ["--input", "junk.blf"], "junk.blf: not a Vector BLF file: expected the signature b'LOGG' and a 144-byte header, got 10 bytes"),
    (IDENT + ["--input", "junk.mf4"], "junk.mf4: not a readable ASAM MDF4 file"),
    # DBC and signal maps
    (IDENT + ["--input", "q2.log", "--dbc", "missing.dbc"], "missing.dbc: no such DBC file"),
    (IDENT + ["--input", "q2.log", "--dbc", "adir"], "adir: is a directory, expected a DBC file"),
    (IDENT + ["--input", "q2.log", "--dbc", "empty.dbc"], "empty.dbc: cannot load DBC: Invalid syntax at line 1"),
    (IDENT + ["--input", "q2.log", "--dbc", "bad.dbc"], "bad.dbc: cannot load DBC: Invalid syntax at line 1"),
    (IDENT + ["--input", "q2.log", "--dbc", "q2.csv"], "q2.csv: cannot load DBC"),
    (IDENT + ["--input", "q2.log", "--dbc", "foreign.dbc"], "foreign.dbc declares no channel"),
    (IDENT[:-2] + ["--input", "q2.log", "--config", "bad.toml"], "bad.toml: invalid TOML"),
    (IDENT[:-2] + ["--input", "q2.log", "--config", "missing.toml"],
     "missing.toml: no such configuration file"),
    (IDENT + ["--input", "q2.log", "--map", "garbage"], "cannot parse signal map 'garbage'"),
    (IDENT + ["--input", "q2.log", "--map", "x1=Nope.Sig"], "message 'Nope' is not in"),
    # options
    (IDENT + ["--input", "q2.csv", "--plot", "nodir/x.png"], "nodir/x.png"),
    (IDENT + ["--input", "q2.csv", "--maxfev", "-1"], "--maxfev: expected an integer >= 1"),
    (IDENT[:-2] + ["--input", "q2.csv", "--config", "x0short.toml"], "fit.x0: expected 4 values"),
    (IDENT[:-2] + ["--input", "q2.csv", "--config", "x0inf.toml"],
     "x0inf.toml: fit.x0: expected \"estimate\", \"rest\" or a list of finite numbers"),
    (IDENT + ["--input", "q2.csv", "--fix", "zz=1"], "no parameter 'zz'"),
    (IDENT + ["--input", "q2.csv", "--fix", "m1=nan"], "--fix 'm1=nan': expected a finite number"),
    (IDENT + ["--input", "q2.csv", "--init", "m1=0"], "parameter m1: expected a finite value > 0"),
    # subnormal or absurdly small SI values (were accepted: exit 0 with cost null, or
    # "success" with every parameter near 1e-300); one parser for every subcommand
    (IDENT + ["--input", "q2.csv", "--fix", "m1=1e-320"],
     "--fix m1: expected a value of magnitude at least 1e-09 in SI units (kg, kg m^2, N/m, N s/m, m), "
     "got 1e-320 (a subnormal number)"),
    (IDENT + ["--input", "q2.csv", "--init", "c1=1e-300"], "--init c1: expected a value of magnitude "
     "at least 1e-09"),
    (["diagnose", "--model", "quarter2", "--input", "q2.csv", "--fix", "k2=-4e-324"],
     "--fix k2: expected a value of magnitude at least 1e-09 in SI units (kg, kg m^2, N/m, N s/m, m), "
     "got -4e-324 (a subnormal number)"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--nominal", "c1=1e-12", "--jsonl"],
     "--nominal c1: expected a value of magnitude at least 1e-09 in SI units (kg, kg m^2, N/m, N s/m, m), "
     "got 1e-12 (absurdly small)"),
    (["fleet", "--model", "quarter2", "--input", "q2.csv", "--nominal", "c1=5e-310", "--json"],
     "--nominal c1: expected a value of magnitude at least 1e-09"),
    (["compare", "--model", "quarter2", "--input", "q2.log", "--nominal", "c1=1e-15"],
     "--nominal c1: expected a value of magnitude at least 1e-09"),
    (["simulate", "--model", "quarter2", "--out", "x.csv", "--param", "m1=1e-320"],
     "--param m1: expected a value of magnitude at least 1e-09"),
    # the nonlinear simulator steps on a uniform grid (was: "fast nonlinear simulation needs
    # uniformly spaced samples", naming neither the option nor the file)
    (["simulate", "--model", "quarter2", "--road", "jitroad.csv", "--effect", "coulomb_friction:F=100",
      "--out", "x.csv"], "--effect with --road jitroad.csv: the nonlinear simulation steps on a uniform "
     "time grid; the road's time steps range from 0.005 to 0.01 s, more than a quarter step of jitter"),
    (NODE + ["--param", "c1=1e-320"], "--param c1: expected a value of magnitude at least 1e-09"),
    (["diagnose", "--model", "quarter2", "--input", "tonly.csv"], "tonly.csv:1: no measured channel"),
    (["diagnose", "--model", "quarter2", "--input", "q2.csv", "--maxfev", "0"], "--maxfev"),
    (["encode", "--input", "missing.csv", "--out", "o.log"], "missing.csv: no such file"),
    (["encode", "--input", "q2.log", "--out", "o.log"], "q2.log: --input must be a measurement CSV"),
    (["encode", "--input", "q2.csv", "--out", "o.txt"], "o.txt: unknown output log format"),
    (["encode", "--input", "q2.csv", "--out", "nodir/o.log"], "nodir/o.log: cannot create log file"),
    (["encode", "--input", "q2.csv", "--out", "o.log", "--t0", "nan"], "--t0 must be a finite"),
    (["encode", "--input", "q2.csv", "--dbc", "empty.dbc", "--out", "o.log"], "empty.dbc"),
    (["simulate", "--model", "quarter2", "--out", "adir"], "adir"),
    (["simulate", "--model", "quarter2", "--out", "nodir/x.csv"], "nodir/x.csv: cannot create"),
    (["simulate", "--model", "quarter2", "--out", "x.csv", "--duration", "nan"], "finite and > 0"),
    (["simulate", "--model", "quarter2", "--out", "x.csv", "--fs", "inf"], "finite and > 0"),
    (["simulate", "--model", "quarter2", "--out", "x.csv", "--duration", "1e9"], "expected at most"),
    (["simulate", "--model", "quarter2", "--out", "x.csv", "--scenario", "iso8608",
      "--config", "roadclass.toml"],
     "roadclass.toml: simulate.road_class: expected one of 'A', 'B', 'C', 'D', 'E', 'F', 'G', "
     "'H', got 'Z' (string)"),
    (NODE + ["--dbc", "bad.dbc"], "bad.dbc: cannot load DBC"),
    (NODE + ["--dbc", "foreign.dbc"], "foreign.dbc"),
    (NODE + ["--noise", "nan"], "--noise must be a finite number"),
    (NODE + ["--duration", "inf"], "finite and > 0"),
    (NODE + ["--fault", "loss=2"], "--fault 'loss=2'"),
    (NODE + ["--fault", "burst=nan:1"], "--fault 'burst=nan:1'"),
    (NODE + ["--rate", "0"], "--rate must be within"),
    (NODE + ["--channels", "zz"], "channel(s) zz not available"),
    (["node", "--scenario", "bump", "--interface", "nope", "--duration", "0.05"],
     "cannot open CAN interface 'nope'"),
    (["monitor", "--model", "quarter2", "--input", "missing.log", "--jsonl"], "missing.log"),
    (["monitor", "--model", "quarter2", "--input", "junk.blf", "--jsonl"], "junk.blf"),
    (["monitor", "--model", "quarter2", "--input", "empty.log", "--jsonl"],
     "empty.log: no accepted frame (0 frames read, rejected none)"),
    # every line skipped: the first one's reason and the format a .log must have (were: only
    # "0 frames read, rejected {'malformed': 50}")
    (IDENT + ["--input", "plain.log"], "rejected {'malformed': 50}; map: x1=QC_Body.Disp"),
    (IDENT + ["--input", "plain.log"], "); nothing parsed, the first skipped: line 1: expected "
     "'(seconds)' first, got 'can0' (a .log is read as candump -L: '(SECONDS) IFACE ID#DATA' per line)"),
    (["monitor", "--model", "quarter2", "--input", "plain.log", "--jsonl"],
     "plain.log: no accepted frame (0 frames read, rejected {'malformed': 50}); nothing parsed, "
     "the first skipped: line 1: expected '(seconds)' first, got 'can0' (a .log is read as candump -L"),
    (["monitor", "--model", "quarter2", "--input", "q2.xyz", "--jsonl"],
     "q2.xyz: unknown input format '.xyz'; expected .csv or a CAN log"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--dbc", "empty.dbc", "--jsonl"], "empty.dbc"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--window", "nan", "--jsonl"], "--window"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--alert-file", "adir", "--jsonl"], "adir"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--config", "lowpass.toml", "--jsonl"],
     "lowpass.toml: window.road_lowpass_hz: expected a number >= 0 (Hz), got -1 (integer)"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--config", "fusion.toml", "--jsonl"],
     "fusion.toml: window.road_fusion_hz: expected a number >= 0 (Hz), got nan (float)"),
    # windows whose buffer would not fit in memory (were: a MemoryError traceback for 1e9,
    # killed by the OOM killer at 24 GB for 1e5)
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--window", "1e9", "--jsonl"],
     "--window/--step: a window and two steps span 2e+09 s, more than the 1000 s a monitor's "
     "decoder buffers (at up to 2 kHz)"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--window", "1e5", "--jsonl"],
     "span 200000 s, more than the 1000 s"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--window", "100", "--step", "500",
      "--jsonl"], "span 1100 s, more than the 1000 s"),
    (["compare", "--model", "quarter2", "--input", "q2.log", "--window", "1e9"], "span 2e+09 s"),
    (["compare", "--model", "quarter2", "--input", "missing.log", "--json"], "missing.log"),
    (["doe", "--model", "quarter1", "--init-scale", "nan", "--json"], "--init-scale"),
    (["doe", "--model", "quarter1", "--ids", "999", "--json"], "--ids '999'"),
    (["nosuchcommand"], "invalid choice"),
    (["identify", "--model", "quarter9", "--input", "q2.csv"], "invalid choice: 'quarter9'"),
]


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse usage errors
        rc = int(exc.code or 0)
    return rc, capsys.readouterr().err


def _one_error(rc: int, err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error: ")]
    assert rc == 2, err
    assert len(errors) == 1, err
    assert "Traceback" not in err
    return errors[0]


@pytest.mark.parametrize("argv, expect", CASES, ids=[" ".join(a[:1] + a[-2:]) for a, _ in CASES])
def test_bad_input_is_one_error_line(work: Path, capsys: pytest.CaptureFixture[str],
                                     monkeypatch: pytest.MonkeyPatch, argv: list[str],
                                     expect: str) -> None:
    monkeypatch.chdir(work)
    line = _one_error(*_run(argv, capsys))
    assert expect in line


def test_debug_shows_the_traceback(work: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(work)
    from suspid.errors import InputError
    with pytest.raises(InputError):
        main(IDENT + ["--input", "missing.csv", "--debug"])
    with pytest.raises(InputError, match="nodir/x.csv"):
        main(["simulate", "--model", "quarter2", "--out", "nodir/x.csv", "--duration", "0.1",
              "--debug"])


# ---- random option values ---------------------------------------------------------------
BAD_NUMBERS = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "NaN", "1e999", "", " ", "0x", "--", "1,2", "1/0"]),
    st.text(alphabet="abcxyz!@%^&=,;:", min_size=1, max_size=8),
)
#: (argv prefix, option) whose value must be a (positive, finite) number
NUMERIC_OPTIONS: list[tuple[list[str], str]] = [
    (["simulate", "--model", "quarter2", "--out", "x.csv"], "--duration"),
    (["simulate", "--model", "quarter2", "--out", "x.csv"], "--fs"),
    (["simulate", "--model", "quarter2", "--out", "x.csv"], "--noise"),
    (["simulate", "--model", "quarter2", "--out", "x.csv"], "--seed"),
    (IDENT + ["--input", "q2.csv"], "--maxfev"),
    (["encode", "--input", "q2.csv", "--out", "o.log"], "--t0"),
    (NODE, "--duration"),
    (NODE, "--rate"),
    (NODE, "--speed"),
    (NODE, "--noise"),
    (NODE, "--seed"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--jsonl"], "--window"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--jsonl"], "--step"),
    (["monitor", "--model", "quarter2", "--input", "q2.log", "--jsonl"], "--alert-drop"),
    (["doe", "--model", "quarter1", "--json"], "--init-scale"),
    (["doe", "--model", "quarter1", "--json"], "--noise"),
    (["doe", "--model", "quarter1", "--json", "--free-masses"], "--mass-init-scale"),
    (COMPARE, "--duration"),
    (COMPARE, "--fs"),
    (COMPARE, "--wear-to"),
]
ASSIGN_OPTIONS: list[tuple[list[str], str]] = [
    (IDENT + ["--input", "q2.csv"], "--fix"),
    (IDENT + ["--input", "q2.csv"], "--init"),
    (["simulate", "--model", "quarter2", "--out", "x.csv"], "--param"),
    (NODE, "--param"),
    (NODE, "--fault"),
]


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(NUMERIC_OPTIONS), value=BAD_NUMBERS)
def test_malformed_numeric_option_values(work: Path, capsys: pytest.CaptureFixture[str],
                                         case: tuple[list[str], str], value: str) -> None:
    cwd = os.getcwd()
    os.chdir(work)
    try:
        prefix, opt = case
        line = _one_error(*_run(prefix + [f"{opt}={value}"], capsys))
        assert opt in line or "finite" in line or "> 0" in line, line
    finally:
        os.chdir(cwd)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(ASSIGN_OPTIONS),
       value=st.one_of(BAD_NUMBERS, BAD_NUMBERS.map(lambda v: f"m1={v}"),
                       st.text(alphabet="=:m1kc2 .x", max_size=8)))
def test_malformed_assignment_option_values(work: Path, capsys: pytest.CaptureFixture[str],
                                            case: tuple[list[str], str], value: str) -> None:
    cwd = os.getcwd()
    os.chdir(work)
    try:
        prefix, opt = case
        _one_error(*_run(prefix + [f"{opt}={value}"], capsys))
    finally:
        os.chdir(cwd)


@pytest.mark.parametrize("argv", [
    ["simulate", "--model", "quarter2", "--scenario", "initial", "--out", "x.csv", "--x0", "nan,0,0,0"],

    COMPARE + ["--duration", "1e9"],
    COMPARE + ["--fs", "1e12"],
])
def test_non_finite_state_and_oversized_streams(work: Path, capsys: pytest.CaptureFixture[str],
                                                argv: list[str]) -> None:
    """A NaN initial state once gave a cost of 0 and 'no missing effect' (exit 0); a 1e9 s
    compare stream a 3.6 TiB allocation."""
    cwd = os.getcwd()
    os.chdir(work)
    try:
        line = _one_error(*_run(argv, capsys))
        assert "finite" in line or "at most" in line, line
    finally:
        os.chdir(cwd)


# ---- the installed console script ------------------------------------------------------
def _suspid(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    exe = shutil.which("suspid")
    cmd = [exe] if exe else [sys.executable, "-c", "import sys; from suspid.cli import main; "
                                                   "sys.exit(main())"]
    return subprocess.run([*cmd, *args], cwd=cwd, text=True, capture_output=True, timeout=120)


@pytest.mark.slow
def test_subprocess_bad_inputs(work: Path) -> None:
    r = _suspid("identify", "--model", "quarter2", "--input", "missing.csv", cwd=work)
    assert r.returncode == 2 and r.stderr.strip() == "error: missing.csv: no such file"
    r = _suspid("encode", "--input", "q2.csv", "--dbc", "empty.dbc", "--out", "o.log", cwd=work)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.startswith("error: empty.dbc: cannot load DBC")
    r = _suspid("simulate", "--model", "quarter2", "--out", "nodir/x.csv", "--duration", "0.1",
                cwd=work)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == ["error: nodir/x.csv: cannot create the CSV: "
                                             "No such file or directory"]


def test_subprocess_debug_traceback(work: Path) -> None:
    r = _suspid("identify", "--model", "quarter2", "--input", "missing.csv", "--debug", cwd=work)
    assert r.returncode != 0 and "Traceback" in r.stderr and "InputError" in r.stderr


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_overflowing_values_raise_no_runtime_warning(work: Path, capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     command: str) -> None:
    """The one error line is all of stderr: the record's decay check squared 2e300 and
    printed numpy's 'RuntimeWarning: overflow encountered in multiply' with its source line
    above the error."""
    monkeypatch.chdir(work)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        rc, err = _run([command, "--model", "quarter2", "--input", "huge.csv", "--json"], capsys)
    assert _one_error(rc, err).startswith("error: huge.csv: column 'x1': values up to 2e+300 overflow")
    assert [str(w.message) for w in seen if issubclass(w.category, RuntimeWarning)] == []


@pytest.mark.parametrize("fmt", [["--jsonl"], []])
def test_monitor_into_a_closed_pipe_stops_quietly(tmp_path: Path, fmt: list[str]) -> None:
    """``suspid monitor --jsonl | head -1``: the reader closes the pipe, the next line fails
    with EPIPE; the monitor stops with exit 0 and nothing on stderr (was: a BrokenPipeError
    traceback and exit 1 -- main's OSError clause re-raised it past its own
    BrokenPipeError clause)."""
    m = get_model("quarter2")
    t, road, x0 = make_scenario(m, "iso8608", duration=8.0, fs=250.0)
    out = simulate(m, m.defaults(), t, road, x0)
    write_measurement(tmp_path / "q2.csv", t,
                      {k: out[k] for k in ("r", "r_dot", "x1", "x2")})
    exe = shutil.which("suspid")
    cmd = [exe] if exe else [sys.executable, "-c", "import sys; from suspid.cli import main; "
                                                   "sys.exit(main())"]
    p = subprocess.Popen([*cmd, "monitor", "--model", "quarter2", "--input", "q2.csv",
                          "--fix", "m1=300", "--no-inspection", *fmt], cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout is not None and p.stderr is not None
    first = p.stdout.readline()   # head -1
    p.stdout.close()
    err = p.stderr.read()
    assert p.wait(timeout=120) == 0, err
    assert first.strip() and err == ""
