"""The identifier: output-error Nelder–Mead fits of the suspension models.

``fit(problem, params)`` is the entry point; :class:`OutputErrorProblem` holds the data and
the cost; :class:`Parameters` the values, ``vary`` flags and bounds.
"""
from estimator.identify.solver import fit, finish, jacobian_log, minimize_log
from estimator.identify.params import Parameter, Parameters
from estimator.identify.problem import COSTS, OutputErrorProblem
from estimator.identify.result import IdentResult
from estimator.identify.multistart import fit_from_starts, resolve_twin, twin_of
from estimator.identify.start import cold_start, data_driven_start, estimate_start

__all__ = ["fit", "finish", "jacobian_log", "minimize_log", "Parameter", "Parameters",
           "COSTS", "OutputErrorProblem", "IdentResult", "cold_start", "data_driven_start", "estimate_start",
           "fit_from_starts", "resolve_twin", "twin_of"]
