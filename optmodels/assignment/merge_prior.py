r"""The merge prior of an unresolved variant π from the sensor's pair probabilities u_ij
(:mod:`~optmodels.assignment.sensor`): the returns merge along chains of unresolved pairs,
pairs taken independent, so that

.. math::
    \ln P(\pi) = C + \sum_{S\in\pi} \ln w(S),\quad
    w(S) = P_{conn}(S) / \prod_{i<j\in S}(1 - u_{ij}),\quad C = \sum_{i<j} \ln(1 - u_{ij}).

* P_conn(S) is computed exactly for that model (:func:`connected_probability`: up to
  five members the sum over the connected edge subsets, positive terms only; from six on
  the recursion over the first member's component, memoised over subsets, and where it
  would lose its digits to cancellation -- an almost surely resolved group, P_conn below
  ~2^|S|·1e-10 -- the lower bound max_T Π_{e∈T} u_e over spanning trees). The only
  approximation is the independence of the pairs (they share the members' positions):
  for a cross-range chain of three at 90 km (σ 50 m × 150 m, cell 500 m × 1.4°) P_conn is
  0.9994 vs 0.9956 by Monte Carlo at 700 m spacing, 0.597 vs 0.530 at 1000 m (see the
  notes). Summed over every π, P(π) = 1 (≤ 1 where the max-tree bound is used).

The paper's constant ρ is the special case of a pair odds u_ij/(1 − u_ij) = ρ for every
pair with groups of at most two objects (``max_group_size = 2``): then ln w(S) = ln ρ =
(|S| − 1) ln ρ, the paper's prior, and the scores equal the constant-ρ ones up to C. For
larger groups the constant model's ρ^{|S|−1} is one chain's weight, while w(S) counts
every connected graph on S (3ρ² + ρ³ for a triple with equal pairs).

``u`` is the dense (Q, Q) table or a :class:`~optmodels.assignment.sensor.PairTable`
(indexed the same way). Holds :func:`connected_probability`, :func:`log_group_weight`,
:func:`log_not_merged` and the max-tree bound :func:`_log_max_tree`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_finite_array


def log_not_merged(u: FloatArray, group: tuple[int, ...]) -> float:
    """Σ_{i<j∈S} ln(1 − u_ij)."""
    idx = list(group)
    sub = u[np.ix_(idx, idx)]
    return float(np.sum(np.log1p(-sub[np.triu_indices(len(idx), 1)])))


def _log_max_tree(u: FloatArray, group: tuple[int, ...]) -> float:
    """ln max_T Π_{e∈T} u_e over the spanning trees T of S (Prim's algorithm on ln u): the
    probability that the most likely tree's pairs are all unresolved, a lower bound on
    P_conn(S) within a factor of the number of trees (≤ |S|^{|S|−2}); no cancellation."""
    idx = list(group)
    lu = np.log(u[np.ix_(idx, idx)])
    k = len(idx)
    done = np.zeros(k, dtype=bool)
    done[0] = True
    best = lu[0].copy()
    total = 0.0
    for _ in range(k - 1):
        cand = np.where(done, -np.inf, best)
        j = int(np.argmax(cand))
        total += float(cand[j])
        done[j] = True
        best = np.maximum(best, lu[j])
    return total


#: Groups up to this size: P_conn by the sum over the connected edge subsets (positive
#: terms, exact to rounding whatever the u_ij); larger ones by the recursion.
_ENUMERATE_UP_TO = 5
#: The recursion 1 − Σ is trusted above this many times its rounding bound 2^|S|·1e-16;
#: below (an almost surely resolved group) the max-tree lower bound is used.
_CANCEL_MARGIN = 1e6
_CONNECTED_SUBSETS: dict[int, tuple[np.ndarray, list[tuple[int, int]]]] = {}


def _connected_subsets(k: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The edge subsets (rows, boolean over the k(k−1)/2 pairs) that connect k nodes."""
    if k not in _CONNECTED_SUBSETS:
        edges = [(i, j) for i in range(k) for j in range(i + 1, k)]
        rows = []
        for mask in range(2 ** len(edges)):
            parent = list(range(k))

            def find(a: int, parent: list[int] = parent) -> int:
                while parent[a] != a:
                    a = parent[a]
                return a

            on = [(mask >> e) & 1 for e in range(len(edges))]
            for (i, j), bit in zip(edges, on, strict=True):
                if bit:
                    parent[find(i)] = find(j)
            if len({find(i) for i in range(k)}) == 1:
                rows.append(on)
        _CONNECTED_SUBSETS[k] = (np.array(rows, dtype=bool), edges)
    return _CONNECTED_SUBSETS[k]


def connected_probability(
    u: FloatArray, group: tuple[int, ...], memo: dict[Any, float] | None = None
) -> float:
    """P_conn(S): the probability that the members of S form one chain of unresolved
    pairs (the random graph on S with independent edges u_ij is connected).

    ``u``: the symmetric (Q, Q) table of pair probabilities in [0, 1] (the diagonal is not
    read; the others are clipped to [U_FLOOR, 1 − U_CEIL_GAP] as the sensor's pair
    probabilities, :mod:`~optmodels.assignment.sensor`) or a
    :class:`~optmodels.assignment.sensor.PairTable`; ``group``: the distinct members
    (indices 0..Q−1); ``memo``: a dict kept between calls on the same ``u``, or None.

    |S| ≤ 5: the sum over the connected edge subsets of S of Π u_e Π (1 − u_e) (at most
    728 positive terms: exact to rounding). |S| ≥ 6: the recursion over the component T
    of S's first member, P_conn(S) = 1 − Σ_{T∋s₁, T⊊S} P_conn(T) Π_{i∈T, j∈S∖T}(1 − u_ij)
    (memoised over subsets in ``memo``, as logarithms keyed by bit mask); where it is within
    ``_CANCEL_MARGIN`` of its rounding bound (an almost surely resolved group) the
    max-tree lower bound :func:`_log_max_tree` is used instead."""
    table, members = _checked(u, group)
    if memo is not None and not isinstance(memo, dict):
        raise ProblemError(
            f"assignment.connected_probability memo: expected a dict or None, got "
            f"{type(memo).__name__}"
        )
    return math.exp(_log_connected(table, members, {} if memo is None else memo))


def _checked(u: Any, group: Any) -> tuple[Any, tuple[int, ...]]:
    """The pair table (a dense one checked and clipped) and the group's members, or one
    ProblemError naming ``u`` or ``group``."""
    from optmodels.assignment.sensor import U_CEIL_GAP, U_FLOOR, PairTable

    fn = "assignment.connected_probability"
    if isinstance(u, PairTable):
        table: Any = u
        q = u.q
    else:
        dense = as_finite_array(f"{fn} u", u, ndim=2)
        q = dense.shape[0]
        if dense.shape != (q, q) or q == 0:
            raise ProblemError(f"{fn} u: expected a square (Q, Q) table, got {dense.shape}")
        if np.any((dense < 0) | (dense > 1)):
            raise ProblemError(f"{fn} u: pair probabilities must lie in [0, 1]")
        if not np.array_equal(dense, dense.T):
            raise ProblemError(f"{fn} u: the pair table must be symmetric (u_ij = u_ji)")
        table = np.clip(dense, U_FLOOR, 1.0 - U_CEIL_GAP)
        np.fill_diagonal(table, 1.0)
    g = as_finite_array(f"{fn} group", group, ndim=1)
    if g.size == 0 or np.any(g != np.round(g)) or np.any((g < 0) | (g >= q)):
        raise ProblemError(
            f"{fn} group: expected ≥ 1 member indices in 0..{q - 1}, got {g.tolist()!r:.60}"
        )
    members = tuple(int(v) for v in g)
    if len(set(members)) != len(members):
        raise ProblemError(f"{fn} group: repeated members {members!r:.60}")
    return table, members


def _log_connected(u: FloatArray, group: tuple[int, ...], memo: dict[Any, float]) -> float:
    """ln P_conn(S) (:func:`connected_probability`); ``memo`` maps the members' bit mask
    (Σ 2^j) to the value."""
    k = len(group)
    if k == 1:
        return 0.0
    if k == 2:
        return float(math.log(u[group[0], group[1]]))
    key = sum(1 << int(j) for j in group)
    got = memo.get(key)
    if got is not None:
        return got
    idx = np.array(group)
    if k <= _ENUMERATE_UP_TO:
        rows, edges = _connected_subsets(k)
        ue = np.array([u[idx[i], idx[j]] for i, j in edges])
        terms = rows @ np.log(ue) + (~rows) @ np.log1p(-ue)
        out = float(np.logaddexp.reduce(terms))
    else:
        sub = u[np.ix_(idx, idx)].copy()
        np.fill_diagonal(sub, 0.0)
        lg = np.log1p(-sub)
        masks = np.arange(2 ** (k - 1) - 1)  # the other members' subsets, not the full one
        inside = np.column_stack(
            [np.ones(len(masks), dtype=bool), (masks[:, None] >> np.arange(k - 1)) & 1]
        ).astype(bool)
        cut = np.einsum("mi,ij,mj->m", inside.astype(float), lg, (~inside).astype(float))
        bits = [1 << int(j) for j in idx]
        keys = (inside.astype(object) @ np.array(bits, dtype=object)).tolist()
        parts = np.array(
            [
                memo[m] if m in memo else _log_connected(u, tuple(int(x) for x in idx[row]), memo)
                for m, row in zip(keys, inside, strict=True)
            ]
        )
        rec = -math.expm1(float(np.logaddexp.reduce(parts + cut)))
        low = _log_max_tree(u, group)
        if rec > _CANCEL_MARGIN * 1e-16 * 2.0**k:
            out = max(math.log(min(rec, 1.0)), low)
        else:
            out = low
    memo[key] = out
    return out


def log_group_weight(
    u: FloatArray, group: tuple[int, ...], memo: dict[Any, float] | None = None
) -> float:
    """ln w(S) = ln P_conn(S) − Σ_{i<j∈S} ln(1 − u_ij): the block's share of ln P(π)
    (module docstring); 0 for a singleton, ln(u_ij/(1 − u_ij)) for a pair."""
    if len(group) == 1:
        return 0.0
    if len(group) == 2:
        v = u[group[0], group[1]]
        return float(math.log(v) - math.log1p(-v))
    return _log_connected(u, tuple(group), {} if memo is None else memo) - log_not_merged(u, group)
