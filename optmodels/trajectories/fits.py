"""The families' least-squares estimates and Ψ along the paper's route (paper 002), in
centred moments: diverging (8)-(9), parallel (12)-(13) (and the misprinted (13)),
independent lines, and the normal equations (3) of any other family (QR of the reduced
design); Ψ (14) along the same route (Schur complements, the same QR). Cached on the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg

from optmodels.core import FloatArray, ProblemError
from optmodels.trajectories.data import FAMILIES, Family, TrajectoryData, resolve_family
from optmodels.trajectories.moments import _Stats, _stats


# --------------------------------------------------------------------------- the fits
@dataclass
class _Fit:
    """θ (R, d) and Ψ (d, R, R) of a family, with what the Newton re-check needs."""

    theta: FloatArray
    cov: FloatArray
    kind: str
    ctx: dict[str, Any] = field(default_factory=dict)


def _kind(fam: Family) -> str:
    """The paper's family this one is (by structure, whatever its name), or "custom"."""
    q = fam.n_objects
    for name in FAMILIES:
        ref = resolve_family(name, q)  # type: ignore[arg-type]
        if (fam.start_groups, fam.velocity_groups) == (ref.start_groups, ref.velocity_groups):
            return name
    return "custom"


def _fit(data: TrajectoryData, fam: Family, *, printed: bool = False) -> _Fit:
    """The family's least-squares estimate and Ψ along the paper's route (or the generic
    one for a custom family), in centred moments."""
    key = ("fit", fam.start_groups, fam.velocity_groups, printed)
    cached = data._cache.get(key)
    if cached is not None:
        return cached
    st = _stats(data)
    kind = _kind(fam)
    with np.errstate(all="ignore"):
        if kind == "diverging":
            fit = _diverging(st)
        elif kind == "parallel":
            fit = _parallel(st, printed=printed)
        elif kind == "independent":
            fit = _independent(st)
        else:
            fit = _generic(st, fam)
    if not (np.all(np.isfinite(fit.theta)) and np.all(np.isfinite(fit.cov))):
        raise ProblemError(
            "family: the data cannot identify this family (the least-squares "
            "sums over- or underflow float64); change units"
        )
    data._cache[key] = fit
    return fit


def _diverging(st: _Stats) -> _Fit:
    """(8)-(9) and Ψ via the Schur complement on y0.

    With B_j = Σw(t − epoch) = N_j u_j and C_j = Σw(t − epoch)² = N_j u_j² + M2_j
    (N_j = Σw, M2_j = Σw(t − T_j)², u_j = T_j − epoch), the printed quotient is evaluated
    as E − B_C = Σ_j N_jM2_j/C_j and D − A_C = Σ_j (N_jM2_j/C_j)·(ȳ_j − u_jV̂_j): y0 is the
    weighted mean of each object's own line extrapolated to the epoch, no cancellation.
    """
    s0, m2, u = st.s0, st.m2, st.u
    c = s0 * u * u + m2  # C_j
    k = s0 * m2 / c  # N_j − B_j²/C_j
    z = st.p - u * st.vhat  # object j's own start at the epoch
    kk = k.sum(axis=0)  # E − B_C
    y0 = (k * z).sum(axis=0) / kk  # (8)
    g = s0 * u / c  # B_j/C_j
    v = st.vhat + g * (z - y0)  # (9): (A_j − y0 B_j)/C_j
    q, d = s0.shape
    var0 = 1.0 / kk  # Var(y0): Schur complement
    cov = np.zeros((d, q + 1, q + 1))
    for i in range(d):
        cov[i, 0, 0] = var0[i]
        cov[i, 0, 1:] = cov[i, 1:, 0] = -g[:, i] * var0[i]
        cov[i, 1:, 1:] = np.diag(1.0 / c[:, i]) + np.outer(g[:, i], g[:, i]) * var0[i]
    return _Fit(
        np.vstack([y0, v]),
        cov,
        "diverging",
        {"c": c, "g": g, "var0": var0, "lam": (k * (z - y0) ** 2).sum()},
    )


def _parallel(st: _Stats, *, printed: bool = False) -> _Fit:
    """(12)-(13) and Ψ via the Schur complement on V.

    D − A_N = Σ_j Σw(t − T_j)(y − ȳ_j) and E − B_N = Σ_j M2_j (E = ΣΣ w(t − epoch)²);
    printed, E = ΣΣ w(t − epoch), so E − B_N = Σ_j N_j u_j (1 − u_j).
    """
    s0, m2, u = st.s0, st.m2, st.u
    num = (m2 * st.vhat).sum(axis=0)  # D − A_N
    den = (s0 * u * (1.0 - u)).sum(axis=0) if printed else m2.sum(axis=0)
    v = num / den
    y0 = st.p - u * v  # (12): (A_j − V B_j)/N_j
    q, d = s0.shape
    varv = 1.0 / m2.sum(axis=0)
    cov = np.zeros((d, q + 1, q + 1))
    for i in range(d):
        cov[i, q, q] = varv[i]
        cov[i, q, :q] = cov[i, :q, q] = -u[:, i] * varv[i]
        cov[i, :q, :q] = np.diag(1.0 / s0[:, i]) + np.outer(u[:, i], u[:, i]) * varv[i]
    return _Fit(np.vstack([y0, v]), cov, "parallel", {"lam": (m2 * (st.vhat - v) ** 2).sum()})


def _independent(st: _Stats) -> _Fit:
    """Single-line least squares per object, moved from T_j to the epoch."""
    s0, m2, u = st.s0, st.m2, st.u
    v = st.vhat
    y0 = st.p - u * v
    q, d = s0.shape
    cov = np.zeros((d, 2 * q, 2 * q))
    idx = np.arange(q)
    for i in range(d):
        cov[i, idx, idx] = 1.0 / s0[:, i] + u[:, i] ** 2 / m2[:, i]
        cov[i, q + idx, q + idx] = 1.0 / m2[:, i]
        cov[i, idx, q + idx] = cov[i, q + idx, idx] = -u[:, i] / m2[:, i]
    return _Fit(np.vstack([y0, v]), cov, "independent", {"lam": 0.0})


def _anchors(st: _Stats, fam: Family, k: int) -> tuple[FloatArray, FloatArray]:
    """Well-conditioned parameters for coordinate k: a start group whose objects share one
    velocity is parametrised by its position at the group's mean time (lever ``b_j`` of
    each object from it, ``a_g`` from the epoch to it); any other start group keeps its
    start at the epoch (lever ``u_j``, ``a_g = 0``): that constraint is tied to the epoch.
    Returns (lever (Q,), a (G,))."""
    lever = st.u[:, k].copy()
    a = np.zeros(len(fam.start_groups))
    vi = fam.velocity_index
    for gi, g in enumerate(fam.start_groups):
        members = list(g)
        if len({int(vi[j]) for j in members}) != 1:
            continue
        r = members[0]
        dlt = (st.tbar[members, k] - st.tbar[r, k]) + (st.tcorr[members, k] - st.tcorr[r, k])
        beta = float(np.sum(st.s0[members, k] * dlt) / np.sum(st.s0[members, k]))
        lever[members] = dlt - beta
        a[gi] = st.u[r, k] + beta
    return lever, a


def _generic(st: _Stats, fam: Family) -> _Fit:
    """Normal equations (3) of any family, solved by QR of the 2Q-row reduction
    (√N_j (ȳ_j − p_j), √M2_j (V̂_j − V_j)) in the anchored parameters of :func:`_anchors`,
    then moved to θ (starts at the epoch). Refuses a numerically singular design."""
    q, d = st.s0.shape
    r = fam.n_params
    si, vi = fam.start_index, fam.velocity_index
    theta = np.empty((r, d))
    cov = np.empty((d, r, r))
    ctx: dict[str, Any] = {"psic": [], "jac": [], "lever": []}
    rows = np.arange(q)
    for k in range(d):
        lever, a = _anchors(st, fam, k)
        g = np.zeros((2 * q, r))
        sq0, sqm = np.sqrt(st.s0[:, k]), np.sqrt(st.m2[:, k])
        g[rows, si] = sq0
        g[rows, vi] = sq0 * lever
        g[q + rows, vi] = sqm
        rhs = np.concatenate([sq0 * st.p[:, k], sqm * st.vhat[:, k]])
        cs = np.sqrt(np.sum(g * g, axis=0))
        qm, rm = np.linalg.qr(g / cs)
        sv = np.linalg.svd(rm, compute_uv=False)
        cond = sv[0] / sv[-1] if sv[-1] > 0 else np.inf
        if not cond < 1e13:
            raise ProblemError(
                f"family: AᵀA is singular (condition {cond:.2g} of the scaled design); the "
                "data cannot identify this family -- are the times far from the epoch?"
            )
        rinv = linalg.solve_triangular(rm, np.eye(r))
        thc = (rinv @ (qm.T @ rhs)) / cs
        psic = (rinv @ rinv.T) / np.outer(cs, cs)
        jac = np.eye(r)
        for gi, grp in enumerate(fam.start_groups):
            if a[gi] != 0.0:
                jac[gi, vi[grp[0]]] = -a[gi]
        theta[:, k] = jac @ thc
        cov[k] = jac @ psic @ jac.T
        ctx["psic"].append(psic)
        ctx["jac"].append(jac)
        ctx["lever"].append(lever)
    return _Fit(theta, cov, "custom", ctx)
