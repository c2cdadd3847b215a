"""Second-order linear suspension models and their one right-hand side.

Every model is written as

    M(p) q'' + C(p) q' + K(p) q = Fk(p) r + Fc(p) r'

with generalised coordinates ``q`` (m, rad), road inputs ``r`` (m) under the tyres and the
parameters ``p`` (SI units). The state is ``x = [q, q']`` and the input vector is
``u = [r, r']``. :meth:`SuspensionModel.rhs` (signature ``rhs(t, x, u, params)``, as in
python-control) is the single source of truth for the physics: the simulator, identifier,
EKF and sensor node all derive from it or from the matrices that define it. Optional
effect terms (nonlinear forces) are added through :attr:`SuspensionModel.extra_force`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from suspid.errors import UsageError

FloatArray = NDArray[np.float64]
#: signature of an additional generalised force: f(t, x, u, params) -> array of len(coords)
ForceFn = Callable[[float, FloatArray, FloatArray, Mapping[str, float]], FloatArray]


@dataclass(frozen=True)
class ParamSpec:
    """Metadata of one physical parameter.

    Attributes
    ----------
    name : str
        Name as in the seed paper and the CLI contract.
    unit : str
        SI unit.
    default : float
        Documented default starting value (a typical passenger car).
    kind : str
        ``"mass"``, ``"inertia"``, ``"damping"``, ``"stiffness"`` or ``"length"``.
    description : str
        What the parameter is.
    """

    name: str
    unit: str
    default: float
    kind: str
    description: str


@dataclass
class SuspensionModel:
    """A linear second-order suspension model (base class; see the concrete models).

    Attributes
    ----------
    name : str
        Model name used on the command line (``quarter1``, ``quarter2``, ``half4``).
    coords : tuple of str
        Generalised coordinates (measured position channel names).
    roads : tuple of str
        Road input names (one per tyre); their derivatives are ``<name>_dot``.
    params : tuple of ParamSpec
        The physical parameters in canonical order.
    """

    name: str
    coords: tuple[str, ...]
    roads: tuple[str, ...]
    params: tuple[ParamSpec, ...]
    scale_invariant: tuple[str, ...] = ()
    extra_force: list[ForceFn] = field(default_factory=list)

    # ---- names -------------------------------------------------------------------
    @property
    def param_names(self) -> tuple[str, ...]:
        """Parameter names in canonical order."""
        return tuple(p.name for p in self.params)

    @property
    def state_names(self) -> tuple[str, ...]:
        """State names ``[q..., q_dot...]``."""
        return self.coords + tuple(f"{c}_dot" for c in self.coords)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Input names ``[r..., r_dot...]``."""
        return self.roads + tuple(f"{r}_dot" for r in self.roads)

    @property
    def channels(self) -> tuple[str, ...]:
        """Every channel a sensor can measure: positions, velocities, accelerations."""
        return (self.coords + tuple(f"{c}_dot" for c in self.coords)
                + tuple(f"{c}_ddot" for c in self.coords))

    @property
    def n_states(self) -> int:
        return 2 * len(self.coords)

    def defaults(self) -> dict[str, float]:
        """Documented default parameter values (typical passenger car, SI)."""
        return {p.name: p.default for p in self.params}

    def spec(self, name: str) -> ParamSpec:
        """The :class:`ParamSpec` called ``name`` (UsageError naming the valid ones if none)."""
        for p in self.params:
            if p.name == name:
                return p
        raise UsageError(f"model {self.name} has no parameter {name!r}; "
                         f"expected one of {', '.join(self.param_names)}")

    # ---- physics (overridden by concrete models) ---------------------------------
    def matrices(self, p: Mapping[str, float]) -> tuple[FloatArray, FloatArray, FloatArray,
                                                         FloatArray, FloatArray]:
        """Return ``(M, C, K, Fk, Fc)`` for parameters ``p`` (SI units)."""
        raise NotImplementedError

    def state_space(self, p: Mapping[str, float]) -> tuple[FloatArray, FloatArray]:
        """Continuous state-space ``(A, B)`` with ``x' = A x + B u``, ``u = [r, r']``.

        Parameters
        ----------
        p : mapping
            Parameter values (SI units).

        Returns
        -------
        A : ndarray, shape (n, n)
        B : ndarray, shape (n, 2 * n_roads)
        """
        M, C, K, Fk, Fc = self.matrices(p)
        nq = len(self.coords)
        Minv = np.linalg.inv(M)
        A = np.zeros((2 * nq, 2 * nq))
        A[:nq, nq:] = np.eye(nq)
        A[nq:, :nq] = -Minv @ K
        A[nq:, nq:] = -Minv @ C
        B = np.zeros((2 * nq, 2 * len(self.roads)))
        B[nq:, : len(self.roads)] = Minv @ Fk
        B[nq:, len(self.roads):] = Minv @ Fc
        return A, B

    def rhs(self, t: float, x: FloatArray, u: FloatArray, params: Mapping[str, float]) -> FloatArray:
        """State derivative ``dx/dt`` (the one right-hand side of the physics).

        Parameters
        ----------
        t : float
            Time (s); unused by the linear models, passed to effect terms.
        x : ndarray, shape (n,)
            State ``[q, q']`` (m, rad, m/s, rad/s).
        u : ndarray, shape (2 * n_roads,)
            Input ``[r, r']`` (m, m/s).
        params : mapping
            Parameter values (SI).

        Returns
        -------
        ndarray, shape (n,)
            ``[q', q'']``.
        """
        M, C, K, Fk, Fc = self.matrices(params)
        nq = len(self.coords)
        nr = len(self.roads)
        q, qd = x[:nq], x[nq:]
        f = Fk @ u[:nr] + Fc @ u[nr:] - C @ qd - K @ q
        for extra in self.extra_force:
            f = f + extra(t, x, u, params)
        return np.concatenate([qd, np.linalg.solve(M, f)])

    def accelerations(self, X: FloatArray, U: FloatArray, p: Mapping[str, float]) -> FloatArray:
        """Accelerations ``q''`` for state rows ``X`` (N, n) and input rows ``U`` (N, 2 nr)."""
        A, B = self.state_space(p)
        nq = len(self.coords)
        return X @ A[nq:].T + U @ B[nq:].T
