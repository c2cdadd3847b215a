"""Fast simulation of a linear model plus physical effect terms (exponential integrator).

The model is ``x' = A x + B u + B_f Q(x, u)``, ``Q = sum_sites b * phi(s, s')``. The road is
a first-order hold absorbed by ``z = x - B_v r``; each site force is interpolated linearly over
the step (ETD2 predictor-corrector ``z_p = Phi z_k + G0 r_k + G1 r_k+1 + (F0 + F1) phi_k``,
``z_k+1 = z_p + F1 (phi(z_p) - phi_k)``): the linear part exact, the effect term second-order
accurate. The time loop is Python generated and unrolled for the model's size.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np
from suspid.errors import UsageError
from suspid.models.base import AffinePieces, FloatArray, SuspensionModel
from suspid.simulate import (foh_expm, foh_weights, mass_inverse, pack_channels, road_matrix,
                             state_matrices, uniform_step)

#: scalar force law at one site: ``phi(s, s_dot) -> force`` (N)
Law = Callable[[float, float], float]


class SiteLike(Protocol):
    """Where a force acts (:class:`suspid.models.base.Site`)."""

    g: FloatArray
    gr: FloatArray
    b: FloatArray


class ForceTerm(Protocol):
    """A physical effect as the simulator sees it (:class:`suspid.effects.PhysicalEffect`)."""

    def sites(self, model: SuspensionModel, p: Mapping[str, float]) -> Sequence[Any]:
        """Sites of ``model`` where the force acts (:class:`SiteLike` objects)."""
        ...

    def law(self, site: Any, base: Mapping[str, float]) -> Law:
        """Scalar force law at ``site`` for base parameters ``base``."""
        ...


@functools.lru_cache(maxsize=16)
def _kernel(n: int, nq: int, S: int) -> Callable:
    """Generate the unrolled time loop for ``n`` states, ``nq`` coordinates and ``S`` sites."""
    L: list[str] = []
    a = L.append
    a("def kernel(P, D, F, F1, AP, AV, CP, CV, laws, z, N):")
    a("    " + ", ".join(f"p{i}_{j}" for i in range(n) for j in range(n)) + ", = P")
    for s in range(S):
        a("    " + ", ".join(f"f{s}_{i}" for i in range(n)) + f", = F[{s}]")
        a("    " + ", ".join(f"g{s}_{i}" for i in range(n)) + f", = F1[{s}]")
        a("    " + ", ".join(f"ap{s}_{i}" for i in range(nq)) + f", = AP[{s}]")
        a("    " + ", ".join(f"av{s}_{i}" for i in range(nq)) + f", = AV[{s}]")
        a(f"    cp{s} = CP[{s}]; cv{s} = CV[{s}]; law{s} = laws[{s}]")
    a("    " + ", ".join(f"z{i}" for i in range(n)) + ", = z")
    a(f"    Z = [0.0] * (N * {n})")
    a(f"    PH = [0.0] * (N * {max(S, 1)})")
    for i in range(n):
        a(f"    Z[{i}] = z{i}")

    def site_eval(s: int, idx: str, var: str, target: str) -> str:
        pos = " + ".join(f"ap{s}_{i}*{var}{i}" for i in range(nq))
        vel = " + ".join(f"av{s}_{i}*{var}{nq + i}" for i in range(nq))
        return f"{target} = law{s}({pos} + cp{s}[{idx}], {vel} + cv{s}[{idx}])"

    for s in range(S):
        a("    " + site_eval(s, "0", "z", f"h{s}"))
        a(f"    PH[{s}] = h{s}")
    a("    for k in range(N - 1):")
    a(f"        b = k * {n}")
    for i in range(n):
        terms = [f"p{i}_{j}*z{j}" for j in range(n)] + [f"D[b + {i}]"]
        terms += [f"f{s}_{i}*h{s}" for s in range(S)]
        a(f"        y{i} = " + " + ".join(terms))
    if S:
        for s in range(S):
            a("        " + site_eval(s, "k + 1", "y", f"e{s}"))
            a(f"        e{s} = e{s} - h{s}")
        for i in range(n):
            a(f"        z{i} = y{i} + " + " + ".join(f"g{s}_{i}*e{s}" for s in range(S)))
        for s in range(S):
            a("        " + site_eval(s, "k + 1", "z", f"h{s}"))
            a(f"        PH[(k + 1) * {S} + {s}] = h{s}")
    else:
        for i in range(n):
            a(f"        z{i} = y{i}")
    a(f"        b = b + {n}")
    for i in range(n):
        a(f"        Z[b + {i}] = z{i}")
    a("    return Z, PH")
    ns: dict = {}
    exec("\n".join(L), ns)  # noqa: S102 - generated from integers only
    return ns["kernel"]


@dataclass
class _Setup:
    """Discretisation of one parameter set (cached between calls with equal inputs)."""

    A: FloatArray
    B: FloatArray
    Bv: FloatArray
    Phi: FloatArray
    G0: FloatArray
    G1: FloatArray
    F0: FloatArray  # (n, S)
    F1: FloatArray  # (n, S)
    Bfs: FloatArray  # (n, S) continuous input direction of each site force


def _modal_weights(A: FloatArray, Bw: FloatArray, h: float
                   ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """``Phi`` and FOH input weights from the eigen-decomposition of ``A`` (None if defective)."""
    try:
        lam, V = np.linalg.eig(A)
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > 1e8:
        return None
    E, g0, g1 = foh_weights(lam, h)
    VB = Vinv @ Bw
    Phi = np.real((V * E[None, :]) @ Vinv)
    W0 = np.real((V * g0[None, :]) @ VB)
    W1 = np.real((V * g1[None, :]) @ VB)
    return Phi, W0, W1


def _discretise(model: SuspensionModel, p: Mapping[str, float], sites: Sequence[SiteLike],
                h: float, affine: AffinePieces | None = None) -> _Setup:
    """Discretise the linear part and the site forces' input directions for step ``h`` (s)."""
    A, B = state_matrices(model, p, affine)
    Minv = mass_inverse(model, p, affine)
    n = model.n_states
    nq = len(model.coords)
    nr = len(model.roads)
    Br, Bv = B[:, :nr], B[:, nr:]
    Bz = A @ Bv + Br
    S = len(sites)
    Bfs = np.zeros((n, S))
    for j, site in enumerate(sites):
        Bfs[nq:, j] = Minv @ site.b
    Bw = np.hstack([Bz, Bfs])
    modal = _modal_weights(A, Bw, h)
    Phi, W0, W1 = modal if modal is not None else foh_expm(A, Bw, h)
    return _Setup(A, B, Bv, Phi, W0[:, :nr], W1[:, :nr], W0[:, nr:], W1[:, nr:], Bfs)


def simulate_effects(model: SuspensionModel, params: Mapping[str, float],
                     effects: Sequence[ForceTerm], t: FloatArray,
                     road: Mapping[str, FloatArray] | None = None, x0: FloatArray | None = None,
                     substeps: int = 1, U: FloatArray | None = None,
                     affine: AffinePieces | None = None) -> dict[str, FloatArray]:
    """Simulate ``model`` with physical ``effects`` on a uniform time grid.

    ``model`` is the linear base model (its ``extra_force`` ignored), ``params`` its parameters
    (SI), ``t`` uniform sample times (s; UsageError otherwise); ``road``, ``x0``, ``affine`` and
    the result as for :func:`suspid.simulate.simulate`. ``substeps``: internal steps per sample
    interval; ``U``: precomputed :func:`suspid.simulate.road_matrix` rows.
    """
    t = np.asarray(t, dtype=float)
    p = dict(params)
    if substeps < 1:
        raise UsageError(f"substeps must be >= 1, got {substeps}")
    h = uniform_step(t)
    if h is None:
        raise UsageError("fast nonlinear simulation needs uniformly spaced samples")
    if U is None:
        U = road_matrix(model, t, road)
    n = model.n_states
    nq = len(model.coords)
    nr = len(model.roads)
    N = t.size
    if substeps > 1:
        tf = t[0] + np.arange((N - 1) * substeps + 1) * (h / substeps)
        Uf = np.column_stack([np.interp(tf, t, U[:, j]) for j in range(U.shape[1])])
    else:
        tf, Uf = t, U
    Nf = tf.size
    sites: list[SiteLike] = []
    laws: list[Law] = []
    for e in effects:
        for site in e.sites(model, p):
            sites.append(site)
            laws.append(e.law(site, p))
    st = _discretise(model, p, sites, h / substeps, affine)
    r = Uf[:, :nr]
    D = r[:-1] @ st.G0.T + r[1:] @ st.G1.T  # (Nf-1, n)
    x0v = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    z0 = x0v - st.Bv @ r[0]
    S = len(sites)
    AP, CP, CV = [], [], []
    for site in sites:
        ap = np.concatenate([site.g, np.zeros(nq)])
        av = np.concatenate([np.zeros(nq), site.g])
        AP.append(site.g.tolist())  # the rate has the same direction as the position
        CP.append((r @ (ap @ st.Bv) + r @ site.gr).tolist())
        CV.append((r @ (av @ st.Bv) + Uf[:, nr:] @ site.gr).tolist())
    kern = _kernel(n, nq, S)
    Zl, PHl = kern(st.Phi.ravel().tolist(), D.ravel().tolist(),
                   (st.F0 + st.F1).T.tolist(), st.F1.T.tolist(), AP, AP, CP, CV, laws,
                   z0.tolist(), Nf)
    Z = np.asarray(Zl).reshape(Nf, n)[::substeps]
    PH = np.asarray(PHl).reshape(Nf, max(S, 1))[::substeps, :S]
    X = Z + U[:, :nr] @ st.Bv.T
    acc = X @ st.A[nq:].T + U @ st.B[nq:].T + PH @ st.Bfs[nq:].T
    return pack_channels(model, X, acc, U, params)


__all__ = ["simulate_effects", "ForceTerm", "SiteLike", "Law"]
