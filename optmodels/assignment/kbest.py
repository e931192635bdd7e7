"""The k best hypotheses of (13)-(14) by repeated MILPs with no-good cuts, and the
JPDA-style posterior marginals β from them (:func:`k_best`, :class:`KBest`; at most
:data:`K_BEST_LIMIT` MILPs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from optmodels.assignment.data import AssignmentData, AssignmentSolution
from optmodels.assignment.hypotheses import COUNT_LIMIT, count_hypotheses
from optmodels.assignment.milp import solve
from optmodels.assignment.solvers import _as_solver
from optmodels.core import Status, as_count

#: :func:`k_best` solves one MILP per hypothesis: at most this many.
K_BEST_LIMIT = 10_000


@dataclass(frozen=True)
class KBest:
    """The ``k`` best hypotheses (best first) and approximate posterior marginals:
    ``beta[i]`` maps a block (tuple) or ``()`` (background) to P(measurement i from it),
    from the k best normalised; ``neglected`` bounds the posterior mass of the hypotheses
    not listed, relative to the listed: (M − k)·e^{s_k} / Σ_listed e^{s} with M the total
    number of hypotheses and s_k the k-th best score (every unlisted one scores ≤ s_k)."""

    hypotheses: list[AssignmentSolution]
    beta: list[dict[tuple[int, ...], float]]
    neglected: float


def k_best(data: AssignmentData, k: int, *, solver: str = "HIGHS") -> KBest:
    """The k best hypotheses by repeated MILPs with no-good cuts (no pruning, so that the
    2nd, 3rd, … best are not removed as dominated), and JPDA-style marginals from them.

    Parameters
    ----------
    k : int
        Whole number in [1, :data:`K_BEST_LIMIT`] (2.5 is refused, not truncated); fewer
        are returned when fewer hypotheses exist. Each costs one MILP.
    solver : str
        A MILP solver, as in :func:`solve`.

    Raises
    ------
    ProblemError
        Bad ``k`` or ``solver``, or the unpruned model above :data:`MAX_MODEL_COLUMNS`.
    SolveError
        If one of the MILPs fails.
    """
    k = as_count("assignment.k_best k", k, minimum=1, maximum=K_BEST_LIMIT)
    _as_solver("assignment.k_best", solver)
    found: list[AssignmentSolution] = []
    for _ in range(k):
        s = solve(data, solver=solver, prune=False, exclude=found)
        if s.status is Status.INFEASIBLE:
            break  # fewer than k hypotheses exist
        found.append(s.require_ok())
    scores = np.array([h.log_score for h in found])
    w = np.exp(scores - scores.max())
    w /= w.sum()
    beta: list[dict[tuple[int, ...], float]] = [{} for _ in range(data.n)]
    for h, wh in zip(found, w, strict=True):
        for i, a in enumerate(h.assignment):
            key = h.partition[a] if a >= 0 else ()
            beta[i][key] = beta[i].get(key, 0.0) + float(wh)
    total = count_hypotheses(data.q, data.n) if max(data.q, data.n) <= COUNT_LIMIT else None
    rest = None if total is None else max(total - len(found), 0)
    if rest == 0:
        neglected = 0.0
    else:  # in logs: the count may exceed the float range
        log_rest = math.inf if rest is None else math.log(rest)
        log_mass = log_rest + float(scores[-1] - scores.max()) - math.log(
            float(np.exp(scores - scores.max()).sum()))
        neglected = math.exp(log_mass) if log_mass < 700 else math.inf
    return KBest(found, beta, neglected)
