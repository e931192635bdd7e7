r"""Items 1-2 of the decomposed MAP (:mod:`~optmodels.assignment.decomposed`): the exact
likelihood gate and the exact dominance pruning on the gated entries, from sparse arrays.

1. **Likelihood gate (exact).** A column γ_iS is only needed if its gain
   ln φ_iS + ln P_D − ln(1 − P_D) exceeds the background's −ln Δx (pruning rule 1 of
   :mod:`~optmodels.assignment.milp`). With ln φ_iS = −½ m² − ½ ln det 2π(K_S + R_i),
   det(K_S + R_i) ≥ det R_i and m² ≥ ‖x_i − μ_S‖² / (λ_max(K_S) + max_i λ_max(R_i)), so
   every needed column has ‖x_i − μ_S‖² < (λ_max(K_S) + R_max) · 2 (ln(P_D/(1 − P_D)) +
   ln Δx − ½ min_i ln det 2πR_i): those pairs come from a k-d tree on the measurements
   (:class:`scipy.spatial.cKDTree`), and ln φ is evaluated for them only
   (:func:`gated_entries`).
2. **Dominance pruning** (rules 2, 3 of :func:`~optmodels.assignment.milp._prune`) on
   those entries (:func:`prune_entries`); an entry outside the gate enters a comparison
   as −∞, a lower bound of its gain, so every removal stays justified.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.spatial import cKDTree

from optmodels.assignment.data import AssignmentData, entry_log_likelihoods, group_arrays
from optmodels.core import FloatArray


def gated_entries(
    data: AssignmentData, groups: list[tuple[int, ...]], bonus: float
) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    """The (measurement, group) pairs that can carry a needed column γ_iS (module
    docstring, item 1) and their gains ln φ_iS + ``bonus``: (rows, cols, gain)."""
    n = data.n
    empty = np.zeros(0, dtype=int)
    if n == 0:
        return empty, empty.copy(), np.zeros(0)
    noise = data.meas_cov if data.per_measurement_cov else data.meas_cov[None]
    _, logdet = np.linalg.slogdet(2 * math.pi * noise)
    m2max = 2.0 * (bonus + math.log(data.volume) - 0.5 * float(logdet.min()))
    if m2max <= 0:
        return empty, empty.copy(), np.zeros(0)
    r_max = float(np.linalg.eigvalsh(noise)[:, -1].max())
    mean, cov = group_arrays(data, groups)
    radius = np.sqrt(m2max * (np.linalg.eigvalsh(cov)[:, -1] + r_max)) * (1 + 1e-9)
    if n * len(groups) <= 4096:  # all pairs directly: cheaper than a tree (measured)
        dist = np.linalg.norm(data.measurements[None, :, :] - mean[:, None, :], axis=2)
        cols, rows = np.nonzero(dist <= radius[:, None])
    else:
        lists = cKDTree(data.measurements).query_ball_point(mean, radius, return_sorted=False)
        lens = np.fromiter(map(len, lists), dtype=int, count=len(groups))
        cols = np.repeat(np.arange(len(groups)), lens)
        rows = np.fromiter(itertools.chain.from_iterable(lists), dtype=int, count=int(lens.sum()))
    return rows, cols, entry_log_likelihoods(data, groups, rows, cols) + bonus


def _lookup(keys: np.ndarray, vals: FloatArray, want: np.ndarray) -> FloatArray:
    """vals at the sorted ``keys`` equal to ``want``, −∞ where absent."""
    pos = np.searchsorted(keys, want)
    pos = np.minimum(pos, max(len(keys) - 1, 0))
    hit = keys[pos] == want if len(keys) else np.zeros(len(want), dtype=bool)
    return np.where(hit, vals[pos] if len(keys) else 0.0, -np.inf)


def prune_entries(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    p0: FloatArray,
    rows: np.ndarray,
    cols: np.ndarray,
    gain: FloatArray,
    bg: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Pruning rules 1-3 (module docstring) on the gated entries: the kept groups (mask)
    and the kept entries (mask). Singletons are always kept (the cover needs them)."""
    n_g = len(groups)
    sizes = np.fromiter(map(len, groups), dtype=int, count=n_g)
    usable = gain > bg
    keys = rows.astype(np.int64) * n_g + cols
    order = np.argsort(keys, kind="stable")
    skeys, sgain = keys[order], gain[order]
    index = {g: c for c, g in enumerate(groups)}
    keep_g = sizes == 1
    for size in sorted(set(sizes[sizes > 1].tolist())):
        cs = np.flatnonzero(sizes == size)
        members = np.array([groups[c] for c in cs], dtype=int)  # (G_s, s); singleton j is j
        split = p0[members].sum(axis=1)
        rest = np.array(
            [
                [index.get(tuple(np.delete(m, pos).tolist()), -1) for pos in range(size)]
                for m in members
            ],
            dtype=int,
        )
        local = np.full(n_g, -1)
        local[cs] = np.arange(len(cs))
        ent = np.flatnonzero(usable & (local[cols] >= 0))
        if len(ent):
            li = local[cols[ent]]
            i = rows[ent].astype(np.int64)
            lhs = p0[cols[ent]] + gain[ent]
            best = np.full(len(ent), -np.inf)
            for pos in range(size):
                best = np.maximum(best, _lookup(skeys, sgain, i * n_g + members[li, pos]))
            rhs = split[li] + best
            for pos in range(size):
                rr = rest[li, pos]
                ok = rr >= 0
                peel = np.full(len(ent), -np.inf)
                peel[ok] = (
                    p0[rr[ok]]
                    + p0[members[li[ok], pos]]
                    + _lookup(skeys, sgain, i[ok] * n_g + rr[ok])
                )
                rhs = np.maximum(rhs, peel)
            usable[ent[lhs <= rhs]] = False
        has = np.zeros(n_g, dtype=bool)
        has[cols[usable]] = True
        keep_g[cs] = has[cs] | (p0[cs] > split)
    return keep_g, usable & keep_g[cols]
