r"""The candidate groups of paper 004's joint assignment: the blocks S that an unresolved
variant π of (13)-(14) may use (the MILP's z_S columns), limited by the data's
``max_group_size`` and ``group_gate`` or by the sensor model's own gate, and the size
guard :data:`MAX_CANDIDATE_GROUPS`.

Holds :func:`candidate_groups` and :func:`_connected_groups` (the connected subsets of the
sensor's gating graph).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.special import comb

from optmodels.assignment.data import AssignmentData
from optmodels.core import ProblemError, as_count, as_instance

#: Size guards (documented in the README). Candidate groups (z_S columns) enumerated at
#: most; beyond it the gate/max_group_size must be tightened. The count is checked while
#: the cliques grow, before anything of that size is allocated.
MAX_CANDIDATE_GROUPS = 100_000


def candidate_groups(
    data: AssignmentData, *, limit: int | None = None, model_gate: bool = True
) -> list[tuple[int, ...]]:
    """Singletons and the groups allowed by ``max_group_size`` and ``group_gate`` (cliques
    of the gate graph: members pairwise within the gate under K_i + K_j), in
    lexicographic order by size.

    With a ``sensor`` and no finite ``group_gate`` the gate follows from the resolution
    model: the groups are the connected subsets of the gating graph (edges: the pairs with
    u_ij > PAIR_NEGLECT, :meth:`AssignmentData.pair_edges`). A group outside it needs an
    unresolved neglected pair in every spanning tree, so the prior mass of all variants
    that use one is at most Σ_neglected u_ij ≤ PAIR_NEGLECT · Q(Q − 1)/2.
    ``model_gate=False`` ignores that gate (every subset, as without a sensor).

    Raises
    ------
    ProblemError
        If there are more than ``limit`` (default :data:`MAX_CANDIDATE_GROUPS`): refused
        while the cliques grow (or, without a gate, from the count Σ_s C(Q, s)), before
        the list or any model of that size is built.
    """
    as_instance("assignment.candidate_groups data", data, AssignmentData)
    limit = (
        MAX_CANDIDATE_GROUPS
        if limit is None
        else as_count("assignment.candidate_groups limit", limit, minimum=1)
    )
    q = data.q
    size = q if data.max_group_size is None else min(q, int(data.max_group_size))

    def refuse(count: str) -> ProblemError:
        return ProblemError(
            f"assignment: {count} candidate groups (Q = {q}, max_group_size = "
            f"{data.max_group_size}, group_gate = {data.group_gate}), above the limit "
            f"{limit}; tighten group_gate or lower max_group_size (merges of more than a "
            f"few objects are rarely plausible)"
        )

    gate = data.group_gate
    gated = gate is not None and bool(np.isfinite(gate))
    if data._pair_u is not None and not gated and model_gate:
        return _connected_groups(data, size, limit, refuse)
    if not gated:
        total = sum(int(comb(q, k, exact=True)) for k in range(1, size + 1))
        if total > limit:
            raise refuse(f"{total:.3g}")
    ok = np.ones((q, q), dtype=bool)
    if gate is not None and gated and size >= 2:
        gate2 = float(gate) ** 2
        for i in range(q - 1):  # Mahalanobis distance to the later objects, one batch
            dm = data.means[i + 1 :] - data.means[i]
            s = data.covs[i + 1 :] + data.covs[i]
            d2 = np.einsum("kd,kd->k", dm, np.linalg.solve(s, dm[..., None])[..., 0])
            ok[i, i + 1 :] = ok[i + 1 :, i] = d2 <= gate2
    out: list[tuple[int, ...]] = [(j,) for j in range(q)]
    # grow cliques of the gate graph in lexicographic order; each carries the mask of the
    # objects adjacent to all its members
    frontier: list[tuple[tuple[int, ...], np.ndarray]] = [((j,), ok[j]) for j in range(q)]
    for _ in range(2, size + 1):
        nxt: list[tuple[tuple[int, ...], np.ndarray]] = []
        for g, common in frontier:
            for j in np.flatnonzero(common[g[-1] + 1 :]) + g[-1] + 1:
                nxt.append(((*g, int(j)), common & ok[j]))
            if len(out) + len(nxt) > limit:
                raise refuse(f"more than {limit}")
        out.extend(g for g, _ in nxt)
        frontier = nxt
        if not frontier:
            break
    return out


def _connected_groups(
    data: AssignmentData, size: int, limit: int, refuse: Callable[[str], ProblemError]
) -> list[tuple[int, ...]]:
    """Singletons and the connected subsets (2 ≤ |S| ≤ ``size``) of the gating graph,
    sorted within each size; refused above ``limit`` while they grow."""
    ii, jj = data.pair_edges()
    out: list[tuple[int, ...]] = [(j,) for j in range(data.q)]
    if size < 2 or len(ii) == 0:
        return out
    nbrs: dict[int, set[int]] = {}
    for a, b in zip(ii.tolist(), jj.tolist(), strict=True):
        nbrs.setdefault(a, set()).add(b)
        nbrs.setdefault(b, set()).add(a)
    cur: list[tuple[int, ...]] = sorted(set(zip(ii.tolist(), jj.tolist(), strict=True)))
    for s_ in range(2, size + 1):
        if len(out) + len(cur) > limit:
            raise refuse(f"more than {limit}")
        out.extend(cur)
        if s_ == size:
            break
        nxt: set[tuple[int, ...]] = set()
        for g in cur:
            members = set(g)
            for v in set().union(*(nbrs[x] for x in g)) - members:
                nxt.add(tuple(sorted((*g, v))))
            if len(out) + len(nxt) > limit:
                raise refuse(f"more than {limit}")
        if not nxt:
            break
        cur = sorted(nxt)
    return out
