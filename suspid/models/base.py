"""Second-order linear suspension models and their one right-hand side.

Every model is written as

    M(p) q'' + C(p) q' + K(p) q = Fk(p) r + Fc(p) r'

with generalised coordinates ``q`` (m, rad), road inputs ``r`` (m) under the tyres and the
parameters ``p`` (SI units). The state is ``x = [q, q']`` and the input vector is
``u = [r, r']``. :meth:`SuspensionModel.rhs` (signature ``rhs(t, x, u, params)``, as in
python-control) is the single source of truth for the physics: the simulator, identifier,
EKF and sensor node all derive from it or from the matrices that define it. Optional
effect terms (nonlinear forces) are added through :attr:`SuspensionModel.extra_force`.

A model object owns everything model-specific, so no other module asks for a model by
name: its structure (coordinates, roads, parameters), where its struts and tyres are
(:class:`Site`, with static tyre loads), its rest and initial states, how its roads follow
each other (:meth:`SuspensionModel.road_lags`, :meth:`SuspensionModel.road_tracks`), its
suspension deflections (:meth:`SuspensionModel.deflections`), which CSV columns are its
(:meth:`SuspensionModel.column_bases`), its CAN identities (:attr:`sensor_set`,
:attr:`alert_id`, matching the DBC), its design of experiments (:attr:`doe_design`) and the
other parameter set a record of some coordinates cannot tell from the true one
(:meth:`SuspensionModel.twin`). See ``docs/architecture.md`` ("Adding a model").
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
    """Two fixed random sets of ``n`` log-normal factors (sigma 0.5): where the affine
    pieces are checked against the model (:meth:`SuspensionModel.affine`)."""
    f = np.exp(np.random.default_rng(7).normal(0.0, 0.5, (2, n)))
    f.setflags(write=False)
    return f


@dataclass(frozen=True)
class Site:
    """One strut or one tyre of a model: where a force element (and an effect) acts.

    The site coordinate is ``s = g . q + gr . r`` (m) with rate ``s' = g . q' + gr . r'``;
    a force ``phi`` of the element enters as the generalised force ``Q = b * phi``.
    For a strut ``s`` is the extension (``s' > 0`` rebound) and ``b = -g``; for a tyre
    ``s`` is the compression ``r - x_wheel``.

    Attributes
    ----------
    name : str
        ``"strut"``, ``"front strut"``, ``"front-left tyre"``, ...
    kind : {"strut", "tyre"}
    g : ndarray, shape (nq,)
    gr : ndarray, shape (nr,)
    b : ndarray, shape (nq,)
    c_name, k_name : str or None
        Names of the base damping / stiffness of the element at this site.
    load : float
        Static load carried by the element (N), for ``tire_liftoff``.
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
        nq = self.g.size
        nr = self.gr.size
        X2 = np.atleast_2d(X)
        U2 = np.atleast_2d(U)
        s = X2[:, :nq] @ self.g + U2[:, :nr] @ self.gr
        sd = X2[:, nq:] @ self.g + U2[:, nr:] @ self.gr
        return s, sd


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


@dataclass(frozen=True)
class DoeDesign:
    """A model's design of experiments: an orthogonal array's factors mapped onto the model.

    ``suspid doe --model NAME`` runs the design of the model's :attr:`SuspensionModel.doe_design`
    (:mod:`estimator.doe.design` makes each row an identification problem: the true
    parameters, the known initial state, a free response).

    Attributes
    ----------
    array : str
        The orthogonal array: one of the seed's, ``"L16-4"`` (Tables 3-4: 16 runs, 5 factors
        A-E at 4 levels) or ``"L27-3"`` (Tables 5-6: 27 runs, factors A-H, J, K at 3
        levels), or the name of the model's own array given in ``rows`` and ``levels``.
    columns : mapping
        Factor letter -> the parameter or state (``x1``, ``x1_dot``) whose value the
        factor sets. A factor of the array not listed here is not used.
    constants : mapping
        Further true parameter values (SI) every row shares; with ``columns`` they must
        give every parameter of the model.
    body_x0 : mapping
        Further initial-state values every row shares (state name -> m, rad, m/s, rad/s).
    choices : mapping
        What the design's source leaves out and how it is chosen, with the reasons
        (recorded in ``suspid doe --json``'s ``setup.choices``).
    rows : tuple of tuple of int, optional
        The model's own array: one row of factor levels (1-based) per run.
    levels : mapping, optional
        The model's own array's factors: letter -> ``(name, unit, level values)`` (SI).
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

    A structural, discrete non-identifiability: the cost has two isolated minima of the
    same value for every record of those coordinates (any road, noise-free or not), so no
    optimiser can tell them apart and the local curvature at either looks fine.

    Attributes
    ----------
    params : dict
        Every parameter of the twin (SI), the given ones where the twin keeps them.
    swapped : str
        What the record cannot tell apart, in words.
    rule : str
        The physical rule that chooses between the two, in words.
    prefer : bool
        ``True`` when the rule chooses the twin over the given parameter set.
    """

    params: dict[str, float]
    swapped: str
    rule: str
    prefer: bool


@dataclass(frozen=True)
class AffinePieces:
    """The forward model as affine pieces: ``q'' = (AB0 + sum_j theta_j dAB_j) [q, q', r, r']``.

    With the mass matrix fixed, every model's ``M^-1 [-K | -C | Fk | Fc]`` is affine in its
    dampers and springs (each enters ``C``, ``K``, ``Fk``, ``Fc`` linearly), so the state
    and input matrices of any parameter set that differs from ``base`` only in the free
    parameters ``names`` are one small product: computed once, used by the simulator, the
    identifier, the window problem, the effects simulator, the EKF and the node's plant alike.

    Attributes
    ----------
    names : tuple of str
        Free parameters ``theta`` (in this order).
    base : dict
        Every parameter's value (SI); the fixed ones are held here.
    AB0 : ndarray, shape (nq, 2 nq + 2 nr)
        Acceleration rows at ``theta = 0``.
    dAB : ndarray, shape (n_free, nq, 2 nq + 2 nr)
        Slope of the acceleration rows per free parameter (per SI unit).
    exact : bool
        ``True`` when the pieces reproduce :meth:`SuspensionModel.state_space` (checked at
        two random parameter sets to 1e-12 relative); ``False`` when a free parameter
        enters non-affinely (a mass, an inertia, a length): use the model instead.
    Minv : ndarray, shape (nq, nq), optional
        Inverse mass matrix at ``base`` (1/kg, 1/(kg m^2)): the accelerations per unit
        generalised force of an added force term (``None`` if not given).
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
        # the slopes as one (n_free, nq * (2 nq + 2 nr)) matrix: accel_rows is one product
        object.__setattr__(self, "_flat", np.ascontiguousarray(
            self.dAB.reshape(self.dAB.shape[0], -1)))
        # the state matrix's kinematic rows [0 | I], copied and filled per parameter set
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
        """``[A_acc | B_acc]`` (nq, 2 nq + 2 nr) at free parameters ``theta``.

        ``q'' = accel_rows(theta) @ [q, q', r, r']``; equal to the rows ``nq:`` of
        :meth:`SuspensionModel.state_space`'s ``[A | B]`` to rounding.
        """
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

    def slopes(self, w: FloatArray) -> FloatArray:
        """Derivatives of the accelerations in the free parameters: ``dq''/dtheta_j``.

        Parameters
        ----------
        w : ndarray, shape (2 nq + 2 nr,) or (2 nq + 2 nr, k)
            ``[q, q', r, r']`` (one point, or ``k`` points as columns).

        Returns
        -------
        ndarray, shape (n_free, nq) or (n_free, nq, k)
            ``dAB_j @ w`` (per SI unit of each free parameter); exact, as the rows are
            affine in ``theta``. The EKF's Jacobian columns of its augmented parameters.
        """
        return np.asarray(self.dAB @ w, dtype=np.float64)


@dataclass
class SuspensionModel:
    """A linear second-order suspension model (base class; see the concrete models).

    Attributes
    ----------
    name : str
        Model name used on the command line (``quarter1``, ``quarter2``, ``half4``, ``full7``).
    coords : tuple of str
        Generalised coordinates (measured position channel names).
    roads : tuple of str
        Road input names (one per tyre); their derivatives are ``<name>_dot``.
    params : tuple of ParamSpec
        The physical parameters in canonical order.
    sensor_set : int
        (class attribute) ``SensorSet`` value of the DBC's ``SN_Status`` for the sensor
        messages of this model (1 quarter-car, 2 half-car, 3 full-car set).
    alert_id : int
        (class attribute) ``Model`` value of the DBC's ``SUSPID_Alert`` for this model.
    known : tuple of str
        (class attribute) Parameters a user normally knows (weighed masses, measured
        geometry); the documented ``--fix`` set of the examples and tests.
    doe_design : DoeDesign or None
        (class attribute) The model's design of experiments for ``suspid doe`` (``None``:
        the model has none).
    angles : tuple of str or None
        (class attribute) The coordinates that are angles (rad; their rates rad/s, rad/s^2);
        the others are lengths (m). ``None``: not declared (a plug-in model's coordinate
        may then be either, e.g. for the units a CSV header names).
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

    # ---- model-owned facts (overridden by concrete models where they differ) -------
    def initial_state(self) -> FloatArray:
        """The ``initial`` scenario's state ``[q, q']`` (m, rad, m/s, rad/s); default rest."""
        return np.zeros(self.n_states)

    def road_tracks(self) -> tuple[int, ...]:
        """Track (wheel path) index of every road: roads on one track see one profile.

        Default: every road on track 0 (a quarter or half car).
        """
        return (0,) * len(self.roads)

    def road_lags(self, p: Mapping[str, float]) -> tuple[float, ...]:
        """Distance (m) each road's tyre runs behind the first axle, per road.

        A road on track ``j`` with lag ``L`` sees, at speed ``v``, the profile of the
        track delayed by ``L / v``. Default: no lag.
        """
        return (0.0,) * len(self.roads)

    def twin(self, p: Mapping[str, float], measured: Collection[str]) -> Twin | None:
        """The other parameter set whose response on the ``measured`` coordinates equals
        that of ``p`` for every road and initial state, or ``None`` (the default: none).

        Parameters
        ----------
        p : mapping
            Every parameter (SI).
        measured : collection of str
            The coordinates (names in :attr:`coords`) with some channel in the cost.
        """
        return None

    def strut_sites(self, p: Mapping[str, float]) -> list[Site]:
        """The suspension struts (coordinate = extension; the force resists extension)."""
        raise UsageError(f"model {self.name} defines no suspension struts")

    def tyre_sites(self, p: Mapping[str, float]) -> list[Site]:
        """The tyre contacts (coordinate = compression ``r - x_wheel``, static load in N)."""
        raise UsageError(f"model {self.name} defines no tyres")

    @property
    def ride_heights(self) -> tuple[str, ...]:
        """Ride-height channel names, one per strut of :meth:`strut_sites` in its order.

        ``"d"`` for a model with one strut, else ``"d1"``, ``"d2"``, ...: the strut's
        extension (m, the body corner minus the wheel; positive in rebound), which
        production cars measure with ride-height sensors. Each may come with ``_dot`` (m/s).
        A model that defines no struts (a plug-in without :meth:`strut_sites`) has none.
        """
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
        """Coordinates whose equation holds only strut forces: the body's.

        Row ``j`` of ``M q'' + C q' + K q = Fk r + Fc r'`` is a body row when its ``C``,
        ``K``, ``Fk``, ``Fc`` entries are exactly those of the struts alone
        (``M[j] q'' = -sum_i g_i[j] (c_i d_i' + k_i d_i)``, ``d_i`` the strut extensions),
        so no tyre and no road acts on it except through a strut. These equations hold
        whatever the road does: the road-unknown identification fits them. Derived from
        the model's matrices, never from its name.

        Parameters
        ----------
        p : mapping, optional
            Parameters (SI); default the model's defaults.
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
        """The channels of a named sensor set (:data:`CHANNEL_SETS`); none is a road.

        ``production``: the accelerations (``_ddot``, m/s^2 or rad/s^2) of the body
        coordinates (:meth:`body_rows`) and every ride height (:attr:`ride_heights`, m),
        what a production car carries -- no road, no wheel motion. ``accelerometers``: the
        acceleration of every coordinate (body and wheel accelerometers).

        Raises
        ------
        UsageError
            An unknown set name (naming the known ones).
        """
        if name == "production":
            return tuple(f"{self.coords[j]}_ddot" for j in self.body_rows()) + self.ride_heights
        if name == "accelerometers":
            return tuple(f"{c}_ddot" for c in self.coords)
        raise UsageError(f"unknown channel set {name!r}; expected one of {', '.join(CHANNEL_SETS)}")

    def deflections(self, data: Mapping[str, FloatArray],
                    p: Mapping[str, float] | None = None) -> dict[str, FloatArray]:
        """Suspension deflections (strut extensions, m) computable from ``data``.

        Parameters
        ----------
        data : mapping
            Channel arrays by name (positions in m/rad; roads in m).
        p : mapping, optional
            Parameters (SI) for the geometry; default the model's defaults.

        Returns
        -------
        dict
            ``strut name -> extension`` for every strut whose coordinates (and road, for a
            strut standing on the road) are all in ``data``; empty if none.
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
        """The SI unit(s) a CSV column or channel of this model is in (empty: not one of it).

        ``t`` in s, roads and ride heights in m (their ``_dot`` in m/s), a coordinate in m
        or rad as :attr:`angles` declares, its ``_dot`` per s and ``_ddot`` per s^2. A model
        that does not declare its angles may have either.
        """
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

    # ---- physics (overridden by concrete models) ---------------------------------
    def matrices(self, p: Mapping[str, float]) -> Matrices:
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

    def affine(self, base: Mapping[str, float], free: list[str] | tuple[str, ...] | None = None
               ) -> AffinePieces:
        """The affine pieces of the forward model in the parameters ``free``.

        Parameters
        ----------
        base : mapping
            Every parameter's value (SI); missing ones take the defaults.
        free : sequence of str, optional
            The parameters that will change (default: every damping and stiffness).

        Returns
        -------
        AffinePieces
            ``exact`` tells whether the pieces are exact for these free parameters.
        """
        p0 = dict(self.defaults(), **dict(base))
        names = tuple(free) if free is not None else tuple(
            s.name for s in self.params if s.kind in ("damping", "stiffness"))
        for k in names:
            self.spec(k)
        nq = len(self.coords)

        def parts(p: Mapping[str, float]) -> tuple[FloatArray, FloatArray]:
            M, C, K, Fk, Fc = self.matrices(p)
            return M, np.hstack([-K, -C, Fk, Fc])

        def rows(p: Mapping[str, float]) -> FloatArray:
            M, H = parts(p)
            return np.asarray(np.linalg.solve(M, H), dtype=np.float64)

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
            # a damper or spring leaves M as it is: the slope is M^-1 times the change of
            # [-K -C Fk Fc] (no cancellation); anything else is differenced as it comes
            dAB[j] = (Minv @ (H1 - H0) if np.array_equal(M1, M0)
                      else np.linalg.solve(M1, H1) - f0) / step
        AB0 = f0 - np.tensordot(th0, dAB, axes=1)
        # checked against the model's own rows at two random parameter sets
        exact = True
        for factors in _check_factors(th0.size):
            th = th0 * factors
            ref = rows(dict(p0, **dict(zip(names, th.tolist()))))
            got = AB0 + np.tensordot(th, dAB, axes=1)
            if not np.all(np.abs(got - ref) <= 1e-12 * (np.abs(ref).max() + 1e-300)):
                exact = False
        return AffinePieces(names, p0, AB0, dAB, exact and f0.shape[0] == nq, Minv)

    def mass_inverse(self, p: Mapping[str, float]) -> FloatArray:
        """``M(p)^-1`` (nq, nq): the accelerations per unit generalised force (1/kg, 1/(kg m^2)).

        The input direction of an added force term ``Q`` (an effect) is ``[0; M^-1 Q]``.
        """
        return np.asarray(np.linalg.inv(self.matrices(p)[0]), dtype=np.float64)

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
