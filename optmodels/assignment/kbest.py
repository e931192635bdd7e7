r"""The k best hypotheses of (13)-(14) and the JPDA-style posterior marginals β from them
(:func:`k_best`, :class:`KBest`; at most :data:`K_BEST_LIMIT` MILPs).

Scheme (exact; ``docs/formulations.md``): the MAP by the pruned MILP; k distinct feasible
hypotheses around it (single changes, repeated from the k best seen until the k-th stops
rising; scored in NumPy) give a lower bound L ≤ s_k on the k-th best score; a dual point
of the LP relaxation of the *unpruned* model (by column generation from every z_S, the
background and the γ_iS that beat it) gives, for each column c, an upper bound U_c on the
score of every hypothesis that uses c (valid for any dual point, computed in NumPy over
every column: it does not trust the LP solver); the columns with U_c < L are removed —
every hypothesis using one scores below s_k — and the k best are found by MILPs with
no-good cuts on that reduced model, each re-checked in NumPy. Nothing here depends on the
likelihood or the block prior (one R or R_i each; constant ρ or a sensor): L is a score
of feasible hypotheses and U_c weak duality on the model's own objective.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps
from scipy.optimize import linprog

from optmodels.assignment.data import AssignmentData, Partition, block_log_prior, score
from optmodels.assignment.generic import solve
from optmodels.assignment.groups import candidate_groups
from optmodels.assignment.hypotheses import COUNT_LIMIT, count_hypotheses
from optmodels.assignment.milp import (
    MAX_MODEL_COLUMNS,
    _build_model,
    _gains,
    _solve_model,
)
from optmodels.assignment.solution import AssignmentSolution, _canonical
from optmodels.assignment.solvers import _as_solver
from optmodels.core import FloatArray, ProblemError, Status, as_count, as_instance

#: :func:`k_best` solves one MILP per hypothesis: at most this many.
K_BEST_LIMIT = 10_000
#: Relative slack of the bound test U_c < L (round-off of the NumPy sums, ~1e-13).
_BOUND_TOL = 1e-9
#: At most this many rounds of the neighbour search for the lower bound L (each expands
#: the k best hypotheses seen so far that were not expanded yet).
_NEIGHBOUR_ROUNDS = 6
#: The LP relaxation's method (scipy's HiGHS). Any dual point gives valid bounds, so the
#: method changes only their tightness: on issue 18's case the interior point is 3× faster
#: (0.5 s vs 1.7 s) but its dual point keeps 1221 merged groups instead of 25, and the
#: k − 1 MILPs then cost more than the simplex saves.
_LP_METHOD = "highs-ds"


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


Hypothesis = tuple[tuple[tuple[int, ...], ...], tuple[int, ...]]


def _neighbours(
    partition: Partition, assignment: Sequence[int], allowed: set[tuple[int, ...]]
) -> list[tuple[Partition, list[int]]]:
    """Hypotheses one change away from ``h``: a measurement moved to the background or to
    another block (its previous owner's measurement to the background), a merged block
    split into singletons (its measurement to the background or to one member), two
    blocks merged when the union is a candidate group (keeping either measurement)."""
    part, a = list(partition), [int(x) for x in assignment]
    owner = {k: i for i, k in enumerate(a) if k >= 0}
    out: list[tuple[Partition, list[int]]] = []
    for i, ki in enumerate(a):
        if ki >= 0:
            out.append((part, [*a[:i], -1, *a[i + 1 :]]))
        for b in range(len(part)):
            if b != ki:
                new = list(a)
                if b in owner:
                    new[owner[b]] = -1
                new[i] = b
                out.append((part, new))
    for b, blk in enumerate(part):
        if len(blk) < 2:
            continue
        rest = [x for x in part if x != blk]
        split = rest + [(j,) for j in blk]
        idx = {x: m for m, x in enumerate(split)}
        base = [idx[part[k]] if k >= 0 and k != b else -1 for k in a]
        out.append((split, base))
        if b in owner:
            for j in blk:
                new = list(base)
                new[owner[b]] = idx[(j,)]
                out.append((split, new))
    for b1 in range(len(part)):
        for b2 in range(b1 + 1, len(part)):
            union = tuple(sorted(part[b1] + part[b2]))
            if union not in allowed:
                continue
            merged = [x for m, x in enumerate(part) if m not in (b1, b2)] + [union]
            idx = {x: m for m, x in enumerate(merged)}
            base = [idx[part[k]] if k >= 0 and k not in (b1, b2) else -1 for k in a]
            out.append((merged, base))
            for b in (b1, b2):
                if b in owner:
                    new = list(base)
                    new[owner[b]] = idx[union]
                    out.append((merged, new))
    return out


def _lower_bound(
    data: AssignmentData,
    first: AssignmentSolution,
    k: int,
    groups: list[tuple[int, ...]],
    ll: FloatArray,
) -> float:
    """A lower bound L on the k-th best score: the k-th best of k distinct feasible
    hypotheses (the MAP and its neighbours; rounds expanding the k best seen, at most
    :data:`_NEIGHBOUR_ROUNDS`, until the k-th stops rising), scored from the likelihood
    table (the k-th re-scored by :func:`score`); −inf when fewer than k are found."""
    if k == 1:
        return first.log_score
    table = dict(zip(groups, ll.T, strict=True))
    allowed = set(groups)
    seen: dict[Hypothesis, float] = {}
    prior: dict[tuple[tuple[int, ...], bool], float] = {}
    bg = -math.log(data.volume)
    rows = np.arange(data.n)

    def fast_score(p: Partition, aa: np.ndarray) -> float:
        """score (13) from the table, without :func:`score`'s validation (the
        neighbours are valid hypotheses by construction; the k-th is re-scored)."""
        used = set(int(x) for x in aa if x >= 0)
        total = 0.0
        for b, blk in enumerate(p):
            key = (blk, b in used)
            if key not in prior:
                prior[key] = block_log_prior(data, blk, b in used)
            total += prior[key]
        on = aa >= 0
        if on.any():
            total += float(sum(table[p[int(b)]][i] for i, b in zip(rows[on], aa[on], strict=True)))
        return total + bg * float(np.count_nonzero(~on))

    def add(part: Partition, a: Sequence[int] | np.ndarray) -> None:
        p, aa = _canonical(part, a)
        key = (tuple(p), tuple(int(x) for x in aa))
        if key not in seen:
            seen[key] = fast_score(p, aa)

    add(first.partition, first.assignment)
    frontier: list[Hypothesis] = list(seen)
    expanded: set[Hypothesis] = set()
    best = -math.inf
    for _ in range(_NEIGHBOUR_ROUNDS):  # expand the k best seen until the k-th stops rising
        for h in frontier:
            expanded.add(h)
            for part, aa in _neighbours(list(h[0]), h[1], allowed):
                add(part, aa)
        top = sorted(seen.items(), key=lambda x: -x[1])[:k]
        kth = top[-1][1] if len(top) >= k else -math.inf
        frontier = [h for h, _ in top if h not in expanded]
        if not frontier or (kth <= best and len(top) >= k):
            break
        best = kth
    ranked = sorted(((s, h) for h, s in seen.items() if np.isfinite(s)), key=lambda x: -x[0])
    if len(ranked) < k:
        return -math.inf
    # L = the k-th score, recomputed by score() (k distinct hypotheses score ≥ it)
    kth_part, kth_assign = ranked[k - 1][1]
    exact = score(data, list(kth_part), list(kth_assign), table)
    return min(exact, ranked[k - 1][0])


def _lp_duals(
    c: FloatArray, a_eq: Any, a_ub: Any, b_ub: FloatArray
) -> tuple[FloatArray, FloatArray] | None:
    """A dual point (y, u ≥ 0) of the LP relaxation max c·x, A_eq x = 1, A_ub x ≤ b_ub,
    0 ≤ x ≤ 1 (HiGHS), or None."""
    try:
        res = linprog(
            -c,
            A_ub=a_ub if a_ub.shape[0] else None,
            b_ub=b_ub if a_ub.shape[0] else None,
            A_eq=a_eq,
            b_eq=np.ones(a_eq.shape[0]),
            bounds=(0.0, 1.0),
            method=_LP_METHOD,
        )
    except (ValueError, ArithmeticError):  # no bound: nothing is removed
        return None
    if res.status != 0 or res.eqlin is None:
        return None
    y = -np.asarray(res.eqlin.marginals, dtype=float)
    u = (
        np.maximum(-np.asarray(res.ineqlin.marginals, dtype=float), 0.0)
        if a_ub.shape[0]
        else np.zeros(0)
    )
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
        return None
    return y, u


def _column_bounds(
    c: FloatArray,
    a_eq: Any,
    a_ub: Any,
    b_ub: FloatArray,
    start: np.ndarray | None = None,
    *,
    rounds: int = 12,
) -> FloatArray | None:
    """U_c ≥ the objective of every 0/1 point of the model with x_c = 1, from a dual
    point (y, u ≥ 0) of the LP relaxation: with r = c − A_eqᵀy − A_ubᵀu and
    D = Σy + u·b + Σ max(0, r), c·x ≤ D + min(0, r_c) for every x ∈ [0, 1] feasible with
    x_c = 1 (weak duality, any y and u ≥ 0). None if the LP gives no dual point.

    With ``start`` (a column mask that is feasible on its own: the background and
    singleton columns) the dual point comes from column generation: the LP restricted to
    the active columns (and the capacity rows of their groups, u = 0 on the others), then
    every column with r > 0 added, at most ``rounds`` times. Any dual point gives valid
    bounds, so stopping early only weakens them; the restricted LPs are much smaller
    than the full one (issue 18: Q = 12, N = 14, every group: 61 439 columns)."""
    y: FloatArray | None = None
    u: FloatArray | None = None
    if start is None:
        duals = _lp_duals(c, a_eq, a_ub, b_ub)
        if duals is None:
            return None
        y, u = duals
    else:
        a_ub = sps.csr_matrix(a_ub)
        n_rows = a_ub.shape[0]
        csc = a_ub.tocsc()
        owner = np.full(len(c), -1)  # each column's capacity row (its group), −1: none
        nz = np.diff(csc.indptr) > 0
        owner[nz] = csc.indices[csc.indptr[:-1][nz]]
        z_of_row = np.full(n_rows, -1)
        zc = np.flatnonzero(np.asarray(csc.min(axis=0).todense()).ravel() < 0)
        z_of_row[owner[zc]] = zc
        active = start.copy()
        for _ in range(rounds):
            rows = np.unique(owner[active & (owner >= 0)])
            active[z_of_row[rows]] = True
            cols = np.flatnonzero(active)
            duals = _lp_duals(c[cols], a_eq[:, cols], a_ub[rows][:, cols], b_ub[rows])
            if duals is None:
                break
            y, u_sub = duals
            u = np.zeros(n_rows)
            u[rows] = u_sub
            r = c - a_eq.T @ y - a_ub.T @ u
            new = np.flatnonzero((r > 1e-9) & ~active)
            if not len(new):
                break  # the restricted LP's optimum is the full LP's
            active[new] = True
    if y is None or u is None:
        return None
    r = c - a_eq.T @ y - (a_ub.T @ u if a_ub.shape[0] else 0.0)
    d = float(y.sum() + u @ b_ub + np.maximum(r, 0.0).sum())
    return d + np.minimum(r, 0.0)


def k_best(data: AssignmentData, k: int, *, solver: str = "HIGHS") -> KBest:
    """The k best hypotheses (exact: module docstring) and JPDA-style marginals from them.

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
    w = "assignment.k_best"
    k = as_count(f"{w} k", k, minimum=1, maximum=K_BEST_LIMIT)
    key = _as_solver(w, solver)
    as_instance(f"{w} data", data, AssignmentData)
    groups = candidate_groups(data)
    n = data.n
    ll, gain = _gains(w, data, groups)
    keep = np.argwhere(np.isfinite(gain)).reshape(-1, 2)  # −inf: impossible, no column
    n_g, n_k = len(groups), len(keep)
    if n_g + n_k + n > MAX_MODEL_COLUMNS:
        raise ProblemError(
            f"{w}: {n_g + n_k + n} binary columns ({n_g} groups, {n_k} measurement-group "
            f"pairs), above the limit {MAX_MODEL_COLUMNS:.0e}; tighten group_gate or "
            f"lower max_group_size"
        )
    first = solve(data, solver=key)
    if first.status is Status.INFEASIBLE:
        return _result(data, [])
    found = [first.require_ok()]
    if k > 1:
        low = _lower_bound(data, first, k, groups, ll)
        if np.isfinite(low):  # drop the columns no hypothesis scoring ≥ L uses
            c, a_eq, a_ub, b_ub = _build_model(data, groups, gain, keep, (), False)
            # column generation from every z_S, the background and the γ_iS that beat
            # it (issue 18's case: one LP of 15 761 of the 61 439 columns, converged)
            bg = -math.log(data.volume)
            start = np.concatenate(
                [
                    np.ones(n_g, dtype=bool),
                    gain[keep[:, 0], keep[:, 1]] > bg,
                    np.ones(n, dtype=bool),
                ]
            )
            bound = _column_bounds(c, a_eq, a_ub, b_ub, start)
            if bound is not None:
                ok = bound >= low - _BOUND_TOL * max(1.0, abs(low))
                ok_g = ok[:n_g] | np.array([len(g) == 1 for g in groups], dtype=bool)
                ok_k = ok[n_g : n_g + n_k] & ok_g[keep[:, 1]]
                new_index = np.cumsum(ok_g) - 1
                groups = [g for g, o in zip(groups, ok_g, strict=True) if o]
                gain = gain[:, ok_g]
                keep = np.column_stack([keep[ok_k, 0], new_index[keep[ok_k, 1]]])
    for _ in range(k - 1):
        s = _solve_model(w, data, groups, gain, keep, found, None, key, 0.0, None, {}, 0.0)
        if s.status is Status.INFEASIBLE:
            break  # fewer than k hypotheses exist (only when nothing was removed)
        found.append(s.require_ok())
    return _result(data, found)


def _result(data: AssignmentData, found: list[AssignmentSolution]) -> KBest:
    """KBest from the hypotheses found: β from their normalised weights, and the bound on
    the neglected mass."""
    beta: list[dict[tuple[int, ...], float]] = [{} for _ in range(data.n)]
    if not found:
        return KBest(found, beta, math.inf)
    scores = np.array([h.log_score for h in found])
    w = np.exp(scores - scores.max())
    w /= w.sum()
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
        log_mass = (
            log_rest
            + float(scores[-1] - scores.max())
            - math.log(float(np.exp(scores - scores.max()).sum()))
        )
        neglected = math.exp(log_mass) if log_mass < 700 else math.inf
    return KBest(found, beta, neglected)
