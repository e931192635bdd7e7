"""The law of Ŵ by sampling (paper 003): the Monte Carlo moments of Ŵ = Ŝ1(Ŝ1 + Ŝ2)⁻¹ with
Ŝ_μ Wishart draws of the estimator (3) (chunked, size-guarded), against which (10) is
checked, and Ŵ from snapshots of the two estimators (sample covariances (3), then (2) or
the correlated W)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_flag,
    check_spd,
)
from optmodels.fusion.inputs import (
    MeanKind,
    _check_mean,
    _check_n,
    _dim_guard,
    _pair,
    _vec,
    _where,
)
from optmodels.fusion.verify import _refuse_inaccurate, _weight_error
from optmodels.fusion.weights import _weight, weight_matrix_correlated
from optmodels.seeds import as_generator

#: Largest trials · m² accepted by :func:`monte_carlo_weight` (measured 1e-7..8e-7 s per
#: trial·m² on a shared 2-core VM: at most ~15 s). The draws are made in chunks of at most
#: :data:`MC_CHUNK` trial·m² values, so memory is bounded whatever ``trials``.
MAX_MC_WORK = 20_000_000
MC_CHUNK = 1 << 20


@dataclass(frozen=True)
class WeightMonteCarlo:
    """``mean`` (m, m) and ``cov`` (m², m²) of vec(Ŵ) over ``trials`` draws."""

    mean: FloatArray
    cov: FloatArray
    trials: int


def monte_carlo_weight(
    s1: ArrayLike,
    s2: ArrayLike,
    n1: int,
    n2: int,
    *,
    trials: int = 100_000,
    seed: int | np.random.Generator | None = None,
    mean: MeanKind = "known",
) -> WeightMonteCarlo:
    """Monte Carlo law of Ŵ = Ŝ1(Ŝ1 + Ŝ2)⁻¹ with Ŝ_μ from (3).

    Σ_s (x_s − m)(x_s − m)ᵀ is Wishart(n, S) with the true mean, Wishart(n − 1, S) with the
    sample mean; both are drawn by :func:`scipy.stats.wishart` (Bartlett decomposition) and
    divided by n − 1. Vectorised over chunks of at most :data:`MC_CHUNK` / m² trials, the
    moments accumulated around the true W, so memory is bounded whatever ``trials``.

    ``seed``: None, a non-negative integer or a :class:`numpy.random.Generator`.
    Size guard: trials · m² ≤ :data:`MAX_MC_WORK` = 2e7 (about 15 s here; 10⁵ trials at
    m = 3 take ~0.5 s) and m ≤ :data:`MAX_DIM`; larger requests raise ProblemError
    rather than run for minutes.
    """
    fn = "monte_carlo_weight"
    a, b = _pair(s1, s2, fn)
    m = a.shape[0]
    _dim_guard(fn, m)
    mean = _check_mean(fn, mean)
    n1 = _check_n(_where(fn, "n1"), n1, m, mean)
    n2 = _check_n(_where(fn, "n2"), n2, m, mean)
    trials = as_count(_where(fn, "trials"), trials, minimum=2)
    if trials * m * m > MAX_MC_WORK:
        raise ProblemError(
            f"{_where(fn, 'trials')}: {trials} trials at m = {m} is "
            f"trials·m² = {trials * m * m:.3g}, above the limit {MAX_MC_WORK:.0e} "
            f"(≈ 15 s); use at most {MAX_MC_WORK // (m * m)} trials (the "
            "Monte Carlo standard error falls only as 1/√trials)"
        )
    rng = _rng(_where(fn, "seed"), seed)
    lost = 0 if mean == "known" else 1
    w0 = _vec(_weight(a, b))  # shift: moments accumulated around the true W (stable sums)
    total = np.zeros(m * m)
    outer = np.zeros((m * m, m * m))
    chunk = max(1, MC_CHUNK // (m * m))
    done = 0
    while done < trials:
        k = min(chunk, trials - done)
        draws = []
        for s, n in ((a, n1), (b, n2)):
            x = stats.wishart(df=n - lost, scale=s).rvs(size=k, random_state=rng)
            draws.append(np.asarray(x).reshape(k, m, m) / (n - 1))
        # Ŵ = Ŝ1 (Ŝ1+Ŝ2)^-1 = ((Ŝ1+Ŝ2)^-1 Ŝ1)^T (symmetric draws)
        w = _weight(draws[0], draws[1])
        dv = w.transpose(0, 2, 1).reshape(k, m * m) - w0  # column-major vec per trial
        total += dv.sum(axis=0)
        outer += dv.T @ dv
        done += k
    mean_dv = total / trials
    cov = (outer - trials * np.outer(mean_dv, mean_dv)) / (trials - 1)
    return WeightMonteCarlo(
        mean=(w0 + mean_dv).reshape(m, m, order="F"), cov=0.5 * (cov + cov.T), trials=trials
    )


def _rng(name: str, seed: Any) -> np.random.Generator:
    """None (fresh entropy), a whole number ≥ 0 (or a sequence of them) or a Generator → a
    Generator (:func:`optmodels.seeds.as_generator`); ProblemError otherwise."""
    return as_generator(name, seed, allow_none=True)


def weight_from_samples(a1: ArrayLike, a2: ArrayLike, *, correlated: bool = False) -> FloatArray:
    """Ŵ from n snapshots of the two estimators, rows of ``a1`` and ``a2`` (n, m): the
    sample covariances (3) with the sample mean and divisor n − 1, then W of (2), or of
    :func:`weight_matrix_correlated` with the sample cross-covariance if ``correlated``.

    Raises :class:`ProblemError` if n ≤ m (singular sample covariance) or the snapshots
    are degenerate.
    """
    fn = "weight_from_samples"
    x1 = as_finite_array(_where(fn, "a1"), a1, ndim=2, max_abs=MAX_MAGNITUDE)
    x2 = as_finite_array(_where(fn, "a2"), a2, shape=x1.shape, max_abs=MAX_MAGNITUDE)
    as_flag(_where(fn, "correlated"), correlated)
    n, m = x1.shape
    _check_n(_where(fn, "a1 rows (snapshots)"), n, m)
    full = np.cov(np.hstack([x1, x2]).T)
    s1, s2, s12 = full[:m, :m], full[m:, m:], full[:m, m:]
    for name, s in (("a1", s1), ("a2", s2)):
        try:
            check_spd(f"sample covariance of {name}", s)
        except ProblemError as exc:
            raise ProblemError(f"{name}: the snapshots are degenerate ({exc})") from None
    if correlated:
        return weight_matrix_correlated(s1, s2, s12)
    w = _weight(s1, s2)
    _refuse_inaccurate(fn, _weight_error(w, s1 + s2, s1), "the sample S1 + S2")
    return w
