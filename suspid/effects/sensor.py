"""Sensor effects: what a sensor reports differently from the truth (a delay, an offset).
"""

from typing import Any, Mapping, Sequence

import numpy as np

# scipy.interpolate is reached through scipy's lazy submodule attribute: loaded when used
import scipy

from suspid.effects.base import EffectParam, SensorEffect, register
from suspid.models.base import FloatArray, SuspensionModel


def _shift(t: FloatArray, y: FloatArray, dt: float) -> FloatArray:
    """``y(t + dt)`` by cubic-spline interpolation of the valid samples (the first value held
    before the first sample, NaN beyond the last)."""
    ok = ~np.isnan(y)
    if ok.sum() < 4:
        return np.interp(t + dt, t[ok], y[ok], right=np.nan)
    tq = t + dt
    out = scipy.interpolate.CubicSpline(t[ok], y[ok], extrapolate=False)(tq)
    out = np.where(tq < t[ok][0], y[ok][0], out)
    return np.where(tq > t[ok][-1], np.nan, out)


def _rate(ch: str, t: FloatArray, predicted: Mapping[str, FloatArray]) -> FloatArray | None:
    """Time derivative of the model's channel ``ch`` (None if the model lacks it)."""
    if ch.endswith("_ddot"):
        return np.gradient(predicted[ch], t) if ch in predicted else None
    if ch.endswith("_dot"):
        return predicted.get(ch[:-4] + "_ddot")
    return predicted.get(f"{ch}_dot")


@register
class SensorDelay(SensorEffect):
    """The listed channels lag the others by ``delay_s``: they read ``y(t - delay_s)``
    (screened per coordinate's channels together and each alone; a lag ``d`` adds ``-d y'``)."""

    name = "sensor_delay"
    params = (EffectParam("channels", "", "channels that lag", "channels"),
              EffectParam("delay_s", "s", "delay of the listed channels"))
    description = "listed channels lag the others by delay_s"
    time_shift = "delay_s"

    def _shifted(self, t: FloatArray, channels: Mapping[str, FloatArray], dt: float) -> dict[str, FloatArray]:
        out = dict(channels)
        tt = np.asarray(t, dtype=float)
        for c in self.values["channels"]:
            if c in out:
                out[c] = _shift(tt, np.asarray(out[c], dtype=float), dt)
        return out

    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        return self._shifted(t, channels, -self.values["delay_s"])

    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        return self._shifted(t, channels, self.values["delay_s"])

    def record_problem(self, t: FloatArray) -> str | None:
        tt = np.asarray(t, dtype=float)
        span = float(tt[-1] - tt[0]) if tt.size > 1 else 0.0
        d = float(self.values["delay_s"])
        if d >= span:
            return (f"delay_s {d:g} s is not shorter than the record ({span:g} s): the delayed "
                    "channels would hold their first value throughout (a delay in ms? give it in s)")
        return None

    @classmethod
    def screen_groups(cls, model: SuspensionModel, measured: Sequence[str]) -> list[list[str]]:
        groups: list[list[str]] = []
        for c in model.coords:
            g = [ch for ch in (c, f"{c}_dot", f"{c}_ddot") if ch in measured]
            if g:
                groups.append(g)
                groups += [[ch] for ch in g] if len(g) > 1 else []
        return groups

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        r = _rate(channel, t, predicted)
        return None if r is None else -np.asarray(r, dtype=float)

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        if not 0.0 < value <= max_delay:
            return None
        return {"channels": list(group), "delay_s": value}


@register
class SensorOffset(SensorEffect):
    """``channel`` reads ``y + offset`` (SI units of the channel)."""

    name = "sensor_offset"
    params = (EffectParam("channel", "", "channel with the offset", "channel"),
              EffectParam("offset", "SI", "constant offset added to the channel", "real"))
    description = "constant offset on one channel"

    def _added(self, channels: Mapping[str, FloatArray], offset: float) -> dict[str, FloatArray]:
        out = dict(channels)
        c = self.values["channel"]
        if c in out:
            out[c] = np.asarray(out[c], dtype=float) + offset
        return out

    def apply(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        return self._added(channels, self.values["offset"])

    def compensate(self, t: FloatArray, channels: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        return self._added(channels, -self.values["offset"])

    @classmethod
    def output_sensitivity(cls, channel: str, t: FloatArray,
                           predicted: Mapping[str, FloatArray]) -> FloatArray | None:
        return np.ones(np.asarray(t).size)

    @classmethod
    def params_from_screen(cls, group: Sequence[str], value: float,
                           max_delay: float) -> dict[str, Any] | None:
        return {"channel": group[0], "offset": value} if len(group) == 1 else None
