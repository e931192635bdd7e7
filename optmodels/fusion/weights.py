"""The weight matrix of the fusion (paper 003): W = (C1 + C2)⁻¹C2 = S1(S1 + S2)⁻¹ (2), (6);
the weight of the best linear unbiased fusion of correlated estimates
W = (S1 − S12)D⁺ (Bar-Shalom & Campo) with the check of S12; and the error covariance
of (I − W)a1 + Wa2 for any W."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from optmodels.core import MAX_MAGNITUDE, FloatArray, ProblemError, as_finite_array, as_float_array
from optmodels.fusion.inputs import _pair, _where
from optmodels.fusion.verify import _refuse_inaccurate, _weight_error


def _weight(a: FloatArray, b: FloatArray) -> FloatArray:
    """S1(S1 + S2)⁻¹ = ((S1 + S2)⁻¹S1)ᵀ for symmetric S1, S2; stacks (..., m, m) too."""
    if a.ndim == 2:
        return linalg.solve(a + b, a, assume_a="pos").T
    return np.swapaxes(np.linalg.solve(a + b, a), -1, -2)


def weight_matrix(s1: ArrayLike, s2: ArrayLike) -> FloatArray:
    """W = (C1 + C2)⁻¹C2 (2), (6), computed as S1(S1 + S2)⁻¹ (no inverse of S_μ).

    The result is re-checked in NumPy: a bound on its relative forward error from the
    residual of W(S1 + S2) = S1 and the conditioning of S1 + S2 (see
    :func:`_weight_error`) must not exceed :data:`optmodels.core.REJECT_TOL`.

    Raises
    ------
    ProblemError
        Non-square, mismatched, non-finite, non-symmetric or non-PD S1/S2, or S1 + S2 so
        ill-conditioned that W cannot be computed to REJECT_TOL.
    """
    a, b = _pair(s1, s2, "weight_matrix")
    w = _weight(a, b)
    _refuse_inaccurate("weight_matrix", _weight_error(w, a + b, a), "S1 + S2")
    return w


def _cross(
    s12: ArrayLike, a: FloatArray, b: FloatArray, fn: str = "fuse"
) -> tuple[FloatArray, FloatArray]:
    """Validate a cross-covariance S12 = Cov(a1, a2): finite (m, m) and the joint covariance
    [[S1, S12], [S12ᵀ, S2]] positive semidefinite. Returns (S12, D) with
    D = S1 + S2 − S12 − S12ᵀ = Cov(a1 − a2) (positive semidefinite, possibly singular)."""
    m = a.shape[0]
    name = _where(fn, "s12")
    c = as_finite_array(name, s12, shape=(m, m), max_abs=MAX_MAGNITUDE)
    joint = np.block([[a, c], [c.T, b]])
    lam = np.linalg.eigvalsh(joint)
    if lam[0] < -1e-10 * max(lam[-1], np.finfo(float).tiny):
        raise ProblemError(
            f"{name}: the joint covariance [[S1, S12], [S12ᵀ, S2]] is not positive "
            f"semidefinite (smallest eigenvalue {lam[0]:.3g}); S12 cannot be the "
            "cross-covariance of these estimates"
        )
    d = a + b - c - c.T
    return c, 0.5 * (d + d.T)


#: Relative eigenvalue threshold below which D = Cov(a1 − a2) is treated as singular.
PINV_RTOL = 1e-10


def _correlated_weight(s1: FloatArray, s12: FloatArray, d: FloatArray) -> FloatArray:
    """(S1 − S12) D⁺ for stacks (..., m, m); D⁺ the pseudo-inverse (eigenvalues below
    :data:`PINV_RTOL` × the largest are dropped)."""
    return (s1 - s12) @ np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True)


def weight_matrix_correlated(s1: ArrayLike, s2: ArrayLike, s12: ArrayLike) -> FloatArray:
    """Weight of the best linear unbiased fusion of two **correlated** estimates
    (Bar-Shalom & Campo): W = (S1 − S12)D⁺, D = S1 + S2 − S12 − S12ᵀ = Cov(a1 − a2),
    S12 = Cov(a1, a2).

    With S12 = 0 this is the paper's W (2), (6), which assumes independent measurers.
    D may be singular: the two estimates then differ only inside range(D) (in the
    two-site system both lie on the bearing from A, so D has rank 1). W is then not
    unique, but (I − W)a1 + Wa2 and its covariance are; the minimum-norm W is returned.
    A valid joint covariance guarantees (S1 − S12)D⁺D = S1 − S12 (for z in null(D),
    zᵀa1 = zᵀa2, so (S1 − S12)z = Cov(a1, zᵀ(a1 − a2)) = 0).
    """
    a, b = _pair(s1, s2, "weight_matrix_correlated")
    c, d = _cross(s12, a, b, "weight_matrix_correlated")
    w = _correlated_weight(a, c, d)
    err = _weight_error(
        w, d, a - c, np.asarray(np.linalg.pinv(d, rcond=PINV_RTOL, hermitian=True), dtype=float)
    )
    _refuse_inaccurate("weight_matrix_correlated", err, "D = S1 + S2 − S12 − S12ᵀ")
    return w


def fused_covariance(
    w: ArrayLike, s1: ArrayLike, s2: ArrayLike, s12: ArrayLike | None = None
) -> FloatArray:
    """Error covariance of (I − W)a1 + Wa2 for **any** W (stacks (..., m, m) broadcast):
    (I − W)S1(I − W)ᵀ + WS2Wᵀ + (I − W)S12Wᵀ + WS12ᵀ(I − W)ᵀ.

    With the paper's W and S12 = 0 this is (C1 + C2)⁻¹; with the paper's W applied to
    correlated estimates it is the covariance one actually gets (larger than
    (C1 + C2)⁻¹, and possibly larger than S1 itself). Only the form of the inputs is
    checked (numeric arrays of (m, m) matrices whose stacks broadcast): NaN entries (a
    failed W) propagate, and S1, S2 are not required to be positive definite.

    Raises
    ------
    ProblemError
        Naming the argument: not a numeric array (ragged, text, ``None`` entries,
        complex values, a mapping), or not (..., m, m) like W; naming all of them when
        their stacks do not broadcast.
    """
    fn = "fused_covariance"
    given = {"W": w, "S1": s1, "S2": s2} | ({} if s12 is None else {"s12": s12})
    mats = {k: as_float_array(_where(fn, k), v) for k, v in given.items()}
    m = mats["W"].shape[-1] if mats["W"].ndim else 0
    for k, mat in mats.items():
        if mat.ndim < 2 or mat.shape[-2:] != (m, m):
            raise ProblemError(
                f"{_where(fn, k)}: expected square matrices (m, m) or a stack of them, "
                f"m = {m} from W, got shape {mat.shape}"
            )
    try:
        np.broadcast_shapes(*(mat.shape for mat in mats.values()))
    except ValueError:
        raise ProblemError(
            f"{_where(fn, ', '.join(mats))}: stacks of shapes "
            f"{', '.join(str(mat.shape) for mat in mats.values())} do not broadcast"
        ) from None
    wm, a, b = mats["W"], mats["S1"], mats["S2"]
    v = np.eye(wm.shape[-1]) - wm
    tr = np.swapaxes
    cov = v @ a @ tr(v, -1, -2) + wm @ b @ tr(wm, -1, -2)
    if s12 is not None:
        c = mats["s12"]
        cov = cov + v @ c @ tr(wm, -1, -2) + wm @ tr(c, -1, -2) @ tr(v, -1, -2)
    return 0.5 * (cov + tr(cov, -1, -2))
