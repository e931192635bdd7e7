r"""The closed form (11) of the smoothest bias field (paper 001, section 4).

Closed form (11), with the sign fixed: η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰ (the printed (11) has no
minus sign; with (10)'s "+Φ¹η" the minimiser needs it), φ* = Φ⁰ + Φ¹η*. Solved by a sparse
LU factorisation (scipy ``splu``) of the 2K × 2K matrix, re-checked in NumPy against the
original problem (9)-(10) like a generic solve
(:func:`optmodels.biasfield.verify.recheck_closed_form`, ending in the gate).
The generic solves are :func:`optmodels.biasfield.generic.solve` (the QP (9)-(10) [+ (8)])
and :func:`optmodels.biasfield.generic.solve_lipschitz`.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import linalg as splinalg

from optmodels.biasfield.data import FieldData, uncertainty_sets
from optmodels.biasfield.problem import check_graph, r_matrix
from optmodels.biasfield.solution import FieldSolution
from optmodels.biasfield.verify import failed_solution, pack_solution, recheck_closed_form
from optmodels.core import ProblemError, Status, timed

__all__ = ["closed_form"]


def closed_form(data: FieldData) -> FieldSolution:
    """(11) with sparse linear algebra: η* = −(Φ¹ᵀRΦ¹)⁻¹Φ¹ᵀRΦ⁰, φ* = Φ⁰ + Φ¹η*.

    A neighbour graph in several components is solved as one (J and the sets decouple, so
    this is the per-component solution); ``info["components"]`` gives their number.

    The result is re-checked in NumPy against the original problem (9)-(10) like a generic
    solve: ``residuals["set"]`` (φ on the sets), ``["stationarity"]`` (Φ¹ᵀRφ relative to
    Φ¹ᵀRΦ⁰, the gradient at η = 0) and ``["conditioning"]`` = κ₁(Φ¹ᵀRΦ¹)·ε (the
    double-precision error floor of η; ``info["condition"]`` gives κ₁). The status follows
    :func:`optmodels.core.verified_status`: above :data:`VERIFY_TOL` OPTIMAL_INACCURATE,
    above :data:`REJECT_TOL` ERROR without a field (an ill-determined field is refused,
    not returned).
    """
    n_comp, _ = check_graph(data)
    with timed() as tm:
        phi0, phi1 = uncertainty_sets(data)
        r = r_matrix(data)
        a = (phi1.T @ r @ phi1).tocsc()
        b = phi1.T @ (r @ phi0)
        try:
            lu = splinalg.splu(a)
        except RuntimeError as exc:  # exactly singular
            raise ProblemError(
                f"biasfield.closed_form data: Φ1ᵀRΦ1 is singular ({exc}); the "
                "field is not identifiable on these cells"
            ) from None
        with np.errstate(all="ignore"):
            eta = -lu.solve(b)
        phi = phi0 + phi1 @ eta
    common = {
        "status": Status.OPTIMAL,
        "method": "closed_form",
        "solve_time": tm.elapsed,
        "message": "(11), sign corrected",
    }
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(eta))):
        common.update(
            status=Status.ERROR,
            message="(11): the solve overflowed (non-finite field); Φ1ᵀRΦ1 is numerically singular",
        )
        return failed_solution(data, (phi0, phi1), common, None)
    sol = pack_solution(data, (phi0, phi1), phi, eta, common, None, None)
    sol.info["components"] = n_comp
    return recheck_closed_form(sol, (phi0, phi1), r, a, lu)
