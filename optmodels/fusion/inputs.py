"""Argument checks shared by the fusion functions (paper 003): covariance matrices S_μ
(symmetric positive definite, scaled), the pair (S1, S2), the size guard :data:`MAX_DIM`
for the (m², m²) matrices of (10)-(14), the snapshot counts n of the estimator (3) and the
``mean`` kind, and ``vec`` (the paper's '#', column stacking)."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    check_spd,
)

MeanKind = Literal["known", "sample"]

#: Largest state dimension m for the functions that build (m², m²) matrices
#: (:func:`weight_jacobians`, :func:`sample_covariance_moments`, :func:`weight_covariance`,
#: :func:`monte_carlo_weight`, :func:`commutation_matrix`): at m = 30 these are 900 × 900
#: (6.5 MB) and (10) costs ~m⁶ = 7e8 flops, about a second.
MAX_DIM = 30


def _where(fn: str, arg: str) -> str:
    """Argument name in messages: '<module>.<function> <argument>'."""
    return f"fusion.{fn} {arg}"


def _dim_guard(fn: str, m: int) -> None:
    if m > MAX_DIM:
        raise ProblemError(
            f"{_where(fn, 'S1')}: dimension m = {m} above {MAX_DIM} (this "
            f"function builds (m², m²) matrices: {m * m}² entries)"
        )


def _cov(name: str, s: ArrayLike, m: int | None = None) -> FloatArray:
    arr = as_finite_array(name, s, ndim=2, max_abs=MAX_MAGNITUDE)
    if arr.shape[0] != arr.shape[1]:
        raise ProblemError(f"{name}: expected a square matrix, got shape {arr.shape}")
    if m is not None and arr.shape[0] != m:
        raise ProblemError(f"{name}: expected ({m}, {m}) like S1, got {arr.shape}")
    check_spd(name, arr)
    low = float(np.linalg.eigvalsh(0.5 * (arr + arr.T))[0])
    if low < 1 / MAX_MAGNITUDE:
        # found by the robustness sweep: C = S⁻¹ at 1e151 times estimates at 1e149
        # overflowed; variances below 1e-100 are a units problem, not a fusion one
        raise ProblemError(
            f"{name}: smallest eigenvalue {low:.3g} below 1e-100 (its inverse "
            "overflows against the estimates); change units"
        )
    return 0.5 * (arr + arr.T)


def _pair(s1: ArrayLike, s2: ArrayLike, fn: str = "") -> tuple[FloatArray, FloatArray]:
    pre = f"fusion.{fn} " if fn else ""
    a = _cov(pre + "S1", s1)
    return a, _cov(pre + "S2", s2, a.shape[0])


def _vec(a: FloatArray) -> FloatArray:
    """Stack the columns (the paper's '#')."""
    return a.reshape(-1, order="F")


def _check_n(name: str, n: int, m: int, mean: str = "sample") -> int:
    """n snapshots give a nonsingular Ŝ (3) a.s. iff n ≥ m with the known mean and
    n ≥ m + 1 with the sample mean (one degree of freedom spent on it); the divisor
    n − 1 needs n ≥ 2."""
    least = max(2, m if mean == "known" else m + 1)
    k = as_count(name, n)  # refuses NaN, inf, 2.5, booleans and strings
    if k < least:
        rel = "n ≥ m" if mean == "known" else "n > m"
        raise ProblemError(
            f"{name}: need an integer sample size {rel} = {m} with the {mean} "
            f"mean (the sample covariance is singular otherwise), got {k}"
        )
    return k


def _check_mean(fn: str, mean: Any) -> MeanKind:
    return as_choice(_where(fn, "mean"), mean, ("known", "sample"))  # type: ignore[return-value]
