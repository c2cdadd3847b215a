"""Synthetic streams with time-varying parameters (damper wear) for tests and benchmarks.

The core's exact linear simulator applied piecewise: parameters held over chunks of
``chunk_s`` seconds, the state carried across chunk boundaries.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Mapping

import numpy as np

from suspid.can.codec import signal_spec
from suspid.can.dbc import channel_signals, load_dbc
from suspid.can.encoder import measurement_frames
from suspid.can.logs import open_log_writer
from suspid.excitation import make_scenario
from suspid.io.csvio import Measurement
from suspid.models import get_model
from suspid.models.base import FloatArray, SuspensionModel
from suspid.simulate import outputs, road_matrix, simulate_states

#: DBC resolutions of suspension.dbc (QC_Body/QC_Wheel/QC_Road) for quarter2's channels
DBC_RESOLUTION = {"x1": 1e-5, "x2": 1e-5, "x1_dot": 1e-4, "x2_dot": 2e-4, "x1_ddot": 0.005,
                  "x2_ddot": 0.02, "r": 1e-5, "r_dot": 5e-4}


@lru_cache(maxsize=None)
def channel_resolution(model_name: str) -> dict[str, float]:
    """``channel -> resolution`` (SI) of the model's signals in suspid's DBC."""
    db = load_dbc()
    return {ch: signal_spec(db.get_message_by_name(m), sig).scale
            for ch, m, sig in channel_signals(db, model_name)}


@dataclass
class Stream:
    """A synthetic stream: times ``t`` (s), channels and roads ``data`` (SI, as the node sends
    them), ``truth`` (``parameter -> value at every sample``, SI), ``nominal`` start values."""

    t: FloatArray
    data: dict[str, FloatArray]
    truth: dict[str, FloatArray]
    nominal: dict[str, float]
    events: dict[str, float] = field(default_factory=dict)

    def crossing_time(self, name: str, level: float) -> float:
        """First time (s) the true ``name`` falls below ``level`` (``nan`` if never)."""
        below = np.flatnonzero(self.truth[name] < level)
        return float(self.t[below[0]]) if below.size else float("nan")


def damper_wear(model: SuspensionModel, duration: float = 150.0, fs: float = 500.0,
                params: Mapping[str, float] | None = None, c_end_fraction: float = 0.5,
                wear_start: float = 20.0, wear_end: float | None = None,
                road_class: str = "C", v_kmh: float = 50.0, seed: int = 0,
                channels: tuple[str, ...] | None = None,
                noise: Mapping[str, float] | None = None, quantize: bool = True,
                chunk_s: float = 0.05, damper: str = "c1") -> Stream:
    """A car on an ISO 8608 road (``road_class``, ``v_kmh``, ``seed``) for ``duration`` s at
    ``fs`` Hz while the damper ``damper`` falls linearly to ``c_end_fraction`` of nominal
    between ``wear_start`` and ``wear_end`` (s; default the end).

    ``channels`` default to every position and the first coordinate's acceleration (roads
    always included); ``noise`` (SI, per channel) defaults to 2 DBC quantization steps, and
    ``quantize`` rounds to the DBC resolution. Parameters change every ``chunk_s`` s.
    """
    p0 = dict(model.defaults(), **(params or {}))
    if channels is None:
        channels = tuple(model.coords) + (f"{model.coords[0]}_ddot",)
    wear_end = duration if wear_end is None else wear_end
    t, road, _ = make_scenario(model, "iso8608", duration=duration, fs=fs, params=p0,
                               v_kmh=v_kmh, road_class=road_class, seed=seed)
    n = t.size
    resolution = channel_resolution(model.name)
    U = road_matrix(model, t, road)
    frac = np.interp(t, [wear_start, wear_end], [1.0, c_end_fraction])
    c_true = p0[damper] * frac
    X = np.empty((n, model.n_states))
    x = np.zeros(model.n_states)
    step = max(1, int(round(chunk_s * fs)))
    affine = model.affine(p0, [damper])  # one forward model for every chunk
    # acceleration needs the parameters of each sample: collect per chunk
    acc_rows = {c: np.empty(n) for c in model.channels if c.endswith("_ddot")}
    for i0 in range(0, n - 1, step):
        i1 = min(i0 + step, n - 1)
        p = dict(p0)
        p[damper] = float(c_true[(i0 + i1) // 2])
        seg = slice(i0, i1 + 1)
        Xs = simulate_states(model, p, t[seg], U[seg], x, affine=affine)
        X[seg] = Xs
        x = Xs[-1]
        out = outputs(model, p, Xs, U[seg], affine)
        for c in acc_rows:
            acc_rows[c][seg] = out[c]
    allout = outputs(model, p0, X, U)
    allout.update(acc_rows)
    rng = np.random.default_rng(seed + 1)
    data: dict[str, FloatArray] = {}
    for c in tuple(channels) + tuple(road):
        y = np.array(road[c] if c in road else allout[c], dtype=float)
        res = resolution.get(c, 0.0)
        sd = (noise or {}).get(c, 2.0 * res)
        if sd > 0:
            y = y + rng.normal(0.0, sd, n)
        if quantize and res > 0:
            y = np.round(y / res) * res
        data[c] = y
    truth = {k: np.full(n, v) for k, v in p0.items()}
    truth[damper] = c_true
    return Stream(t, data, truth, p0, {"wear_start": wear_start, "wear_end": wear_end})


def production_wear(model: SuspensionModel, **kwargs: object) -> Stream:
    """:func:`damper_wear` as a production car sends it: body accelerations and ride heights
    (default ``model.channel_set("production")``), quantized and noisy, without the road."""
    kw = dict(kwargs)
    kw.setdefault("channels", model.channel_set("production"))
    s = damper_wear(model, **kw)  # type: ignore[arg-type]
    s.data = {k: v for k, v in s.data.items() if k not in model.input_names}
    return s


def write_log(stream: Stream, path: str, model_name: str = "quarter2", t0: float = 0.0) -> int:
    """Write a stream as the CAN log the sensor node would send (format by suffix, frames by
    :func:`suspid.can.encoder.measurement_frames`); returns the number of frames."""
    inputs = get_model(model_name).input_names
    roads = {k: v for k, v in stream.data.items() if k in inputs}
    measured = {k: v for k, v in stream.data.items() if k not in roads}
    meas = Measurement(stream.t, roads, measured, source="stream")
    n = 0
    with open_log_writer(path) as writer:
        for msg in measurement_frames(meas, model_name, load_dbc(), t0):
            writer.on_message_received(msg)
            n += 1
    return n
