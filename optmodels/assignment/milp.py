r"""The joint MAP hypothesis of (13)-(14) as one sparse MILP in CVXPY (HiGHS by default), the
original form behind :func:`optmodels.assignment.solve` (``model="cvxpy"``) and
:func:`~optmodels.assignment.k_best`: exact pruning, the model, and its solve ended by the
re-check and gate :func:`optmodels.assignment.verify._finish`.

MILP (binary z_S per candidate group, γ_iS, γ_i0):

.. math::
    \max\ \sum_S z_S\,p_0(S)
          + \sum_{i,S}\gamma_{iS}\,[\ln\varphi_{iS} + \ln P_D - \ln(1-P_D)]
          - \sum_i \gamma_{i0}\ln\Delta x

subject to Σ_{S∋j} z_S = 1 (exact cover), Σ_i γ_iS ≤ z_S, Σ_S γ_iS + γ_i0 = 1 (the
equality (2) omits), with p_0(S) the block's undetected prior term (constant ρ:
(|S| − 1) ln ρ + ln(1 − P_D), so the first sum is (Q − |π|) ln ρ + |π| ln(1 − P_D); with a
sensor ln w(S) + ln(1 − P_D), :mod:`~optmodels.assignment.sensor`) and φ_iS the
measurement's likelihood with its own covariance R_i. Exact pruning: a γ_iS whose gain
ln φ_iS + ln P_D − ln(1 − P_D) does not exceed the background's −ln Δx can be replaced
by γ_i0 without lowering the score, so it is never needed for a MAP hypothesis and is
not created.

Holds: the dominance pruning :func:`_prune`, the model's columns :func:`_gains` and
:func:`_columns`, the sparse model :func:`_build_model`, its solve :func:`_solve_model`,
and the size guards :data:`MAX_LIKELIHOOD_ENTRIES`, :data:`MAX_MODEL_COLUMNS`; each MILP
solver's gap and time-limit names are the back-end's
(:func:`optmodels.backends.profiles.milp_options`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sps

from optmodels.assignment.data import (
    AssignmentData,
    Partition,
    block_log_prior,
    log_likelihoods,
)
from optmodels.assignment.solution import AssignmentSolution
from optmodels.assignment.verify import _finish
from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.backends.profiles import milp_options
from optmodels.core import FloatArray, ProblemError, Status, timed

#: Entries of the ln φ_iS table (N × candidate groups, 8 bytes each: 160 MB at the limit).
MAX_LIKELIHOOD_ENTRIES = 20_000_000
#: Binary columns of the MILP (z_S + γ_iS + γ_i0) after pruning; about 1 kB of peak memory
#: each in CVXPY + HiGHS (measured, ``solvers_cmp/bench_assignment_memory.py``).
MAX_MODEL_COLUMNS = 1_000_000


# ----------------------------------------------------------------------------- MILP
def _prune(
    data: AssignmentData, groups: list[tuple[int, ...]], gain: FloatArray, usable: np.ndarray
) -> tuple[list[tuple[int, ...]], FloatArray, np.ndarray]:
    """Exact dominance pruning of merged groups (never removes a MAP hypothesis), for any
    prior that decomposes over blocks, with p0(S) = ``block_log_prior(S, undetected)``
    and the column gains gain_iS = ln φ_iS + p1(S) − p0(S) (whatever the likelihoods: one
    R for all measurements or R_i each; the rules only compare entries of this table).

    2. Measurement i on a merged group S is dominated if splitting S into singletons, giving
       i to its best member and leaving the others undetected, scores at least as much:
       p0(S) + gain_iS ≤ Σ_{j∈S} p0({j}) + max_{j∈S} gain_ij; or if peeling one member j
       off (i on S ∖ {j}, {j} undetected) does: p0(S) + gain_iS ≤ p0(S ∖ j) + p0({j}) +
       gain_{i,S∖j}. The swaps are always feasible (S's members are used nowhere else, the
       other blocks keep their prior terms), so γ_iS is never needed.
    3. A merged group left without any measurement can only be undetected; if
       p0(S) ≤ Σ_{j∈S} p0({j}), its singletons (undetected) score at least as much, so
       z_S is never needed. (Constant prior: p0(S) = (|S| − 1) ln ρ + ln(1 − P_D), so the
       rules read (|S| − 1) ln ρ + gain_iS ≤ max_j gain_ij + (|S| − 1) ln(1 − P_D),
       gain_iS + ln ρ ≤ gain_{i,S∖j} + ln(1 − P_D), and ρ ≤ 1 − P_D.)
    """
    index = {g: c for c, g in enumerate(groups)}
    single = {g[0]: c for c, g in enumerate(groups) if len(g) == 1}
    p0 = np.array([block_log_prior(data, g, False) for g in groups])
    keep_g = np.ones(len(groups), dtype=bool)
    sizes = np.array([len(g) for g in groups])
    for size in np.unique(sizes[sizes > 1]):  # one batch per group size
        cs = np.flatnonzero(sizes == size)
        members = np.array([groups[c] for c in cs])  # (G_s, s)
        scol = np.vectorize(single.__getitem__, otypes=[int])(members)
        split = p0[scol].sum(axis=1)  # Σ_j p0({j})
        lhs = p0[cs] + gain[:, cs]  # (N, G_s)
        dominated = lhs <= split + gain[:, scol].max(axis=2)
        # 2'. peel one member j: S \ {j} keeps i, {j} undetected. S \ {j} is a candidate
        # too (subsets of a gated clique are cliques, sizes only shrink)
        for pos in range(size):
            rest = np.array([index.get(tuple(np.delete(m, pos).tolist()), -1) for m in members])
            ok = rest >= 0
            if ok.any():
                rr = rest[ok]
                dominated[:, ok] |= lhs[:, ok] <= p0[rr] + p0[scol[ok, pos]] + gain[:, rr]
        usable[:, cs] &= ~dominated
        keep_g[cs] = usable[:, cs].any(axis=0) | (p0[cs] > split)
    idx = np.flatnonzero(keep_g)
    return [groups[c] for c in idx], gain[:, idx], usable[:, idx]


def _build_model(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    gain: FloatArray,
    keep: np.ndarray,
    exclude: Sequence[AssignmentSolution],
    fixed: bool,
) -> tuple[FloatArray, sps.csr_matrix, sps.csr_matrix, FloatArray]:
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
    c = np.concatenate([g_cost, gain[keep[:, 0], keep[:, 1]] if n_k else [], np.full(n, bg)])
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
    a_ub = sps.csr_matrix(
        (
            np.concatenate(ub_v),
            (np.concatenate(ub_r).astype(int), np.concatenate(ub_c).astype(int)),
        ),
        shape=(len(b), cols),
    )
    if fixed:  # z_S = 1 for the given blocks (implied by the cover; stated for clarity)
        a_ub = sps.vstack([a_ub, -sps.eye(n_g, cols, format="csr")], format="csr")
        b = np.concatenate([b, -np.ones(n_g)])
    return c, a_eq, a_ub, b


def _columns(
    w: str,
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    fixed: Partition | None,
    prune: bool,
) -> tuple[list[tuple[int, ...]], FloatArray, np.ndarray]:
    """The model's columns: the groups kept, the gains (N, G) and the measurement-group
    pairs ``keep`` (K, 2) after the exact pruning (module docstring; rules 2-3 only for
    the whole model with the default prior), refused above :data:`MAX_MODEL_COLUMNS`
    before the model is built."""
    n = data.n
    _, gain = _gains(w, data, groups)
    bg = -math.log(data.volume)
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
            + "; tighten group_gate or lower max_group_size"
        )
    return groups, gain, keep


def _gains(
    w: str, data: AssignmentData, groups: list[tuple[int, ...]]
) -> tuple[FloatArray, FloatArray]:
    """The log-likelihoods (N, G) of the measurements on the groups and the gains ln φ +
    ln P(detected) − ln P(undetected) of the MILP's columns γ_iS, after the size guard
    :data:`MAX_LIKELIHOOD_ENTRIES`."""
    n = data.n
    if n * len(groups) > MAX_LIKELIHOOD_ENTRIES:
        raise ProblemError(
            f"{w}: N × candidate groups = {n} × {len(groups)} likelihoods, "
            f"above the limit {MAX_LIKELIHOOD_ENTRIES:.0e}; tighten "
            f"group_gate or lower max_group_size"
        )
    ll = log_likelihoods(data, groups)
    bonus = np.array(
        [block_log_prior(data, g, True) - block_log_prior(data, g, False) for g in groups]
    )
    return ll, ll + bonus


def _solve_model(
    w: str,
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    gain: FloatArray,
    keep: np.ndarray,
    exclude: Sequence[AssignmentSolution],
    fixed: Partition | None,
    key: str,
    gap: float,
    limit: float | None,
    options: dict[str, Any],
    build_time: float,
) -> AssignmentSolution:
    """The MILP on the columns ``groups``/``keep`` (with the no-good cuts of ``exclude``),
    solved by ``key`` and ended by the NumPy re-check and the status gate
    (:func:`~optmodels.assignment.verify._finish`); ``build_time`` is the caller's
    share of the model building."""
    q, n = data.q, data.n
    with timed() as tb:
        c, a_eq, a_ub, b_ub = _build_model(data, groups, gain, keep, exclude, fixed is not None)
        x = cp.Variable(len(c), boolean=True)
        cons = [a_eq @ x == np.ones(q + n)]
        if a_ub.shape[0]:
            cons.append(a_ub @ x <= b_ub)
        prob = cp.Problem(cp.Maximize(c @ x), cons)
    # solve_problem silences HiGHS' banner before a HIGHS solve
    opts = milp_options(key, gap, limit, verbose=bool(options.get("verbose", False)), where=w)
    res = solve_problem(prob, key, **{**opts, **options})
    common = res.common()
    common["build_time"] += build_time + tb.elapsed
    gap_reached = res.info.get("mip_gap")
    info = dict(res.info, candidate_groups=len(groups), assignment_variables=len(keep))
    if not res.status.ok or x.value is None:
        msg = common.pop("message")
        if gap_reached is not None and np.isfinite(gap_reached):
            msg += f"; MIP gap reached {gap_reached:.3g}"
        if res.status.ok:  # OK without a point: not a solution
            common["status"] = Status.ERROR
        return AssignmentSolution(
            objective=float("nan"), message=msg, mip_gap=gap_reached, info=info, **common
        )
    xv = np.asarray(x.value, dtype=float).reshape(-1)
    return _finish(
        data,
        groups,
        keep,
        xv,
        a_eq,
        a_ub,
        b_ub,
        float(res.objective),
        exclude,
        fixed,
        common=common,
        gap_reached=gap_reached,
        gap=gap,
        info=info,
    )
