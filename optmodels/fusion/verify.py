"""NumPy re-check of the fusion answers (paper 003): forward error bounds of the weight W
(2), (6) (and of the correlated W) from the residual of W(S1 + S2) = S1 and the
conditioning (LAPACK xGERFS style, componentwise), of the fused estimate (1), the WLS
objective (1) itself, and the status gate :func:`_finish` (via
:func:`optmodels.core.verified_status`); :func:`_refuse_inaccurate` for functions that
return a bare matrix."""

from __future__ import annotations

from typing import TypeVar

import numpy as np

from optmodels.core import REJECT_TOL, FloatArray, ProblemError, Solution, Status, Verdict, finish
from optmodels.fusion.solution import _failure

_EPS = float(np.finfo(float).eps)


def _bounded_error(
    mat: FloatArray, sol: FloatArray, rhs: FloatArray, inv: FloatArray
) -> FloatArray:
    """LAPACK-style (xGERFS) forward error bound of a computed ``sol`` of
    ``mat @ sol = rhs``: |inv| (|r| + γ(|mat||sol| + |rhs|)) elementwise, r the residual,
    γ = (m + 2) eps, ``inv`` the (pseudo-)inverse of ``mat``. Componentwise, so a
    badly scaled but well-conditioned system (diagonal S) is not penalised."""
    gamma = (mat.shape[0] + 2) * _EPS
    r = rhs - mat @ sol
    return np.abs(inv) @ (np.abs(r) + gamma * (np.abs(mat) @ np.abs(sol) + np.abs(rhs)))


def _weight_bound(
    w: FloatArray, mat: FloatArray, rhs: FloatArray, inv: FloatArray | None = None
) -> FloatArray:
    """Elementwise forward error bound |δW| of W solving W·mat = rhs (mat symmetric, i.e.
    mat·Wᵀ = rhsᵀ): S1 + S2 and S1 for the paper's W (2), D and S1 − S12 for the
    correlated one (``inv`` = D⁺ there); inf where W is not finite."""
    if not np.all(np.isfinite(w)):
        return np.full_like(w, np.inf)
    if inv is None:
        inv = np.asarray(np.linalg.inv(mat), dtype=float)
    return _bounded_error(mat, w.T, rhs.T, inv).T


def _weight_error(
    w: FloatArray, mat: FloatArray, rhs: FloatArray, inv: FloatArray | None = None
) -> float:
    """Relative forward error bound max|δW| / max|W| (see :func:`_weight_bound`)."""
    return _relative_weight_error(_weight_bound(w, mat, rhs, inv), w)


def _relative_weight_error(dw: FloatArray, w: FloatArray) -> float:
    """max|δW| / max|W| for an elementwise bound ``dw`` on W's error."""
    return float(np.max(dw) / max(float(np.max(np.abs(w))), np.finfo(float).tiny))


def _combination_bound(w: FloatArray, dw: FloatArray, x1: FloatArray, x2: FloatArray) -> FloatArray:
    """Elementwise error bound of a1 + W(a2 − a1) given |δW| ≤ dw: dw|a2 − a1| plus the
    round-off of the product and the sum."""
    spread = np.abs(x2 - x1)
    return dw @ spread + (x1.size + 2) * _EPS * (np.abs(x1) + np.abs(w) @ spread)


def _refuse_inaccurate(fn: str, err: float, what: str) -> None:
    """Functions that return a bare matrix cannot downgrade a status: refuse instead."""
    if not np.isfinite(err) or err > REJECT_TOL:
        raise ProblemError(
            f"fusion.{fn}: {what} is too ill-conditioned: the result's "
            f"relative forward error bound {err:.2g} exceeds {REJECT_TOL:g} "
            "(NumPy re-check)"
        )


def _wls_objective(
    x: FloatArray, a1: FloatArray, c1: FloatArray, a2: FloatArray, c2: FloatArray
) -> float:
    d1, d2 = x - a1, x - a2
    return float(d1 @ c1 @ d1 + d2 @ c2 @ d2)


S = TypeVar("S", bound=Solution)


def _note(v: Verdict) -> str:
    verdict = "fails the NumPy check" if v.status == Status.ERROR else "(NumPy check)"
    return f"{v.key} {v.worst:.1e} {verdict}"


def _finish(sol: S) -> S:
    """A solver's (or a closed form's) 'optimal' is not taken on trust: the one gate
    (:func:`optmodels.core.finish`, i.e. :func:`~optmodels.core.verified_status` of the
    largest NumPy-recomputed residual). A result that is not OK keeps no estimate (NaN),
    and no W/covariance if W failed."""
    return finish(sol, note=_note, reject=_failure)
