r"""The NumPy re-check of a MILP point against the original problem (13)-(14) of paper 004
and the gate of the package's MILP solves (the CVXPY model of
:mod:`~optmodels.assignment.milp` and the decomposed path of
:mod:`~optmodels.assignment.decomposed`).

Holds :func:`_recheck` (integrality, every constraint row, a valid hypothesis, the
recomputed score (13) against the solver's objective) and :func:`_finish` (the re-check,
then :func:`optmodels.core.finish` with the failure form
:func:`optmodels.assignment.solution._failure`, then the MIP-gap note).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from optmodels.assignment.data import AssignmentData, Partition, score
from optmodels.assignment.solution import AssignmentSolution, _canonical, _failure
from optmodels.core import VERIFY_TOL, FloatArray, ProblemError, Status, Verdict, finish


class Matrix(Protocol):
    """A constraint matrix as the re-check applies it, ``A @ x``: a scipy.sparse matrix
    (the CVXPY model) or :class:`~optmodels.assignment.decomposed.Rows` (the decomposed
    path)."""

    def __matmul__(self, x: FloatArray, /) -> FloatArray: ...


# ----------------------------------------------------------------------------- re-check
def _recheck(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    keep: np.ndarray,
    x: FloatArray,
    a_eq: Matrix,
    a_ub: Matrix,
    b_ub: FloatArray,
    solver_objective: float,
    exclude: Sequence[AssignmentSolution],
    fixed: Partition | None,
) -> tuple[Partition, np.ndarray, float, dict[str, float], str]:
    """Re-check the solver's point against the original problem, in NumPy.

    Returns the rounded hypothesis, its recomputed score (13) and the residuals: the
    integrality of x, the constraint rows at x (exact cover, one source per measurement,
    ≤ 1 measurement per block, the no-good cuts), and the relative difference between
    the solver's objective and the recomputed score. A rounded point that is not a valid
    hypothesis (or repeats an excluded one) gives an infinite residual and a message.
    """
    n_g, n_k = len(groups), len(keep)
    xr = np.round(x)
    res = {"integrality": float(np.max(np.abs(x - xr), initial=0.0))}
    eq = a_eq @ x - 1.0
    res["exact_cover"] = float(np.max(np.abs(eq[: data.q]), initial=0.0))
    res["one_source"] = float(np.max(np.abs(eq[data.q :]), initial=0.0))
    ub = a_ub @ x - b_ub
    res["block_capacity"] = float(np.max(np.maximum(ub[:n_g], 0.0), initial=0.0))
    res["no_good_cuts"] = float(np.max(np.maximum(ub[n_g:], 0.0), initial=0.0))
    z_on = np.flatnonzero(xr[:n_g] > 0.5)
    part = [groups[c] for c in z_on]
    where = {g: k for k, g in enumerate(part)}
    assign = np.full(data.n, -1)
    why = ""
    for v, (i, c) in zip(xr[n_g : n_g + n_k], keep, strict=True):
        if v > 0.5:
            if groups[c] not in where or assign[i] >= 0:
                why = "γ assigns a measurement twice or to a block that is off"
            else:
                assign[i] = where[groups[c]]
    s = math.nan
    if not why:
        try:
            part, assign = _canonical(part, assign)
            s = score(data, part, assign)
        except ProblemError as exc:
            why = f"the rounded point is not a hypothesis ({exc})"
    if not why and any(h.partition == part and list(h.assignment) == list(assign) for h in exclude):
        why = "the solver returned an excluded hypothesis"
    if not why and fixed is not None and part != sorted(fixed):
        why = "the solver changed the fixed partition"
    if why or not np.isfinite(s):
        res["objective"] = math.inf
        return part, assign, s, res, why or "the recomputed score is not finite"
    res["objective"] = (
        abs(solver_objective - s) / max(1.0, abs(s)) if np.isfinite(solver_objective) else math.inf
    )
    return part, assign, s, res, ""


# ----------------------------------------------------------------------------- the gate
def _finish(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    keep: np.ndarray,
    x: FloatArray,
    a_eq: Matrix,
    a_ub: Matrix,
    b_ub: FloatArray,
    solver_objective: float,
    exclude: Sequence[AssignmentSolution],
    fixed: Partition | None,
    *,
    common: dict[str, Any],
    gap_reached: float | None,
    gap: float,
    info: dict[str, Any],
) -> AssignmentSolution:
    """End of a MILP solve for the solver's point ``x`` (``common``: the back-end's
    fields, status OK): :func:`_recheck`, then the one gate
    (:func:`optmodels.core.finish`) on its residuals; refused: the failure form
    :func:`~optmodels.assignment.solution._failure` (no hypothesis; the rounded one in
    ``info["rejected_partition"]``/``["rejected_assignment"]``). Accepted OPTIMAL with a
    reached MIP gap above VERIFY_TOL (relative to max(1, |score|)) is OPTIMAL_INACCURATE:
    not proven optimal."""
    part, assign, s, resid, why = _recheck(
        data, groups, keep, x, a_eq, a_ub, b_ub, solver_objective, exclude, fixed
    )
    fields = {k: v for k, v in common.items() if k not in ("status", "message")}

    def note(v: Verdict) -> str:
        if why:
            return f"re-check failed: {why}"
        return "" if v.status.ok else f"re-check failed: residuals {resid}"

    sol = AssignmentSolution(
        status=common["status"],
        objective=s,
        partition=part,
        assignment=assign,
        log_score=s,
        message=common["message"],
        mip_gap=gap_reached if gap_reached is not None else gap,
        residuals=resid,
        info=info,
        **fields,
    )
    sol = finish(sol, note=note, reject=lambda bad: _failure(bad, gap_reached))
    if sol.ok and gap_reached is not None and np.isfinite(gap_reached):
        # HiGHS' gap is relative to |incumbent|; judge it relative to max(1, |score|)
        scaled = gap_reached * abs(s) / max(1.0, abs(s))
        if scaled > VERIFY_TOL and sol.status is Status.OPTIMAL:
            sol.status = Status.OPTIMAL_INACCURATE
            sol.message += f"; stopped at MIP gap {gap_reached:.3g} (not proven optimal)"
    return sol
