"""Identification with the road unknown: the body equations, fitted by modulating functions.

Every body row of the model (:meth:`SuspensionModel.body_rows`) reads
``sum_k M[j, k] q_k'' + sum_i g_i[j] (c_i d_i' + k_i d_i) = 0`` with ``d_i`` strut
``i``'s extension (its ride height): it holds whatever the road does and is linear in
the masses, inertias, dampers and springs, so body accelerations and ride heights
determine them by least squares (up to one common scale). The equations are formed by
integrating against ``phi_k(t) = sin^4(pi t / T) exp(-j w_k t)`` (five FFT bins per
integral; no derivative of a noisy channel, offsets drop out from bin 3), on the band
where every regressor stands ``SNR_MIN`` above its noise floor, weighted by the first
pass's equation-error spectrum. The method and its measurements: docs/road-unknown.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import numpy as np

from estimator.choices import ROAD_MODES
from estimator.identify.params import Parameters
from estimator.identify.outputs import check_magnitudes
from estimator.identify.result import IdentResult
from estimator.identify.misfit import MISFIT_FLOOR, MISFIT_SHARE
from suspid.errors import UsageError
from suspid.io.csvio import Measurement
from suspid.models.base import FloatArray, Site, SuspensionModel
from suspid.models.modes import modes

#: window ``sin^4(pi t / T)`` as a Fourier series: coefficients of ``exp(j 2 pi m t / T)``,
#: ``m = -2..2``
WINDOW = {-2: 1.0 / 16.0, -1: -0.25, 0: 0.375, 1: -0.25, 2: 1.0 / 16.0}
#: first bin used: bins 0..2 see the window's own mean (a constant offset)
FIRST_BIN = 3
#: a regressor channel's smoothed power must exceed its noise floor by this factor
SNR_MIN = 30.0
#: bins over which spectra and the equation error are smoothed
SMOOTH_BINS = 17
#: groups of the jackknife standard errors
JACKKNIFE_GROUPS = 20
#: bins per cluster of the standard errors' sandwich (the window's spectrum spans 5 bins)
CLUSTER_BINS = 8
#: shortest stretch of samples that forms equations
MIN_SEGMENT = 32
#: the band reaches at least this far (Hz)
MIN_BAND_HZ = 10.0
#: relative standard error above which a parameter counts as not determined
MAX_REL_STDERR = 0.5
#: sources of a quantity by preference: a measured derivative of the same order first
_ORDER_SUFFIX = {0: "", 1: "_dot", 2: "_ddot"}


@dataclass(frozen=True)
class Term:
    """One measured channel in an equation term: ``coef * J[channel^(power)]``."""

    channel: str
    order: int       # derivative order the channel is measured at (0 position, 1 rate, 2 acc.)
    coef: float


@dataclass
class BodyEquations:
    """Which measured channels form the body equations of a model, and what they determine:
    the body ``rows`` (coordinate indices) fitted, ``regressors`` (``parameter -> per row:
    list of (target derivative order, terms)``), the parameter ``names`` that enter them, why
    a part could not be formed (``missing``) and the power of ``j w`` every equation is
    multiplied by (``shift``: 0 unless a quantity is measured only as a higher derivative).
    """

    rows: tuple[int, ...]
    regressors: dict[str, list[list[tuple[int, list[Term]]]]]
    names: tuple[str, ...]
    missing: list[str] = field(default_factory=list)
    shift: int = 0

    @property
    def channels(self) -> list[str]:
        """Every measured channel the equations use."""
        out: list[str] = []
        for per_row in self.regressors.values():
            for parts in per_row:
                for _, terms in parts:
                    out.extend(t.channel for t in terms if t.channel not in out)
        return out


def _source(name: str, order: int, measured: Mapping[str, FloatArray]) -> tuple[str, int] | None:
    """The channel of quantity ``name`` that best gives its ``order``-th derivative: the same
    order, else the nearest lower one, else the nearest higher.
    """
    have = {o: name + suf for o, suf in _ORDER_SUFFIX.items() if name + suf in measured}
    for o in [order] + list(range(order - 1, -1, -1)) + list(range(order + 1, 3)):
        if o in have:
            return have[o], o
    return None


def _quantity(weights: Mapping[str, float], order: int,
              measured: Mapping[str, FloatArray]) -> list[Term] | None:
    """Terms of ``sum_q weights[q] q^(order)`` from the measured channels (None: one missing)."""
    terms = []
    for q, wq in weights.items():
        src = _source(q, order, measured)
        if src is None:
            return None
        terms.append(Term(src[0], src[1], float(wq)))
    return terms


def body_equations(model: SuspensionModel, measured: Mapping[str, FloatArray],
                   p: Mapping[str, float]) -> BodyEquations:
    """The body equations of ``model`` that the ``measured`` channels can form.

    Parameters
    ----------
    model : SuspensionModel
    measured : mapping
        Channel name -> samples (only the names matter here).
    p : mapping
        Parameter values (SI): the geometry the strut directions depend on.

    Returns
    -------
    BodyEquations
        Rows whose every term has a channel; ``missing`` names what the others lack.
    """
    pp = dict(model.defaults(), **dict(p))
    rows = model.body_rows(pp)
    sites = model.strut_sites(pp)
    nq = len(model.coords)
    M0 = model.matrices(pp)[0]
    # M is linear in the masses and inertias: its slope in each (exact for a linear M)
    mass_names = [s.name for s in model.params if s.kind in ("mass", "inertia")]
    dM = {}
    for n in mass_names:
        bumped = dict(pp)
        bumped[n] = pp[n] + 1.0
        slope = model.matrices(bumped)[0] - M0
        if np.any(slope[list(rows)] != 0.0):
            dM[n] = slope
    heights = model.ride_heights
    missing: list[str] = []
    regressors: dict[str, list[list[tuple[int, list[Term]]]]] = {}
    used_rows: list[int] = []
    # per row, the parameter -> [(order, terms)] contributions
    per_row: list[dict[str, list[tuple[int, list[Term]]]]] = []
    for j in rows:
        contrib: dict[str, list[tuple[int, list[Term]]]] = {}
        ok = True
        for n, slope in dM.items():
            w = {model.coords[k]: float(slope[j, k]) for k in range(nq) if slope[j, k] != 0.0}
            if not w:
                continue
            terms = _quantity(w, 2, measured)
            if terms is None:
                missing.append(f"body row {model.coords[j]}: no channel of "
                               f"{', '.join(w)} (position, rate or acceleration)")
                ok = False
                break
            contrib[n] = [(2, terms)]
        for i, site in enumerate(sites):
            gj = float(site.g[j])
            if gj == 0.0:
                continue
            for name, order in ((site.c_name, 1), (site.k_name, 0)):
                if name is None:
                    continue
                terms = _deflection(heights[i], site, order, gj, model, measured)
                if terms is None:
                    wheel = [model.coords[k] for k in range(nq) if site.g[k] != 0.0]
                    road = " and its road" if np.any(site.gr != 0.0) else ""
                    missing.append(f"{site.name}: neither its ride height {heights[i]} "
                                   f"nor the motion of {', '.join(wheel)}{road}")
                    ok = False
                    break
                contrib.setdefault(name, []).append((order, terms))
            if not ok:
                break
        if ok:
            used_rows.append(j)
            per_row.append(contrib)
    names = tuple(dict.fromkeys(n for c in per_row for n in c))
    for n in names:
        regressors[n] = [c.get(n, []) for c in per_row]
    shift = 0
    for per in regressors.values():
        for parts in per:
            for order, terms in parts:
                shift = max(shift, max(t.order - order for t in terms))
    return BodyEquations(tuple(used_rows), regressors, names, sorted(set(missing)), shift)


def _deflection(height: str, site: Site, order: int, gj: float, model: SuspensionModel,
                measured: Mapping[str, FloatArray]) -> list[Term] | None:
    """Terms of ``g_i[j] d_i^(order)``: the ride height, else the coordinates' motion (a strut
    not standing on the road).
    """
    src = _source(height, order, measured)
    if src is not None:
        return [Term(src[0], src[1], gj)]
    if np.any(site.gr != 0.0):
        return None
    w = {model.coords[k]: gj * float(site.g[k]) for k in range(len(model.coords))
         if site.g[k] != 0.0}
    return _quantity(w, order, measured)


@dataclass
class _Segment:
    """A stretch of uniformly spaced samples where every used channel is finite."""

    dt: float
    data: dict[str, FloatArray]


def _segments(meas: Measurement, channels: Sequence[str]) -> list[_Segment]:
    """The record's stretches of at least :data:`MIN_SEGMENT` samples with no missing value in
    ``channels`` and no time step off the median by more than 1 %.
    """
    t = np.asarray(meas.t, dtype=float)
    if t.size < MIN_SEGMENT:
        return []
    good = np.ones(t.size, dtype=bool)
    for c in channels:
        good &= np.isfinite(meas.measured[c])
    dt = float(np.median(np.diff(t)))
    step_ok = np.abs(np.diff(t) - dt) <= 0.01 * dt
    # a break before sample i when sample i-1 -> i is not a regular step
    brk = np.ones(t.size, dtype=bool)
    brk[1:] = ~step_ok
    out: list[_Segment] = []
    i = 0
    while i < t.size:
        if not good[i]:
            i += 1
            continue
        j = i + 1
        while j < t.size and good[j] and not brk[j]:
            j += 1
        if j - i >= MIN_SEGMENT:
            out.append(_Segment(dt, {c: np.asarray(meas.measured[c][i:j], dtype=float)
                                     for c in channels}))
        i = j
    return out


def _smooth(x: FloatArray, n: int = SMOOTH_BINS) -> FloatArray:
    """Running mean over ``n`` bins (shorter at the ends)."""
    k = np.ones(n)
    num = np.convolve(x, k, mode="same")
    den = np.convolve(np.ones_like(x), k, mode="same")
    return np.asarray(num / den, dtype=float)


@dataclass
class _SegmentEquations:
    """One segment's equations over its band: complex regressors ``X`` (rows, bins,
    parameters), their expected noise power ``noise``, the bins' ``omega`` (rad/s) and the
    length ``T`` (s).
    """

    X: np.ndarray
    noise: np.ndarray
    omega: FloatArray
    T: float


def _noise_floor(Y: np.ndarray) -> float:
    """Per-bin noise power of a spectrum: the median power of its top 16 % of bins over ln 2."""
    nb = Y.size
    top = max(4, int(0.16 * nb))
    return float(np.median(np.abs(Y[nb - top:]) ** 2) / math.log(2.0))


def band_limit(model: SuspensionModel, p: Mapping[str, float]) -> float:
    """Upper end of the fit band (Hz): twice the model's highest natural frequency at ``p``, at
    least :data:`MIN_BAND_HZ` (above it the record holds what the model does not).
    """
    f = max((md.f_n for md in modes(model, dict(model.defaults(), **dict(p)))), default=0.0)
    return max(MIN_BAND_HZ, 2.0 * f)


def _segment_equations(seg: _Segment, eqs: BodyEquations, free: Sequence[str], f_hi: float
                       ) -> _SegmentEquations | None:
    """The windowed equations of one segment up to ``f_hi`` (Hz), on the bins where every free
    parameter's regressor stands :data:`SNR_MIN` above its noise.
    """
    n = next(iter(seg.data.values())).size
    T = n * seg.dt
    spectra = {c: np.fft.rfft(v) * seg.dt for c, v in seg.data.items()}
    floors = {c: _noise_floor(Y) for c, Y in spectra.items()}
    nb = n // 2 + 1
    omega_all = 2.0 * np.pi * np.arange(nb) / T
    # up to a quarter of the sample rate: the rectangle rule's integrals stay clear of aliasing
    kmax = min(nb - 3, int(0.25 * n), int(f_hi * T))
    if kmax < FIRST_BIN:
        return None
    bins = np.arange(FIRST_BIN, kmax + 1)
    a2 = {m: a * a for m, a in WINDOW.items()}
    cache: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}

    def J(channel: str, power: int) -> tuple[np.ndarray, np.ndarray]:
        key = (channel, power)
        if key not in cache:
            Y = spectra[channel]
            acc = np.zeros(bins.size, dtype=complex)
            nz = np.zeros(bins.size)
            for m, a in WINDOW.items():
                w = (1j * omega_all[bins - m]) ** power
                acc += a * w * Y[bins - m]
                nz += a2[m] * np.abs(w) ** 2 * floors[channel]
            cache[key] = (acc, nz)
        return cache[key]

    n_rows = len(eqs.rows)
    X = np.zeros((n_rows, bins.size, len(eqs.names)), dtype=complex)
    N = np.zeros((n_rows, bins.size, len(eqs.names)))
    for pi, name in enumerate(eqs.names):
        for r, parts in enumerate(eqs.regressors[name]):
            for order, terms in parts:
                for tm in terms:
                    acc, nz = J(tm.channel, order + eqs.shift - tm.order)
                    X[r, :, pi] += tm.coef * acc
                    N[r, :, pi] += tm.coef ** 2 * nz
    ok = np.ones(bins.size, dtype=bool)
    for name in free:
        i = eqs.names.index(name)
        sig = _smooth(np.sum(np.abs(X[:, :, i]) ** 2, axis=0))
        ok &= sig > SNR_MIN * np.sum(N[:, :, i], axis=0)
    if not ok.any():
        return None
    return _SegmentEquations(X[:, ok], N[:, ok], np.asarray(omega_all[bins[ok]], dtype=float), T)


@dataclass
class _Solution:
    """The bias-compensated weighted least-squares solution over a set of segments."""

    theta: FloatArray          # free parameters (SI)
    se: FloatArray             # their standard errors (SI)
    cost: float                # weighted residual sum of squares
    n_obs: int                 # real equations
    blocks: list[tuple[np.ndarray, np.ndarray, _SegmentEquations]]


def _solve(segs: list[_SegmentEquations], ip: list[int], ih: list[int],
           theta_h: FloatArray, stderr: bool = True) -> _Solution:
    """Two passes of weighted least squares: the second weights each bin by the inverse of the
    first pass's smoothed equation-error power; the regressors' noise power is taken off
    the normal equations' diagonal; standard errors by the cluster sandwich.
    """
    # per segment: A (rows, bins, p) complex, y (rows, bins) complex
    blocks = []
    for s in segs:
        A = s.X[:, :, ip]
        y = -(s.X[:, :, ih] @ theta_h)
        blocks.append((A, y, s))
    col = np.sqrt(sum(np.sum(np.abs(A) ** 2, axis=(0, 1)) for A, _, _ in blocks))
    col[col == 0.0] = 1.0

    def solve(weights: list[np.ndarray]) -> tuple[FloatArray, np.ndarray, np.ndarray, np.ndarray]:
        AA = np.vstack([_real((A / col) * w[:, :, None]) for (A, _, _), w in zip(blocks, weights)])
        yy = np.concatenate([_real(y * w) for (_, y, _), w in zip(blocks, weights)])
        noise = sum(np.sum(s.noise[:, :, ip] * (w ** 2)[:, :, None], axis=(0, 1))
                    for (_, _, s), w in zip(blocks, weights)) / col ** 2
        G = AA.T @ AA
        G = G - np.diag(np.minimum(noise, 0.5 * np.diag(G)))
        try:
            beta = np.linalg.solve(G, AA.T @ yy)
        except np.linalg.LinAlgError:
            beta = np.full(len(ip), np.nan)
        return beta, AA, yy, G

    beta, _, _, _ = solve([np.ones(A.shape[:2]) for A, _, _ in blocks])
    weights = []
    for A, y, _ in blocks:
        e = y - (A / col) @ beta
        pw = np.vstack([_smooth(np.abs(er) ** 2) for er in e])
        pw = np.maximum(pw, 1e-300 + 1e-12 * pw.max())
        weights.append(1.0 / np.sqrt(pw))
    beta, AA, yy, H = solve(weights)
    resid = yy - AA @ beta
    if not stderr:
        return _Solution(beta / col, np.zeros(len(ip)), float(resid @ resid), int(yy.size), blocks)
    # the sandwich's middle: outer products of the scores summed over runs of CLUSTER_BINS bins
    S = np.zeros((len(ip), len(ip)))
    start = 0
    for A, _, _ in blocks:
        nr, nbins = A.shape[:2]
        m = nr * nbins
        a_re, a_im = AA[start:start + m], AA[start + m:start + 2 * m]
        e_re, e_im = resid[start:start + m], resid[start + m:start + 2 * m]
        u = (a_re * e_re[:, None] + a_im * e_im[:, None]).reshape(nr, nbins, -1).sum(axis=0)
        for i in range(0, nbins, CLUSTER_BINS):
            g = u[i:i + CLUSTER_BINS].sum(axis=0)
            S += np.outer(g, g)
        start += 2 * m
    try:
        Hinv = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        Hinv = np.full_like(H, np.inf)
    cov = Hinv @ S @ Hinv
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / col
    return _Solution(beta / col, se, float(resid @ resid), int(yy.size), blocks)


def _with_columns(meas: Measurement, eqs: BodyEquations,
                  extra: Mapping[str, Sequence[FloatArray]]) -> tuple[Measurement, BodyEquations]:
    """The record and equations with further force columns (see :func:`fit_road_unknown`)."""
    measured = dict(meas.measured)
    regressors = dict(eqs.regressors)
    for name, series in extra.items():
        if len(series) != len(eqs.rows):
            raise UsageError(f"extra column {name!r}: {len(series)} series, expected one per "
                             f"body row ({len(eqs.rows)})")
        per_row = []
        for r, z in enumerate(series):
            ch = f"{name}@{r}"
            measured[ch] = np.asarray(z, dtype=float)
            per_row.append([(0, [Term(ch, 0, 1.0)])])
        regressors[name] = per_row
    eqs2 = BodyEquations(eqs.rows, regressors, eqs.names + tuple(extra), list(eqs.missing),
                         eqs.shift)
    return replace(meas, measured=measured), eqs2


def _jackknife(segs: list[_SegmentEquations], ip: list[int], ih: list[int],
               theta_h: FloatArray) -> FloatArray:
    """Delete-a-group jackknife standard errors over :data:`JACKKNIFE_GROUPS` runs of bins."""
    sizes = [s.omega.size for s in segs]
    total = sum(sizes)
    groups = min(JACKKNIFE_GROUPS, total // CLUSTER_BINS)
    if groups < 3:
        return np.zeros(len(ip))
    # runs of neighbouring bins of equal information, none shorter than CLUSTER_BINS
    info = np.concatenate([np.sum(np.abs(s.X[:, :, ip]) ** 2 / np.maximum(s.noise[:, :, ip], 1e-300),
                                  axis=(0, 2)) for s in segs])
    share = np.cumsum(info) / max(float(info.sum()), 1e-300)
    label = np.zeros(total, dtype=int)
    g, start = 0, 0
    for i in range(total):
        if i - start >= CLUSTER_BINS and share[i] > (g + 1) / groups and total - i >= CLUSTER_BINS:
            g, start = g + 1, i
        label[i] = g
    groups = g + 1
    offs = np.cumsum([0] + sizes)
    thetas = []
    for g in range(groups):
        kept = []
        for s, a, b in zip(segs, offs[:-1], offs[1:]):
            keep = label[a:b] != g
            if keep.sum() >= CLUSTER_BINS:
                kept.append(_SegmentEquations(s.X[:, keep], s.noise[:, keep], s.omega[keep], s.T))
        if kept:
            thetas.append(_solve(kept, ip, ih, theta_h, stderr=False).theta)
    th = np.array(thetas)
    G = th.shape[0]
    if G < 3:
        return np.zeros(len(ip))
    return np.asarray(np.sqrt((G - 1) / G * np.sum((th - th.mean(axis=0)) ** 2, axis=0)), dtype=float)


def fit_road_unknown(model: SuspensionModel, meas: Measurement, params: Parameters,
                     extra: Mapping[str, Sequence[FloatArray]] | None = None,
                     jackknife: bool = True, misfit_fails: bool = True) -> IdentResult:
    """Identify what the body equations determine, the road under the tyres unknown.

    Parameters
    ----------
    model : SuspensionModel
    meas : Measurement
        Body accelerations (or motion) and every strut's ride height (or its wheel's
        motion); road columns are not used.
    params : Parameters
        Held values (``vary=False``) and the given values of the free parameters (SI).
    extra : mapping, optional
        Further generalised-force columns with free coefficients: name -> one series per
        body row (N, N m per unit coefficient), e.g. an effect's force at the struts. Their
        coefficients come back in ``params`` and ``stderr`` under their names.
    jackknife : bool
        Standard errors as the larger of the sandwich and the jackknife; ``False`` the
        sandwich alone.
    misfit_fails : bool
        Whether a misfit (:func:`body_misfit`) makes the fit unsuccessful; ``False`` only warns.

    Returns
    -------
    IdentResult
        Every parameter (an undetermined one keeps its given value, no standard error),
        ``stderr`` of the determined free parameters, ``identifiable``, ``warnings``,
        ``road`` ``"unknown"`` and ``undetermined``.
    """
    values = params.valuesdict()
    check_magnitudes(meas.source, meas.measured)
    eqs = body_equations(model, meas.measured, values)
    extra = dict(extra or {})
    if extra:
        meas, eqs = _with_columns(meas, eqs, extra)
    warnings: list[str] = list(meas.warnings) + ["road unknown: fitted the body equations "
                           f"({', '.join(model.coords[j] for j in eqs.rows) or 'none'}) on "
                           "body accelerations and ride heights; the road under the tyres "
                           "is never used"]
    warnings.extend(f"road unknown: cannot form the equation of {m}" for m in eqs.missing)
    free = [n for n in eqs.names if n in extra or params[n].vary]
    held = [n for n in eqs.names if n not in extra and not params[n].vary]
    homogeneous = not held and bool(free)
    scale_name = ""
    if homogeneous:
        masses = [n for n in free if n not in extra and model.spec(n).kind in ("mass", "inertia")]
        scale_name = masses[0] if masses else free[0]
        free.remove(scale_name)
        held = [scale_name]
    result = IdentResult(model=model.name, params=dict(values), fixed=params.fixed, stderr={},
                         cost=float("nan"), nfev=0, success=False, rms_residual={},
                         identifiable=False, warnings=warnings, road="unknown")
    pieces = _segments(meas, eqs.channels) if eqs.rows else []
    f_hi = band_limit(model, values)
    model_free = [n for n in free if n not in extra]

    def equations(f: float) -> list[_SegmentEquations]:
        return [s for s in (_segment_equations(seg, eqs, model_free, f) for seg in pieces)
                if s is not None]

    segs = equations(f_hi)
    undetermined = [n for n in params.free if n not in free]
    if not free or not segs:
        why = ("no free parameter enters the body equations" if not free and eqs.rows
               else "no stretch of the record forms the body equations"
               if eqs.rows else "no body equation can be formed from the measured channels")
        warnings.append(f"road unknown: {why}")
        result.undetermined = sorted(set(undetermined) | set(free))
        _explain_undetermined(model, result, eqs, scale_name)
        return result
    ip = [eqs.names.index(n) for n in free]
    ih = [eqs.names.index(n) for n in held]
    theta_h = np.array([values[n] for n in held])
    sol = _solve(segs, ip, ih, theta_h)
    # the band reaches twice the highest natural frequency: judged again at the estimate
    # when the given values were far off
    mine = np.array([n not in extra for n in free], dtype=bool)
    if np.all(sol.theta[mine] > 0.0):
        f_est = band_limit(model, {**values, **{n: v for n, v in zip(free, sol.theta.tolist())
                                                if n not in extra}})
        if abs(f_est / f_hi - 1.0) > 0.2:
            again = equations(f_est)
            if again:
                segs, sol = again, _solve(again, ip, ih, theta_h)
    theta, se = sol.theta, (np.maximum(sol.se, _jackknife(segs, ip, ih, theta_h)) if jackknife
                            else sol.se)
    result.nfev = 2
    result.n_obs = sol.n_obs
    result.cost = sol.cost
    result.success = bool(np.all(np.isfinite(theta)))
    determined = []
    for n, v, e in zip(free, theta, se):
        result.params[n] = float(v)
        if n in extra:   # a force column's coefficient may have either sign
            result.stderr[n] = float(e)
            continue
        ok = bool(np.isfinite(e) and v > 0.0 and e < MAX_REL_STDERR * v)
        if ok and not homogeneous:
            result.stderr[n] = float(e)
            determined.append(n)
        else:
            undetermined.append(n)
            if not (v > 0.0):
                warnings.append(f"road unknown: {n} came out {v:.4g} {model.spec(n).unit} "
                                "(not physical): the record does not determine it")
    if homogeneous:
        undetermined.append(scale_name)
    result.undetermined = sorted(set(undetermined))
    result.identifiable = result.success and not result.undetermined
    result.rms_residual = _rms_residual(model, eqs, sol.blocks, theta, values)
    # the cost: the body rows' in-band mean-square equation error, (m/s^2)^2 (rad/s^2)^2
    result.cost = float(sum(v * v for v in result.rms_residual.values()))
    result.band_hz = [round(min(float(s.omega.min()) for s in segs) / (2 * np.pi), 4),
                      round(max(float(s.omega.max()) for s in segs) / (2 * np.pi), 4)]
    full = np.zeros(len(eqs.names))
    full[ip], full[ih] = theta, theta_h
    misfit = body_misfit(model, eqs, sol.blocks, full)
    if misfit:
        result.misfit = {k: [r, sh] for k, (r, sh) in misfit.items()}
        if misfit_fails:
            result.success = False
        held_text = ", ".join(f"{k}={values[k]:.6g}" for k in params.fixed if k in eqs.names)
        rows = ", ".join(f"the {k} equation (noise-floor ratio {r:.3g}, {100.0 * sh:.3g} % "
                         "of the signal)" for k, (r, sh) in misfit.items())
        warnings.append(
            f"misfit: the body equations leave far more than measurement noise in {rows}; the "
            "model does not explain the record; likely causes: an effect the model lacks "
            "(suspid diagnose --road unknown), "
            + (f"a value held fixed ({held_text}: --fix) " if held_text else "")
            + "or a faulty channel")
    _explain_undetermined(model, result, eqs, scale_name)
    return result


def body_misfit(model: SuspensionModel, eqs: BodyEquations,
                blocks: list[tuple[np.ndarray, np.ndarray, _SegmentEquations]],
                theta: FloatArray) -> dict[str, tuple[float, float]]:
    """Body rows whose in-band equation error is clearly more than measurement noise:
    ``coordinate -> (ratio, share)``, the error power over ``sum_i theta_i^2 N_i`` from the
    channels' noise floors above :data:`~estimator.identify.misfit.MISFIT_FLOOR` and the
    excess over the held terms' power above :data:`~estimator.identify.misfit.MISFIT_SHARE`
    (``blocks``: :func:`_solve`'s; ``theta``: every column, in :attr:`BodyEquations.names` order).
    """
    n_rows = len(eqs.rows)
    err = np.zeros(n_rows)
    noise = np.zeros(n_rows)
    signal = np.zeros(n_rows)
    for _, y, s in blocks:
        err += np.sum(np.abs(s.X @ theta) ** 2, axis=1)
        noise += np.sum(s.noise @ (theta ** 2), axis=1)
        signal += np.sum(np.abs(y) ** 2, axis=1)
    out = {}
    for r, j in enumerate(eqs.rows):
        if not (noise[r] > 0.0 and signal[r] > 0.0):
            continue
        ratio = float(err[r] / noise[r])
        share = float((err[r] - noise[r]) / signal[r])
        if ratio > MISFIT_FLOOR and share > MISFIT_SHARE:
            out[model.coords[j]] = (ratio, share)
    return out


def _real(z: np.ndarray) -> np.ndarray:
    """Complex equations (..., p) or (...,) flattened and stacked as real then imaginary parts."""
    flat: np.ndarray = z.reshape(-1, z.shape[2]) if z.ndim == 3 else z.reshape(-1)
    return np.concatenate([flat.real, flat.imag])


def _rms_residual(model: SuspensionModel, eqs: BodyEquations,
                  blocks: list[tuple[np.ndarray, np.ndarray, _SegmentEquations]],
                  theta: FloatArray, values: Mapping[str, float]) -> dict[str, float]:
    """In-band RMS equation error of each body row in its acceleration channel's unit (Parseval
    over the windowed bins, divided by the row's mass or inertia).
    """
    M = model.matrices(dict(model.defaults(), **dict(values)))[0]
    num = np.zeros(len(eqs.rows))
    den = 0.0
    for A, y, s in blocks:
        e = y - A @ theta
        if eqs.shift:
            e = e / (1j * s.omega[None, :]) ** eqs.shift
        num += 2.0 * np.sum(np.abs(e) ** 2, axis=1) / s.T
        den += s.T * 35.0 / 128.0
    out = {}
    for r, j in enumerate(eqs.rows):
        out[f"{model.coords[j]}_ddot"] = float(math.sqrt(num[r] / den) / abs(M[j, j]))
    return out


def _explain_undetermined(model: SuspensionModel, result: IdentResult, eqs: BodyEquations,
                          scale_name: str) -> None:
    """Warnings naming each free parameter the record leaves undetermined, and why."""
    und = result.undetermined or []
    if not und:
        return
    in_eq = [n for n in und if n in eqs.names]
    outside = [n for n in und if n not in eqs.names]
    if scale_name:
        ratio = ", ".join(f"{n}/{scale_name}" for n in eqs.names if n != scale_name)
        result.warnings.append(
            f"not identifiable: the body equations are homogeneous, so they determine only "
            f"the ratios {ratio}; hold one of {', '.join(eqs.names)} (--fix, e.g. a weighed "
            f"body mass or a spring's rate) to scale them (values shown at {scale_name} = "
            f"{result.params[scale_name]:.6g} {model.spec(scale_name).unit}, its given value)")
        in_eq = [n for n in in_eq if n != scale_name and n not in eqs.names]
    if in_eq:
        result.warnings.append(f"not identifiable: {', '.join(in_eq)}: the record does not "
                               "determine them (too little excitation in the band or a "
                               "channel missing); values shown are not estimates")
    if outside:
        result.warnings.append(
            f"not identifiable with the road unknown: {', '.join(outside)} (they act only "
            "through the wheels' equations, which hold the unmeasured road); values shown "
            "are the given ones, not estimates; hold them (--fix) or measure the road")


def is_free_response(meas: Measurement) -> bool:
    """Whether the record is a free response: largest motion at the start, decayed by the end."""
    n = meas.t.size
    if n < 40 or not meas.measured:
        return False
    blocks = 20
    verdicts = []
    for v in meas.measured.values():
        x = np.asarray(v, dtype=float)
        if np.count_nonzero(np.isfinite(x)) < n // 2:
            continue
        x = x - np.nanmedian(x[-max(1, n // 5):])
        parts = np.array_split(x, blocks)
        rms = np.array([math.sqrt(float(np.nanmean(p * p))) if np.any(np.isfinite(p)) else 0.0
                        for p in parts])
        peak = float(rms.max())
        if peak == 0.0:
            continue
        tail = float(np.sqrt(np.nanmean(x[-max(1, n // 5):] ** 2)))
        verdicts.append(rms[0] >= 0.5 * peak and tail < 0.2 * peak)
    return bool(verdicts) and all(verdicts)


def resolve_road(model: SuspensionModel, meas: Measurement, requested: str | None
                 ) -> tuple[str, Measurement, list[str]]:
    """The road mode a record is fitted in, the record as fitted, and what was chosen.

    Parameters
    ----------
    model : SuspensionModel
    meas : Measurement
    requested : {"measured", "zero", "unknown"} or None
        ``--road``; ``None`` chooses ``measured`` with road columns, else ``zero`` for a
        free response (:func:`is_free_response`) and ``unknown`` for driving data.

    Returns
    -------
    mode : str
    meas : Measurement
        ``meas`` itself, or a copy without its road columns.
    warnings : list of str

    Raises
    ------
    UsageError
        ``measured`` on a record without road columns, or an unknown mode.
    """
    has_road = any(r in meas.road for r in model.roads)
    warnings: list[str] = []
    if requested is not None and requested not in ROAD_MODES:
        raise UsageError(f"--road: expected one of {', '.join(ROAD_MODES)}, got {requested!r}")
    if requested is None:
        if has_road:
            return "measured", meas, warnings
        mode = "zero" if is_free_response(meas) else "unknown"
        if mode == "zero":
            warnings.append("no road column and the motion decays from the start: fitted as a "
                            "free response with no road input (--road zero); give --road "
                            "unknown if a road moved the car")
        else:
            warnings.append("no road column and the motion does not decay (driving data): the "
                            "road under the tyres is unknown (--road unknown): identifying what "
                            "body accelerations and ride heights determine; give --road zero "
                            "for a free response")
    else:
        mode = requested
    if mode == "measured":
        if not has_road:
            raise UsageError(f"--road measured: {meas.source or 'the record'} has no road "
                             f"column; expected {', '.join(model.roads)} (or give --road "
                             "unknown for driving data, --road zero for a free response)")
        return mode, meas, warnings
    if has_road:
        warnings.append(f"--road {mode}: the record's road column(s) "
                        f"{', '.join(r for r in model.roads if r in meas.road)} not used")
    return mode, replace(meas, road={}), warnings
