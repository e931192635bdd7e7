"""Counting and enumerating the hypotheses H = (π, γ) of (13)-(14), and the paper's own
method: score every hypothesis and keep the best (:func:`brute_force`, (13)-(14)).

Holds: :func:`set_partitions` (the unresolved variants π, Bell(Q) of them),
:func:`count_per_variant`, :func:`count_hypotheses` (closed-form counts, up to
:data:`COUNT_LIMIT`), :func:`count_gated` (the paper's "30 vs 8"),
:func:`enumerate_hypotheses` and :func:`brute_force` (refused above
:data:`BRUTE_FORCE_LIMIT`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from optmodels.assignment.data import AssignmentData, Partition, log_likelihoods, score
from optmodels.assignment.groups import candidate_groups
from optmodels.assignment.solution import AssignmentSolution, _canonical
from optmodels.core import ProblemError, Status, as_count, as_instance, timed

#: :func:`brute_force` refuses above this many hypotheses (:func:`count_hypotheses`); it
#: scores about 10⁵ per second, so the limit is about two minutes.
BRUTE_FORCE_LIMIT = 10_000_000
#: :func:`count_hypotheses` / :func:`count_per_variant` accept Q, N up to this (exact
#: big-integer counts; Q = N = 1000 takes about two seconds).
COUNT_LIMIT = 1000


# ----------------------------------------------------------------------------- counting
def set_partitions(items: Sequence[int]) -> Iterator[Partition]:
    """Every set partition of ``items`` (Bell(Q) of them), blocks as sorted tuples.

    Raises
    ------
    ProblemError
        Naming ``items`` if it is not a sequence of distinct integers (object indices).
    """
    name = "assignment.set_partitions items"
    if isinstance(items, str | bytes | dict) or not hasattr(items, "__iter__"):
        raise ProblemError(
            f"{name}: expected a sequence of object indices, got {type(items).__name__}"
        )
    try:
        checked = [as_count(f"{name} entry", j, minimum=0) for j in items]
    except TypeError:
        raise ProblemError(f"{name}: expected a sequence of object indices") from None
    if len(set(checked)) != len(checked):
        raise ProblemError(f"{name}: the indices must be distinct, got {checked}")
    return _set_partitions(checked)


def _set_partitions(items: list[int]) -> Iterator[Partition]:
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for part in _set_partitions(rest):
        for k in range(len(part)):
            yield [*part[:k], tuple(sorted((first, *part[k]))), *part[k + 1 :]]
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
    return (
        as_count(f"{where} q", q, minimum=1, maximum=COUNT_LIMIT),
        as_count(f"{where} n", n, minimum=0, maximum=COUNT_LIMIT),
    )


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
        raise ProblemError(
            f"{w}: {size:.3g} joint choices to enumerate, above the limit {BRUTE_FORCE_LIMIT:.0e}"
        )
    extra = 2 if bool(new_target) else 1
    total = 0
    for choice in itertools.product(*[[*g, -1] for g in gate_lists]):
        used = [c for c in choice if c >= 0]
        if len(used) == len(set(used)):
            total += extra ** sum(1 for c in choice if c < 0)
    return total


# ----------------------------------------------------------------------------- enumeration
def enumerate_hypotheses(data: AssignmentData) -> Iterator[tuple[Partition, tuple[int, ...]]]:
    """Every hypothesis (14): each set partition (restricted to candidate groups) and each
    assignment of the measurements to its blocks (≤ 1 each) or the background."""
    as_instance("assignment.enumerate_hypotheses data", data, AssignmentData)
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


def brute_force(
    data: AssignmentData, *, max_hypotheses: int = BRUTE_FORCE_LIMIT
) -> AssignmentSolution:
    """The paper's method (13)-(14): score every hypothesis, keep the best (ties: the
    first).

    Raises
    ------
    ProblemError
        If :func:`count_hypotheses` exceeds ``max_hypotheses`` (default
        :data:`BRUTE_FORCE_LIMIT` = 10⁷, about two minutes at 10⁵ hypotheses per second):
        use :func:`solve` (the same MAP as one MILP) instead.
    """
    as_instance("assignment.brute_force data", data, AssignmentData)
    limit = as_count("assignment.brute_force max_hypotheses", max_hypotheses, minimum=1)
    total = (
        count_hypotheses(data.q, data.n)
        if data.q <= COUNT_LIMIT and data.n <= COUNT_LIMIT
        else math.inf
    )
    if total > limit:
        raise ProblemError(
            f"assignment.brute_force: Q = {data.q}, N = {data.n} gives {float(total):.3g} "
            f"hypotheses, above max_hypotheses = {limit:.3g}; use assignment.solve (the "
            f"same MAP hypothesis as one MILP) or assignment.k_best for several"
        )
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
        return AssignmentSolution(
            status=Status.ERROR,
            objective=float("nan"),
            method="brute_force",
            solve_time=tm.elapsed,
            message="no hypothesis with a finite score",
            info={"hypotheses": count},
        )
    part, assign = _canonical(best[1], best[2])
    return AssignmentSolution(
        status=Status.OPTIMAL,
        objective=best[0],
        method="brute_force",
        solve_time=tm.elapsed,
        partition=part,
        assignment=assign,
        log_score=best[0],
        mip_gap=0.0,
        info={"hypotheses": count},
    )
