"""A synthetic fleet of drive logs with known wear (benchmarks, tests, demonstrations).

Each drive is a ``quarter2`` simulation over an ISO 8608 road, encoded as ``suspid encode``
does; ``c1`` (and ``k1``) fall linearly at the vehicle's rate. With ``FleetSpec.distance`` the
drives carry the odometer or speed (CSV columns, or J1939 VDHR/CCVS1, :func:`distance_dbc`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import can
from cantools.database.can import Database
from cantools.j1939 import frame_id_pack

from suspid.can.dbc import default_dbc_path, load_dbc
from suspid.can.encoder import measurement_frames
from suspid.can.logs import open_log_writer
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.simulate import simulate

DAY_S = 86400.0
#: drive start of day 0 (2026-09-01 00:00 UTC)
EPOCH0 = 1788220800.0


@dataclass
class VehicleWear:
    """One synthetic vehicle: folder ``name``, damper and spring loss per day (fraction of nominal),
    ``km_per_day`` driven from ``odometer0_km`` on day 0.
    """

    name: str
    c1_rate: float = 0.0
    k1_rate: float = 0.0
    km_per_day: float = 150.0
    odometer0_km: float = 20_000.0

    def odometer_m(self, t: float) -> float:
        """The odometer (m) at epoch ``t`` (s)."""
        return 1e3 * (self.odometer0_km + self.km_per_day * (t - EPOCH0) / DAY_S)


@dataclass
class FleetSpec:
    """A synthetic fleet: ``drives`` in all over ``days``, each ``duration`` s at ``fs`` Hz.

    ``noise`` is a fraction of each channel's std, ``params`` the nominal ``quarter2`` values (SI),
    ``fmt`` the log suffix and ``distance`` ``""``, ``"odometer"`` or ``"speed"``.
    """

    vehicles: list[VehicleWear]
    drives: int = 40
    days: float = 60.0
    duration: float = 30.0
    fs: float = 200.0
    noise: float = 0.02
    params: dict[str, float] = field(default_factory=lambda: {
        "m1": 300.0, "c1": 1500.0, "k1": 20000.0, "m2": 40.0, "c2": 300.0, "k2": 200000.0})
    speed_kmh: float = 50.0
    fmt: str = ".log"
    distance: str = ""

    def truth(self, vehicle: VehicleWear, t: float) -> dict[str, float]:
        """True parameters of ``vehicle`` at epoch ``t`` (s)."""
        days = (t - EPOCH0) / DAY_S
        p = dict(self.params)
        p["c1"] *= 1.0 - vehicle.c1_rate * days
        p["k1"] *= 1.0 - vehicle.k1_rate * days
        return p

    def crossing_t(self, vehicle: VehicleWear, name: str, drop: float) -> float | None:
        """Epoch s at which ``name`` truly falls to ``(1 - drop) x nominal``."""
        rate = {"c1": vehicle.c1_rate, "k1": vehicle.k1_rate}.get(name, 0.0)
        return EPOCH0 + drop / rate * DAY_S if rate > 0 else None


#: J1939 groups of the vehicle's distance and speed, added to suspid's DBC by :func:`distance_dbc`
J1939_DISTANCE = """BO_ 2566832638 VDHR: 8 Vector__XXX
 SG_ HighResolutionTotalVehicleDistance : 0|32@1+ (5,0) [0|21055406000] "m" Vector__XXX
 SG_ HighResolutionTripDistance : 32|32@1+ (5,0) [0|21055406000] "m" Vector__XXX

BO_ 2566844926 CCVS1: 8 Vector__XXX
 SG_ WheelBasedVehicleSpeed : 8|16@1+ (0.00390625,0) [0|250.996] "km/h" Vector__XXX

"""
#: the signal map of the distance channels in the DBC of :func:`distance_dbc`
DISTANCE_MAP = {"odometer": "odometer=VDHR.HighResolutionTotalVehicleDistance",
                "speed": "speed=CCVS1.WheelBasedVehicleSpeed*0.2777777777777778"}
#: source address of the controller sending them (the engine)
J1939_SOURCE = 0x00
#: their period (s)
DISTANCE_PERIOD_S = 0.1


def distance_dbc(path: str | Path) -> Path:
    """Write suspid's DBC with the J1939 groups VDHR and CCVS1 added (matched by PGN); returns ``path``."""
    text = default_dbc_path().read_text(encoding="utf-8")
    ids = (2566832638, 2566844926)
    text = text.replace("\nCM_ ", "\n" + J1939_DISTANCE + "CM_ ", 1)
    text = text.replace("\nBA_DEF_DEF_ ", '\nBA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN",'
                        '"ExtendedCAN","reserved","J1939PG";\nBA_DEF_DEF_ ', 1)
    text = text.replace("\nBA_ ", "\n" + "".join(f'BA_ "VFrameFormat" BO_ {i} 3;\n' for i in ids)
                        + "BA_ ", 1)
    p = Path(path)
    p.write_text(text, encoding="utf-8")
    return p


def distance_frames(db: Database, kind: str, t: np.ndarray, t0: float, odometer_m: float,
                    speed_ms: float) -> list[can.Message]:
    """The VDHR (``"odometer"``) or CCVS1 (``"speed"``) frames of a drive, stamped at epoch ``t0 + t``."""
    name = "VDHR" if kind == "odometer" else "CCVS1"
    msg = db.get_message_by_name(name)
    arb = frame_id_pack(6, 0, 0, (msg.frame_id >> 16) & 0xFF, (msg.frame_id >> 8) & 0xFF,
                        J1939_SOURCE)
    out = []
    for tt in np.arange(float(t[0]), float(t[-1]), DISTANCE_PERIOD_S):
        odo = odometer_m + speed_ms * (tt - float(t[0]))
        values = ({"HighResolutionTotalVehicleDistance": odo,
                   "HighResolutionTripDistance": odo - odometer_m} if kind == "odometer"
                  else {"WheelBasedVehicleSpeed": speed_ms * 3.6})
        out.append(can.Message(timestamp=t0 + float(tt), arbitration_id=arb, is_extended_id=True,
                               data=msg.encode(values)))
    return out


def _candump(path: Path, frames: list) -> None:
    with open(path, "w", encoding="ascii") as fh:
        fh.writelines(f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n"
                      for m in frames)


def _write_csv(path: str | Path, t: np.ndarray, cols: dict[str, np.ndarray]) -> None:
    """A measurement CSV with epoch ``t`` to 6 decimals (``%.10g`` would round it to 1 s)."""
    np.savetxt(path, np.column_stack([t, *cols.values()]), fmt=["%.6f"] + ["%.10g"] * len(cols),
               delimiter=",", header=",".join(["t", *cols]), comments="")


def write_drive(path: Path, spec: FleetSpec, vehicle: VehicleWear, t0: float, seed: int,
                db: Database) -> dict[str, float]:
    """Simulate, encode and write one drive starting at epoch ``t0``; returns the truth."""
    model = get_model("quarter2")
    p = spec.truth(vehicle, t0)
    t, road, x0 = make_scenario(model, "iso8608", duration=spec.duration, fs=spec.fs, params=p,
                                v_kmh=spec.speed_kmh, seed=seed)
    out = simulate(model, p, t, road, x0)
    rng = np.random.default_rng(seed + 7919)
    measured = {c: out[c] + rng.standard_normal(t.size) * spec.noise * np.std(out[c])
                for c in ("x1_ddot", "x2_ddot")}
    roads = {"r": out["r"], "r_dot": out["r_dot"]}
    speed = spec.speed_kmh / 3.6
    odo0 = vehicle.odometer_m(t0)
    if spec.fmt == ".csv":
        cols = {**roads, **measured}
        if spec.distance == "odometer":
            cols["odometer"] = odo0 + speed * (t - t[0])
        elif spec.distance == "speed":
            cols["speed"] = np.full(t.size, speed)
        _write_csv(path, t + t0, cols)
        return p
    meas = Measurement(t=t, road=roads, measured=measured)
    frames = list(measurement_frames(meas, "quarter2", db, t0=t0))
    if spec.distance:
        frames = sorted(frames + distance_frames(db, spec.distance, t, t0, odo0, speed),
                        key=lambda m: m.timestamp)
    if spec.fmt == ".log":
        _candump(path, frames)
    else:
        with open_log_writer(path) as w:
            for m in frames:
                w.on_message_received(m)
    return p


def write_production_drive(path: str | Path, params: dict[str, float], t0: float,
                           duration: float = 20.0, fs: float = 200.0, noise: float = 0.02,
                           seed: int = 0, speed_kmh: float = 50.0, model: str = "quarter2"
                           ) -> dict[str, float]:
    """Write one ISO 8608 drive as a production car logs it (body accelerations, ride heights, noise;
    no road) to a CSV from epoch ``t0``; returns the truth (``params`` with the defaults).
    """
    m = get_model(model)
    p = {**m.defaults(), **params}
    t, road, x0 = make_scenario(m, "iso8608", duration=duration, fs=fs, params=p,
                                v_kmh=speed_kmh, seed=seed)
    out = simulate(m, p, t, road, x0)
    rng = np.random.default_rng(seed + 7919)
    cols = {c: out[c] + rng.standard_normal(t.size) * noise * np.std(out[c])
            for c in m.channel_set("production")}
    _write_csv(path, t + t0, cols)
    return p


def make_fleet(folder: str | Path, spec: FleetSpec) -> list[dict[str, object]]:
    """Write ``spec.drives`` logs under ``folder/<vehicle>/``; returns each drive's truth.

    Per drive: ``path``, ``vehicle``, ``t`` (epoch s), ``params`` and ``odometer_m``.
    """
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    db = load_dbc(distance_dbc(root / "distance.dbc") if spec.distance and spec.fmt != ".csv"
                  else None)
    out = []
    nv = len(spec.vehicles)
    per = max(1, -(-spec.drives // nv))
    for i in range(spec.drives):
        v = spec.vehicles[i % nv]
        k = i // nv
        t0 = EPOCH0 + spec.days * DAY_S * k / max(per - 1, 1) + 3600.0 * (i % nv)
        d = root / v.name
        d.mkdir(parents=True, exist_ok=True)
        path = d / f"drive-{k:04d}{spec.fmt}"
        truth = write_drive(path, spec, v, t0, seed=1000 + i, db=db)
        out.append({"path": str(path), "vehicle": v.name, "t": t0, "params": truth,
                    "odometer_m": v.odometer_m(t0)})
    return out
