"""Extended Kalman filter on the state augmented with suspension parameters.

State ``z = [q, q', theta]``, ``theta_p = p / p_nominal`` (a random walk); prediction by RK4 on
``model.rhs`` with its exact tangent-linear Jacobian. Design and tuning: ``docs/monitoring.md``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.stats import chi2
from filterpy.kalman import ExtendedKalmanFilter

from suspid.errors import UsageError
from suspid.models.base import FloatArray, SuspensionModel


@dataclass
class EKFTuning:
    """Noise settings of the augmented EKF (documented in ``docs/monitoring.md``).

    ``q_param``: parameter random walk, relative per sqrt(s); ``q_state``: acceleration noise
    (m/s^2 per sqrt(Hz)); ``p0_param``: initial relative std of the parameters; ``p0_pos``,
    ``p0_vel``: initial std of positions (m) and velocities (m/s); ``substeps``: RK4 sub-intervals
    per sample; ``input_noise``: the road's white noise as process noise.
    """

    q_param: float = 0.005
    q_state: float = 0.05
    p0_param: float = 0.3
    p0_pos: float = 0.01
    p0_vel: float = 0.1
    substeps: int = 1
    input_noise: bool = True


class ParamEKF(ExtendedKalmanFilter):
    """What both EKFs share: relative parameters after the ``nx`` motion states, the update, the NIS."""

    nx: int
    nominal: FloatArray
    aug: list[str]
    params: dict[str, float]
    x: FloatArray
    P: FloatArray
    F: Any
    _I: FloatArray
    #: running sum of the normalised innovations squared and their degrees of freedom
    nis_sum = 0.0
    nis_dof = 0

    def param_values(self, z: FloatArray | None = None) -> dict[str, float]:
        """Every parameter (SI) with the augmented ones from state ``z`` (default current)."""
        zz = self.x[:, 0] if z is None else z
        p = dict(self.params)
        for j, k in enumerate(self.aug):
            p[k] = float(self.nominal[j] * zz[self.nx + j])
        return p

    def param_stderr(self) -> dict[str, float]:
        """Standard deviation of each augmented parameter (SI) from ``P``."""
        d = np.sqrt(np.clip(np.diag(self.P)[self.nx:], 0.0, None))
        return {k: float(self.nominal[j] * d[j]) for j, k in enumerate(self.aug)}

    def restart_motion(self, n: int, tuning: EKFTuning, walk: float = 0.0) -> None:
        """The first ``2 n`` states' (positions, rates) initial covariance back; ``walk`` s of walk."""
        P = self.P.copy()
        P[:2 * n, :] = 0.0
        P[:, :2 * n] = 0.0
        P[:2 * n, :2 * n] = np.diag([tuning.p0_pos ** 2] * n + [tuning.p0_vel ** 2] * n)
        P[self.nx:, self.nx:] += np.eye(len(self.aug)) * tuning.q_param ** 2 * walk
        self.P = P

    def joseph_update(self, y: FloatArray,
                      hx_jac: Callable[[], tuple[FloatArray, FloatArray]]) -> None:
        """Kalman update with measurement ``y`` and ``hx_jac() = (h(x), dh/dx)`` (filterpy's algebra,
        Joseph form, without its deep copies); NaN entries left out.
        """
        zz = np.asarray(y, dtype=float).reshape(-1)
        ok = np.isfinite(zz)
        if not ok.any():
            return
        hx, H = hx_jac()
        Rm = np.asarray(self.R, dtype=float)
        if not ok.all():
            H, hx, zz, Rm = H[ok], hx[ok], zz[ok], Rm[np.ix_(ok, ok)]
        PHT = self.P @ H.T
        S = H @ PHT + Rm
        K = np.linalg.solve(S, PHT.T).T
        e = zz - hx
        self.x = self.x + (K @ e)[:, None]
        I_KH = self._I - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ Rm @ K.T
        # normalised innovation squared: chi-square with e.size dof when the filter fits
        self.nis_sum += float(e @ np.linalg.solve(S, e))
        self.nis_dof += int(e.size)


class AugmentedEKF(ParamEKF):
    """filterpy EKF whose prediction integrates the model's right-hand side.

    ``params`` holds every value (SI), the ``augmented`` dampers and springs at nominal;
    ``channels`` are the measured channels, ``dt`` the sample interval (s).
    """

    def __init__(self, model: SuspensionModel, params: Mapping[str, float],
                 augmented: Sequence[str], channels: Sequence[str], dt: float,
                 tuning: EKFTuning | None = None) -> None:
        self.model = model
        self.tuning = tuning or EKFTuning()
        self.nq = len(model.coords)
        self.nx = 2 * self.nq
        self.nr = len(model.roads)
        for k in augmented:
            kind = model.spec(k).kind
            if kind not in ("damping", "stiffness"):
                raise UsageError(f"the EKF estimates dampers and springs only; {k} is a {kind}")
        self.aug = list(augmented)
        self.channels = list(channels)
        self.params = dict(params)
        self.nominal = np.array([float(params[k]) for k in self.aug])
        self.dt = float(dt)
        nz = self.nx + len(self.aug)
        super().__init__(dim_x=nz, dim_z=len(self.channels))
        # [A(theta) | B(theta)] affine in the augmented parameters; _G: slopes per relative unit
        self.pieces = model.affine(self.params, self.aug)
        if not self.pieces.exact:
            raise UsageError(f"model {model.name}: the parameters {', '.join(self.aug)} do not "
                             f"enter its matrices affinely; the EKF needs them to")
        self._G = self.pieces.dAB * self.nominal[:, None, None]  # per relative unit
        self._J0 = np.zeros((nz, nz))                          # dq/dt = q'
        self._J0[:self.nq, self.nq:self.nx] = np.eye(self.nq)
        self._I = np.eye(nz)
        self._linear = not model.extra_force
        self._rows = []
        for c in self.channels:
            base = c.split("_")[0]
            if base not in model.coords:
                raise UsageError(f"channel {c!r} is not a channel of model {model.name}")
            i = model.coords.index(base)
            order = 2 if c.endswith("_ddot") else (1 if c.endswith("_dot") else 0)
            self._rows.append((i, order))
        tu = self.tuning
        self.P = np.diag([tu.p0_pos ** 2] * self.nq + [tu.p0_vel ** 2] * self.nq
                         + [tu.p0_param ** 2] * len(self.aug))
        self.x = np.concatenate([np.zeros(self.nx), np.ones(len(self.aug))])[:, None]
        #: process noise from the road's own noise (:meth:`set_input_noise`)
        self._q_input = np.zeros((nz, nz))
        self.set_q(self.dt)

    def set_q(self, dt: float) -> None:
        """Process noise for a step ``dt`` (s)."""
        nq, qa = self.nq, self.tuning.q_state ** 2 * dt   # white acceleration noise per coordinate
        Q = np.diag([qa * dt * dt / 3.0] * nq + [qa] * nq + [self.tuning.q_param ** 2 * dt] * len(self.aug))
        Q[:nq, nq:self.nx] = Q[nq:self.nx, :nq] = np.eye(nq) * (qa * dt / 2.0)
        self.Q = Q + self._q_input

    def set_input_noise(self, sig_u: FloatArray) -> None:
        """Add the road's white noise ``sig_u`` (m, m/s per road input) to ``Q`` through the step's
        sensitivity ``G0``, ``G1`` to its two road samples: ``G0 R_u G0^T + G1 R_u G1^T``.
        """
        sig = np.asarray(sig_u, dtype=float)
        z = self.x[:, 0].copy()
        zero = np.zeros(sig.size)
        base = self.rk4(z, zero, zero, self.dt, with_jacobian=False)[0]
        Q = np.zeros((self.dim_x, self.dim_x))
        for j in range(sig.size):
            if not sig[j] > 0:
                continue
            e = zero.copy()
            e[j] = sig[j]
            for g in (self.rk4(z, e, zero, self.dt, with_jacobian=False)[0] - base,
                      self.rk4(z, zero, e, self.dt, with_jacobian=False)[0] - base):
                g[self.nx:] = 0.0
                Q += np.outer(g, g)
        self._q_input = Q
        self.set_q(self.dt)

    # ---- dynamics -------------------------------------------------------------------------
    def f(self, z: FloatArray, u: FloatArray, t: float = 0.0) -> FloatArray:
        """Continuous augmented dynamics ``dz/dt`` (parameters constant): ``model.rhs``."""
        dz = np.zeros_like(z)
        dz[:self.nx] = self.model.rhs(t, z[:self.nx], u, self.param_values(z))
        return dz

    def jac(self, z: FloatArray, u: FloatArray) -> FloatArray:
        """Continuous Jacobian ``df/dz`` (analytic): ``A(theta)`` and the parameter columns."""
        nq, nx = self.nq, self.nx
        J = self._J0.copy()
        J[nq:nx, :nx] = self._ab(z[nx:])[:, :nx]
        J[nq:nx, nx:] = (self._G @ np.concatenate([z[:nx], u])).T
        return J

    def rk4(self, z: FloatArray, u0: FloatArray, u1: FloatArray, dt: float,
            with_jacobian: bool = True) -> tuple[FloatArray, FloatArray | None]:
        """One RK4 step over ``dt`` (s), road ``[r, r']`` from ``u0`` to ``u1``, and its exact Jacobian."""
        n = max(1, self.tuning.substeps)
        h = dt / n
        if self._linear:
            return self._rk4_linear(z, u0, u1, h, n, with_jacobian)
        F = self._I.copy()
        for s in range(n):
            a, b = s / n, (s + 1) / n
            ua = u0 + (u1 - u0) * a
            um = u0 + (u1 - u0) * (a + b) / 2
            ub = u0 + (u1 - u0) * b
            k1 = self.f(z, ua)
            z2 = z + h / 2 * k1
            k2 = self.f(z2, um)
            z3 = z + h / 2 * k2
            k3 = self.f(z3, um)
            z4 = z + h * k3
            k4 = self.f(z4, ub)
            if with_jacobian:
                I = self._I
                D1 = self.jac(z, ua)
                D2 = self.jac(z2, um) @ (I + h / 2 * D1)
                D3 = self.jac(z3, um) @ (I + h / 2 * D2)
                D4 = self.jac(z4, ub) @ (I + h * D3)
                F = (I + h / 6 * (D1 + 2 * D2 + 2 * D3 + D4)) @ F
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return z, (F if with_jacobian else None)

    def _ab(self, theta: FloatArray) -> FloatArray:
        """``[A | B]`` rows of the accelerations at parameters ``theta`` (relative)."""
        return self.pieces.accel_rows(self.nominal * theta)

    def _rk4_linear(self, z: FloatArray, u0: FloatArray, u1: FloatArray, h: float, n: int,
                    with_jacobian: bool) -> tuple[FloatArray, FloatArray | None]:
        """:meth:`rk4` for a model without effect terms: one ``[A | B]`` for every stage."""
        nq, nx = self.nq, self.nx
        theta = z[nx:]
        AB = self._ab(theta)                                         # (nq, nx + 2 nr)
        J = self._J0.copy()
        J[nq:nx, :nx] = AB[:, :nx]
        Af = J[:nx, :nx]                                             # A(theta), (nx, nx)
        x = z[:nx]
        I = self._I
        F = I.copy()
        du = u1 - u0
        W = np.empty((AB.shape[1], 4))                               # [x_i; u_i] per stage
        for s in range(n):
            a, b = s / n, (s + 1) / n
            U = np.column_stack([u0 + du * a, u0 + du * ((a + b) / 2), u0 + du * b])
            bu = AB[:, nx:] @ U                                      # B u at a, mid, b
            W[nx:, 0], W[nx:, 1], W[nx:, 2], W[nx:, 3] = U[:, 0], U[:, 1], U[:, 1], U[:, 2]
            W[:nx, 0] = x
            k1 = Af @ x
            k1[nq:] += bu[:, 0]
            W[:nx, 1] = x2 = x + h / 2 * k1
            k2 = Af @ x2
            k2[nq:] += bu[:, 1]
            W[:nx, 2] = x3 = x + h / 2 * k2
            k3 = Af @ x3
            k3[nq:] += bu[:, 1]
            W[:nx, 3] = x4 = x + h * k3
            k4 = Af @ x4
            k4[nq:] += bu[:, 2]
            if with_jacobian:
                P = self._G @ W               # parameter columns at the 4 stages, (naug, nq, 4)
                D: list[FloatArray] = []
                for st, c in enumerate((0.0, h / 2, h / 2, h)):
                    Jst = J.copy()
                    Jst[nq:nx, nx:] = P[:, :, st].T
                    D.append(Jst if not D else Jst @ (I + c * D[-1]))
                F = (I + h / 6 * (D[0] + 2 * D[1] + 2 * D[2] + D[3])) @ F
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return np.concatenate([x, theta]), (F if with_jacobian else None)

    # ---- measurement ----------------------------------------------------------------------
    def hx(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Predicted measurement ``h(z)`` (column vector)."""
        z = x[:, 0] if x.ndim == 2 else x
        out = np.empty(len(self._rows))
        acc = None
        for k, (i, order) in enumerate(self._rows):
            if order < 2:
                out[k] = z[order * self.nq + i]
            else:
                if acc is None:
                    if self._linear:   # model.rhs as A x + B u (see _rk4_linear)
                        acc = self._ab(z[self.nx:]) @ np.concatenate([z[:self.nx], u])
                    else:
                        acc = self.model.rhs(0.0, z[:self.nx], u, self.param_values(z))[self.nq:]
                out[k] = acc[i]
        return out[:, None]

    def HJ(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Measurement Jacobian ``dh/dz``."""
        z = x[:, 0] if x.ndim == 2 else x
        H = np.zeros((len(self._rows), self.dim_x))
        J = None
        for k, (i, order) in enumerate(self._rows):
            if order < 2:
                H[k, order * self.nq + i] = 1.0
            else:
                if J is None:
                    J = self.jac(z, u)
                H[k] = J[self.nq + i]
        return H

    def step(self, y: FloatArray, u0: FloatArray, u1: FloatArray) -> None:
        """Predict to this sample (RK4 and its Jacobian as ``F``) and update with measurement ``y``."""
        znext, self.F = self.rk4(self.x[:, 0], u0, u1, self.dt)
        self.x = znext[:, None]
        self.P = np.dot(self.F, self.P).dot(self.F.T) + self.Q
        self.joseph_update(y, lambda: (self.hx(self.x, u1)[:, 0], self.HJ(self.x, u1)))


#: the NIS consistency band: its probability and the factor it is widened by
NIS_LEVEL = 0.999
NIS_TOLERANCE = 1.5


def window_nis(nis_sum: float, nis_dof: int, before: tuple[float, int],
               level: float = NIS_LEVEL, tolerance: float = NIS_TOLERANCE
               ) -> tuple[float, int, float, float, str | None]:
    """Mean normalised innovation squared per dof since ``before`` and its consistency band:
    ``(nis, dof, lo, hi, warning)``, the ``level`` band widened ``tolerance`` times.
    """
    s0, n0 = before
    dof = nis_dof - n0
    nis = (nis_sum - s0) / dof if dof > 0 else float("nan")
    lo = hi = float("nan")
    warning = None
    if dof > 0:
        a = (1.0 - level) / 2.0
        lo = float(chi2.ppf(a, dof)) / dof / tolerance
        hi = float(chi2.ppf(1.0 - a, dof)) / dof * tolerance
        if not lo <= nis <= hi:
            warning = (f"EKF inconsistent: mean normalised innovation squared {nis:.3g} per "
                       f"degree of freedom outside [{lo:.3g}, {hi:.3g}] ({100 * level:g} % band "
                       f"of {dof} dof, widened {tolerance:g}x); the filter no longer fits the "
                       "data and its stderr is not to be trusted")
    return nis, dof, lo, hi, warning
