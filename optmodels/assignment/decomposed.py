r"""The MAP hypothesis of (13)-(14) at air-picture scale: gated likelihoods, exact pruning,
the exact decomposition into the connected components of the model's graph, closed forms
for the uncontended components and ONE direct HiGHS MILP for all contended ones per scan.

Same problem, same columns as the CVXPY model of :mod:`~optmodels.assignment.milp` (the
original-form reference, ``solve(..., model="cvxpy")``; tested equal), built from sparse
arrays only:

1. **Likelihood gate (exact)** and 2. **dominance pruning** on the gated entries:
   :mod:`~optmodels.assignment.gating` (the likelihoods ln φ_iS are evaluated for the
   gated pairs only).
3. **Components.** The graph on objects and measurements joins the members of each kept
   group and each measurement to the members of each group it has a column on. Every
   constraint row (exact cover of an object, one source per measurement, ≤ 1 measurement
   per block) and every objective term involves the columns of one component only, so the
   MILP separates: the MAP is the union of the component MAPs (``docs/formulations.md``).
   Components without objects: background. With one object: the best column in closed
   form. Several objects, no merged group: a linear assignment
   (:func:`scipy.optimize.linear_sum_assignment`). With merged groups ("contended"): up
   to :data:`ENUMERATE_OBJECTS` objects and :data:`ENUMERATE_VARIANTS` unresolved
   variants, every variant by its linear assignment (the paper's per-variant problem
   (14), exact); the others all in one HiGHS model (``highspy``, built from the same
   sparse triplets), so HiGHS' fixed cost is paid at most once per scan.
4. **Re-check** of the assembled point against the whole model and the recomputed score
   (13) (:func:`~optmodels.assignment.verify._recheck`, as for the CVXPY path) and the
   gate :func:`~optmodels.assignment.verify._finish`.

:func:`solve_decomposed` reads build (:func:`_build`: gate, pruning, sparse model,
components) → run (:func:`_closed_forms` for the uncontended and small contended
components, :func:`_run_contended` for the rest in one HiGHS model) → finish
(:func:`~optmodels.assignment.verify._finish`); its arguments are checked by
:func:`optmodels.assignment.solve`.

Measured (``python -m solvers_cmp.assignment_scale``, 2-core VM at load ≈ 10, medians):
per scan 0.09 s at Q = 1000 and 0.60 s at Q = 3000 (under an 8 GiB address-space limit)
against 0.20 s / 1.42 s for a vectorised numpy + scipy GNN on the same scans.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sps
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components

from optmodels.assignment.data import AssignmentData, block_log_prior
from optmodels.assignment.gating import gated_entries, prune_entries
from optmodels.assignment.sensor import PAIR_NEGLECT
from optmodels.assignment.solution import AssignmentSolution
from optmodels.assignment.verify import _finish
from optmodels.backends.profiles import milp_options
from optmodels.core import FloatArray, ProblemError, Status, timed

#: Binary columns of the batched MILP of the contended components (z_S + γ_iS + γ_i0).
MAX_MILP_COLUMNS = 2_000_000


@functools.cache
def highspy_module() -> Any:
    """``highspy`` if importable (checked once per process), else None; the HiGHS banner
    is silenced once (:func:`optmodels.backends.cvxpy_backend.silence_highs_banner`)."""
    try:
        import highspy
    except ImportError:  # pragma: no cover - HiGHS ships with CVXPY here
        return None
    from optmodels.backends.cvxpy_backend import silence_highs_banner

    silence_highs_banner()
    return highspy


# ----------------------------------------------------------------------------- the model
class Rows:
    """A sparse matrix as (row, col, value) triplets, applied by ``@`` with
    :func:`numpy.bincount` (what the re-check needs; building a scipy.sparse matrix costs
    ~0.3 ms each, measured, a tenth of a small scan's budget)."""

    def __init__(self, r: np.ndarray, c: np.ndarray, v: FloatArray, shape: tuple[int, int]) -> None:
        self.r, self.c, self.v, self.shape = r, c, v, shape

    def __matmul__(self, x: FloatArray) -> FloatArray:
        out: FloatArray = np.bincount(
            self.r, weights=self.v * x[self.c], minlength=self.shape[0]
        ).astype(float, copy=False)
        return out

    def tocsr(self) -> sps.csr_matrix:
        return sps.csr_matrix((self.v, (self.r, self.c)), shape=self.shape)


def sparse_model(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    p0: FloatArray,
    keep: np.ndarray,
    keep_gain: FloatArray,
) -> tuple[FloatArray, Rows, Rows, FloatArray]:
    """The MILP of :func:`~optmodels.assignment.milp._build_model` (no cuts) from sparse
    arrays: x = (z_S, γ_iS for ``keep`` (K, 2) = (i, group), γ_i0); c, A_eq, A_ub, b_ub
    (``Rows(...).tocsr()`` gives the scipy matrices)."""
    q, n, n_g, n_k = data.q, data.n, len(groups), len(keep)
    c = np.concatenate([p0, keep_gain, np.full(n, -math.log(data.volume))])
    cols = n_g + n_k + n
    sizes = np.fromiter(map(len, groups), dtype=int, count=n_g)
    member_r = np.fromiter(itertools.chain.from_iterable(groups), dtype=int, count=int(sizes.sum()))
    member_c = np.repeat(np.arange(n_g), sizes)
    rows = np.concatenate([member_r, q + keep[:, 0], q + np.arange(n)])
    colx = np.concatenate([member_c, n_g + np.arange(n_k), n_g + n_k + np.arange(n)])
    a_eq = Rows(rows, colx, np.ones(len(rows)), (q + n, cols))
    a_ub = Rows(
        np.concatenate([np.arange(n_g), keep[:, 1]]),
        np.concatenate([np.arange(n_g), n_g + np.arange(n_k)]),
        np.concatenate([-np.ones(n_g), np.ones(n_k)]),
        (n_g, cols),
    )
    return c, a_eq, a_ub, np.zeros(n_g)


def _components(n_nodes: int, ea: np.ndarray, eb: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components (count, label per node): scipy's csgraph, or for a few edges
    a union-find in NumPy-free Python (below ~2000 edges it is faster than building the
    sparse graph, measured)."""
    if len(ea) > 2000:
        graph = sps.coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n_nodes, n_nodes))
        return connected_components(graph, directed=False)
    parent = list(range(n_nodes))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in zip(ea.tolist(), eb.tolist(), strict=True):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    roots = [find(a) for a in range(n_nodes)]
    _, label = np.unique(roots, return_inverse=True)
    return int(label.max(initial=-1)) + 1, label.reshape(-1)


def _highs_solve(
    c: FloatArray,
    ar: np.ndarray,
    ac: np.ndarray,
    av: FloatArray,
    shape: tuple[int, int],
    lo: FloatArray,
    hi: FloatArray,
    gap: float,
    limit: float | None,
    verbose: bool,
) -> tuple[Status, FloatArray | None, float, float | None, str, float]:
    """max cᵀx, lo ≤ A x ≤ hi (A from the triplets ``ar``, ``ac``, ``av``), x binary, by
    HiGHS directly: status, x, objective, the MIP gap reached, HiGHS' message, seconds."""
    order = np.lexsort((ar, ac))  # column-wise
    start = np.concatenate([[0], np.cumsum(np.bincount(ac, minlength=shape[1]))])
    hs = highspy_module()
    h = hs.Highs()
    # the project's HiGHS profile for this model (optmodels.backends.profiles.milp_options:
    # mip_abs_gap 1e-12 with a zero gap, presolve off, the time limit), the same as the
    # CVXPY path's; and without the feasibility-jump heuristic, measured on HiGHS 1.16 at
    # 13-23 ms per run even for 10 binaries (a heuristic only: optimality is still proven
    # by the branch and bound). "threads" is not set: HiGHS' thread pool is global and a
    # run asking for another size than the pool's fails (seen after a CVXPY HiGHS solve)
    for key, value in milp_options(
        "HIGHS", gap, limit, verbose=verbose, where="assignment.solve"
    ).items():
        h.setOptionValue(key, value)
    h.setOptionValue("mip_heuristic_run_feasibility_jump", False)
    lp = hs.HighsLp()
    lp.num_col_, lp.num_row_ = shape[1], shape[0]
    lp.col_cost_ = c
    lp.col_lower_ = np.zeros(shape[1])
    lp.col_upper_ = np.ones(shape[1])
    lp.row_lower_, lp.row_upper_ = lo, hi
    lp.sense_ = hs.ObjSense.kMaximize
    lp.a_matrix_.format_ = hs.MatrixFormat.kColwise
    lp.a_matrix_.start_ = start.astype(np.int32)
    lp.a_matrix_.index_ = ar[order].astype(np.int32)
    lp.a_matrix_.value_ = av[order]
    lp.integrality_ = [hs.HighsVarType.kInteger] * shape[1]
    with timed() as ts:
        h.passModel(lp)
        h.run()
    ms = h.getModelStatus()
    info = h.getInfo()
    text = h.modelStatusToString(ms)
    gap_reached = float(info.mip_gap) if np.isfinite(info.mip_gap) else None
    if ms == hs.HighsModelStatus.kOptimal:
        x = np.asarray(h.getSolution().col_value, dtype=float)
        return (
            Status.OPTIMAL,
            x,
            float(info.objective_function_value),
            gap_reached,
            text,
            ts.elapsed,
        )
    if ms in (
        hs.HighsModelStatus.kTimeLimit,
        hs.HighsModelStatus.kIterationLimit,
        hs.HighsModelStatus.kSolutionLimit,
        hs.HighsModelStatus.kInterrupt,
    ):
        return Status.ITERATION_LIMIT, None, math.nan, gap_reached, text, ts.elapsed
    if ms == hs.HighsModelStatus.kInfeasible:
        return Status.INFEASIBLE, None, math.nan, gap_reached, text, ts.elapsed
    return Status.ERROR, None, math.nan, gap_reached, text, ts.elapsed


@dataclass
class _Model:
    """The decomposed model of one scan (:func:`_build`): the kept ``groups`` (singletons
    first), their undetected prior terms ``p0``, the kept entries ``keep`` (K, 2) =
    (measurement, group) sorted, with gains ``kgain``; the sparse MILP ``c``, ``a_eq``,
    ``a_ub``, ``b_ub`` (:func:`sparse_model`); the components of the graph on objects
    0..Q−1 and measurements Q..Q+N−1 (``label`` per node, ``n_comp``, ``n_obj`` objects
    per component, ``contended``: with a merged group), each group's ``first`` member and
    each column's component ``col_comp``."""

    groups: list[tuple[int, ...]]
    p0: FloatArray
    keep: np.ndarray
    kgain: FloatArray
    c: FloatArray
    a_eq: Rows
    a_ub: Rows
    b_ub: FloatArray
    first: np.ndarray
    label: np.ndarray
    n_comp: int
    n_obj: np.ndarray
    contended: np.ndarray
    col_comp: np.ndarray


def _build(data: AssignmentData, groups: list[tuple[int, ...]], bg: float) -> _Model:
    """Items 1-3 of the module docstring: the gated gains, the pruning, the sparse model
    on the kept columns and its connected components."""
    q, n = data.q, data.n
    p0 = np.array([block_log_prior(data, g, False) for g in groups])
    bonus = math.log(data.pd) - math.log1p(-data.pd)
    rows, cols, gain = gated_entries(data, groups, bonus)
    keep_g, keep_e = prune_entries(data, groups, p0, rows, cols, gain, bg)
    new = np.cumsum(keep_g) - 1
    groups = [g for g, k in zip(groups, keep_g, strict=True) if k]
    p0 = p0[keep_g]
    keep = np.column_stack([rows[keep_e], new[cols[keep_e]]]).astype(int).reshape(-1, 2)
    kgain = gain[keep_e]
    order = np.lexsort((keep[:, 1], keep[:, 0]))
    keep, kgain = keep[order], kgain[order]
    c, a_eq, a_ub, b_ub = sparse_model(data, groups, p0, keep, kgain)
    # components on objects 0..Q-1 and measurements Q..Q+N-1
    first = np.fromiter((g[0] for g in groups), dtype=int, count=len(groups))
    merged = [g for g in groups if len(g) > 1]
    ea = np.array([a for g in merged for a in g[:-1]] + (q + keep[:, 0]).tolist(), dtype=int)
    eb = np.array([b for g in merged for b in g[1:]] + first[keep[:, 1]].tolist(), dtype=int)
    n_comp, label = _components(q + n, ea, eb)
    contended = np.zeros(n_comp, dtype=bool)
    contended[label[[g[0] for g in merged]]] = True
    return _Model(
        groups=groups,
        p0=p0,
        keep=keep,
        kgain=kgain,
        c=c,
        a_eq=a_eq,
        a_ub=a_ub,
        b_ub=b_ub,
        first=first,
        label=label,
        n_comp=int(n_comp),
        n_obj=np.bincount(label[:q], minlength=n_comp),
        contended=contended,
        col_comp=np.concatenate([label[first], label[q + keep[:, 0]], label[q:]]),
    )


def solve_decomposed(
    data: AssignmentData,
    groups: list[tuple[int, ...]],
    *,
    gap: float,
    limit: float | None,
    verbose: bool,
    where: str,
) -> AssignmentSolution:
    """The MAP hypothesis over the candidate ``groups`` (module docstring), re-checked:
    build → the closed forms → one HiGHS model for the contended rest → the gate."""
    q = data.q
    bg = -math.log(data.volume)
    with timed() as tb:
        m = _build(data, groups, bg)
    n_g, n_k = len(m.groups), len(m.keep)
    x = np.zeros(len(m.c))
    x[:q] = 1.0  # groups are sorted by size: the singletons come first, all on by default
    x[n_g + n_k :] = 1.0  # every measurement on the background until given to a block
    info: dict[str, Any] = {
        "candidate_groups": n_g,
        "assignment_variables": n_k,
        "components": m.n_comp,
        "contended_components": int(m.contended.sum()),
        "largest_component": int(np.bincount(m.label).max(initial=0)),
        "neglected_pair_bound": _neglected_bound(data),
    }
    with timed() as tc:
        info["enumerated_components"] = _closed_forms(data, m, x, bg)
    gap_reached: float | None = 0.0
    status, msg, solve_t = Status.OPTIMAL, "decomposed", tc.elapsed
    solver_obj = float(m.c @ x)
    if m.contended.any():
        sel_c = np.flatnonzero(m.contended[m.col_comp])
        if len(sel_c) > MAX_MILP_COLUMNS:
            raise ProblemError(
                f"{where}: {len(sel_c)} binary columns in the contended "
                f"components, above the limit {MAX_MILP_COLUMNS:.0e}; lower "
                f"max_group_size"
            )
        status, xs, obj, gap_reached, text, t_milp = _run_contended(
            data, m, sel_c, gap, limit, verbose
        )
        solve_t += t_milp
        msg = f"decomposed; HiGHS on {int(m.contended.sum())} contended components: {text}"
        info["milp_columns"] = len(sel_c)
        if xs is None:
            if gap_reached is not None:
                msg += f"; MIP gap reached {gap_reached:.3g}"
            return AssignmentSolution(
                status=status,
                objective=math.nan,
                method="highs:decomposed",
                message=msg,
                build_time=tb.elapsed,
                solve_time=solve_t,
                mip_gap=gap_reached,
                info=info,
            )
        rest = np.ones(len(m.c), dtype=bool)
        rest[sel_c] = False
        x[sel_c] = xs
        solver_obj = obj + float(m.c[rest] @ x[rest])
    common = {
        "status": status,
        "method": "highs:decomposed",
        "build_time": tb.elapsed,
        "solve_time": solve_t,
        "iterations": None,
        "message": msg,
    }
    return _finish(
        data,
        m.groups,
        m.keep,
        x,
        m.a_eq,
        m.a_ub,
        m.b_ub,
        solver_obj,
        (),
        None,
        common=common,
        gap_reached=gap_reached,
        gap=gap,
        info=info,
    )


def _closed_forms(data: AssignmentData, m: _Model, x: FloatArray, bg: float) -> int:
    """Set in ``x`` the MAP of every component that needs no MILP: singleton-only ones (one
    object: its best column; several: a linear assignment) and contended ones of at most
    :data:`ENUMERATE_OBJECTS` objects (every unresolved variant, each by its linear
    assignment: the paper's per-variant problem (14), exact), which are then marked
    uncontended in ``m.contended``. Returns the number of components enumerated."""
    q = data.q
    n_g, n_k = len(m.groups), len(m.keep)
    keep, kgain = m.keep, m.kgain
    single_col = keep[:, 1] < q
    comp_e = m.label[q + keep[:, 0]]
    easy = ~m.contended[comp_e] & single_col
    one = easy & (m.n_obj[comp_e] == 1)
    if one.any():
        e = np.flatnonzero(one)
        e = e[np.lexsort((kgain[e], keep[e, 1]))]  # by object, then gain ascending
        last = np.append(np.diff(keep[e, 1]) != 0, True)  # each object's best
        _take(x, n_g, n_k, keep, e[last])
    several = np.flatnonzero(easy & (m.n_obj[comp_e] > 1))
    if len(several):
        by = np.argsort(comp_e[several], kind="stable")
        several = several[by]
        bounds = np.flatnonzero(np.diff(comp_e[several])) + 1
        for part in np.split(several, bounds):
            _take(x, n_g, n_k, keep, _lsa(keep[part], kgain[part] - bg, part))
    enumerated = 0
    g_comp = m.label[m.first]
    for comp in np.flatnonzero(m.contended):
        if m.n_obj[comp] > ENUMERATE_OBJECTS:
            continue
        gi = np.flatnonzero(g_comp == comp)
        ei = np.flatnonzero(comp_e == comp)
        got = _enumerate(m.groups, gi, m.p0, keep, kgain - bg, ei)
        if got is None:
            continue
        on, chosen = got
        x[gi] = 0.0
        x[on] = 1.0
        _take(x, n_g, n_k, keep, chosen)
        m.contended[comp] = False
        enumerated += 1
    return enumerated


def _run_contended(
    data: AssignmentData,
    m: _Model,
    sel_c: np.ndarray,
    gap: float,
    limit: float | None,
    verbose: bool,
) -> tuple[Status, FloatArray | None, float, float | None, str, float]:
    """The contended components' columns ``sel_c`` and their rows as one HiGHS model
    (:func:`_highs_solve`): status, their x, objective, MIP gap reached, message, s."""
    q, n = data.q, data.n
    label, contended = m.label, m.contended
    row_on = np.concatenate([contended[label[:q]], contended[label[q:]], contended[label[m.first]]])
    new_row = np.cumsum(row_on) - 1
    new_col = np.full(len(m.c), -1)
    new_col[sel_c] = np.arange(len(sel_c))
    r_all = np.concatenate([m.a_eq.r, m.a_ub.r + q + n])
    c_all = np.concatenate([m.a_eq.c, m.a_ub.c])
    v_all = np.concatenate([m.a_eq.v, m.a_ub.v])
    on = row_on[r_all] & (new_col[c_all] >= 0)
    n_eq = int(row_on[: q + n].sum())
    n_rows = int(row_on.sum())
    lo = np.concatenate([np.ones(n_eq), np.full(n_rows - n_eq, -np.inf)])
    hi = np.concatenate([np.ones(n_eq), m.b_ub[row_on[q + n :]]])
    return _highs_solve(
        m.c[sel_c],
        new_row[r_all[on]],
        new_col[c_all[on]],
        v_all[on],
        (n_rows, len(sel_c)),
        lo,
        hi,
        gap,
        limit,
        verbose,
    )


#: Contended components of at most this many objects (and at most ENUMERATE_VARIANTS
#: unresolved variants) are solved by enumerating the variants: a HiGHS run costs 1-25 ms
#: on a busy 2-core machine even for 10 binaries, a small component's variants 0.1 ms.
ENUMERATE_OBJECTS = 6
ENUMERATE_VARIANTS = 64


def _enumerate(
    groups: list[tuple[int, ...]],
    gi: np.ndarray,
    p0: FloatArray,
    keep: np.ndarray,
    value: FloatArray,
    ei: np.ndarray,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The best hypothesis of one component: every partition of its objects into its kept
    groups (exact covers), each scored by the linear assignment of its measurements to the
    blocks or the background (``value`` = gain − background > 0 per kept column); the
    groups on and the columns chosen, or None above ENUMERATE_VARIANTS variants."""
    containing: dict[int, list[int]] = {}
    for g in gi.tolist():
        for j in groups[g]:
            containing.setdefault(j, []).append(g)
    objs = sorted(containing)
    parts: list[list[int]] = []

    def cover(left: frozenset[int], chosen: list[int]) -> bool:
        if not left:
            parts.append(list(chosen))
            return len(parts) <= ENUMERATE_VARIANTS
        j = min(left)
        for g in containing[j]:
            mem = groups[g]
            if all(m in left for m in mem):
                if not cover(left - set(mem), [*chosen, g]):
                    return False
        return True

    if not cover(frozenset(objs), []):
        return None
    rows = keep[ei, 0]
    meas = sorted(set(rows.tolist()))
    mrow = {m: r for r, m in enumerate(meas)}
    best: tuple[float, list[int], np.ndarray] | None = None
    for part in parts:
        col = {g: k for k, g in enumerate(part)}
        mine = np.array([k for k in ei.tolist() if int(keep[k, 1]) in col], dtype=int)
        total = float(p0[part].sum())
        chosen = np.zeros(0, dtype=int)
        if len(mine):
            mat = np.full((len(meas), len(part) + len(meas)), -1e300)
            mat[:, len(part) :] = 0.0
            r_ = [mrow[int(keep[k, 0])] for k in mine]
            c_ = [col[int(keep[k, 1])] for k in mine]
            mat[r_, c_] = value[mine]
            rr, cc = linear_sum_assignment(mat, maximize=True)
            pick = {(a, b) for a, b in zip(rr.tolist(), cc.tolist(), strict=True) if b < len(part)}
            chosen = np.array(
                [k for k, a, b in zip(mine.tolist(), r_, c_, strict=True) if (a, b) in pick],
                dtype=int,
            )
            total += float(value[chosen].sum())
        if best is None or total > best[0] + 1e-12 * max(1.0, abs(total)):
            best = (total, part, chosen)
    assert best is not None  # the singletons always cover
    return np.array(best[1], dtype=int), best[2]


def _take(x: FloatArray, n_g: int, n_k: int, keep: np.ndarray, ent: np.ndarray) -> None:
    """Give the entries ``ent`` (indices into ``keep``) their blocks in ``x``."""
    if len(ent):
        x[n_g + ent] = 1.0
        x[n_g + n_k + keep[ent, 0]] = 0.0


def _lsa(pairs: np.ndarray, value: FloatArray, idx: np.ndarray) -> np.ndarray:
    """The entries (of ``idx``) chosen by the linear assignment of one singleton-only
    component: measurements to objects or the background, value ``value`` > 0 each."""
    mi, mj = np.unique(pairs[:, 0], return_inverse=True)
    oi, oj = np.unique(pairs[:, 1], return_inverse=True)
    mat = np.full((len(mi), len(oi) + len(mi)), -1e300)
    mat[:, len(oi) :] = 0.0
    mat[mj, oj] = value
    r, cc = linear_sum_assignment(mat, maximize=True)
    where = {(int(a), int(b)): int(k) for k, a, b in zip(idx, mj, oj, strict=True)}
    return np.array(
        [
            where[(int(a), int(b))]
            for a, b in zip(r, cc, strict=True)
            if b < len(oi) and (int(a), int(b)) in where
        ],
        dtype=int,
    )


def _neglected_bound(data: AssignmentData) -> float:
    """Σ over the neglected pairs of their bound on u_ij: the prior mass of the unresolved
    variants left out by the gated candidate groups is at most this."""
    if data._pair_u is None:
        return 0.0
    n_edges = len(data.pair_edges()[0])
    return PAIR_NEGLECT * (data.q * (data.q - 1) // 2 - n_edges)
