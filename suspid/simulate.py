"""Simulation of the suspension models: :func:`simulate`, exact for the linear models (the
road a first-order hold (FOH), solved per sample in modal form with the road velocity absorbed
by ``z = x - B_v r``), and :func:`simulate_ode` (``solve_ivp`` on ``model.rhs``, for effect
terms and validation). Both return ``channel -> ndarray``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from suspid.errors import UsageError
from suspid.models.base import AffinePieces, FloatArray, SuspensionModel


def uniform_step(t: FloatArray, rtol: float = 1e-6) -> float | None:
    """The sample interval (s) if ``t`` is uniform (to ``rtol`` plus the rounding of epoch-second
    stamps), else ``None``."""
    if t.size < 2:
        return None
    d = np.diff(t)
    h = float((t[-1] - t[0]) / (t.size - 1))
    ulp = float(np.spacing(max(abs(float(t[0])), abs(float(t[-1])))))
    if h <= 0 or np.max(np.abs(d - h)) > rtol * h + 1e-12 + 4.0 * ulp:
        return None
    return h


def road_matrix(model: SuspensionModel, t: FloatArray,
                road: Mapping[str, FloatArray] | None) -> FloatArray:
    """Input rows ``U = [r..., r_dot...]`` (N, 2 n_roads); missing roads are zero, a missing
    ``_dot`` is :func:`numpy.gradient` of the road."""
    n = t.size
    nr = len(model.roads)
    U = np.zeros((n, 2 * nr))
    if not road:
        return U
    for i, name in enumerate(model.roads):
        if name in road and road[name] is not None:
            r = np.asarray(road[name], dtype=float)
            if r.shape != (n,):
                raise UsageError(f"road {name!r} has {r.size} samples, expected {n}")
            U[:, i] = r
            rd = road.get(f"{name}_dot")
            U[:, nr + i] = (np.asarray(rd, dtype=float) if rd is not None
                            else (np.gradient(r, t) if n > 2 else 0.0))
    return U


@dataclass
class Modal:
    """Modal form ``A = V diag(lam) V^-1`` of a linear model for one parameter set.

    One mode of each conjugate pair is kept and counts twice (``fac = 2``). The FOH recursion
    is ``w[k+1] = E w[k] + g0 s[k] + g1 s[k+1]`` with modal input ``s = V^-1 (A B_v + B_r) r``.
    """

    lam: np.ndarray  # kept eigenvalues (m,)
    V: np.ndarray  # kept eigenvectors (n, m)
    Vinv: np.ndarray  # matching rows of V^-1 (m, n)
    fac: FloatArray  # 1 for real modes, 2 for complex pairs (m,)
    Bz: FloatArray  # z-system input matrix (n, nr)
    Bv: FloatArray  # road-velocity input matrix (n, nr)
    A: FloatArray
    B: FloatArray


def state_matrices(model: SuspensionModel, p: Mapping[str, float],
                   affine: AffinePieces | None = None) -> tuple[FloatArray, FloatArray]:
    """``(A, B)`` at ``p``: from the affine pieces when they apply to ``p``, else the model."""
    if affine is not None and affine.matches(p):
        return affine.state_space(affine.theta(p))
    return model.state_space(p)


def mass_inverse(model: SuspensionModel, p: Mapping[str, float],
                 affine: AffinePieces | None = None) -> FloatArray:
    """``M(p)^-1`` (accelerations per unit generalised force): the pieces' when they apply."""
    if affine is not None and affine.Minv is not None and affine.matches(p):
        return affine.Minv
    return model.mass_inverse(p)


#: largest 1-norm condition number of the eigenvector matrix taken as diagonalisable
MODE_COND_MAX = 1e8


def modal_form(model: SuspensionModel, p: Mapping[str, float],
               affine: AffinePieces | None = None) -> Modal | None:
    """Eigen-decomposition of ``A`` for ``p`` (through ``affine`` when it applies), keeping the
    real eigenvalues and the positive-imaginary member of each pair; ``None`` if ``A`` is
    (nearly) defective (``V``'s 1-norm condition above ``MODE_COND_MAX``) or the eigenvalues
    do not pair up."""
    A, B = state_matrices(model, p, affine)
    nr = len(model.roads)
    Br, Bv = B[:, :nr], B[:, nr:]
    Bz = A @ Bv + Br
    try:
        lam, V = np.linalg.eig(A)
        Vinv = np.linalg.inv(V)
    except np.linalg.LinAlgError:  # non-finite A, no convergence or a singular V
        return None
    if not np.abs(V).sum(axis=0).max() * np.abs(Vinv).sum(axis=0).max() <= MODE_COND_MAX:
        return None
    lim = np.abs(lam).max()
    tol = 1e-12 * (lim if lim > 1.0 else 1.0)
    keep = np.flatnonzero(lam.imag >= -tol)
    is_real = np.abs(lam.imag[keep]) <= tol
    n_real = int(is_real.sum())
    # a real eigenvalue must have a real eigenvector; pairs must really pair up
    if n_real + 2 * (keep.size - n_real) != lam.size:
        return None
    Vk = V[:, keep]
    if n_real:
        Vk[:, is_real] = Vk[:, is_real].real
    return Modal(lam[keep], Vk, Vinv[keep], np.where(is_real, 1.0, 2.0), Bz, Bv, A, B)


def foh_weights(lam: np.ndarray, h: float | np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact first-order-hold discretisation of the modes ``w' = lam w + b(t)``.

    With ``b`` linear between two samples, ``w1 = E w0 + g0 b0 + g1 b1``: ``E = exp(lam h)``,
    ``g1 = int_0^h e^{lam (h - s)} s / h ds``, ``g0 = int_0^h e^{lam (h - s)} ds - g1`` (s), for
    eigenvalues ``lam`` (1/s) broadcast against the step(s) ``h`` (s). Where ``|lam h| < 1e-3``
    the closed forms cancel: a fourth-order series is used there.
    """
    z = lam * h
    E = np.exp(z)
    small = np.abs(z) < 1e-3
    if not small.any():  # the common case: the closed forms alone
        em1 = E - 1.0
        i1 = (em1 - z) / (z * z) * h
        return E, em1 / z * h - i1, i1
    zs = np.where(small, 1.0, z)
    i0 = np.where(small, h * (1 + z / 2 + z * z / 6 + z ** 3 / 24), (E - 1) / zs * h)
    i1 = np.where(small, h * (0.5 + z / 6 + z * z / 24 + z ** 3 / 120),
                  (E - 1 - zs) / (zs * zs) * h)
    return E, i0 - i1, i1


_SCAN_BLOCK = 32


def first_order_scan(E: np.ndarray, d: np.ndarray, w0: np.ndarray,
                     block: int = _SCAN_BLOCK) -> np.ndarray:
    """Solve ``w[k+1] = E * w[k] + d[k]`` for every column at once (``E`` (m,), ``d`` (n, m),
    ``w0`` (m,)); returns ``w[1:]``.

    Blocked scan: inside a block of ``L`` samples a lower-triangular Toeplitz product with
    ``E**0 .. E**(L-1)``; the block starts follow recursively with ``E**L``. Only powers up to
    ``E**L`` appear, so it is as stable as the plain recursion (and needs no scipy.signal).
    """
    n, m = d.shape
    if n == 0:
        return np.empty((0, m), dtype=complex)
    L = min(block, n)
    nb = -(-n // L)
    pw = np.empty((m, L + 1), dtype=complex)
    pw[:, 0] = 1.0
    for k in range(1, L + 1):
        pw[:, k] = pw[:, k - 1] * E
    j = np.arange(L)
    lag = j[:, None] - j[None, :]
    K = np.where(lag >= 0, pw[:, np.clip(lag, 0, L)], 0.0)  # (m, L, L), K[j, i] = E^(j-i)
    D = np.zeros((m, nb * L), dtype=complex)
    D[:, :n] = d.T
    P = np.matmul(D.reshape(m, nb, L), K.transpose(0, 2, 1))  # (m, nb, L) zero-start blocks
    if nb == 1:
        starts = w0[:, None]
    else:
        carry = first_order_scan(pw[:, L], P[:, :-1, L - 1].T, w0, block)  # (nb-1, m)
        starts = np.concatenate([w0[:, None], carry.T], axis=1)  # (m, nb)
    W = pw[:, None, 1:] * starts[:, :, None] + P  # (m, nb, L)
    return W.reshape(m, nb * L)[:, :n].T


def modal_trajectory(modal: Modal, h: float | FloatArray, r: FloatArray,
                     x0: FloatArray) -> np.ndarray:
    """Kept modal coordinates ``W`` (N, m) for road ``r`` (N, nr) and initial state ``x0``.

    ``h`` is the step (s) of a uniform grid, or the ``N - 1`` steps (s) of a non-uniform one
    (then stepped sample by sample). The states are ``x = Re(V W fac) + B_v r``.
    """
    N = r.shape[0]
    m = modal.lam.size
    z0 = x0 - modal.Bv @ r[0]
    w0 = modal.Vinv @ z0
    W = np.empty((N, m), dtype=complex)
    W[0] = w0
    if N > 1:
        steps = np.ndim(h) > 0
        if steps:
            E, g0, g1 = foh_weights(modal.lam[None, :], np.asarray(h, dtype=float)[:, None])
        else:
            E, g0, g1 = foh_weights(modal.lam, float(h))
        if np.any(r):
            S = r @ (modal.Vinv @ modal.Bz).T
            drive = g0 * S[:-1] + g1 * S[1:]
            if steps:
                w = w0
                for k in range(N - 1):
                    w = E[k] * w + drive[k]
                    W[k + 1] = w
            else:
                W[1:] = first_order_scan(E, drive, w0)
        else:
            W[1:] = (step_powers(E) if steps else powers(E, N))[1:] * w0[None, :]
    return W


def step_powers(E: np.ndarray) -> np.ndarray:
    """Running products ``prod_{j<k} E[j]`` (N, m) of per-step multipliers ``E`` (N-1, m)."""
    P = np.empty((E.shape[0] + 1, E.shape[1]), dtype=np.result_type(E, 1.0))
    P[0] = 1.0
    np.cumprod(E, axis=0, out=P[1:])
    return P


def modal_step_powers(modal: Modal, t: FloatArray) -> np.ndarray:
    """``exp(lam (t[k] - t[0]))`` (N, m) on a non-uniform grid ``t`` (s)."""
    return step_powers(np.exp(np.diff(np.asarray(t, dtype=float))[:, None] * modal.lam[None, :]))


def modal_powers(modal: Modal, h: float, N: int) -> np.ndarray:
    """``E**k = exp(lam h k)`` for ``k = 0..N-1``, shape (N, m), as a running product."""
    return powers(np.exp(modal.lam * h), N)


def powers(E: np.ndarray, N: int) -> np.ndarray:
    """``E**k`` for ``k = 0..N-1`` and every entry of the 1-D array ``E``, shape (N, m)."""
    P = np.empty((N, E.size), dtype=np.result_type(E, 1.0))
    if N == 0:
        return P
    P[0] = 1.0
    if N > 1:  # running product read straight from a broadcast E (no filled copy)
        np.multiply.accumulate(np.broadcast_to(E, (N - 1, E.size)), axis=0, out=P[1:])
    return P


def free_response_basis(modal: Modal, h: float, N: int, Cm: FloatArray,
                        P: np.ndarray | None = None) -> FloatArray:
    """Real regressors ``G`` (N, p, n) of the outputs ``Cm x`` on the n real coordinates of the
    kept modal initial state (real parts, then imaginary parts of the pairs): for ``x0``'s
    variable projection."""
    if P is None:
        P = modal_powers(modal, h, N)
    CV = (Cm @ modal.V) * modal.fac  # (p, m)
    T = P[:, None, :] * CV[None, :, :]  # (N, p, m)
    pairs = modal.fac == 2.0
    return np.concatenate([T.real, -T.imag[:, :, pairs]], axis=2)


def free_coeffs_to_state(modal: Modal, coef: FloatArray) -> FloatArray:
    """Initial state ``x0`` from the real modal coefficients of :func:`free_response_basis`."""
    m = modal.lam.size
    pairs = modal.fac == 2.0
    w = coef[:m].astype(complex)
    w[pairs] += 1j * coef[m:]
    return np.real(modal.V @ (w * modal.fac))


def simulate_states(model: SuspensionModel, p: Mapping[str, float], t: FloatArray,
                    U: FloatArray, x0: FloatArray | None = None,
                    modal: Modal | None = None, affine: AffinePieces | None = None) -> FloatArray:
    """State trajectory ``X`` (N, n) of the linear model under FOH road input ``U``.

    ``p`` in SI, ``t`` (N,) in s, ``U`` (N, 2 n_roads) from :func:`road_matrix`, ``x0`` at
    ``t[0]`` (default rest); ``modal``: :func:`modal_form` for ``p`` if computed already.
    """
    n = model.n_states
    nr = len(model.roads)
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    r = U[:, :nr]
    h = uniform_step(t)
    if modal is None:
        modal = modal_form(model, p, affine)
    if modal is not None:
        W = modal_trajectory(modal, h if h is not None else np.diff(t), r, x0)
        return np.real(W @ ((np.eye(n) @ modal.V) * modal.fac).T) + r @ modal.Bv.T
    return _simulate_states_loop(model, p, t, U, x0, affine)


def _simulate_states_loop(model: SuspensionModel, p: Mapping[str, float], t: FloatArray,
                          U: FloatArray, x0: FloatArray,
                          affine: AffinePieces | None = None) -> FloatArray:
    """Exact FOH stepping with block matrix exponentials (defective A)."""
    A, B = state_matrices(model, p, affine)
    n = model.n_states
    nr = len(model.roads)
    Br, Bv = B[:, :nr], B[:, nr:]
    Bz = A @ Bv + Br
    r = U[:, :nr]
    X = np.empty((t.size, n))
    z = x0 - Bv @ r[0]
    X[0] = x0
    cache: dict[float, tuple[FloatArray, FloatArray, FloatArray]] = {}
    for k in range(t.size - 1):
        h = float(t[k + 1] - t[k])
        key = round(h, 12)
        if key not in cache:
            cache[key] = foh_expm(A, Bz, h)
        Phi, Ga, Gb = cache[key]
        z = Phi @ z + Ga @ r[k] + Gb @ r[k + 1]
        X[k + 1] = z + Bv @ r[k + 1]
    return X


def foh_expm(A: FloatArray, Bw: FloatArray, h: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Exact FOH step of ``x' = A x + Bw w`` (``w`` linear over ``h``, s) by one block matrix
    exponential: ``x1 = Phi x0 + W0 w0 + W1 w1``; returns ``(Phi, W0, W1)``."""
    # only a defective A lands here: `suspid simulate` otherwise loads no scipy
    from scipy.linalg import expm  # noqa: PLC0415

    n, m = Bw.shape
    blk = np.zeros((n + 2 * m, n + 2 * m))
    blk[:n, :n] = A * h
    blk[:n, n:n + m] = Bw * h
    blk[n:n + m, n + m:] = np.eye(m)
    F = expm(blk)
    Phi, Ga, Gb = F[:n, :n], F[:n, n:n + m], F[:n, n + m:]
    return Phi, Ga - Gb, Gb


def ride_height_maps(model: SuspensionModel, p: Mapping[str, float]
                     ) -> tuple[FloatArray, FloatArray]:
    """Output maps of the ride heights (strut extensions, m): ``d = G q + Gr r`` (and the same
    for the rates), one row per strut; ``p`` (SI) sets the geometry."""
    if not model.ride_heights:
        return np.zeros((0, len(model.coords))), np.zeros((0, len(model.roads)))
    sites = model.strut_sites(dict(model.defaults(), **dict(p)))
    G = np.array([np.asarray(s.g, dtype=float) for s in sites]).reshape(len(sites), -1)
    Gr = np.array([np.asarray(s.gr, dtype=float) for s in sites]).reshape(len(sites), -1)
    return G, Gr


def ride_height_outputs(model: SuspensionModel, p: Mapping[str, float], X: FloatArray,
                        U: FloatArray | None = None) -> dict[str, FloatArray]:
    """The ride heights (m, rebound positive) and their ``_dot`` (m/s) from states ``X`` (N, n)
    and inputs ``U`` (N, 2 nr; ``None``: no road)."""
    names = model.ride_heights
    if not names:
        return {}
    G, Gr = ride_height_maps(model, p)
    nq = len(model.coords)
    nr = len(model.roads)
    D = X[:, :nq] @ G.T
    Dd = X[:, nq:2 * nq] @ G.T
    if U is not None and nr:
        D = D + U[:, :nr] @ Gr.T
        Dd = Dd + U[:, nr:2 * nr] @ Gr.T
    out: dict[str, FloatArray] = {}
    for i, name in enumerate(names):
        out[name] = D[:, i]
        out[f"{name}_dot"] = Dd[:, i]
    return out


def pack_channels(model: SuspensionModel, X: FloatArray, acc: FloatArray,
                  U: FloatArray | None = None,
                  p: Mapping[str, float] | None = None) -> dict[str, FloatArray]:
    """Channel dict from states ``X`` (N, n), accelerations ``acc`` (N, nq), the road columns
    of ``U`` (N, 2 nr) if given, and with ``p`` (SI) the ride heights."""
    nq = len(model.coords)
    out: dict[str, FloatArray] = {}
    for i, c in enumerate(model.coords):
        out[c] = X[:, i]
        out[f"{c}_dot"] = X[:, nq + i]
        out[f"{c}_ddot"] = acc[:, i]
    if p is not None:
        out.update(ride_height_outputs(model, p, X, U))
    if U is not None:
        nr = len(model.roads)
        for i, name in enumerate(model.roads):
            out[name] = U[:, i]
            out[f"{name}_dot"] = U[:, nr + i]
    return out


def accelerations(model: SuspensionModel, p: Mapping[str, float], X: FloatArray, U: FloatArray,
                  affine: AffinePieces | None = None) -> FloatArray:
    """Accelerations ``q''`` (N, nq) for state rows ``X`` and input rows ``U``."""
    if affine is not None and affine.matches(p):
        return affine.accelerations(X, U, affine.theta(p))
    return model.accelerations(X, U, p)


def outputs(model: SuspensionModel, p: Mapping[str, float], X: FloatArray,
            U: FloatArray, affine: AffinePieces | None = None) -> dict[str, FloatArray]:
    """Every channel from states and inputs except the road columns."""
    out = pack_channels(model, X, accelerations(model, p, X, U, affine))
    out.update(ride_height_outputs(model, p, X, U))
    return out


def simulate(model: SuspensionModel, params: Mapping[str, float], t: FloatArray,
             road: Mapping[str, FloatArray] | None = None,
             x0: FloatArray | None = None,
             affine: AffinePieces | None = None) -> dict[str, FloatArray]:
    """Simulate a linear model exactly (FOH road) and return every channel: ``params`` (SI),
    times ``t`` (s), road arrays by name (m; optional ``<name>_dot``, m/s), initial state ``x0``
    (default rest); ``affine``: the model's affine pieces, when many damper/spring sets are run.
    """
    t = np.asarray(t, dtype=float)
    U = road_matrix(model, t, road)
    if model.extra_force:
        return simulate_ode(model, params, t, road, x0)
    X = simulate_states(model, params, t, U, x0, affine=affine)
    return pack_channels(model, X, accelerations(model, params, X, U, affine), U, params)


def simulate_ode(model: SuspensionModel, params: Mapping[str, float], t: FloatArray,
                 road: Mapping[str, FloatArray] | None = None, x0: FloatArray | None = None,
                 method: str = "DOP853", rtol: float = 1e-10, atol: float = 1e-12,
                 road_fn=None) -> dict[str, FloatArray]:
    """General path: integrate ``model.rhs`` with :func:`scipy.integrate.solve_ivp`.

    The road is :func:`simulate`'s piecewise-linear one (integration restarts at every sample,
    at its kinks), unless ``road_fn(t) -> u`` gives the input as a continuous function.
    """
    # scipy.integrate is slow to import and only this reference path needs it
    from scipy.integrate import solve_ivp  # noqa: PLC0415

    t = np.asarray(t, dtype=float)
    U = road_matrix(model, t, road)
    nr = len(model.roads)
    n = model.n_states
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    X = np.empty((t.size, n))
    X[0] = x
    if road_fn is not None:
        sol = solve_ivp(lambda tt, xx: model.rhs(tt, xx, road_fn(tt), params), (t[0], t[-1]), x,
                        method=method, rtol=rtol, atol=atol, t_eval=t, dense_output=False)
        X = sol.y.T
        Uo = np.array([road_fn(tt) for tt in t])
    else:
        for k in range(t.size - 1):
            h = t[k + 1] - t[k]
            slope = (U[k + 1, :nr] - U[k, :nr]) / h

            def f(tt: float, xx: FloatArray, k: int = k, slope: FloatArray = slope) -> FloatArray:
                u = np.concatenate([U[k, :nr] + slope * (tt - t[k]), slope])
                return model.rhs(tt, xx, u, params)

            sol = solve_ivp(f, (t[k], t[k + 1]), x, method=method, rtol=rtol, atol=atol)
            x = sol.y[:, -1]
            X[k + 1] = x
        Uo = U
    nq = len(model.coords)
    acc = np.array([model.rhs(tt, xx, uu, params)[nq:] for tt, xx, uu in zip(t, X, Uo)])
    return pack_channels(model, X, acc, Uo, params)
