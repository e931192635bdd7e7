r"""ML joint assignment of measurements to closely spaced objects that may be unresolved,
with clutter (paper 004, Logachev, Khudov, Shchennikov), as one integer program.

Paper: ``shared/papers/004_ce4b6db66d57cef7.txt``. The paper's rule (13)-(14) enumerates
every unresolved variant (a set partition π of the Q objects) and every identification
matrix γ; optmodels solves the same maximisation exactly as one MILP.

Model (the paper leaves the group likelihood and the prior open; this is the default):

* object j predicted N(m_j, K_j); a measurement of it is N(x; m_j, K_j + K1) -- (5);
* an unresolved group S (|S| ≥ 2) gives one measurement at the members' mean:
  N(x; mean_{j∈S} m_j, Σ_{j∈S}K_j/|S|² + K1);
* background (clutter): 1/Δx -- (8);
* hypothesis H = (π, γ): every measurement goes to exactly one block of π or to the
  background, every block gets at most one measurement;
* ln P(H) = (Q − |π|) ln ρ + Σ_{S∈π}[d_S ln P_D + (1 − d_S) ln(1 − P_D)];
* score(H) = ln P(H) + Σ_i ln φ_{i,γ(i)}; the MAP hypothesis maximises it.

MILP (binary z_S per candidate group, γ_iS, γ_i0):

.. math::
    \max\ \sum_S z_S\,[(|S|-1)\ln\rho + \ln(1-P_D)]
          + \sum_{i,S}\gamma_{iS}\,[\ln\varphi_{iS} + \ln P_D - \ln(1-P_D)]
          - \sum_i \gamma_{i0}\ln\Delta x

subject to Σ_{S∋j} z_S = 1 (exact cover), Σ_i γ_iS ≤ z_S, Σ_S γ_iS + γ_i0 = 1 (the
equality (2) omits). Since Σ_S z_S |S| = Q, the first sum is exactly (Q − |π|)ln ρ plus
|π| ln(1 − P_D). Exact pruning: a γ_iS whose gain ln φ_iS + ln P_D − ln(1 − P_D) does not
exceed the background's −ln Δx can be replaced by γ_i0 without lowering the score, so it
is never needed for a MAP hypothesis and is not created.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.special import comb, perm

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_finite_array,
    check_spd,
    check_spd_stack,
    timed,
)

__all__ = [
    "AssignmentData",
    "AssignmentSolution",
    "KBest",
    "block_log_prior",
    "brute_force",
    "candidate_groups",
    "count_hypotheses",
    "count_per_variant",
    "enumerate_hypotheses",
    "k_best",
    "linear_assignment",
    "log_likelihoods",
    "score",
    "set_partitions",
    "solve",
]

Partition = list[tuple[int, ...]]


# ----------------------------------------------------------------------------- data
@dataclass
class AssignmentData:
    """Predictions ``means`` (Q, d), ``covs`` (Q, d, d); ``measurements`` (N, d) with noise
    ``meas_cov`` (d, d); surveillance ``volume`` Δx; detection probability ``pd`` ∈ (0, 1);
    per-merge prior factor ``rho`` > 0; candidate groups limited by ``max_group_size``
    (default: all sizes) and ``group_gate`` (members pairwise within this Mahalanobis
    distance of each other's predictions, under K_i + K_j; default: no gate).

    Your own model: ``log_likelihood(data, S)`` → (N,) ln φ_iS for block S (replaces the
    Gaussian default), and ``block_log_prior(S, detected)`` → the block's share of ln P(H)
    (default (|S| − 1) ln ρ + ln P_D or ln(1 − P_D)). The prior must decompose over blocks
    for the MILP to stay linear. With a custom prior only the background-dominance pruning
    is applied (the others rely on the default prior's form)."""

    means: FloatArray
    covs: FloatArray
    measurements: FloatArray
    meas_cov: FloatArray
    volume: float
    pd: float
    rho: float
    max_group_size: int | None = None
    group_gate: float | None = None
    log_likelihood: Callable[[AssignmentData, tuple[int, ...]], FloatArray] | None = None
    block_log_prior: Callable[[tuple[int, ...], bool], float] | None = None

    def __post_init__(self) -> None:
        self.means = as_finite_array("means", self.means, ndim=2)
        q, d = self.means.shape
        if q < 1:
            raise ProblemError("means: need at least one object")
        self.covs = as_finite_array("covs", self.covs, shape=(q, d, d))
        check_spd_stack("covs", self.covs)
        self.measurements = as_finite_array("measurements", np.asarray(
            self.measurements, dtype=float).reshape(-1, d) if np.size(self.measurements) == 0
            else self.measurements, ndim=2)
        if self.measurements.shape[1] != d:
            raise ProblemError(f"measurements: expected (N, {d}) like means, got "
                               f"{self.measurements.shape}")
        self.meas_cov = as_finite_array("meas_cov", self.meas_cov, shape=(d, d))
        check_spd("meas_cov", self.meas_cov)
        for name, lo, hi in (("pd", 0.0, 1.0),):
            v = float(getattr(self, name))
            if not lo < v < hi:
                raise ProblemError(f"{name}: must lie in (0, 1), got {v}")
        for name in ("volume", "rho"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise ProblemError(f"{name}: must be positive and finite, got {v}")
        if self.max_group_size is not None and int(self.max_group_size) < 1:
            raise ProblemError(f"max_group_size: need ≥ 1, got {self.max_group_size}")
        if self.group_gate is not None and not float(self.group_gate) > 0:
            raise ProblemError(f"group_gate: need a positive distance, got {self.group_gate}")

    @property
    def q(self) -> int:
        return int(self.means.shape[0])

    @property
    def n(self) -> int:
        return int(self.measurements.shape[0])


# ----------------------------------------------------------------------------- counting
def set_partitions(items: Sequence[int]) -> Iterator[Partition]:
    """Every set partition of ``items`` (Bell(Q) of them), blocks as sorted tuples."""
    items = list(items)
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for part in set_partitions(rest):
        for k in range(len(part)):
            yield [*part[:k], tuple(sorted((first, *part[k]))), *part[k + 1:]]
        yield [(first,), *part]


def _assignments_count(blocks: int, n: int) -> int:
    """Ways to give N measurements to B blocks (≤ 1 each) or the background:
    Σ_k C(B, k) · N!/(N − k)!."""
    return int(sum(comb(blocks, k, exact=True) * perm(n, k, exact=True)
                   for k in range(min(blocks, n) + 1)))


def count_per_variant(q: int, n: int) -> dict[int, tuple[int, int]]:
    """For each number of blocks B: (number of unresolved variants with B blocks — the
    Stirling number S(Q, B) —, hypotheses per such variant)."""
    stirling = [[0] * (q + 1) for _ in range(q + 1)]
    stirling[0][0] = 1
    for i in range(1, q + 1):
        for b in range(1, i + 1):
            stirling[i][b] = b * stirling[i - 1][b] + stirling[i - 1][b - 1]
    return {b: (stirling[q][b], _assignments_count(b, n)) for b in range(1, q + 1)}


def count_hypotheses(q: int, n: int) -> int:
    """Total number of hypotheses H = (π, γ) over all unresolved variants (closed form:
    Σ_B S(Q, B) Σ_k C(B, k) N!/(N − k)!). For Q = 3 there are Bell(3) = 5 variants, as the
    paper says. The paper's "30 MHT vs 8 JPDA hypotheses for two objects and three marks"
    follow another convention (gated measurements; MHT also allows "new target"): see
    :func:`count_gated`."""
    if q < 1 or n < 0:
        raise ProblemError(f"q, n: need Q ≥ 1 and N ≥ 0, got {q}, {n}")
    return sum(s * h for s, h in count_per_variant(q, n).values())


def count_gated(gates: Sequence[Sequence[int]], *, new_target: bool = False) -> int:
    """Resolved-only joint events when measurement i may only go to the targets in
    ``gates[i]`` (each target at most once), or to clutter — and, with ``new_target``, to
    a new track as well. The classic two-target, three-measurement example (measurement 1
    gated by target 0, 2 by both, 3 by target 1) gives 8 (JPDA) and 30 (MHT with new
    targets): the paper's numbers."""
    extra = 2 if new_target else 1
    total = 0
    for choice in itertools.product(*[[*g, -1] for g in gates]):
        used = [c for c in choice if c >= 0]
        if len(used) == len(set(used)):
            total += extra ** sum(1 for c in choice if c < 0)
    return total


# ----------------------------------------------------------------------------- likelihoods
def _logpdf(x: FloatArray, mean: FloatArray, cov: FloatArray) -> FloatArray:
    """ln N(x_i; mean, cov) for all rows of x (computed in logs; never log 0)."""
    chol = np.linalg.cholesky(cov)
    z = np.linalg.solve(chol, (x - mean).T)
    d = x.shape[1]
    return -0.5 * np.sum(z**2, axis=0) - np.sum(np.log(np.diag(chol))) - 0.5 * d * math.log(
        2 * math.pi)


def candidate_groups(data: AssignmentData) -> list[tuple[int, ...]]:
    """Singletons and the groups allowed by ``max_group_size`` and ``group_gate``."""
    q = data.q
    size = q if data.max_group_size is None else min(q, int(data.max_group_size))
    ok = np.ones((q, q), dtype=bool)
    if data.group_gate is not None:
        for i in range(q):
            for j in range(i + 1, q):
                dm = data.means[i] - data.means[j]
                s = data.covs[i] + data.covs[j]
                ok[i, j] = ok[j, i] = float(dm @ np.linalg.solve(s, dm)) <= data.group_gate**2
    out: list[tuple[int, ...]] = [(j,) for j in range(q)]
    if size >= 2:
        # grow cliques of the gate graph in lexicographic order
        frontier = [(j,) for j in range(q)]
        for _ in range(2, size + 1):
            nxt = []
            for g in frontier:
                for j in range(g[-1] + 1, q):
                    if all(ok[j, i] for i in g):
                        nxt.append((*g, j))
            out.extend(nxt)
            frontier = nxt
    return out


def block_log_prior(data: AssignmentData, group: tuple[int, ...], detected: bool) -> float:
    """A block's share of ln P(H): the user's ``block_log_prior`` or the default
    (|S| − 1) ln ρ + (ln P_D if detected else ln(1 − P_D))."""
    if data.block_log_prior is not None:
        v = float(data.block_log_prior(tuple(group), bool(detected)))
        if not np.isfinite(v):
            raise ProblemError(f"block_log_prior: non-finite value for {group}, {detected}")
        return v
    return (len(group) - 1) * math.log(data.rho) + (
        math.log(data.pd) if detected else math.log1p(-data.pd))


def log_likelihoods(data: AssignmentData, groups: Sequence[tuple[int, ...]]) -> FloatArray:
    """ln φ_iS (N, len(groups)): the user's ``log_likelihood`` or the default model."""
    out = np.empty((data.n, len(groups)))
    if data.log_likelihood is not None:
        for c, g in enumerate(groups):
            v = np.asarray(data.log_likelihood(data, tuple(g)), dtype=float)
            if v.shape != (data.n,) or np.any(np.isnan(v)) or np.any(v == np.inf):
                raise ProblemError(f"log_likelihood: expected {data.n} finite log values "
                                   f"(or −inf) for block {g}, got shape {v.shape}")
            out[:, c] = v
        return out
    for c, g in enumerate(groups):
        idx = list(g)
        mean = data.means[idx].mean(axis=0)
        cov = data.covs[idx].sum(axis=0) / len(idx) ** 2 + data.meas_cov
        out[:, c] = _logpdf(data.measurements, mean, cov) if data.n else []
    return out


def score(data: AssignmentData, partition: Partition, assignment: Sequence[int],
          loglik: dict[tuple[int, ...], FloatArray] | None = None) -> float:
    """score(H) of a hypothesis: ``assignment[i]`` indexes ``partition`` or is −1."""
    blocks = [tuple(sorted(b)) for b in partition]
    if sorted(j for b in blocks for j in b) != list(range(data.q)):
        raise ProblemError("partition: must cover every object exactly once")
    a = list(assignment)
    if len(a) != data.n or any(not -1 <= k < len(blocks) for k in a):
        raise ProblemError("assignment: one entry per measurement, −1 or a block index")
    used = [k for k in a if k >= 0]
    if len(used) != len(set(used)):
        raise ProblemError("assignment: a block received more than one measurement")
    ll = loglik if loglik is not None else dict(zip(blocks, log_likelihoods(data, blocks).T,
                                                    strict=True))
    s = sum(block_log_prior(data, b, k in used) for k, b in enumerate(blocks))
    for i, k in enumerate(a):
        s += float(ll[blocks[k]][i]) if k >= 0 else -math.log(data.volume)
    return s


# ----------------------------------------------------------------------------- solutions
@dataclass
class AssignmentSolution(Solution):
    """``partition`` (sorted list of sorted tuples), ``assignment`` (N,) index into
    ``partition`` or −1 (background), ``log_score``, ``mip_gap`` reached."""

    partition: Partition = field(default_factory=list)
    assignment: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=int))
    log_score: float = float("nan")
    mip_gap: float | None = None


def _canonical(partition: Sequence[Sequence[int]], assignment: Sequence[int]
               ) -> tuple[Partition, np.ndarray]:
    blocks = [tuple(sorted(b)) for b in partition]
    order = sorted(range(len(blocks)), key=lambda k: blocks[k])
    new_index = {old: new for new, old in enumerate(order)}
    return [blocks[k] for k in order], np.array([new_index[k] if k >= 0 else -1
                                                 for k in assignment], dtype=int)


def enumerate_hypotheses(data: AssignmentData) -> Iterator[tuple[Partition, tuple[int, ...]]]:
    """Every hypothesis (14): each set partition (restricted to candidate groups) and each
    assignment of the measurements to its blocks (≤ 1 each) or the background."""
    allowed = set(candidate_groups(data))
    for part in set_partitions(range(data.q)):
        blocks = sorted(tuple(sorted(b)) for b in part)
        if any(b not in allowed for b in blocks):
            continue
        yield from ((blocks, a) for a in _assignments(len(blocks), data.n))


def _assignments(blocks: int, n: int) -> Iterator[tuple[int, ...]]:
    def rec(i: int, used: frozenset[int]) -> Iterator[tuple[int, ...]]:
        if i == n:
            yield ()
            return
        for rest in rec(i + 1, used):
            yield (-1, *rest)
        for k in range(blocks):
            if k not in used:
                for rest in rec(i + 1, used | {k}):
                    yield (k, *rest)

    # (recursion depth N; the hypotheses are yielded lazily)
    yield from rec(0, frozenset())


def brute_force(data: AssignmentData) -> AssignmentSolution:
    """The paper's method: score every hypothesis, keep the best (ties: the first)."""
    with timed() as tm:
        groups = candidate_groups(data)
        ll = dict(zip(groups, log_likelihoods(data, groups).T, strict=True))
        best: tuple[float, Partition, tuple[int, ...]] | None = None
        count = 0
        for part, a in enumerate_hypotheses(data):
            count += 1
            s = score(data, part, a, ll)
            if best is None or s > best[0] + 1e-12:
                best = (s, part, a)
    assert best is not None
    part, assign = _canonical(best[1], best[2])
    return AssignmentSolution(status=Status.OPTIMAL, objective=best[0], method="brute_force",
                              solve_time=tm.elapsed, partition=part, assignment=assign,
                              log_score=best[0], mip_gap=0.0, info={"hypotheses": count})


def linear_assignment(data: AssignmentData) -> AssignmentSolution:
    """Merges disallowed: a linear assignment on the augmented N × (Q + N) gain matrix
    (object columns: ln φ_ij + ln P_D − ln(1 − P_D); clutter column i: −ln Δx, others
    forbidden), by :func:`scipy.optimize.linear_sum_assignment`."""
    with timed() as tm:
        q, n = data.q, data.n
        singles = [(j,) for j in range(q)]
        gain = log_likelihoods(data, singles) + np.array(
            [block_log_prior(data, g, True) - block_log_prior(data, g, False)
             for g in singles])
        big = -1e300
        mat = np.full((n, q + n), big)
        mat[:, :q] = gain
        mat[np.arange(n), q + np.arange(n)] = -math.log(data.volume)
        rows, cols = linear_sum_assignment(mat, maximize=True)
        assign = np.full(n, -1)
        for r, c in zip(rows, cols, strict=True):
            if c < q:
                assign[r] = c
    part, assign = _canonical(singles, assign)
    s = score(data, part, assign)
    return AssignmentSolution(status=Status.OPTIMAL, objective=s, method="linear_assignment",
                              solve_time=tm.elapsed, partition=part, assignment=assign,
                              log_score=s, mip_gap=0.0)


# ----------------------------------------------------------------------------- MILP
def _prune(data: AssignmentData, groups: list[tuple[int, ...]], gain: FloatArray,
           usable: np.ndarray) -> tuple[list[tuple[int, ...]], FloatArray, np.ndarray]:
    """Exact dominance pruning of merged groups (never removes a MAP hypothesis).

    2. Measurement i on a merged group S is dominated if splitting S into singletons, giving
       i to its best member and leaving the others undetected, scores at least as much:
       (|S| − 1) ln ρ + gain_iS ≤ max_{j∈S} gain_ij + (|S| − 1) ln(1 − P_D); or if peeling
       one member j off (i on S ∖ {j}, {j} undetected) does: gain_iS + ln ρ ≤
       gain_{i,S∖j} + ln(1 − P_D). The swaps are always feasible (S's members are used
       nowhere else), so γ_iS is never needed.
    3. A merged group left without any measurement can only be undetected; if
       ρ ≤ 1 − P_D, its singletons (undetected) score at least as much
       (|S| ln(1 − P_D) ≥ (|S| − 1) ln ρ + ln(1 − P_D)), so z_S is never needed.
    """
    lr, l1 = math.log(data.rho), math.log1p(-data.pd)
    index = {g: c for c, g in enumerate(groups)}
    single = {g[0]: c for c, g in enumerate(groups) if len(g) == 1}
    keep_g = np.ones(len(groups), dtype=bool)
    for c, g in enumerate(groups):
        if len(g) == 1:
            continue
        best_member = np.max(gain[:, [single[j] for j in g]], axis=1)
        dominated = (len(g) - 1) * lr + gain[:, c] <= best_member + (len(g) - 1) * l1
        # 2'. peel one member j: S \ {j} keeps i, {j} undetected. S \ {j} is a candidate
        # too (subsets of a gated clique are cliques, sizes only shrink)
        for j in g:
            rest = index.get(tuple(x for x in g if x != j))
            if rest is not None:
                dominated |= gain[:, c] + lr <= gain[:, rest] + l1
        usable[:, c] &= ~dominated
        if not usable[:, c].any() and lr <= l1:
            keep_g[c] = False
    idx = np.flatnonzero(keep_g)
    return [groups[c] for c in idx], gain[:, idx], usable[:, idx]


def solve(data: AssignmentData, *, solver: str = "HIGHS", mip_gap: float = 0.0,
          time_limit: float | None = None, fixed_partition: Partition | None = None,
          prune: bool = True, exclude: Sequence[AssignmentSolution] = (),
          **options: Any) -> AssignmentSolution:
    """The joint MAP hypothesis as one MILP (CVXPY; HiGHS by default, SCIP where installed).

    ``fixed_partition`` solves one unresolved variant (the per-variant problem of (14)).
    ``prune=False`` keeps every variable (needed when hypotheses other than the MAP matter,
    as in :func:`k_best`); ``exclude`` adds a no-good cut per given hypothesis. The score
    of the returned hypothesis is re-computed in NumPy (``log_score``); a time or node
    limit is reported as ITERATION_LIMIT with the gap reached, never as optimal.
    """
    groups = candidate_groups(data)
    if fixed_partition is not None:
        fixed = [tuple(sorted(b)) for b in fixed_partition]
        groups = sorted(set(fixed))
        if sorted(j for b in groups for j in b) != list(range(data.q)):
            raise ProblemError("fixed_partition: must cover every object exactly once")
    with timed() as tb:
        q, n = data.q, data.n
        ll = log_likelihoods(data, groups)
        bonus = np.array([block_log_prior(data, g, True) - block_log_prior(data, g, False)
                          for g in groups])
        bg = -math.log(data.volume)
        gain = ll + bonus
        if prune:
            usable = gain > bg  # exact pruning 1 (module docstring)
            if fixed_partition is None and data.block_log_prior is None:
                groups, gain, usable = _prune(data, groups, gain, usable)
        else:
            usable = np.isfinite(gain)  # a user's −inf likelihood: impossible, no variable
        keep = np.argwhere(usable)
        g_cost = np.array([block_log_prior(data, g, False) for g in groups])
        z = cp.Variable(len(groups), boolean=True)
        gam = cp.Variable(len(keep), boolean=True) if len(keep) else None
        g0 = cp.Variable(n, boolean=True) if n else None
        member = np.zeros((q, len(groups)))
        for c, g in enumerate(groups):
            member[list(g), c] = 1.0
        cons = [member @ z == 1]
        obj = g_cost @ z
        if n:
            assert g0 is not None
            obj = obj + bg * cp.sum(g0)
            meas_rows = np.zeros((n, len(keep)))
            grp_rows = np.zeros((len(groups), len(keep)))
            if len(keep):
                meas_rows[keep[:, 0], np.arange(len(keep))] = 1.0
                grp_rows[keep[:, 1], np.arange(len(keep))] = 1.0
                assert gam is not None
                obj = obj + gain[keep[:, 0], keep[:, 1]] @ gam
                cons += [meas_rows @ gam + g0 == 1, grp_rows @ gam <= z]
            else:
                cons += [g0 == 1]
        if fixed_partition is not None:
            cons.append(z == 1)
        index = {g: c for c, g in enumerate(groups)}
        pair = {(int(i), int(c)): k for k, (i, c) in enumerate(keep)}
        for h in exclude:  # no-good cut: at least one binary differs from h
            z_on = np.zeros(len(groups))
            for b in h.partition:
                if b not in index:
                    raise ProblemError("exclude: a hypothesis uses a group outside the model")
                z_on[index[b]] = 1.0
            g_on = np.zeros(len(keep))
            for i, k in enumerate(h.assignment):
                if k >= 0:
                    g_on[pair[(i, index[h.partition[k]])]] = 1.0
            expr = (2 * z_on - 1) @ z
            if gam is not None:
                expr = expr + (2 * g_on - 1) @ gam
            cons.append(expr <= z_on.sum() + g_on.sum() - 1)
        prob = cp.Problem(cp.Maximize(obj), cons)
    opts: dict[str, Any] = {}
    if solver.upper() == "HIGHS":
        opts = {"mip_rel_gap": float(mip_gap), "mip_abs_gap": 1e-12 if mip_gap == 0 else 1e-6}
        if time_limit is not None:
            opts["time_limit"] = float(time_limit)
    elif solver.upper() == "SCIP":
        opts = {"scip_params": {"limits/gap": float(mip_gap)}}
        if time_limit is not None:
            opts["scip_params"]["limits/time"] = float(time_limit)
    res = solve_problem(prob, solver, **{**opts, **options})
    common = res.common()
    common["build_time"] += tb.elapsed
    gap_reached = res.info.get("mip_gap")
    if not res.status.ok or z.value is None:
        msg = common.pop("message")
        if gap_reached is not None and np.isfinite(gap_reached):
            msg += f"; MIP gap reached {gap_reached:.3g}"
        return AssignmentSolution(objective=float("nan"), message=msg, mip_gap=gap_reached,
                                  info=dict(res.info), **common)
    zv = np.round(z.value).astype(int)
    part = [groups[c] for c in np.flatnonzero(zv)]
    assign = np.full(n, -1)
    if gam is not None and gam.value is not None:
        for v, (i, c) in zip(np.round(gam.value).astype(int), keep, strict=True):
            if v:
                assign[i] = part.index(groups[c])
    part, assign = _canonical(part, assign)
    s = score(data, part, assign)
    sol = AssignmentSolution(objective=s, partition=part, assignment=assign, log_score=s,
                             mip_gap=gap_reached if gap_reached is not None else mip_gap,
                             **common)
    sol.info["candidate_groups"] = len(groups)
    sol.info["assignment_variables"] = len(keep)
    # the solver's objective and the recomputed score must agree (same model)
    if res.objective is not None and np.isfinite(res.objective):
        sol.residuals["objective"] = abs(res.objective - s) / max(1.0, abs(s))
    return sol


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
    2nd, 3rd, … best are not removed as dominated), and JPDA-style marginals from them."""
    if int(k) < 1:
        raise ProblemError(f"k: need k ≥ 1, got {k}")
    found: list[AssignmentSolution] = []
    for _ in range(int(k)):
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
    total = count_hypotheses(data.q, data.n)
    rest = max(total - len(found), 0)
    neglected = float(rest * np.exp(scores[-1] - scores.max()) / np.exp(
        scores - scores.max()).sum()) if rest else 0.0
    return KBest(found, beta, neglected)
