r"""The polyline of one track (paper 001, (3)): hat functions, knots, the normal equations
of the GLS fit and their block-tridiagonal solve.

A polyline with knots τ_0 < … < τ_K is Σ_k h_k(t)θ_k with hat functions h_k
(:func:`hat_basis`); θ_k ∈ R² is the position at τ_k. With plots z_j at t_j and Cartesian
covariances V_j the GLS normal matrix N = Σ_j (h_j h_jᵀ) ⊗ V_j⁻¹ is block-tridiagonal
(2×2 blocks): :func:`normal_band` assembles its band (bincount, O(n)) and
:func:`solve_bands` solves many of them at once by the block Cholesky recursion (O(K)),
giving θ̂ and the band of Cov θ̂ (all a :class:`~optmodels.biasfield.tracks.TrackFit`
stores). :func:`polyline_normal` is the dense assembly (the small fits of the parametric
baseline). Used by :mod:`~optmodels.biasfield.tracks` and
:mod:`~optmodels.biasfield.baseline`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import MAX_MAGNITUDE, FloatArray, ProblemError, as_finite_array

__all__ = [
    "BATCH",
    "hat_basis",
    "inv2",
    "locate",
    "normal_band",
    "polyline_knots",
    "polyline_normal",
    "solve_band",
    "solve_bands",
    "split_at_gaps",
    "whiten",
]


def hat_basis(t: ArrayLike, knots: FloatArray) -> FloatArray:
    """(T, K) hat-function values h_k(t) of the polyline with these knots (t inside;
    knots strictly increasing, s)."""
    tt = as_finite_array("biasfield.hat_basis t", t, ndim=(0, 1), max_abs=MAX_MAGNITUDE).reshape(-1)
    knots = as_finite_array("biasfield.hat_basis knots", knots, ndim=1, max_abs=MAX_MAGNITUDE)
    if knots.size < 2 or np.any(np.diff(knots) <= 0):
        raise ProblemError(
            f"biasfield.hat_basis knots: need ≥ 2 strictly increasing knots, got {knots.size}"
        )
    k = np.clip(np.searchsorted(knots, tt, side="right") - 1, 0, len(knots) - 2)
    u = (tt - knots[k]) / (knots[k + 1] - knots[k])
    out = np.zeros((tt.size, len(knots)))
    rows = np.arange(tt.size)
    out[rows, k] = 1.0 - u
    out[rows, k + 1] = u
    return out


def locate(t: FloatArray, knots: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Interval index k (t in [τ_k, τ_k+1]) and the weight u of τ_k+1 for each t."""
    k = np.searchsorted(knots, t, side="right") - 1
    np.minimum(k, len(knots) - 2, out=k)
    np.maximum(k, 0, out=k)
    return k, (t - knots[k]) / (knots[k + 1] - knots[k])


def inv2(a: FloatArray) -> FloatArray:
    """Inverse of a stack of 2×2 matrices (..., 2, 2), closed form."""
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    out = np.empty_like(a)
    out[..., 0, 0] = a[..., 1, 1]
    out[..., 1, 1] = a[..., 0, 0]
    out[..., 0, 1] = -a[..., 0, 1]
    out[..., 1, 0] = -a[..., 1, 0]
    return out / det[..., None, None]


def split_at_gaps(t: FloatArray, max_gap: float) -> list[np.ndarray]:
    """Index arrays of the pieces of the sorted times ``t`` (s) split where consecutive
    instants are more than ``max_gap`` (s) apart."""
    cuts = np.flatnonzero(np.diff(t) > max_gap) + 1
    return np.split(np.arange(t.size), cuts)


def polyline_knots(t: FloatArray, spacing: float) -> FloatArray:
    """Knots of a piece: its first and last plot times, and the multiples of ``spacing``
    between them (the same absolute instants for every radar). Interior knots closer than
    spacing/2 to an end, or whose hat support carries less than half a plot of weight,
    are dropped (the polyline then spans them linearly): no knot is left to be determined
    by a stray plot at the far end of its support, and no position is ever extrapolated
    beyond the plots."""
    t0, t1 = float(t[0]), float(t[-1])
    if t1 - t0 < 1e-9:
        return np.array([t0, t0 + spacing])
    inner = np.arange(np.ceil(t0 / spacing), np.floor(t1 / spacing) + 1) * spacing
    inner = inner[(inner > t0 + 0.5 * spacing) & (inner < t1 - 0.5 * spacing)]
    knots = np.concatenate([[t0], inner, [t1]])
    while knots.size > 2:
        k, u = locate(t, knots)
        support = np.bincount(k, 1.0 - u, minlength=knots.size) + np.bincount(
            k + 1, u, minlength=knots.size
        )
        weak = np.flatnonzero(support[1:-1] < 0.5) + 1
        if weak.size == 0:
            break
        knots = np.delete(knots, weak[np.argmin(support[weak])])
    return knots


def polyline_normal(
    t: FloatArray, knots: FloatArray, vinv: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Normal equations of the polyline GLS: N = Σ_j (h_j h_jᵀ) ⊗ V_j⁻¹ (2K, 2K),
    b = Σ_j h_j ⊗ V_j⁻¹z_j (θ row-major), and the hat values h (n, K). Each plot touches
    the two knots of its interval, so N is block-tridiagonal; it is assembled by scatter
    (dense: for the small fits of the parametric baseline; the track fits use
    :func:`normal_band`)."""
    k = knots.size
    idx = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, k - 2)
    u = (t - knots[idx]) / (knots[idx + 1] - knots[idx])
    wts = np.column_stack([1.0 - u, u])
    nblk = np.zeros((k, k, 2, 2))
    bblk = np.zeros((k, 2))
    vz = np.einsum("nab,nb->na", vinv, z)
    for p_ in range(2):
        np.add.at(bblk, idx + p_, wts[:, p_, None] * vz)
        for q_ in range(2):
            np.add.at(nblk, (idx + p_, idx + q_), (wts[:, p_] * wts[:, q_])[:, None, None] * vinv)
    return nblk.transpose(0, 2, 1, 3).reshape(2 * k, 2 * k), bblk.reshape(-1), hat_basis(t, knots)


def normal_band(
    t: FloatArray, knots: FloatArray, vinv: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray, FloatArray]:
    """The blocks of the block-tridiagonal N: diagonal D (K, 2, 2), upper B (K−1, 2, 2)
    (B_k = N[k, k+1]), right side b (K, 2); and each plot's interval and weight."""
    k = knots.size
    idx, u = locate(t, knots)
    w0, w1 = 1.0 - u, u
    flat = vinv.reshape(-1, 4)
    vz = np.einsum("nab,nb->na", vinv, z)

    def acc(at: np.ndarray, w: FloatArray, vals: FloatArray, size: int) -> FloatArray:
        return np.stack(
            [np.bincount(at, w * vals[:, c], minlength=size) for c in range(vals.shape[1])], axis=1
        )

    diag = (acc(idx, w0 * w0, flat, k) + acc(idx + 1, w1 * w1, flat, k)).reshape(k, 2, 2)
    upper = acc(idx, w0 * w1, flat, k - 1).reshape(k - 1, 2, 2)
    rhs = acc(idx, w0, vz, k) + acc(idx + 1, w1, vz, k)
    return diag, upper, rhs, idx, u


def solve_band(
    diag: FloatArray, upper: FloatArray, rhs: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """Block Cholesky of the block-tridiagonal SPD N (2×2 blocks, plain floats): θ = N⁻¹b
    and the block band of N⁻¹ (diagonal, upper), or None if N is not numerically
    positive definite.

    Forward: S_0 = D_0, S_k+1 = D_k+1 − B_kᵀS_k⁻¹B_k, r likewise; backward, with
    A_k = −S_k⁻¹B_k (θ_k = A_k θ_k+1 + e_k, Cov e_k = S_k⁻¹): θ_k = S_k⁻¹r_k + A_kθ_k+1,
    Σ_k,k+1 = A_kΣ_k+1, Σ_k = A_kΣ_k+1A_kᵀ + S_k⁻¹."""
    k = diag.shape[0]
    d = diag.reshape(k, 4).tolist()
    bl = upper.reshape(max(k - 1, 0), 4).tolist()
    r = rhs.tolist()
    sinv: list[tuple[float, float, float]] = []  # S⁻¹ (symmetric: a, b, c)
    gain: list[tuple[float, float, float, float]] = []  # A_k
    red: list[tuple[float, float]] = []  # S⁻¹ r
    scale = float(np.abs(diag[:, (0, 1), (0, 1)]).max())
    s00, s01, s11 = d[0][0], 0.5 * (d[0][1] + d[0][2]), d[0][3]
    r0, r1 = r[0]
    for j in range(k):
        det = s00 * s11 - s01 * s01
        if not (s00 > 1e-13 * scale and det > 1e-13 * scale * s00 and det > 0):
            return None
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        sinv.append((i00, i01, i11))
        red.append((i00 * r0 + i01 * r1, i01 * r0 + i11 * r1))
        if j == k - 1:
            break
        b00, b01, b10, b11 = bl[j]
        # A = −S⁻¹B
        a00 = -(i00 * b00 + i01 * b10)
        a01 = -(i00 * b01 + i01 * b11)
        a10 = -(i01 * b00 + i11 * b10)
        a11 = -(i01 * b01 + i11 * b11)
        gain.append((a00, a01, a10, a11))
        dn = d[j + 1]
        # S_next = D + Bᵀ A ; r_next = b + Aᵀ r
        s00 = dn[0] + b00 * a00 + b10 * a10
        s01 = 0.5 * (dn[1] + dn[2] + b00 * a01 + b10 * a11 + b01 * a00 + b11 * a10)
        s11 = dn[3] + b01 * a01 + b11 * a11
        rn = r[j + 1]
        r0, r1 = rn[0] + a00 * r0 + a10 * r1, rn[1] + a01 * r0 + a11 * r1
    theta = np.empty((k, 2))
    cdiag = np.empty((k, 2, 2))
    cnext = np.empty((max(k - 1, 0), 2, 2))
    i00, i01, i11 = sinv[-1]
    c00, c01, c11 = i00, i01, i11
    x0, x1 = red[-1]
    theta[-1] = x0, x1
    cdiag[-1] = [[c00, c01], [c01, c11]]
    for j in range(k - 2, -1, -1):
        a00, a01, a10, a11 = gain[j]
        # Σ_j,j+1 = A Σ_{j+1}
        n00, n01 = a00 * c00 + a01 * c01, a00 * c01 + a01 * c11
        n10, n11 = a10 * c00 + a11 * c01, a10 * c01 + a11 * c11
        cnext[j] = [[n00, n01], [n10, n11]]
        i00, i01, i11 = sinv[j]
        # Σ_j = (AΣ) Aᵀ + S⁻¹
        c00, c01, c11 = (
            n00 * a00 + n01 * a01 + i00,
            0.5 * (n00 * a10 + n01 * a11 + n10 * a00 + n11 * a01) + i01,
            n10 * a10 + n11 * a11 + i11,
        )
        cdiag[j] = [[c00, c01], [c01, c11]]
        rx0, rx1 = red[j]
        x0, x1 = rx0 + a00 * x0 + a01 * x1, rx1 + a10 * x0 + a11 * x1
        theta[j] = x0, x1
    return theta, cdiag, cnext


def whiten(vinv: FloatArray, r: FloatArray) -> FloatArray:
    """Lᵀr with V⁻¹ = LLᵀ: residuals in noise units (unit covariance if V is right)."""
    return np.einsum("nab,na->nb", np.linalg.cholesky(vinv), r)


#: Pieces solved together by :func:`solve_bands` (sorted by size, padded to the largest).
BATCH = 256


def solve_bands(
    bands: list[tuple[FloatArray, ...]],
) -> list[tuple[FloatArray, FloatArray, FloatArray] | None]:
    """:func:`solve_band` for many pieces at once: the same recursion on arrays over the
    pieces (sorted by K, padded with identity blocks that couple to nothing), so that the
    Python loop runs over the knots of a batch, not over every knot of every piece."""
    out: list[tuple[FloatArray, FloatArray, FloatArray] | None] = [None] * len(bands)
    sizes = np.array([b[0].shape[0] for b in bands], dtype=np.int64)
    order = np.argsort(sizes, kind="stable")
    for start in range(0, order.size, BATCH):
        idx = order[start : start + BATCH]
        nb, kmax = idx.size, int(sizes[idx].max())
        d = np.tile(np.array([1.0, 0.0, 0.0, 1.0]), (nb, kmax, 1))
        bl = np.zeros((nb, max(kmax - 1, 0), 4))
        r = np.zeros((nb, kmax, 2))
        for j, i in enumerate(idx):
            k = int(sizes[i])
            d[j, :k] = bands[i][0].reshape(k, 4)
            bl[j, : k - 1] = bands[i][1].reshape(k - 1, 4)
            r[j, :k] = bands[i][2]
        k_of = sizes[idx]
        scale = np.array([np.abs(bands[i][0][:, (0, 1), (0, 1)]).max() for i in idx])
        ok = np.ones(nb, dtype=bool)
        sinv = np.empty((kmax, 3, nb))
        gain = np.empty((max(kmax - 1, 0), 4, nb))
        red = np.empty((kmax, 2, nb))
        s00, s01, s11 = d[:, 0, 0], 0.5 * (d[:, 0, 1] + d[:, 0, 2]), d[:, 0, 3]
        r0, r1 = r[:, 0, 0], r[:, 0, 1]
        for j in range(kmax):
            det = s00 * s11 - s01 * s01
            real = j < k_of
            ok &= ~real | ((s00 > 1e-13 * scale) & (det > 1e-13 * scale * s00) & (det > 0))
            det = np.where(det > 0, det, 1.0)
            i00, i01, i11 = s11 / det, -s01 / det, s00 / det
            sinv[j] = i00, i01, i11
            red[j] = i00 * r0 + i01 * r1, i01 * r0 + i11 * r1
            if j == kmax - 1:
                break
            b00, b01, b10, b11 = bl[:, j, 0], bl[:, j, 1], bl[:, j, 2], bl[:, j, 3]
            a00 = -(i00 * b00 + i01 * b10)
            a01 = -(i00 * b01 + i01 * b11)
            a10 = -(i01 * b00 + i11 * b10)
            a11 = -(i01 * b01 + i11 * b11)
            gain[j] = a00, a01, a10, a11
            dn = d[:, j + 1]
            s00 = dn[:, 0] + b00 * a00 + b10 * a10
            s01 = 0.5 * (dn[:, 1] + dn[:, 2] + b00 * a01 + b10 * a11 + b01 * a00 + b11 * a10)
            s11 = dn[:, 3] + b01 * a01 + b11 * a11
            rn = r[:, j + 1]
            r0, r1 = rn[:, 0] + a00 * r0 + a10 * r1, rn[:, 1] + a01 * r0 + a11 * r1
        theta = np.empty((kmax, 2, nb))
        cdiag = np.empty((kmax, 3, nb))
        cnext = np.empty((max(kmax - 1, 0), 4, nb))
        c00, c01, c11 = sinv[-1]
        x0, x1 = red[-1]
        theta[-1] = x0, x1
        cdiag[-1] = c00, c01, c11
        for j in range(kmax - 2, -1, -1):
            a00, a01, a10, a11 = gain[j]
            n00, n01 = a00 * c00 + a01 * c01, a00 * c01 + a01 * c11
            n10, n11 = a10 * c00 + a11 * c01, a10 * c01 + a11 * c11
            cnext[j] = n00, n01, n10, n11
            i00, i01, i11 = sinv[j]
            c00, c01, c11 = (
                n00 * a00 + n01 * a01 + i00,
                0.5 * (n00 * a10 + n01 * a11 + n10 * a00 + n11 * a01) + i01,
                n10 * a10 + n11 * a11 + i11,
            )
            cdiag[j] = c00, c01, c11
            rx0, rx1 = red[j]
            x0, x1 = rx0 + a00 * x0 + a01 * x1, rx1 + a10 * x0 + a11 * x1
            theta[j] = x0, x1
        th = theta.transpose(2, 0, 1)
        cd = cdiag.transpose(2, 0, 1)[..., (0, 1, 1, 2)].reshape(nb, kmax, 2, 2)
        cn = cnext.transpose(2, 0, 1).reshape(nb, max(kmax - 1, 0), 2, 2)
        for j, i in enumerate(idx):
            if ok[j]:
                k = int(sizes[i])
                out[i] = (th[j, :k].copy(), cd[j, :k].copy(), cn[j, : k - 1].copy())
    return out
