"""The starts policy: the fit from the data-driven start, the given start and the twin.

:func:`fit_from_starts` runs the fit from each start it needs, keeps the lowest cost and
rejects a result the starts do not confirm (run-away, ambiguous, unconfirmed, misfit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from estimator.identify.misfit import (EXACT_FIT, NOISE_FLOOR, misfit_channels, misfit_warning,
                                       noise_floor_ratio)
from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.profile import SIGMAS, apply_bands
from estimator.identify.result import IdentResult
from estimator.identify.start import StartEstimate, estimate_start, kind_scaled_start
from suspid.models.base import Twin

#: normalised cost of the data-driven estimate above which the given start runs as well
POOR_ESTIMATE = 0.5
#: factor from its start and from the data-driven estimate beyond which a parameter ran away
RUNAWAY = 100.0
#: relative distance, or distance in standard errors, within which two fits are the same point
CONFIRM_TOL = 0.01
CONFIRM_SIGMA = 0.3
#: factor by which a confirmed parameter, moved alone, must raise the cost by more than 3 sigma
CONFIRM_SPAN = 10.0
#: factor beyond which two noisy fits at costs within the noise are reported as undecided
AGREE = 10.0
#: factor within which the fit from the data-driven start must agree with the given start in
#: every free parameter for the noise-floor rule to skip the given start (the whiteness test
#: misses a misfit of a few per cent of a noise-dominated residual; docs/performance.md)
SKIP_AGREE = 30.0
#: factor by which some kind's common factor must leave 1 for the rescaled start to run
KIND_MIN_FACTOR = 3.0
#: factor by which one twin fit must fit the channels outside the cost better to be chosen
TWIN_DECIDE = 4.0


def _exact(problem: OutputErrorProblem, res: IdentResult) -> bool:
    """``res`` explains the record exactly (a noise-free record)."""
    return bool(problem.normalized_ss(res.params) < EXACT_FIT)


def _at_noise_floor(problem: OutputErrorProblem, res: IdentResult) -> bool:
    """``res`` leaves only white measurement noise on a noisy record (not an exact fit)."""
    return not _exact(problem, res) and noise_floor_ratio(problem, res.params) <= NOISE_FLOOR


def _positive(*xs: float) -> bool:
    return all(math.isfinite(x) and x > 0 for x in xs)


def _far(a: Mapping[str, float], b: Mapping[str, float], free: list[str],
         factor: float) -> list[str]:
    """Free parameters in which ``a`` and ``b`` differ by more than ``factor`` (or are not positive)."""
    return [k for k in free if not _positive(float(a[k]), float(b[k]))
            or abs(math.log(float(a[k]) / float(b[k]))) > math.log(factor)]


def _noise_step(problem: OutputErrorProblem, p: Mapping[str, float], nfree: int
                ) -> tuple[float, float] | None:
    """The normalised cost at ``p`` and the rise a 3-sigma step of one parameter costs,
    ``SIGMAS**2 * ss / (N - nfree)`` (``None`` where not defined)."""
    ss = problem.normalized_ss(p)
    try:
        n = int(problem.residual_vector(p).size)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    if not math.isfinite(ss) or n <= nfree:
        return None
    return ss, SIGMAS ** 2 * ss / (n - nfree)


def _within_noise(problem: OutputErrorProblem, best: IdentResult, other: IdentResult,
                  nfree: int) -> bool:
    """``other``'s cost exceeds ``best``'s by less than 3 sigma of the noise (noisy records)."""
    if _exact(problem, best):
        return False
    ss_other = problem.normalized_ss(other.params)
    step = _noise_step(problem, best.params, nfree)
    return step is not None and math.isfinite(ss_other) and ss_other - step[0] <= step[1]


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _plausibility(res: IdentResult, free: list[str], start: Mapping[str, float],
                  data: Mapping[str, float]) -> list[tuple[str, str]]:
    """Free parameters at which ``res`` sits at an absurd place, each with the reason."""
    out = []
    for k in free:
        v = res.params[k]
        if not _positive(v):
            out.append((k, f"{k} reached {v!r}, not a finite positive value"))
            continue
        far_start = k not in start or abs(math.log(v / start[k])) > math.log(RUNAWAY)
        far_data = k not in data or abs(math.log(v / data[k])) > math.log(RUNAWAY)
        if far_start and far_data:
            ref = f" and from the data-driven estimate {data[k]:.4g}" if k in data else ""
            if k not in start and k not in data:
                continue  # neither a given start nor a usable estimate to compare with
            st = f"its start {start[k]:.4g}" if k in start else "its start"
            out.append((k, f"{k} ran to {v:.4g}, more than {RUNAWAY:g}x from {st}{ref}; "
                           "the record does not support it"))
    return out


def _same(a: IdentResult, b: IdentResult, k: str) -> bool:
    """``b``'s value of ``k`` is ``a``'s: within ``CONFIRM_TOL`` or ``CONFIRM_SIGMA`` standard errors."""
    x, y = float(a.params[k]), float(b.params[k])
    if not _positive(x, y):
        return False
    se = a.stderr.get(k)
    tol = max(CONFIRM_TOL, CONFIRM_SIGMA * se / x if se is not None and math.isfinite(se) else 0.0)
    return abs(y / x - 1.0) <= tol


def _confirmed(problem: OutputErrorProblem, res: IdentResult, start: Mapping[str, float],
               k: str, free: list[str],
               others: Sequence[tuple[str, Mapping[str, float], IdentResult]]) -> str | None:
    """Label of another start that confirms ``res``'s value of ``k`` (``None`` if none does).

    Confirmed: a second start, begun more than ``KIND_MIN_FACTOR`` x away in ``k``, reached
    the same fit, and moving ``k`` alone ``CONFIRM_SPAN`` x up and down lowers the cost
    neither way and raises it one way by more than 3 sigma of the noise (the record bounds
    it on at least one side; a drift along a flat direction leaves the cost unchanged).
    """
    v = res.params[k]
    if not _positive(v):
        return None
    label = None
    for lab, s, r in others:
        if r is res or k not in s or k not in start \
                or abs(math.log(s[k] / start[k])) <= math.log(KIND_MIN_FACTOR):
            continue
        if all(_same(res, r, j) for j in free):
            label = lab
            break
    if label is None:
        return None
    step = _noise_step(problem, res.params, len(free))
    if step is None:
        return None
    ss, rise = step[0], max(step[1], EXACT_FIT)
    bounded = False
    for f in (CONFIRM_SPAN, 1.0 / CONFIRM_SPAN):
        moved = dict(res.params)
        moved[k] = v * f
        c = problem.normalized_ss(moved)
        if math.isfinite(c) and c < ss - rise:
            return None  # not even a minimum along k
        bounded = bounded or (math.isfinite(c) and c - ss > rise)
    return label if bounded else None


def _reject(res: IdentResult, warnings: list[str], misfit: bool = False) -> None:
    """Report ``res`` as no success and (unless a ``misfit``) not identifiable, with the reasons."""
    res.success = False
    res.identifiable = res.identifiable and misfit
    for entry in res.starts or []:
        if entry.get("chosen"):
            entry["success"] = False
    res.warnings += warnings


# an absurd parameter set overflows the response: an infinite cost, not a RuntimeWarning
@np.errstate(over="ignore", invalid="ignore", divide="ignore")
def fit_from_starts(problem: OutputErrorProblem, params: Parameters,
                    run: Callable[[Parameters], IdentResult], *, data_start: bool = True,
                    keep_init: bool = True, init_fallback: bool = True,
                    intervals: bool = True, estimate: StartEstimate | None = None) -> IdentResult:
    """Run the fit ``run`` from the data-driven start and from ``params``; keep the best.

    The given start is skipped when the fit from the data-driven start is clean, ``params``
    begins at no lower cost, and that fit either leaves only white noise
    (:func:`noise_floor_ratio` at most ``NOISE_FLOOR``) within ``SKIP_AGREE`` x of
    ``params``, or explains the record exactly from an estimate below ``POOR_ESTIMATE``.
    Without a clean answer, the given start rescaled per kind (:func:`kind_scaled_start`)
    runs as a further start when it begins lower and moves some kind by more than
    ``KIND_MIN_FACTOR``; a parameter that ran away gets a confirming start; a twin fit is
    resolved (:func:`resolve_twin`).

    Parameters
    ----------
    problem : OutputErrorProblem
        The whole record.
    params : Parameters
        Fixed values and the given start of the free parameters.
    run : callable
        ``run(start) -> IdentResult``: one identification from ``start``.
    data_start : bool
        Compute the data-driven start (:func:`estimate_start`) and run from it.
    keep_init : bool
        Also consider ``params`` as a start (always when there is no data-driven start).
    init_fallback : bool
        With ``keep_init`` false, still run ``params`` (the defaults) when the data-driven
        start gives no clean answer.
    intervals : bool
        Attach the 3-sigma bands (:func:`~estimator.identify.profile.apply_bands`).
    estimate : StartEstimate, optional
        The data-driven start when already computed.

    Returns
    -------
    IdentResult
        The lowest-cost result with ``starts``, ``data_start`` and the summed ``nfev``. It is
        neither a success nor identifiable when a parameter ran ``RUNAWAY`` x from its
        start and the estimate unconfirmed, when another start reached a fit ``AGREE`` x
        away at a cost within the noise, or when a noisy fit from the estimate is not
        confirmed by the given start (``unconfirmed result``); a misfit
        (:func:`misfit_channels`) is no success.
    """
    free = params.free
    est = (estimate if estimate is not None
           else estimate_start(problem, params) if data_start and free else None)
    runs: list[tuple[str, Parameters]] = []
    if est is not None and est.values:
        runs.append(("data", params.with_values(est.values)))
    if keep_init or not runs:
        runs.append(("init", params))
    at_start = [problem.normalized_ss(s.valuesdict()) for _, s in runs]
    data_vals = ({k: v for k, v in est.values.items() if k not in est.undetermined}
                 if est is not None else {})

    def usable(label: str, start: Parameters) -> dict[str, float]:
        """Start values to judge a run-away against (not the floor of an unusable estimate)."""
        return {k: start[k].value for k in free if label != "data" or k in data_vals}

    results: list[tuple[str, Parameters, IdentResult | None]] = []
    for i, (label, start) in enumerate(runs):
        done = [r for _, _, r in results if r is not None]
        # skipped: the fits so far are clean, exact or at the noise floor, and it begins no lower
        if done and all(r.success for r in done) and at_start[i] >= min(at_start[:i]) \
                and (est is not None
                     and est.cost < POOR_ESTIMATE and all(_exact(problem, r) for r in done)
                     or all(_at_noise_floor(problem, r) for r in done)
                     and not any(_far(r.params, start.valuesdict(), free, SKIP_AGREE)
                                 for r in done)) \
                and not _plausibility(done[0], free, usable(runs[0][0], runs[0][1]), data_vals):
            results.append((label, start, None))
            continue
        results.append((label, start, run(start)))
    issues = _issues(problem, results, at_start, free, data_vals, usable)

    def add(label: str, start: Parameters, cost: float | None = None) -> _Issues:
        """Run a further start and judge every fit again."""
        runs.append((label, start))
        at_start.append(problem.normalized_ss(start.valuesdict()) if cost is None else cost)
        results.append((label, start, run(start)))
        return _issues(problem, results, at_start, free, data_vals, usable)

    def unclean(issues: _Issues) -> bool:
        """No clean answer: rejected, no success, or a residual that is not white noise."""
        return issues.rejected or not issues.res.success or not _exact(problem, issues.res) \
            and noise_floor_ratio(problem, issues.res.params) > NOISE_FLOOR

    if init_fallback and not any(label == "init" for label, _ in runs) and unclean(issues):
        issues = add("init", params)  # no start given, no clean answer: the defaults
    if unclean(issues):
        scaled = (kind_scaled_start(problem, params)
                  if any(label == "init" for label, _ in runs) else None)
        if scaled is not None and scaled[2] < min(at_start) and any(
                abs(math.log(f)) > math.log(KIND_MIN_FACTOR) for f in scaled[1].values()):
            issues = add("scaled", scaled[0], scaled[2])
    if issues.runaway and not issues.ambiguous and not issues.unconfirmed and _positive(
            *(issues.res.params[k] for k in issues.runaway)):
        # a start next to the fit, the run-away parameters moved CONFIRM_SPAN x back: it
        # returns to the fit if the cost has a minimum there
        ref = usable(*issues.best[:2])
        moved = {k: v if k not in issues.runaway else
                 v * (CONFIRM_SPAN if ref.get(k, v) > v else 1.0 / CONFIRM_SPAN)
                 for k, v in ((k, float(issues.res.params[k])) for k in free)}
        issues = add("confirm", params.with_values(moved))
    res = issues.res
    twin_warning = None
    if not issues.rejected:
        res, twin_run, twin_warning = resolve_twin(problem, params, res, run)
        if twin_run is not None:
            runs.append(("twin", twin_run[0]))
            at_start.append(problem.normalized_ss(twin_run[0].valuesdict()))
            results.append(("twin", *twin_run))
    ran = [(label, s, r) for label, s, r in results if r is not None]
    res.nfev = int(sum(r.nfev for _, _, r in ran))
    res.starts = []
    for (label, s, r), c0 in zip(results, at_start):
        entry: dict[str, Any] = {"start": label, "from": {k: float(s[k].value) for k in free},
                                 "cost_at_start": _finite(problem.seed_cost(c0 * problem.scale))}
        if r is None:
            entry.update({"cost": None,
                          "skipped": "the fit from the data-driven start is clean and "
                                     "explains the record down to white noise within "
                                     f"{SKIP_AGREE:g}x of this start, or exactly from a good "
                                     "estimate while this start begins at no lower cost"})
        else:
            entry.update({"cost": _finite(r.cost), "params": {k: float(r.params[k]) for k in free},
                          "success": bool(r.success), "chosen": r is res})
        res.starts.append(entry)
    if est is not None:
        res.data_start = ({"values": dict(est.values), "bandwidth_hz": est.bandwidth_hz,
                           "notes": list(est.notes)} if est.values
                          else {"reason": est.reason})
        if not est.values:
            res.warnings.append(f"no data-driven start: {est.reason}")
    if issues.bad:
        alts = ", ".join(f"{label} start: cost {r.cost:.4g}" for label, _, r in ran)
        _reject(res, [f"implausible result: {b}" for b in issues.bad]
                + [f"costs reached from each start: {alts}"])
    elif issues.rejected:
        _reject(res, issues.ambiguous or issues.unconfirmed)
    elif intervals:
        apply_bands(problem, res, free)
    if twin_warning is not None:
        res.warnings.append(twin_warning)
    misfit = misfit_channels(problem, res.params)
    if misfit:  # the model does not explain the record, however well the search converged
        _reject(res, [misfit_warning(misfit, {k: res.params[k] for k in params.fixed})], misfit=True)
    return res


def twin_of(problem: OutputErrorProblem, params: Parameters, p: Mapping[str, float]
            ) -> Twin | None:
    """The model's twin of ``p`` on the coordinates in ``problem``'s cost, or ``None``.

    ``None`` as well when a free value is not positive or the twin changes a fixed parameter.
    """
    model = problem.model
    measured = problem.measured_coords()
    if not _positive(*(p[k] for k in params.free)):
        return None
    tw = model.twin(p, measured)
    if tw is None or any(not math.isclose(tw.params[k], p[k], rel_tol=1e-12)
                         for k in params.fixed):
        return None
    return tw


def resolve_twin(problem: OutputErrorProblem, params: Parameters, res: IdentResult,
                 run: Callable[[Parameters], IdentResult]
                 ) -> tuple[IdentResult, tuple[Parameters, IdentResult] | None, str | None]:
    """``res`` or the fit ``run`` reaches from its twin (:func:`twin_of`), whichever is right.

    Returns the chosen result, ``(start, result)`` of the twin's fit (``None`` without a
    twin) and the warning naming the other fit when both are equally good.
    """
    tw = twin_of(problem, params, res.params)
    if tw is None:
        return res, None, None
    start = params.with_values({k: tw.params[k] for k in params.free})
    other = run(start)
    best, warning = _choose_twin(problem, res, other, tw)
    return best, (start, other), warning


def _choose_twin(problem: OutputErrorProblem, res: IdentResult, other: IdentResult,
                 tw: Twin) -> tuple[IdentResult, str | None]:
    """Choose between ``res`` and ``other``, the fit from the model's twin of ``res``.

    At equal costs (exact or within the noise) the measured channels outside the cost
    decide if one fits them ``TWIN_DECIDE`` times better, else the twin's rule
    (:attr:`Twin.rule`); a clearly lower cost wins outright. Returns the result and a
    warning naming the other (``None`` when the costs decided).
    """
    same = (_exact(problem, res) and _exact(problem, other)
            or _within_noise(problem, res, other, len(res.stderr)))
    if not same:
        return (other if other.cost < res.cost else res), None
    outside = [c for c in res.rms_residual
               if c not in problem.channels and c in other.rms_residual]

    def misfit(r: IdentResult) -> float:
        total = 0.0
        for c in outside:
            var = float(np.nanvar(problem.meas.measured[c]))
            total += r.rms_residual[c] ** 2 / var if var > 0 else 0.0
        return total

    a, b = misfit(res), misfit(other)
    if outside and max(a, b) > TWIN_DECIDE * min(a, b) and max(a, b) > EXACT_FIT:
        take_other = b < a
        why = f"as the channels outside the cost ({', '.join(outside)}) fit it better"
    else:
        take_other = tw.prefer
        why = f"by the rule: {tw.rule}"
    best, alt = (other, res) if take_other else (res, other)
    vals = ", ".join(f"{k} = {alt.params[k]:.6g}" for k in alt.stderr)
    return best, (f"two fits explain the record equally well (costs {res.cost:.6g} and "
                  f"{other.cost:.6g}): the cost cannot tell {tw.swapped}; the other fit is "
                  f"{vals}; this one is chosen {why}")


@dataclass
class _Issues:
    """The lowest-cost fit of :func:`fit_from_starts` and why it is no success (if so)."""

    best: tuple[str, Parameters, IdentResult]
    bad: list[str]
    ambiguous: list[str]
    unconfirmed: list[str]
    #: the free parameters behind ``bad`` (ran away, not confirmed by another start)
    runaway: list[str]

    @property
    def res(self) -> IdentResult:
        return self.best[2]

    @property
    def rejected(self) -> bool:
        return bool(self.bad or self.ambiguous or self.unconfirmed)


def _issues(problem: OutputErrorProblem,
            results: list[tuple[str, Parameters, IdentResult | None]], at_start: list[float],
            free: list[str], data_vals: Mapping[str, float],
            usable: Callable[[str, Parameters], dict[str, float]]) -> _Issues:
    """The lowest-cost fit of ``results`` and the reasons to reject it (nothing changed)."""
    ran = [(label, s, r) for label, s, r in results if r is not None]

    def key(item: tuple[str, Parameters, IdentResult]) -> float:
        c = item[2].cost
        return c if math.isfinite(c) else math.inf

    # a confirmation run only vouches for (or against) the fit it started next to
    best = min((item for item in ran if item[0] != "confirm"), key=key)
    res = best[2]
    start = usable(best[0], best[1])
    others = [(label, usable(label, s), r) for label, s, r in ran]
    flagged = [(k, why) for k, why in _plausibility(res, free, start, data_vals)
               if _confirmed(problem, res, start, k, free, others) is None]
    bad = [why for _, why in flagged]
    ambiguous: list[str] = []
    for label, _, r in ran:
        far = _far(res.params, r.params, free, AGREE) if r is not res else []
        if far and _within_noise(problem, res, r, len(free)):
            ks = ", ".join(f"{k} {res.params[k]:.4g} ({best[0]} start) against "
                           f"{r.params[k]:.4g} ({label} start)" for k in far)
            ambiguous.append(
                f"implausible result: the {best[0]} and {label} starts reached fits more than "
                f"{AGREE:g}x apart ({ks}) at costs {res.cost:.4g} and {r.cost:.4g}, within "
                f"{SIGMAS:g} sigma of the noise; the record does not decide between them")
    # a noisy fit from the estimate (or the rescaled start) while the given start's fit
    # failed: unconfirmed when far from the given start or begun at a higher cost
    unconfirmed: list[str] = []
    if best[0] in ("data", "scaled") and not _exact(problem, res):
        c_best = at_start[[label for label, _, _ in results].index(best[0])]
        what, origin, led = {
            "data": ("the data-driven start", "an estimate", "the record's estimate"),
            "scaled": ("the rescaled init start", "a rescaled start", "the rescaling"),
        }[best[0]]
        for (label, s, got), c0 in zip(results, at_start):
            if label != "init" or got is None or got.success:
                continue
            far = _far(res.params, s.valuesdict(), free, SKIP_AGREE)
            if far:
                ks = ", ".join(f"{k} {res.params[k]:.4g} against {s[k].value:.4g}" for k in far)
                why = f"lies more than {SKIP_AGREE:g}x from the {label} start ({ks})"
            elif c_best > c0:
                why = (f"comes from {origin} that began at a higher cost than the {label} "
                       f"start ({problem.seed_cost(c_best * problem.scale):.4g} against "
                       f"{problem.seed_cost(c0 * problem.scale):.4g})")
            else:
                continue
            unconfirmed.append(
                f"unconfirmed result: the fit from {what} {why} on a noisy "
                f"record, and the fit from the {label} start failed (cost {got.cost:.4g} "
                f"against {res.cost:.4g}); no second start reached it, so {led} may have "
                "led to a local minimum")
    return _Issues(best, bad, ambiguous, unconfirmed, [k for k, _ in flagged])
