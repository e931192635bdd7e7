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

import contextlib
import ctypes
import functools
import itertools
import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sps
from cvxpy.reductions.solvers.defines import MI_SOLVERS
from scipy.optimize import linear_sum_assignment
from scipy.special import comb

from optmodels.backends.cvxpy_backend import available_solvers, solve_problem
from optmodels.core import (
    VERIFY_TOL,
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_count,
    as_finite_array,
    as_number,
    as_positive,
    as_probability,
    check_spd,
    check_spd_stack,
    timed,
    verified_status,
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

#: Size guards (documented in the README). Candidate groups (z_S columns) enumerated at
#: most; beyond it the gate/max_group_size must be tightened. The count is checked while
#: the cliques grow, before anything of that size is allocated.
MAX_CANDIDATE_GROUPS = 100_000
#: Entries of the ln φ_iS table (N × candidate groups, 8 bytes each: 160 MB at the limit).
MAX_LIKELIHOOD_ENTRIES = 20_000_000
#: Binary columns of the MILP (z_S + γ_iS + γ_i0) after pruning; about 1 kB of peak memory
#: each in CVXPY + HiGHS (measured, ``solvers_cmp/bench_assignment_memory.py``).
MAX_MODEL_COLUMNS = 1_000_000
#: :func:`brute_force` refuses above this many hypotheses (:func:`count_hypotheses`); it
#: scores about 10⁵ per second, so the limit is about two minutes.
BRUTE_FORCE_LIMIT = 10_000_000
#: :func:`count_hypotheses` / :func:`count_per_variant` accept Q, N up to this (exact
#: big-integer counts; Q = N = 1000 takes about two seconds).
COUNT_LIMIT = 1000
#: :func:`k_best` solves one MILP per hypothesis: at most this many.
K_BEST_LIMIT = 10_000
#: CVXPY solvers that take integer variables; any other name is refused.
MILP_SOLVERS: tuple[str, ...] = tuple(MI_SOLVERS)


# ----------------------------------------------------------------------------- data
@dataclass
class AssignmentData:
    """Predictions ``means`` (Q, d), ``covs`` (Q, d, d); ``measurements`` (N, d) with noise
    ``meas_cov`` (d, d); surveillance ``volume`` Δx (m^d); detection probability ``pd`` ∈
    (0, 1); per-merge prior factor ``rho`` ∈ (0, 1]; candidate groups limited by
    ``max_group_size`` (default: all sizes) and ``group_gate`` (members pairwise within
    this Mahalanobis distance of each other's predictions, under K_i + K_j; default: no
    gate). Units SI: means and measurements in m (or the sensor's own units, the same
    for all), covariances in their square, Δx in m^d.

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
        w = "assignment.AssignmentData"
        self.means = as_finite_array(f"{w} means", self.means, ndim=2)
        q, d = self.means.shape
        if q < 1 or d < 1:
            raise ProblemError(f"{w} means: need at least one object with at least one "
                               f"coordinate, got shape {self.means.shape}")
        self.covs = as_finite_array(f"{w} covs", self.covs, shape=(q, d, d))
        check_spd_stack(f"{w} covs", self.covs)
        meas = self.measurements
        if meas is not None and not isinstance(meas, str) and np.size(meas) == 0:
            meas = np.zeros((0, d))
        self.measurements = as_finite_array(f"{w} measurements", meas, ndim=2)
        if self.measurements.shape[1] != d:
            raise ProblemError(f"{w} measurements: expected (N, {d}) like means, got "
                               f"{self.measurements.shape}")
        self.meas_cov = as_finite_array(f"{w} meas_cov", self.meas_cov, shape=(d, d))
        check_spd(f"{w} meas_cov", self.meas_cov)
        self.pd = as_probability(f"{w} pd", self.pd, low_open=True, high_open=True)
        # Δx (m^d, SI) enters through its logarithm: positive and finite. ρ is the prior
        # factor of one merge, P(H) ∝ ρ^(Q − |π|): in (0, 1] (ρ > 1 would make merged
        # variants a priori more likely than the resolved one)
        self.volume = as_positive(f"{w} volume", self.volume)
        self.rho = as_probability(f"{w} rho", self.rho, low_open=True)
        if self.max_group_size is not None:
            self.max_group_size = as_count(f"{w} max_group_size", self.max_group_size,
                                           minimum=1)
        if self.group_gate is not None:
            self.group_gate = as_positive(f"{w} group_gate", self.group_gate, allow_inf=True)
        for name in ("log_likelihood", "block_log_prior"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise ProblemError(f"{w} {name}: expected a callable or None, got "
                                   f"{type(getattr(self, name)).__name__}")

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
    Σ_k C(B, k) · N!/(N − k)!, by the exact recurrence
    t_{k+1} = t_k (B − k)(N − k)/(k + 1)."""
    total, term = 0, 1
    for k in range(min(blocks, n) + 1):
        total += term
        term = term * (blocks - k) // (k + 1) * (n - k)
    return total


def _check_counts(where: str, q: Any, n: Any) -> tuple[int, int]:
    return (as_count(f"{where} q", q, minimum=1, maximum=COUNT_LIMIT),
            as_count(f"{where} n", n, minimum=0, maximum=COUNT_LIMIT))


def count_per_variant(q: int, n: int) -> dict[int, tuple[int, int]]:
    """For each number of blocks B: (number of unresolved variants with B blocks — the
    Stirling number S(Q, B) —, hypotheses per such variant).

    Parameters
    ----------
    q, n : int
        Objects Q ≥ 1 and measurements N ≥ 0, each at most :data:`COUNT_LIMIT`.
    """
    q, n = _check_counts("assignment.count_per_variant", q, n)
    row = [1] + [0] * q  # S(0, ·)
    for i in range(1, q + 1):  # S(i, b) = b S(i − 1, b) + S(i − 1, b − 1), one row kept
        row = [0] + [b * row[b] + row[b - 1] for b in range(1, i + 1)] + [0] * (q - i)
    return {b: (row[b], _assignments_count(b, n)) for b in range(1, q + 1)}


def count_hypotheses(q: int, n: int) -> int:
    """Total number of hypotheses H = (π, γ) over all unresolved variants (closed form:
    Σ_B S(Q, B) Σ_k C(B, k) N!/(N − k)!). For Q = 3 there are Bell(3) = 5 variants, as the
    paper says. The paper's "30 MHT vs 8 JPDA hypotheses for two objects and three marks"
    follow another convention (gated measurements; MHT also allows "new target"): see
    :func:`count_gated`.

    Raises
    ------
    ProblemError
        If Q or N is not a whole number in [1, :data:`COUNT_LIMIT`] resp.
        [0, :data:`COUNT_LIMIT`].
    """
    q, n = _check_counts("assignment.count_hypotheses", q, n)
    return sum(s * h for s, h in count_per_variant(q, n).values())


def count_gated(gates: Sequence[Sequence[int]], *, new_target: bool = False) -> int:
    """Resolved-only joint events when measurement i may only go to the targets in
    ``gates[i]`` (each target at most once), or to clutter — and, with ``new_target``, to
    a new track as well. The classic two-target, three-measurement example (measurement 1
    gated by target 0, 2 by both, 3 by target 1) gives 8 (JPDA) and 30 (MHT with new
    targets): the paper's numbers."""
    w = "assignment.count_gated gates"
    try:
        gate_lists = [[as_count(f"{w}[{i}]", t) for t in g] for i, g in enumerate(gates)]
    except TypeError:
        raise ProblemError(f"{w}: expected a list of lists of target indices") from None
    size = math.prod(len(g) + 1 for g in gate_lists)
    if size > BRUTE_FORCE_LIMIT:
        raise ProblemError(f"{w}: {size:.3g} joint choices to enumerate, above the limit "
                           f"{BRUTE_FORCE_LIMIT:.0e}")
    extra = 2 if bool(new_target) else 1
    total = 0
    for choice in itertools.product(*[[*g, -1] for g in gate_lists]):
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


def candidate_groups(data: AssignmentData, *,
                     limit: int | None = None) -> list[tuple[int, ...]]:
    """Singletons and the groups allowed by ``max_group_size`` and ``group_gate`` (cliques
    of the gate graph: members pairwise within the gate under K_i + K_j), in
    lexicographic order by size.

    Raises
    ------
    ProblemError
        If there are more than ``limit`` (default :data:`MAX_CANDIDATE_GROUPS`): refused
        while the cliques grow (or, without a gate, from the count Σ_s C(Q, s)), before
        the list or any model of that size is built.
    """
    limit = MAX_CANDIDATE_GROUPS if limit is None else as_count(
        "assignment.candidate_groups limit", limit, minimum=1)
    q = data.q
    size = q if data.max_group_size is None else min(q, int(data.max_group_size))

    def refuse(count: str) -> ProblemError:
        return ProblemError(
            f"assignment: {count} candidate groups (Q = {q}, max_group_size = "
            f"{data.max_group_size}, group_gate = {data.group_gate}), above the limit "
            f"{limit}; tighten group_gate or lower max_group_size (merges of more than a "
            f"few objects are rarely plausible)")

    gated = data.group_gate is not None and np.isfinite(data.group_gate)
    if not gated:
        total = sum(int(comb(q, k, exact=True)) for k in range(1, size + 1))
        if total > limit:
            raise refuse(f"{total:.3g}")
    ok = np.ones((q, q), dtype=bool)
    if gated and size >= 2:
        gate2 = float(data.group_gate) ** 2
        for i in range(q - 1):  # Mahalanobis distance to the later objects, one batch
            dm = data.means[i + 1:] - data.means[i]
            s = data.covs[i + 1:] + data.covs[i]
            d2 = np.einsum("kd,kd->k", dm, np.linalg.solve(s, dm[..., None])[..., 0])
            ok[i, i + 1:] = ok[i + 1:, i] = d2 <= gate2
    out: list[tuple[int, ...]] = [(j,) for j in range(q)]
    # grow cliques of the gate graph in lexicographic order; each carries the mask of the
    # objects adjacent to all its members
    frontier: list[tuple[tuple[int, ...], np.ndarray]] = [((j,), ok[j]) for j in range(q)]
    for _ in range(2, size + 1):
        nxt: list[tuple[tuple[int, ...], np.ndarray]] = []
        for g, common in frontier:
            for j in np.flatnonzero(common[g[-1] + 1:]) + g[-1] + 1:
                nxt.append(((*g, int(j)), common & ok[j]))
            if len(out) + len(nxt) > limit:
                raise refuse(f"more than {limit}")
        out.extend(g for g, _ in nxt)
        frontier = nxt
        if not frontier:
            break
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
            try:
                v = np.asarray(data.log_likelihood(data, tuple(g)), dtype=float)
            except (TypeError, ValueError) as exc:
                raise ProblemError(f"log_likelihood: not a numeric array for block {g} "
                                   f"({exc})") from None
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
    blocks = _as_partition("assignment.score partition", partition, data.q)
    a = _as_assignment("assignment.score assignment", assignment, data.n, len(blocks))
    used = [k for k in a if k >= 0]
    ll = loglik if loglik is not None else dict(zip(blocks, log_likelihoods(data, blocks).T,
                                                    strict=True))
    s = sum(block_log_prior(data, b, k in used) for k, b in enumerate(blocks))
    for i, k in enumerate(a):
        s += float(ll[blocks[k]][i]) if k >= 0 else -math.log(data.volume)
    return s


def _as_partition(name: str, partition: Any, q: int) -> Partition:
    """``partition`` as sorted tuples of object indices that cover 0..Q−1 exactly once."""
    try:
        blocks = [tuple(sorted(as_count(f"{name} entry", j, maximum=q - 1) for j in b))
                  for b in partition]
    except TypeError:
        raise ProblemError(f"{name}: expected a list of blocks (lists of object "
                           f"indices), got {type(partition).__name__}") from None
    if any(not b for b in blocks) or sorted(j for b in blocks for j in b) != list(range(q)):
        raise ProblemError(f"{name}: must cover every object 0..{q - 1} exactly once "
                           f"with non-empty blocks")
    return blocks


def _as_assignment(name: str, assignment: Any, n: int, blocks: int) -> list[int]:
    """``assignment`` as N block indices or −1, no block twice."""
    try:
        a = [as_count(f"{name} entry", k, minimum=-1, maximum=blocks - 1) for k in assignment]
    except TypeError:
        raise ProblemError(f"{name}: expected one block index or −1 per measurement") from None
    if len(a) != n:
        raise ProblemError(f"{name}: one entry per measurement ({n}), got {len(a)}")
    used = [k for k in a if k >= 0]
    if len(used) != len(set(used)):
        raise ProblemError(f"{name}: a block received more than one measurement")
    return a


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


def brute_force(data: AssignmentData, *,
                max_hypotheses: int = BRUTE_FORCE_LIMIT) -> AssignmentSolution:
    """The paper's method (13)-(14): score every hypothesis, keep the best (ties: the
    first).

    Raises
    ------
    ProblemError
        If :func:`count_hypotheses` exceeds ``max_hypotheses`` (default
        :data:`BRUTE_FORCE_LIMIT` = 10⁷, about two minutes at 10⁵ hypotheses per second):
        use :func:`solve` (the same MAP as one MILP) instead.
    """
    limit = as_count("assignment.brute_force max_hypotheses", max_hypotheses, minimum=1)
    total = count_hypotheses(data.q, data.n) if data.q <= COUNT_LIMIT and \
        data.n <= COUNT_LIMIT else math.inf
    if total > limit:
        raise ProblemError(
            f"assignment.brute_force: Q = {data.q}, N = {data.n} gives {float(total):.3g} "
            f"hypotheses, above max_hypotheses = {limit:.3g}; use assignment.solve (the "
            f"same MAP hypothesis as one MILP) or assignment.k_best for several")
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
    if best is None or not np.isfinite(best[0]):
        return AssignmentSolution(status=Status.ERROR, objective=float("nan"),
                                  method="brute_force", solve_time=tm.elapsed,
                                  message="no hypothesis with a finite score",
                                  info={"hypotheses": count})
    part, assign = _canonical(best[1], best[2])
    return AssignmentSolution(status=Status.OPTIMAL, objective=best[0], method="brute_force",
                              solve_time=tm.elapsed, partition=part, assignment=assign,
                              log_score=best[0], mip_gap=0.0, info={"hypotheses": count})


def linear_assignment(data: AssignmentData) -> AssignmentSolution:
    """Merges disallowed: a linear assignment on the augmented N × (Q + N) gain matrix
    (object columns: ln φ_ij + ln P_D − ln(1 − P_D); clutter column i: −ln Δx, others
    forbidden), by :func:`scipy.optimize.linear_sum_assignment`.

    The result is re-checked in NumPy: the hypothesis is valid and its score (13),
    recomputed, equals the assignment's total gain plus the constant Σ_j ln(1 − P_D) to
    :data:`~optmodels.core.VERIFY_TOL` (relative); otherwise it is downgraded or refused
    (:func:`~optmodels.core.verified_status`).
    """
    with timed() as tm:
        q, n = data.q, data.n
        singles = [(j,) for j in range(q)]
        gain = log_likelihoods(data, singles) + np.array(
            [block_log_prior(data, g, True) - block_log_prior(data, g, False)
             for g in singles])
        mat = np.full((n, q + n), -np.inf)  # -inf: forbidden (scipy's convention)
        mat[:, :q] = gain
        mat[np.arange(n), q + np.arange(n)] = -math.log(data.volume)
        rows, cols = linear_sum_assignment(mat, maximize=True)
        assign = np.full(n, -1)
        for r, c in zip(rows, cols, strict=True):
            if c < q:
                assign[r] = c
        total = float(mat[rows, cols].sum()) + sum(block_log_prior(data, g, False)
                                                   for g in singles)
    part, assign = _canonical(singles, assign)
    s = score(data, part, assign)
    res = {"objective": abs(total - s) / max(1.0, abs(s)) if np.isfinite(s) else math.inf}
    status = verified_status(Status.OPTIMAL, res["objective"])
    if not status.ok:
        return AssignmentSolution(status=status, objective=float("nan"),
                                  method="linear_assignment", solve_time=tm.elapsed,
                                  residuals=res, message="the assignment's total gain and "
                                  "the recomputed score disagree")
    return AssignmentSolution(status=status, objective=s, method="linear_assignment",
                              solve_time=tm.elapsed, partition=part, assignment=assign,
                              log_score=s, mip_gap=0.0, residuals=res)


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


@functools.cache
def _silence_highs_banner() -> None:
    """HiGHS prints its banner ("Running HiGHS 1.x ...") from C to the process's stdout
    when the first ``Highs`` object of the process is created, before any option
    (``output_flag``, ``log_to_console``) can be set -- CVXPY creates it inside the solve.
    Create that first object here with file descriptor 1 pointed at /dev/null, once per
    process; later objects print nothing with CVXPY's ``log_to_console=False``."""
    try:
        import highspy
    except ImportError:  # HiGHS not installed: nothing to silence
        return
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no usable fd 1: nothing to protect
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        highspy.Highs()
        with contextlib.suppress(OSError, AttributeError):  # flush C stdio before restoring
            ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _solver_options(where: str, solver: str, mip_gap: float, time_limit: float | None,
                    verbose: bool) -> dict[str, Any]:
    """Each MILP solver's own names for the relative gap and the time limit (s)."""
    if solver == "HIGHS":
        # mip_abs_gap 1e-12 (log-score units): with mip_rel_gap = 0 HiGHS stops when the
        # bound is within round-off of the incumbent; the gap it reports is ~1e-16
        # presolve off: on these set-partitioning models HiGHS 1.16's presolve is the
        # bottleneck (Q = 200, pairs allowed: 54 s of presolve, then 3 s of branch and
        # bound; 5 s in all without it), and the root LP is already tight; pass
        # presolve="on" to restore it
        opts: dict[str, Any] = {"mip_rel_gap": mip_gap,
                                "mip_abs_gap": 1e-12 if mip_gap == 0 else 1e-6,
                                "output_flag": verbose, "presolve": "off"}
        if time_limit is not None:
            opts["time_limit"] = time_limit
        return opts
    if solver == "SCIPY":  # scipy.optimize.milp (HiGHS inside)
        sopts: dict[str, Any] = {"mip_rel_gap": mip_gap}
        if time_limit is not None:
            sopts["time_limit"] = time_limit
        return {"scipy_options": sopts}
    if solver == "SCIP":
        params: dict[str, Any] = {"limits/gap": mip_gap}
        if time_limit is not None:
            params["limits/time"] = time_limit
        return {"scip_params": params}
    if time_limit is not None or mip_gap != 0:
        raise ProblemError(f"{where} solver: time_limit and mip_gap are passed to HIGHS, "
                           f"SCIPY and SCIP only; give {solver}'s own options instead")
    return {}


def _as_solver(where: str, solver: Any) -> str:
    if not isinstance(solver, str):
        raise ProblemError(f"{where} solver: expected a solver name, got {solver!r}")
    key = solver.upper()
    if key not in MILP_SOLVERS:
        installed = [s for s in MILP_SOLVERS if s in available_solvers()]
        raise ProblemError(f"{where} solver: {solver!r} does not solve integer programs; "
                           f"use a MILP solver ({', '.join(installed)} installed here)")
    return key


def _build_model(data: AssignmentData, groups: list[tuple[int, ...]], gain: FloatArray,
                 keep: np.ndarray, exclude: Sequence[AssignmentSolution],
                 fixed: bool) -> tuple[FloatArray, sps.csr_matrix, sps.csr_matrix,
                                       FloatArray]:
    """The MILP in one vector x = (z_S, γ_iS for the kept pairs, γ_i0): objective c and
    sparse constraints A_eq x = 1, A_ub x ≤ b_ub (every matrix has O(columns) nonzeros).

    Rows of A_eq: exact cover (Q), each measurement once (N). Rows of A_ub: each block at
    most one measurement, Σ_i γ_iS − z_S ≤ 0 (G); one no-good cut per excluded hypothesis:
    Σ_{x ∈ on(H)} x ≤ |on(H)| − 1 over H's blocks and its N measurement choices (a
    feasible point with all of them on equals H, by the equalities, so this removes H and
    nothing else; it has |π| + N nonzeros instead of a dense row).
    """
    q, n, n_g, n_k = data.q, data.n, len(groups), len(keep)
    bg = -math.log(data.volume)
    g_cost = np.array([block_log_prior(data, g, False) for g in groups])
    c = np.concatenate([g_cost, gain[keep[:, 0], keep[:, 1]] if n_k else [],
                        np.full(n, bg)])
    cols = n_g + n_k + n
    member_r = [j for g in groups for j in g]
    member_c = [c_ for c_, g in enumerate(groups) for _ in g]
    rows = np.concatenate([member_r, q + keep[:, 0], q + np.arange(n)]).astype(int)
    colx = np.concatenate([member_c, n_g + np.arange(n_k), n_g + n_k + np.arange(n)])
    a_eq = sps.csr_matrix((np.ones(len(rows)), (rows, colx.astype(int))), shape=(q + n, cols))
    ub_r = [np.arange(n_g), keep[:, 1]]
    ub_c = [np.arange(n_g), n_g + np.arange(n_k)]
    ub_v = [-np.ones(n_g), np.ones(n_k)]
    b_ub = [np.zeros(n_g)]
    index = {g: k for k, g in enumerate(groups)}
    pair = {(int(i), int(k)): n_g + m for m, (i, k) in enumerate(keep)}
    for r, h in enumerate(exclude):
        if any(b not in index for b in h.partition):
            continue  # a block that is not a column here: H is not in this model anyway
        on = [index[b] for b in h.partition]
        for i, k in enumerate(h.assignment):
            if k >= 0:
                col = pair.get((i, index[h.partition[k]]))
                if col is None:  # that pair is not in the model: H is excluded already
                    on = []
                    break
                on.append(col)
            else:
                on.append(n_g + n_k + i)
        if not on:
            continue
        ub_r.append(np.full(len(on), n_g + r))
        ub_c.append(np.array(on))
        ub_v.append(np.ones(len(on)))
        b_ub.append(np.array([len(on) - 1.0]))
    b = np.concatenate(b_ub)
    a_ub = sps.csr_matrix((np.concatenate(ub_v), (np.concatenate(ub_r).astype(int),
                                                  np.concatenate(ub_c).astype(int))),
                          shape=(len(b), cols))
    if fixed:  # z_S = 1 for the given blocks (implied by the cover; stated for clarity)
        a_ub = sps.vstack([a_ub, -sps.eye(n_g, cols, format="csr")], format="csr")
        b = np.concatenate([b, -np.ones(n_g)])
    return c, a_eq, a_ub, b


def _recheck(data: AssignmentData, groups: list[tuple[int, ...]], keep: np.ndarray,
             x: FloatArray, a_eq: sps.csr_matrix, a_ub: sps.csr_matrix, b_ub: FloatArray,
             solver_objective: float, exclude: Sequence[AssignmentSolution],
             fixed: Partition | None) -> tuple[Partition, np.ndarray, float,
                                               dict[str, float], str]:
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
    res["exact_cover"] = float(np.max(np.abs(eq[:data.q]), initial=0.0))
    res["one_source"] = float(np.max(np.abs(eq[data.q:]), initial=0.0))
    ub = a_ub @ x - b_ub
    res["block_capacity"] = float(np.max(np.maximum(ub[:n_g], 0.0), initial=0.0))
    res["no_good_cuts"] = float(np.max(np.maximum(ub[n_g:], 0.0), initial=0.0))
    z_on = np.flatnonzero(xr[:n_g] > 0.5)
    part = [groups[c] for c in z_on]
    where = {g: k for k, g in enumerate(part)}
    assign = np.full(data.n, -1)
    why = ""
    for v, (i, c) in zip(xr[n_g:n_g + n_k], keep, strict=True):
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
    if not why and any(h.partition == part and list(h.assignment) == list(assign)
                       for h in exclude):
        why = "the solver returned an excluded hypothesis"
    if not why and fixed is not None and part != sorted(fixed):
        why = "the solver changed the fixed partition"
    if why or not np.isfinite(s):
        res["objective"] = math.inf
        return part, assign, s, res, why or "the recomputed score is not finite"
    res["objective"] = (abs(solver_objective - s) / max(1.0, abs(s))
                        if np.isfinite(solver_objective) else math.inf)
    return part, assign, s, res, ""


def solve(data: AssignmentData, *, solver: str = "HIGHS", mip_gap: float = 0.0,
          time_limit: float | None = None, fixed_partition: Partition | None = None,
          prune: bool = True, exclude: Sequence[AssignmentSolution] = (),
          **options: Any) -> AssignmentSolution:
    """The joint MAP hypothesis of (13)-(14) as one MILP (CVXPY; HiGHS by default).

    Parameters
    ----------
    data : AssignmentData
    solver : str
        A CVXPY MILP solver (:data:`MILP_SOLVERS`; HIGHS, SCIPY, SCIP, ...). A continuous
        solver (CLARABEL, OSQP, ...) is refused with :class:`ProblemError`.
    mip_gap : float
        Relative MIP gap in [0, 1) to stop at; 0 (default) proves optimality. A solution
        with a reached gap above :data:`~optmodels.core.VERIFY_TOL` (relative to
        max(1, |score|)) is OPTIMAL_INACCURATE, never OPTIMAL.
    time_limit : float, optional
        Seconds, positive and finite (None: no limit). A solve stopped by it is
        ITERATION_LIMIT (with the gap reached in the message), never returned as a
        solution.
    fixed_partition : list of tuples, optional
        Solve one unresolved variant (the per-variant problem of (14)).
    prune : bool
        Exact dominance pruning (module docstring). ``False`` keeps every variable (needed
        when hypotheses other than the MAP matter, as in :func:`k_best`).
    exclude : sequence of AssignmentSolution
        Hypotheses to exclude, one sparse no-good cut each.
    **options
        Passed to the solver (its own names; ``verbose=True`` shows its log).

    Returns
    -------
    AssignmentSolution
        The hypothesis, re-checked in NumPy (:func:`_recheck`): integrality, every
        constraint row, a valid partition and assignment, and the recomputed score (13)
        against the solver's objective; ``residuals`` holds them and the status is
        downgraded or refused by :func:`~optmodels.core.verified_status`.

    Raises
    ------
    ProblemError
        Bad arguments, or a model above the size guards :data:`MAX_CANDIDATE_GROUPS`,
        :data:`MAX_LIKELIHOOD_ENTRIES`, :data:`MAX_MODEL_COLUMNS` (checked before the
        model is allocated).
    """
    w = "assignment.solve"
    if not isinstance(data, AssignmentData):
        raise ProblemError(f"{w} data: expected AssignmentData, got {type(data).__name__}")
    key = _as_solver(w, solver)
    gap = as_number(f"{w} mip_gap", mip_gap, low=0.0, high=1.0, high_open=True)
    limit = None if time_limit is None else as_positive(f"{w} time_limit", time_limit)
    if not isinstance(prune, bool | np.bool_):
        raise ProblemError(f"{w} prune: expected True or False, got {prune!r}")
    if isinstance(exclude, AssignmentSolution) or not all(
            isinstance(h, AssignmentSolution) for h in exclude):
        raise ProblemError(f"{w} exclude: expected a sequence of AssignmentSolution")
    fixed = None
    if fixed_partition is not None:
        fixed = _as_partition(f"{w} fixed_partition", fixed_partition, data.q)
        groups = sorted(set(fixed))
    else:
        groups = candidate_groups(data)
    q, n = data.q, data.n
    if n * len(groups) > MAX_LIKELIHOOD_ENTRIES:
        raise ProblemError(f"{w}: N × candidate groups = {n} × {len(groups)} likelihoods, "
                           f"above the limit {MAX_LIKELIHOOD_ENTRIES:.0e}; tighten "
                           f"group_gate or lower max_group_size")
    with timed() as tb:
        ll = log_likelihoods(data, groups)
        bonus = np.array([block_log_prior(data, g, True) - block_log_prior(data, g, False)
                          for g in groups])
        bg = -math.log(data.volume)
        gain = ll + bonus
        if prune:
            usable = gain > bg  # exact pruning 1 (module docstring)
            if fixed is None and data.block_log_prior is None:
                groups, gain, usable = _prune(data, groups, gain, usable)
        else:
            usable = np.isfinite(gain)  # a user's −inf likelihood: impossible, no variable
        keep = np.argwhere(usable).reshape(-1, 2)
        columns = len(groups) + len(keep) + n
        if columns > MAX_MODEL_COLUMNS:
            raise ProblemError(
                f"{w}: {columns} binary columns ({len(groups)} groups, {len(keep)} "
                f"measurement-group pairs), above the limit {MAX_MODEL_COLUMNS:.0e}"
                + ("; prune=False keeps every pair" if not prune else "")
                + "; tighten group_gate or lower max_group_size")
        c, a_eq, a_ub, b_ub = _build_model(data, groups, gain, keep, exclude,
                                           fixed is not None)
        x = cp.Variable(columns, boolean=True)
        cons = [a_eq @ x == np.ones(q + n)]
        if a_ub.shape[0]:
            cons.append(a_ub @ x <= b_ub)
        prob = cp.Problem(cp.Maximize(c @ x), cons)
    if key == "HIGHS":
        _silence_highs_banner()
    opts = _solver_options(w, key, gap, limit, bool(options.get("verbose", False)))
    res = solve_problem(prob, key, **{**opts, **options})
    common = res.common()
    common["build_time"] += tb.elapsed
    gap_reached = res.info.get("mip_gap")
    info = dict(res.info, candidate_groups=len(groups), assignment_variables=len(keep))
    if not res.status.ok or x.value is None:
        msg = common.pop("message")
        if gap_reached is not None and np.isfinite(gap_reached):
            msg += f"; MIP gap reached {gap_reached:.3g}"
        if res.status.ok:  # OK without a point: not a solution
            common["status"] = Status.ERROR
        return AssignmentSolution(objective=float("nan"), message=msg, mip_gap=gap_reached,
                                  info=info, **common)
    xv = np.asarray(x.value, dtype=float).reshape(-1)
    part, assign, s, resid, why = _recheck(data, groups, keep, xv, a_eq, a_ub, b_ub,
                                           float(res.objective), exclude, fixed)
    status = verified_status(res.status, max(resid.values()))
    message = common.pop("message")
    common.pop("status")
    if why:
        message += f"; re-check failed: {why}"
    elif not status.ok:
        message += f"; re-check failed: residuals {resid}"
    if status.ok and gap_reached is not None and np.isfinite(gap_reached):
        # HiGHS' gap is relative to |incumbent|; judge it relative to max(1, |score|)
        scaled = gap_reached * abs(s) / max(1.0, abs(s))
        if scaled > VERIFY_TOL and status is Status.OPTIMAL:
            status = Status.OPTIMAL_INACCURATE
            message += f"; stopped at MIP gap {gap_reached:.3g} (not proven optimal)"
    if not status.ok:
        return AssignmentSolution(status=status, objective=float("nan"), message=message,
                                  mip_gap=gap_reached, residuals=resid,
                                  info=dict(info, rejected_partition=part,
                                            rejected_assignment=assign), **common)
    return AssignmentSolution(status=status, objective=s, partition=part, assignment=assign,
                              log_score=s, message=message,
                              mip_gap=gap_reached if gap_reached is not None else gap,
                              residuals=resid, info=info, **common)


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
