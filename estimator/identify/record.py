"""One record identified as ``suspid identify`` does it, the offset check included.

``suspid identify``, each drive of ``suspid fleet`` and ``suspid diagnose``'s
offset-corrected fit call :func:`identify_record`: the data-driven start, the check for
a constant road or position offset at it (:func:`check_offset`), the offset removed
(default) or kept, then :func:`~estimator.identify.multistart.fit_from_starts`.
"""
from __future__ import annotations

from dataclasses import dataclass

from estimator.choices import OFFSET_MODES
from estimator.identify.offset import Offset, find_offset, on_record
from estimator.identify.params import Parameters
from estimator.identify.problem import OutputErrorProblem
from estimator.identify.result import IdentResult
from estimator.identify.solver import fit, too_little_data, withhold_estimates
from estimator.identify.multistart import fit_from_starts
from estimator.identify.start import StartEstimate, estimate_start
from suspid.errors import UsageError


#: evaluations per free parameter shared by every start of one record when no ``maxfev``
#: is given (a converging fit takes a few hundred)
RECORD_MAXFEV = 1200


@dataclass
class OffsetCheck:
    """The offset check of a record: the constant road or position offsets found, and the
    data-driven start (blind to a constant level; ``None`` when not computed) it was made at.
    """

    offset: Offset | None
    estimate: StartEstimate | None


def check_offset(problem: OutputErrorProblem, params: Parameters, *,
                 data_start: bool = True) -> OffsetCheck:
    """Look for a constant road or position offset in ``problem``'s record, at the
    data-driven start (``data_start``) or else at ``params``' values.
    """
    est = estimate_start(problem, params) if data_start and params.free else None
    offset = find_offset(problem, {**params.valuesdict(), **(est.values if est else {})})
    return OffsetCheck(offset, est)


def identify_record(problem: OutputErrorProblem, params: Parameters, *, restarts: int = 6,
                    maxfev: int | None = None, polish: bool = True, multistart: int = 4,
                    data_start: bool = True, keep_init: bool = True, offset: str = "remove",
                    check: OffsetCheck | None = None
                    ) -> tuple[IdentResult, OutputErrorProblem]:
    """Identify ``params`` from ``problem``'s record as ``suspid identify`` does.

    Parameters
    ----------
    problem : OutputErrorProblem
        The record as read, and its cost.
    params : Parameters
        Fixed values (SI) and the given start of the free parameters.
    restarts, maxfev, polish, multistart
        Settings of every :func:`~estimator.identify.solver.fit`.
    data_start, keep_init
        Start from the data-driven estimate too, and from ``params`` (:func:`fit_from_starts`).
    offset : {"remove", "keep"}
        Subtract a found offset before the fit, or fit the record as it is; either way the
        first warning names it.
    check : OffsetCheck, optional
        The record's :func:`check_offset` when already made.

    Returns
    -------
    result : IdentResult
        The identification; ``result.offset`` holds a found offset.
    fitted : OutputErrorProblem
        The problem the fit ran on (``problem``, or the record with the offset removed).
    """
    if offset not in OFFSET_MODES:
        raise UsageError(f"offset: expected one of {', '.join(OFFSET_MODES)}, got {offset!r}")
    short = too_little_data(problem, len(params.free))
    if short is not None:  # no offset can be told from so few values either
        found = OffsetCheck(None, None)
    else:
        found = check if check is not None else check_offset(problem, params,
                                                             data_start=data_start)
    fitted = problem
    if found.offset is not None and offset == "remove":
        fitted = on_record(problem, found.offset.remove(problem.meas))
    removed = fitted is not problem
    # the corrected record gets its own estimate (its cost and checks are the record's)
    est = None if removed else found.estimate

    # without a budget, all starts of the record share RECORD_MAXFEV per free parameter
    left = [maxfev if maxfev is not None else RECORD_MAXFEV * max(1, len(params.free))]

    def run(start: Parameters) -> IdentResult:
        res = fit(fitted, start, restarts=restarts, maxfev=max(1, left[0]), polish=polish,
                  multistart=multistart)[0]
        if maxfev is None:
            left[0] -= res.nfev
        return res

    result = fit_from_starts(fitted, params, run, data_start=data_start, keep_init=keep_init,
                             estimate=est)
    if found.offset is not None:
        result.warnings.insert(0, found.offset.warning(problem.model, removed))
        result.offset = found.offset.to_json(removed)
        n_values = len(result.offset.get("values", {})) if removed else 0
        short = too_little_data(problem, len(params.free), n_values)
        if short is not None:
            withhold_estimates(result, short)
    return result, fitted


__all__ = ["OFFSET_MODES", "OffsetCheck", "check_offset", "identify_record"]
