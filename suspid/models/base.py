"""Second-order linear suspension models and their one right-hand side.

Every model is ``M(p) q'' + C(p) q' + K(p) q = Fk(p) r + Fc(p) r'`` with generalised
coordinates ``q`` (m, rad), road inputs ``r`` (m) and parameters ``p`` (SI); the state is
``x = [q, q']``, the input ``u = [r, r']``. :meth:`SuspensionModel.rhs` is the single source of
truth for the physics. A model owns everything model-specific (structure, sites, roads, CSV
columns, CAN identities, design of experiments, twin): see ``docs/architecture.md``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Collection, Mapping

import numpy as np
from numpy.typing import NDArray

from suspid.errors import UsageError

FloatArray = NDArray[np.float64]
#: ``(M, C, K, Fk, Fc)`` of :meth:`SuspensionModel.matrices`
Matrices = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
#: signature of an additional generalised force: f(t, x, u, params) -> array of len(coords)
ForceFn = Callable[[float, FloatArray, FloatArray, Mapping[str, float]], FloatArray]
#: standard gravity (m/s^2) for static wheel loads
GRAVITY = 9.81
#: named channel sets (``suspid simulate --channels``, ``suspid node --channels``), see
#: :meth:`SuspensionModel.channel_set`
CHANNEL_SETS: dict[str, str] = {
    "production": "the sensors of a production car: body accelerations and ride heights",
    "accelerometers": "an accelerometer on every coordinate (body and wheels)",
}


@functools.lru_cache(maxsize=32)
def _check_factors(n: int) -> FloatArray:
    """Two fixed random sets of ``n`` log-normal factors: where :meth:`SuspensionModel.affine` checks."""
    f = np.exp(np.random.default_rng(7).normal(0.0, 0.5, (2, n)))
    f.setflags(write=False)
    return f


@dataclass(frozen=True)
class Site:
    """One strut or tyre of a model: where a force element (and an effect) acts.

    The site coordinate is ``s = g . q + gr . r`` (m); a force ``phi`` of the element enters as
    the generalised force ``Q = b * phi``. For a strut ``s`` is the extension (``b = -g``), for a
    tyre the compression ``r - x_wheel``. ``c_name``/``k_name`` name the base damper/spring;
    ``load`` is the static load (N), for ``tire_liftoff``.
    """

    name: str
    kind: str
    g: FloatArray
    gr: FloatArray
    b: FloatArray
    c_name: str | None
    k_name: str | None
    load: float = 0.0

    def coordinate(self, X: FloatArray, U: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Site coordinate ``s`` (m) and rate ``s'`` (m/s) for state rows ``X`` and inputs ``U``."""
        nq, nr = self.g.size, self.gr.size
        X2, U2 = np.atleast_2d(X), np.atleast_2d(U)
        return (X2[:, :nq] @ self.g + U2[:, :nr] @ self.gr,
                X2[:, nq:] @ self.g + U2[:, nr:] @ self.gr)


@dataclass(frozen=True)
class ParamSpec:
    """One physical parameter: name (the paper's), SI unit, default (a typical passenger car),
    kind (``mass``, ``inertia``, ``damping``, ``stiffness``, ``length``) and description."""

    name: str
    unit: str
    default: float
    kind: str
    description: str


@dataclass(frozen=True)
class DoeDesign:
    """A model's design of experiments (``suspid doe``; see ``docs/architecture.md``).

    ``array`` is one of the seed's (``"L16-4"``, ``"L27-3"``) or the model's own given in
    ``rows`` (1-based levels per run) and ``levels`` (letter -> name, unit, values in SI).
    ``columns`` maps a factor letter to the parameter or state it sets; ``constants`` and
    ``body_x0`` are values every row shares; ``choices`` records what the source leaves out.
    """

    array: str
    columns: Mapping[str, str]
    constants: Mapping[str, float] = field(default_factory=dict)
    body_x0: Mapping[str, float] = field(default_factory=dict)
    choices: Mapping[str, str] = field(default_factory=dict)
    rows: tuple[tuple[int, ...], ...] | None = None
    levels: Mapping[str, tuple[str, str, tuple[float, ...]]] | None = None


@dataclass(frozen=True)
class Twin:
    """A second parameter set with exactly the same response on some coordinates.

    A discrete non-identifiability: two isolated minima of equal cost for every record of
    those coordinates. ``swapped`` says what cannot be told apart, ``rule`` what chooses, and
    ``prefer`` whether the rule chooses the twin.
    """

    params: dict[str, float]
    swapped: str
    rule: str
    prefer: bool


@dataclass(frozen=True)
class AffinePieces:
    """The forward model as affine pieces: ``q'' = (AB0 + sum_j theta_j dAB_j) [q, q', r, r']``.

    With the masses fixed, ``M^-1 [-K | -C | Fk | Fc]`` is affine in the dampers and springs,
    so the matrices of any parameter set differing from ``base`` only in ``names`` are one
    small product. ``exact`` is ``False`` when a free parameter enters non-affinely (checked
    at two random parameter sets to 1e-12); ``Minv`` is ``M^-1`` at ``base``.
    """

    names: tuple[str, ...]
    base: dict[str, float]
    AB0: FloatArray
    dAB: FloatArray
    exact: bool
    Minv: FloatArray | None = None
    _flat: FloatArray = field(init=False, repr=False, compare=False)
    _A0: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_flat", np.ascontiguousarray(
            self.dAB.reshape(self.dAB.shape[0], -1)))
        nq = self.AB0.shape[0]
        A0 = np.zeros((2 * nq, 2 * nq))
        A0[:nq, nq:] = np.eye(nq)
        object.__setattr__(self, "_A0", A0)

    @property
    def nq(self) -> int:
        """Number of generalised coordinates."""
        return int(self.AB0.shape[0])

    def theta(self, p: Mapping[str, float]) -> FloatArray:
        """The free parameters of ``p`` as a vector (SI)."""
        return np.array([float(p[k]) for k in self.names])

    def matches(self, p: Mapping[str, float]) -> bool:
        """Whether ``p`` equals ``base`` in every fixed parameter (the pieces then apply)."""
        free = set(self.names)
        return self.exact and all(p[k] == v for k, v in self.base.items() if k not in free)

    def accel_rows(self, theta: FloatArray) -> FloatArray:
        """``[A_acc | B_acc]`` (nq, 2 nq + 2 nr) at ``theta``: ``q'' = accel_rows(theta) @ [q, q', r, r']``."""
        th = np.asarray(theta, dtype=float)
        return self.AB0 + (th @ self._flat).reshape(self.AB0.shape)

    def state_space(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(A, B)`` at free parameters ``theta``, as :meth:`SuspensionModel.state_space`."""
        AB = self.accel_rows(theta)
        nq = AB.shape[0]
        n = 2 * nq
        A = self._A0.copy()
        A[nq:] = AB[:, :n]
        B = np.zeros((n, AB.shape[1] - n))
        B[nq:] = AB[:, n:]
        return A, B

    def accelerations(self, X: FloatArray, U: FloatArray, theta: FloatArray) -> FloatArray:
        """Accelerations ``q''`` (N, nq) for state rows ``X`` (N, 2 nq) and inputs ``U`` (N, 2 nr)."""
        AB = self.accel_rows(theta)
        n = 2 * AB.shape[0]
        return np.asarray(X @ AB[:, :n].T + U @ AB[:, n:].T, dtype=np.float64)


@dataclass
class SuspensionModel:
    """A linear second-order suspension model (base class; see the concrete models).

    ``coords`` are the generalised coordinates, ``roads`` the road inputs (one per tyre),
    ``params`` the parameters in canonical order. Class attributes: ``sensor_set`` and
    ``alert_id`` (the DBC's ``SN_Status.SensorSet`` and ``SUSPID_Alert.Model``), ``known``
    (the parameters a user normally knows, the usual ``--fix`` set), ``doe_design`` and
    ``angles`` (the coordinates in rad; ``None``: not declared).
    """

    sensor_set: ClassVar[int] = 0
    alert_id: ClassVar[int] = -1
    known: ClassVar[tuple[str, ...]] = ()
    doe_design: ClassVar[DoeDesign | None] = None
    angles: ClassVar[tuple[str, ...] | None] = None

    name: str
    coords: tuple[str, ...]
    roads: tuple[str, ...]
    params: tuple[ParamSpec, ...]
    scale_invariant: tuple[str, ...] = ()
    extra_force: list[ForceFn] = field(default_factory=list)

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

    def initial_state(self) -> FloatArray:
        """The ``initial`` scenario's state ``[q, q']`` (m, rad, m/s, rad/s); default rest."""
        return np.zeros(self.n_states)

    def road_tracks(self) -> tuple[int, ...]:
        """Track (wheel path) index of every road: roads on one track see one profile."""
        return (0,) * len(self.roads)

    def road_lags(self, p: Mapping[str, float]) -> tuple[float, ...]:
        """Distance (m) each road's tyre runs behind the first axle (delay ``L / v`` at speed ``v``)."""
        return (0.0,) * len(self.roads)

    def twin(self, p: Mapping[str, float], measured: Collection[str]) -> Twin | None:
        """The other parameter set whose response on the ``measured`` coordinates equals that
        of ``p`` (SI) for every road and initial state, or ``None``."""
        return None

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        """The suspension struts (coordinate = extension; the force resists extension)."""
        raise UsageError(f"model {self.name} defines no suspension struts")

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        """The tyre contacts (coordinate = compression ``r - x_wheel``, static load in N)."""
        raise UsageError(f"model {self.name} defines no tyres")

    @property
    def ride_heights(self) -> tuple[str, ...]:
        """Ride-height channels (strut extensions, m), one per strut: ``d`` or ``d1``, ``d2``, ..."""
        try:
            n = len(self.strut_sites(self.defaults()))
        except UsageError:
            return ()
        return ("d",) if n == 1 else tuple(f"d{i}" for i in range(1, n + 1))

    @property
    def ride_height_channels(self) -> tuple[str, ...]:
        """:attr:`ride_heights` and their rates (``_dot``)."""
        return self.ride_heights + tuple(f"{d}_dot" for d in self.ride_heights)

    def body_rows(self, p: Mapping[str, float] | None = None) -> tuple[int, ...]:
        """Coordinates whose equation holds only strut forces (the body's), from the matrices.

        These equations hold whatever the road does: the road-unknown identification fits them.
        ``p``: parameters (SI), default the model's defaults.
        """
        pp = dict(self.defaults(), **dict(p or {}))
        M, C, K, Fk, Fc = self.matrices(pp)
        Cs = np.zeros_like(C)
        Ks = np.zeros_like(K)
        Fks = np.zeros_like(Fk)
        Fcs = np.zeros_like(Fc)
        for s in self.strut_sites(pp):
            c = pp[s.c_name] if s.c_name else 0.0
            k = pp[s.k_name] if s.k_name else 0.0
            Cs += c * np.outer(s.g, s.g)
            Ks += k * np.outer(s.g, s.g)
            Fks -= k * np.outer(s.g, s.gr)
            Fcs -= c * np.outer(s.g, s.gr)
        rows = []
        for j in range(len(self.coords)):
            scale = max(np.abs(C[j]).max(), np.abs(K[j]).max(), 1e-300)
            same = all(np.allclose(a[j], b[j], rtol=1e-12, atol=1e-12 * scale)
                       for a, b in ((C, Cs), (K, Ks), (Fk, Fks), (Fc, Fcs)))
            if same and np.abs(K[j]).max() > 0.0:
                rows.append(j)
        return tuple(rows)

    def channel_set(self, name: str) -> tuple[str, ...]:
        """The channels of a named sensor set (:data:`CHANNEL_SETS`); UsageError if unknown.

        ``production``: the body accelerations and every ride height; ``accelerometers``: the
        acceleration of every coordinate.
        """
        if name == "production":
            return tuple(f"{self.coords[j]}_ddot" for j in self.body_rows()) + self.ride_heights
        if name == "accelerometers":
            return tuple(f"{c}_ddot" for c in self.coords)
        raise UsageError(f"unknown channel set {name!r}; expected one of {', '.join(CHANNEL_SETS)}")

    def deflections(self, data: Mapping[str, FloatArray],
                    p: Mapping[str, float] | None = None) -> dict[str, FloatArray]:
        """Strut extensions (m) by strut name, for every strut whose coordinates are in ``data``.

        ``data``: channel arrays (m, rad); ``p``: parameters (SI) for the geometry.
        """
        pp = dict(self.defaults(), **(p or {}))
        out: dict[str, FloatArray] = {}
        names = self.coords + self.roads
        for site in self.strut_sites(pp):
            w = np.concatenate([site.g, site.gr])
            used = [(names[i], float(w[i])) for i in np.flatnonzero(w)]
            if all(n in data for n, _ in used):
                out[site.name] = sum((c * np.asarray(data[n], dtype=float) for n, c in used),
                                     start=np.zeros(np.shape(data[used[0][0]])))
        return out

    def column_bases(self) -> set[str]:
        """Base names of the CSV columns of this model (coordinates, ride heights, roads)."""
        return set(self.coords) | set(self.ride_heights) | set(self.roads)

    def column_units(self, column: str) -> tuple[str, ...]:
        """The SI unit(s) of a CSV column of this model (empty: not one of it; both m and rad
        for a coordinate when :attr:`angles` is not declared)."""
        if column == "t":
            return ("s",)
        base, per = column, ""
        for suffix, rate in (("_ddot", "/s^2"), ("_dot", "/s")):
            if column.endswith(suffix):
                base, per = column[: -len(suffix)], rate
                break
        if base in self.roads and per != "/s^2":
            return ("m" + per,)
        if column in self.ride_height_channels:
            return ("m" + per,)
        if column not in self.channels:
            return ()
        if self.angles is None:   # not declared: either
            return ("m" + per, "rad" + per)
        return ("rad" + per,) if base in self.angles else ("m" + per,)

    def matrices(self, p: Mapping[str, float]) -> Matrices:
        """Return ``(M, C, K, Fk, Fc)`` for parameters ``p`` (SI units)."""
        raise NotImplementedError

    def state_space(self, p: Mapping[str, float]) -> tuple[FloatArray, FloatArray]:
        """Continuous state-space ``(A, B)`` with ``x' = A x + B u``, ``u = [r, r']`` (``p`` in SI)."""
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

    def affine(self, base: Mapping[str, float], free: list[str] | tuple[str, ...] | None = None
               ) -> AffinePieces:
        """The :class:`AffinePieces` of the forward model in ``free`` (default: every damper
        and spring) around ``base`` (SI; missing parameters take the defaults)."""
        p0 = dict(self.defaults(), **dict(base))
        names = tuple(free) if free is not None else tuple(
            s.name for s in self.params if s.kind in ("damping", "stiffness"))
        for k in names:
            self.spec(k)
        nq = len(self.coords)

        def parts(p: Mapping[str, float]) -> tuple[FloatArray, FloatArray]:
            M, C, K, Fk, Fc = self.matrices(p)
            return M, np.hstack([-K, -C, Fk, Fc])

        M0, H0 = parts(p0)
        Minv = np.asarray(np.linalg.inv(M0), dtype=np.float64)
        f0 = Minv @ H0
        th0 = np.array([p0[k] for k in names])
        dAB = np.empty((len(names),) + f0.shape)
        for j, k in enumerate(names):
            p1 = dict(p0)
            step = max(abs(p0[k]), 1.0)
            p1[k] = p0[k] + step
            M1, H1 = parts(p1)
            # a damper or spring leaves M as it is: no cancellation in M^-1 (H1 - H0)
            dAB[j] = (Minv @ (H1 - H0) if np.array_equal(M1, M0)
                      else np.linalg.solve(M1, H1) - f0) / step
        AB0 = f0 - np.tensordot(th0, dAB, axes=1)
        # checked against the model's own rows at two random parameter sets
        exact = True
        for factors in _check_factors(th0.size):
            th = th0 * factors
            ref = np.linalg.solve(*parts(dict(p0, **dict(zip(names, th.tolist())))))
            got = AB0 + np.tensordot(th, dAB, axes=1)
            if not np.all(np.abs(got - ref) <= 1e-12 * (np.abs(ref).max() + 1e-300)):
                exact = False
        return AffinePieces(names, p0, AB0, dAB, exact and f0.shape[0] == nq, Minv)

    def mass_inverse(self, p: Mapping[str, float]) -> FloatArray:
        """``M(p)^-1`` (nq, nq): accelerations per unit generalised force (1/kg, 1/(kg m^2))."""
        return np.asarray(np.linalg.inv(self.matrices(p)[0]), dtype=np.float64)

    def rhs(self, t: float, x: FloatArray, u: FloatArray, params: Mapping[str, float]) -> FloatArray:
        """State derivative ``[q', q'']`` (the one right-hand side of the physics).

        ``t`` in s (passed to effect terms), ``x = [q, q']`` (m, rad, m/s, rad/s), ``u = [r, r']``
        (m, m/s), ``params`` in SI.
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
