r"""The original problem of section 4 (paper 001, (8)-(10)) and what every method shares.

The objective (9) J(φ) = φᵀ(Q ⊗ P)φ written as ‖Gφ‖² with the sparse edge-difference
factor G (:func:`edge_factor`, :func:`objective`) and R = Q ⊗ P itself (:func:`r_matrix`,
its null space :func:`r_null_space` on each radar's connected parts :func:`radar_parts`,
over every entry or only the seen ones :func:`seen_entries`);
the sets (10) as computed once per solve (:data:`Sets`, from
:func:`optmodels.biasfield.data.uncertainty_sets`); the box (8) as bounds on φ
(:func:`box_bounds`); the checks of the arguments common to the solves
(:func:`check_graph`, :func:`check_arguments`); the per-component scaling the solvers see
(:func:`variable_scales`, and the scaled Lipschitz SOCP's matrices :func:`lipschitz_data`,
shared by its solve and its certificate check) and the solver call (:func:`run_solver`).

Those helpers are the selection stage's shared pieces: public inside the package (used by
:mod:`~optmodels.biasfield.closedform`, :mod:`~optmodels.biasfield.generic`,
:mod:`~optmodels.biasfield.verify` and :mod:`~optmodels.biasfield.referee`), not
re-exported by ``optmodels.biasfield``. The solution is
:class:`~optmodels.biasfield.solution.FieldSolution`, packed and re-checked by
:mod:`~optmodels.biasfield.verify`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cvxpy as cp
import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.sparse import csgraph

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.biasfield.data import FieldData, laplacian, uncertainty_sets
from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_finite_array,
    as_float_array,
    as_instance,
    as_positive,
)

__all__ = ["Sets", "edge_factor", "objective"]


#: (Φ⁰, Φ¹) of (10), computed once per solve and handed to the helpers below.
Sets = tuple[FloatArray, sparse.csr_matrix]


# ----------------------------------------------------------------------------- pieces
def p_full(data: FieldData) -> FloatArray:
    """P of ‖·‖_F as the (2m, 2m) matrix (a (2, 2) P repeated for every radar)."""
    if data.P.shape != (2, 2):
        return data.P
    return np.asarray(np.kron(np.eye(data.m), data.P), dtype=float)


def _edges(data: FieldData) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    upper = sparse.triu(data.adjacency, k=1).tocoo()
    i, j = upper.row, upper.col
    d2 = np.sum((data.centers[i] - data.centers[j]) ** 2, axis=1)
    return i, j, d2


def check_graph(data: FieldData) -> tuple[int, np.ndarray]:
    """Connected components of the neighbour graph; isolated cells are refused."""
    if not isinstance(data, FieldData):
        raise ProblemError(
            f"biasfield data: expected a FieldData (biasfield.build_field_data "
            f"or FieldData(...)), got {type(data).__name__}"
        )
    n, labels = csgraph.connected_components(_overlap_graph(data), directed=False)
    sizes = np.bincount(labels)
    lonely = np.flatnonzero(sizes[labels] == 1)
    if lonely.size:
        what = "have no neighbour" if data.seen is None else "share no radar with any neighbour"
        raise ProblemError(
            f"adjacency: cells {lonely[:10].tolist()} {what}; their "
            "field is not determined by the smoothness criterion (add edges "
            "or drop them)"
        )
    return int(n), labels


def _overlap_graph(data: FieldData) -> sparse.csr_matrix:
    """The radar-overlap graph: the neighbour pairs (k, l) whose subsets share a radar,
    S_k ∩ S_l ≠ ∅ (the adjacency itself without subsets). J (9) couples two cells only
    along its edges, so its connected components are the pieces the field decouples
    into (docs/formulations.md)."""
    if data.seen is None:
        return data.adjacency
    upper = sparse.triu(data.adjacency, k=1).tocoo()
    share = np.any(data.seen[upper.row] & data.seen[upper.col], axis=1)
    a = sparse.csr_matrix(
        (np.ones(int(share.sum())), (upper.row[share], upper.col[share])),
        shape=data.adjacency.shape,
    )
    return (a + a.T).tocsr()


def _edge_radars(data: FieldData) -> np.ndarray | None:
    """(E, m) bool: radar i enters the term of neighbour pair e = (k < l) of (9), i.e. it
    sees both cells (None without subsets: every radar on every edge)."""
    if data.seen is None:
        return None
    i, j, _ = _edges(data)
    return data.seen[i] & data.seen[j]


def _edge_difference(data: FieldData, weights: FloatArray) -> sparse.csr_matrix:
    """Rows weights_e · Lᵀ(f(x̌_i) − f(x̌_j)) for every neighbour pair e = (i < j), P = LLᵀ:
    (2m·E × 2mK)."""
    i, j, _ = _edges(data)
    e = np.arange(i.size)
    diff = sparse.csr_matrix(
        (np.concatenate([weights, -weights]), (np.concatenate([e, e]), np.concatenate([i, j]))),
        shape=(i.size, data.k),
    )
    lt = np.linalg.cholesky(p_full(data)).T
    g = sparse.kron(diff, sparse.csr_matrix(lt), format="csr")
    on = _edge_radars(data)
    if on is None:
        return g
    # per-cell subsets: radar i's rows of edge e only where it sees both cells (P is
    # block-diagonal, so Lᵀ keeps each radar's two rows to its own two columns)
    g = (sparse.diags(np.repeat(on.reshape(-1), 2).astype(float)) @ g).tocsr()
    g.eliminate_zeros()
    return g


def edge_factor(data: FieldData) -> sparse.csr_matrix:
    """Sparse G (2m·E × 2mK) with GᵀG = Q ⊗ P: for each neighbour pair (i < j) the rows
    √a_ij Lᵀ(f(x̌_i) − f(x̌_j)), a_ij = 1/‖x̌_i − x̌_j‖², P = LLᵀ."""
    return _edge_difference(data, 1.0 / np.sqrt(_edges(data)[2]))


def objective(data: FieldData, phi: ArrayLike) -> float:
    """J(φ) = φᵀ(Q ⊗ P)φ (9) (half the paper's sum over ordered pairs, see errata);
    ``phi`` (2mK,) cell by cell, radar by radar, [range m, azimuth rad]."""
    g = edge_factor(data)
    v = g @ as_finite_array("biasfield.objective phi", phi, shape=(g.shape[1],))
    return float(v @ v)


def r_matrix(data: FieldData) -> sparse.csr_matrix:
    """R of (9): Q ⊗ P; with per-cell subsets GᵀG (each radar's Laplacian over the cells
    it sees, ⊗ its block of P), which is Q ⊗ P when every radar sees every cell."""
    if data.seen is not None:
        g = edge_factor(data)
        return (g.T @ g).tocsr()
    return sparse.kron(
        laplacian(data.centers, data.adjacency), sparse.csr_matrix(p_full(data)), format="csr"
    )


def radar_parts(data: FieldData) -> list[tuple[int, np.ndarray]]:
    """Per radar i, the connected parts of its own neighbour graph (the edges between cells
    it both sees; every edge without per-cell subsets): (number of parts, part of each
    cell). R couples radar i's cells only along these edges (:func:`r_matrix`)."""
    if data.seen is None:
        part = csgraph.connected_components(data.adjacency, directed=False)
        return [(int(part[0]), part[1])] * data.m
    out = []
    for i in range(data.m):
        on = sparse.diags(data.seen[:, i].astype(float))
        n, labels = csgraph.connected_components(on @ data.adjacency @ on, directed=False)
        out.append((int(n), labels))
    return out


def seen_entries(data: FieldData) -> np.ndarray:
    """(2m·K,) bool: the entries φ_{k,i} (both components) of the radars i ∈ S_k that see
    cell k, in φ's layout (cell by cell, radar by radar); all True without subsets. The
    other entries enter neither J (9) (zero rows and columns of R) nor the sets (10)."""
    return np.repeat(data.subsets.reshape(-1), 2)


def r_null_space(data: FieldData, *, seen_only: bool = False) -> sparse.csr_matrix:
    """The null space of R: fields constant per radar on each connected part of that
    radar's neighbour graph (:func:`radar_parts`) (2m·K × 2·Σ parts). ``seen_only``: the
    null space of R restricted to the seen entries (rows :func:`seen_entries`; R's zero
    rows and columns of the other entries dropped): the constants on the parts that hold
    a cell the radar sees, (n_seen × 2·Σ those parts); a cell a radar does not see is a
    part of its own in :func:`radar_parts` and has no column here."""
    k, m = data.k, data.m
    seen = data.subsets
    rows, cols = [], []
    first = 0
    for i, (n, labels) in enumerate(radar_parts(data)):
        cells = np.flatnonzero(seen[:, i]) if seen_only else np.arange(k)
        part = labels[cells]
        if seen_only:  # renumber the parts that hold a seen cell 0, 1, ...
            used, part = np.unique(part, return_inverse=True)
            n = used.size
        for comp in (0, 1):
            rows.append(2 * (cells * m + i) + comp)
            cols.append(2 * (first + part.ravel()) + comp)
        first += n
    r, c = np.concatenate(rows), np.concatenate(cols)
    if seen_only:  # full index → index among the seen entries
        keep = seen_entries(data)
        r = (np.cumsum(keep) - 1)[r]
        n_rows = int(keep.sum())
    else:
        n_rows = 2 * m * k
    return sparse.csr_matrix((np.ones(r.size), (r, c)), shape=(n_rows, 2 * first))


def box_bounds(
    data: FieldData, box: Sequence[float] | None, where: str = "biasfield.solve"
) -> FloatArray | None:
    """The box (8) as bounds on φ (2mK,): ``box`` = (K1 range bound, m; K2 azimuth bound,
    rad), two positive finite numbers, or None."""
    as_instance(f"{where} data", data, FieldData)
    if box is None:
        return None
    if isinstance(box, str | bytes) or as_float_array(f"{where} box", box).shape != (2,):
        raise ProblemError(
            f"{where} box: expected a pair (K1 range bound in m, K2 azimuth "
            f"bound in rad), got {box!r:.80}"
        )
    k1 = as_positive(f"{where} box[0] (K1, range bound, m)", box[0])
    k2 = as_positive(f"{where} box[1] (K2, azimuth bound, rad)", box[1])
    return np.tile([k1, k2], data.m * data.k)


def _solver_name(where: str, solver: Any) -> str:
    if not isinstance(solver, str) or not solver:
        raise ProblemError(f"{where} solver: expected a CVXPY solver name, got {solver!r:.60}")
    return solver


# ----------------------------------------------------------------------------- solves
def variable_scales(data: FieldData, phi0: FloatArray) -> FloatArray:
    """Per-component scale of φ (range, azimuth) so that the solver sees O(1) numbers."""
    v = np.abs(phi0.reshape(-1, 2))
    if data.seen is not None:
        v = v[data.seen.reshape(-1)]
    s = np.array([max(float(np.median(v[:, 0])), 1e-9), max(float(np.median(v[:, 1])), 1e-15)])
    return np.tile(s, data.m * data.k)


def check_arguments(
    fn: str, data: FieldData, formulation: Any, solver: Any, box: Any
) -> tuple[int, Any, str, Any, Any]:
    """The checked arguments common to :func:`~optmodels.biasfield.generic.solve` and
    :func:`~optmodels.biasfield.generic.solve_lipschitz`: the number of graph components,
    the formulation, the solver's name, the box bound and the uncertainty sets (10)."""
    n_comp, _ = check_graph(data)
    formulation = as_choice(f"{fn} formulation", formulation, ("constrained", "reduced"))
    solver = _solver_name(fn, solver)
    bound = box_bounds(data, box, fn)
    return n_comp, formulation, solver, bound, uncertainty_sets(data)


def run_solver(where: str, prob: cp.Problem, solver: str, opts: dict[str, Any]) -> Any:
    """:func:`solve_problem`, with a rejected option named as this function's argument."""
    try:
        return solve_problem(prob, solver, **opts)
    except ProblemError as exc:
        raise ProblemError(f"{where} options: {exc}") from None


def lipschitz_data(data: FieldData, sets: Sets) -> dict[str, Any]:
    """The scaled SOCP's matrices: φ = sc·u, u = u0 + B η̃ (η = sc_range·η̃); the jump of
    edge e is D_e u (= Lᵀ(f_i − f_j)); cone e: (ℓ d_e/ref, (D_e u)/lip0) with L = ℓ·lip0/ref,
    lip0 the largest jump ratio at η = 0 times ref = median edge length."""
    phi0, phi1 = sets
    sc = variable_scales(data, phi0)
    m2 = 2 * data.m
    dist = np.sqrt(_edges(data)[2])
    jump = _edge_difference(data, np.ones(dist.size))  # Lᵀ(f_i − f_j) per edge
    dmat = (jump @ sparse.diags(sc)).tocsr()
    u0 = phi0 / sc
    bmat = (sparse.diags(1 / sc) @ phi1 * sc[0]).tocsr()
    ref = float(np.median(dist))
    lip0 = float(np.max(np.linalg.norm((dmat @ u0).reshape(-1, m2), axis=1) / dist)) * ref
    if not (np.isfinite(lip0) and lip0 > 0):
        lip0 = 1.0
    return {
        "sc": sc,
        "u0": u0,
        "bmat": bmat,
        "dmat": dmat,
        "dist": dist,
        "ref": ref,
        "lip0": lip0,
        "jump": jump,
        "db": (dmat @ bmat).tocsr() / lip0,
        "c": dmat @ u0 / lip0,
    }
