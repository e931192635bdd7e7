"""Merges disallowed (``max_group_size = 1``): the resolved-only MAP hypothesis of (13) as a
linear assignment on the augmented gain matrix (:func:`linear_assignment`, scipy), re-checked
against the recomputed score.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from optmodels.assignment.data import AssignmentData, block_log_prior, log_likelihoods, score
from optmodels.assignment.solution import AssignmentSolution, _canonical
from optmodels.core import Status, as_instance, failure, finish, timed


def linear_assignment(data: AssignmentData) -> AssignmentSolution:
    """Merges disallowed: a linear assignment on the augmented N × (Q + N) gain matrix
    (object columns: ln φ_ij + ln P_D − ln(1 − P_D); clutter column i: −ln Δx, others
    forbidden), by :func:`scipy.optimize.linear_sum_assignment`.

    The result is re-checked in NumPy: the hypothesis is valid and its score (13),
    recomputed, equals the assignment's total gain plus the constant Σ_j ln(1 − P_D) to
    :data:`~optmodels.core.VERIFY_TOL` (relative); otherwise it is downgraded or refused
    (:func:`~optmodels.core.verified_status`).
    """
    as_instance("assignment.linear_assignment data", data, AssignmentData)
    with timed() as tm:
        q, n = data.q, data.n
        singles = [(j,) for j in range(q)]
        gain = log_likelihoods(data, singles) + np.array(
            [block_log_prior(data, g, True) - block_log_prior(data, g, False) for g in singles]
        )
        mat = np.full((n, q + n), -np.inf)  # -inf: forbidden (scipy's convention)
        mat[:, :q] = gain
        mat[np.arange(n), q + np.arange(n)] = -math.log(data.volume)
        rows, cols = linear_sum_assignment(mat, maximize=True)
        assign = np.full(n, -1)
        for r, c in zip(rows, cols, strict=True):
            if c < q:
                assign[r] = c
        total = float(mat[rows, cols].sum()) + sum(block_log_prior(data, g, False) for g in singles)
    part, assign = _canonical(singles, assign)
    s = score(data, part, assign)
    res = {"objective": abs(total - s) / max(1.0, abs(s)) if np.isfinite(s) else math.inf}
    sol = AssignmentSolution(
        status=Status.OPTIMAL,
        objective=s,
        method="linear_assignment",
        solve_time=tm.elapsed,
        partition=part,
        assignment=assign,
        log_score=s,
        mip_gap=0.0,
        residuals=res,
    )
    return finish(
        sol,
        note=lambda v: "",
        reject=lambda bad: failure(
            AssignmentSolution,
            "linear_assignment",
            "the assignment's total gain and the recomputed score disagree",
            status=bad.status,
            solve_time=tm.elapsed,
            residuals=res,
        ),
    )
