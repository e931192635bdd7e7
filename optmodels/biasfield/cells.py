r"""Cells, averaging and uncertainty sets (paper 001, section 3 and (9)-(10)).

* Cell centres x̌_(k): a grid, or k-means of the fitted positions (where traffic is).
  A sample belongs to the cell of its nearest centre if it lies within ``cell_radius``.
* Averaging (6)-(7): for every object seen by **all** m radars in cell k, the fitted
  ξ̂_i^a(t) are averaged over the instants τ_(k)^a the object spent in the cell (a regular
  grid of instants inside the common span of the m fits), then over the objects. The
  covariance follows exactly (the average is linear in the fitted knots; objects and
  radars are independent).
* Neighbours c(x, y): Delaunay edges (or all pairs within a radius); weights
  a_ij = 1/‖x_i − x_j‖²; Q the graph Laplacian of (9).
* Uncertainty sets (10) in the polar space F, linearised at ξ̂_(k) = mean_i ξ̂_i(k):

  .. math::
      \varphi = \Phi^0 + \Phi^1\eta,\quad \Phi^0_k = [p_i(\hat\xi_{i(k)}) - p_i(\hat\xi_{(k)})]_i,
      \quad \Phi^1 = \operatorname{blockdiag}_k [\nabla p_i(\hat\xi_{(k)})]_i,

  η_k = ξ̂_(k) − x_(k) ∈ R² per cell, so Φ¹ is 2mK × 2K and **block-diagonal** (the
  printed (10) stacks the blocks in one column, which does not fit η ∈ R^{2K}).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.spatial import Delaunay, QhullError, cKDTree

from optmodels.biasfield.data import PlotTable, RadarSet, check_tables
from optmodels.biasfield.geometry import polar_jacobian, to_polar, wrap_angle
from optmodels.biasfield.tracks import TrackFit, fit_tracks
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_positive,
    check_spd,
    check_spd_stack,
)
from optmodels.io import read_npz

__all__ = ["FieldData", "build_field_data", "laplacian", "neighbours", "place_centers",
           "synthetic_field_data", "uncertainty_sets"]


@dataclass
class FieldData:
    """Input of the field selection (part 2).

    ``radars`` (m, 2) sites; ``centers`` (K, 2); ``xi`` (K, m, 2) averaged biased
    positions ξ̂_i(k); ``adjacency`` symmetric 0/1, given as a dense or sparse (K, K) matrix
    or an (E, 2) edge list, stored sparse (CSR); ``P`` the weight of ‖·‖_F: (2, 2)
    for every radar, or (2m, 2m); ``xi_cov`` (K, m, 2, 2) covariances of ξ̂_i(k) if known.

    3-D geometry (optional, all saved and loaded): ``jacobians`` (K, m, 2, 2) the exact
    ∇p_i = ∂(slant range, azimuth)/∂(East, North) of each radar at each cell's mean
    position ξ̂_(k) and mean target height; ``heights`` (K,) that height (m above the
    WGS-84 ellipsoid); ``geodetic`` (m, 3) the sites (lat deg, lon deg, h m) and
    ``origin`` (3,) the common plane's origin. With ``geodetic``, ``origin`` and
    ``heights`` the sets (10) use the exact 3-D polar maps (:func:`uncertainty_sets`);
    with ``jacobians`` alone, Φ⁰ is linearised through them; without any, the 2-D maps
    of the sites ``radars``.

    Per-cell radar subsets (the field over the union of coverage, docs/formulations.md
    "The field over the union of coverage"): ``seen`` (K, m) bool, the radars S_k whose
    averaged position enters cell k (≥ 2 per cell); ``None`` (the paper's case) means
    every radar sees every cell. ``xi`` (and ``xi_cov``, ``jacobians``) must still be
    finite where a radar does not see a cell; those entries are not used (the builder
    stores the cell's mean position there). With subsets, ``P`` must be block-diagonal per
    radar (the smoothness functional (9) is summed per radar over the cells it sees).
    """

    radars: FloatArray
    centers: FloatArray
    xi: FloatArray
    adjacency: np.ndarray
    P: FloatArray
    xi_cov: FloatArray | None = None
    jacobians: FloatArray | None = None
    heights: FloatArray | None = None
    geodetic: FloatArray | None = None
    origin: FloatArray | None = None
    seen: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.radars = as_finite_array("radars", self.radars, ndim=2)
        m = self.radars.shape[0]
        if self.radars.shape[1] != 2 or m < 2:
            raise ProblemError(f"radars: expected (m, 2) with m ≥ 2, got {self.radars.shape}")
        self.centers = as_finite_array("centers", self.centers, ndim=2, max_abs=MAX_MAGNITUDE)
        k = self.centers.shape[0]
        self.xi = as_finite_array("xi", self.xi, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
        self.adjacency = _as_adjacency(self.adjacency, k)
        if self.centers.shape[1] != 2:
            raise ProblemError(f"centers: expected (K, 2), got {self.centers.shape}")
        upper = sparse.triu(self.adjacency, k=1).tocoo()
        d2 = np.sum((self.centers[upper.row] - self.centers[upper.col]) ** 2, axis=1)
        if np.any(d2 <= 0):
            e = int(np.flatnonzero(d2 <= 0)[0])
            # found by the robustness sweep: a_ij = 1/‖x̌_i − x̌_j‖² divided by zero
            raise ProblemError(f"centers: neighbours {upper.row[e]} and {upper.col[e]} "
                               "coincide (a_ij = 1/‖x̌_i − x̌_j‖² is undefined); merge the cells")
        p = as_finite_array("P", self.P, ndim=2, max_abs=MAX_MAGNITUDE)
        if p.shape not in ((2, 2), (2 * m, 2 * m)):
            raise ProblemError(f"P: expected (2, 2) or ({2 * m}, {2 * m}), got {p.shape}")
        # Cholesky, as the solver will use it (the robustness sweep found a P whose smallest
        # eigenvalue was positive but whose Cholesky factorisation failed)
        check_spd("P", p)
        self.P = p
        if self.xi_cov is not None:
            cov = as_finite_array("biasfield.FieldData xi_cov", self.xi_cov, shape=(k, m, 2, 2),
                                  max_abs=MAX_MAGNITUDE)
            # covariances of the averaged positions: symmetric positive definite (an
            # indefinite one was accepted before)
            check_spd_stack("biasfield.FieldData xi_cov", cov)
            self.xi_cov = cov
        self._check_geometry3d(k, m)
        self._check_seen(k, m)

    def _check_seen(self, k: int, m: int) -> None:
        if self.seen is None:
            return
        arr = np.asarray(self.seen)
        if arr.shape != (k, m) or not (arr.dtype == bool or np.isin(arr, (0, 1)).all()):
            raise ProblemError(f"biasfield.FieldData seen: expected a ({k}, {m}) boolean "
                               f"array (radar i sees cell k), got shape {arr.shape}")
        arr = arr.astype(bool)
        few = np.flatnonzero(arr.sum(axis=1) < 2)
        if few.size:
            raise ProblemError(f"biasfield.FieldData seen: cells {few[:10].tolist()} are seen "
                               "by fewer than 2 radars (a cell needs two radars to carry a "
                               "set (10))")
        p = self.P
        if p.shape == (2 * m, 2 * m):
            off = p.copy()
            for i in range(m):
                off[2 * i:2 * i + 2, 2 * i:2 * i + 2] = 0.0
            if np.any(off != 0.0):
                raise ProblemError("biasfield.FieldData P: with per-cell radar subsets (seen) "
                                   "P must be block-diagonal per radar (2 × 2 blocks)")
        self.seen = arr

    @property
    def subsets(self) -> np.ndarray:
        """(K, m) bool: radar i sees cell k (all True without ``seen``)."""
        if self.seen is None:
            return np.ones((self.k, self.m), dtype=bool)
        return self.seen

    def _check_geometry3d(self, k: int, m: int) -> None:
        from optmodels.biasfield.geometry3d import site_geodetic

        if self.jacobians is not None:
            jac = as_finite_array("biasfield.FieldData jacobians", self.jacobians,
                                  shape=(k, m, 2, 2), max_abs=MAX_MAGNITUDE)
            det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
            scale = np.abs(jac).max(axis=(-1, -2)) ** 2
            if np.any(np.abs(det) <= 1e-12 * scale):
                raise ProblemError("biasfield.FieldData jacobians: a singular ∇p_i (a cell "
                                   "at a radar site?)")
            self.jacobians = jac
        if self.heights is not None:
            self.heights = as_finite_array("biasfield.FieldData heights", self.heights,
                                           shape=(k,), max_abs=1e6)
        if (self.geodetic is None) != (self.origin is None):
            raise ProblemError("biasfield.FieldData geodetic: give both the geodetic sites "
                               "and the origin, or neither")
        if self.geodetic is not None:
            geo = as_finite_array("biasfield.FieldData geodetic", self.geodetic, shape=(m, 3))
            for j in range(m):
                site_geodetic(f"biasfield.FieldData geodetic[{j}]", geo[j])
            self.geodetic = geo
            self.origin = site_geodetic("biasfield.FieldData origin", self.origin)
            if self.heights is None:
                raise ProblemError("biasfield.FieldData heights: the 3-D sets need the cell "
                                   "heights (K,) with the geodetic sites")

    @property
    def is_3d(self) -> bool:
        """True when the sets (10) use the exact 3-D polar maps (geodetic, origin, heights)
        or per-cell Jacobians."""
        return self.geodetic is not None or self.jacobians is not None

    @property
    def m(self) -> int:
        return int(self.radars.shape[0])

    @property
    def k(self) -> int:
        return int(self.centers.shape[0])

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (radars, centers, xi, edges (E, 2), P[, xi_cov])."""
        upper = sparse.triu(self.adjacency, k=1).tocoo()
        arrays = {"radars": self.radars, "centers": self.centers, "xi": self.xi,
                  "edges": np.column_stack([upper.row, upper.col]).astype(np.int64),
                  "P": self.P}
        for name in ("xi_cov", "jacobians", "heights", "geodetic", "origin", "seen"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if not isinstance(path, str | Path):
            raise ProblemError(f"biasfield.FieldData.save path: expected a file name, got "
                               f"{type(path).__name__}")
        try:
            np.savez_compressed(path, **arrays)  # type: ignore[arg-type]
        except OSError as exc:
            raise ProblemError(f"biasfield.FieldData.save path: cannot write {path} ({exc})"
                               ) from None

    @classmethod
    def load(cls, path: str | Path) -> FieldData:
        """Read an ``.npz`` written by :meth:`save` (or by hand with the same keys; the
        neighbours as ``edges`` (E, 2) or a dense ``adjacency`` (K, K)); the optional keys
        ``xi_cov``, ``jacobians``, ``heights``, ``geodetic``, ``origin`` (files of the 2-D
        chain have none of these four), ``seen`` (per-cell radar subsets)."""
        if not isinstance(path, str | Path):
            raise ProblemError(f"biasfield.FieldData.load path: expected a file name, got "
                               f"{type(path).__name__}")
        d = read_npz(path, what="FieldData .npz", required=("radars", "centers", "xi", "P"),
                     one_of=("edges", "adjacency"))
        adj = d["edges"] if "edges" in d else d["adjacency"]
        try:
            return cls(d["radars"], d["centers"], d["xi"], adj, d["P"], d.get("xi_cov"),
                       d.get("jacobians"), d.get("heights"), d.get("geodetic"),
                       d.get("origin"), d.get("seen"))
        except ProblemError as exc:
            raise ProblemError(f"{path}: {exc}") from None


def _as_adjacency(adj: Any, k: int) -> sparse.csr_matrix:
    """Dense/sparse (K, K) 0/1 matrix or (E, 2) edge list → symmetric CSR int8."""
    if sparse.issparse(adj):
        a = sparse.csr_matrix(adj)
    else:
        arr = np.asarray(adj)
        if arr.ndim == 2 and arr.shape[1] == 2 and arr.shape != (k, k) and \
                np.issubdtype(arr.dtype, np.integer):
            if arr.size and (arr.min() < 0 or arr.max() >= k):
                raise ProblemError(f"adjacency: edge list refers to cells outside 0..{k - 1}")
            a = sparse.csr_matrix((np.ones(arr.shape[0]), (arr[:, 0], arr[:, 1])), shape=(k, k))
            a = a + a.T
        else:
            a = sparse.csr_matrix(arr)
    if a.shape != (k, k):
        raise ProblemError(f"adjacency: expected ({k}, {k}) or an (E, 2) edge list, got "
                           f"{a.shape}")
    a = (a != 0).astype(np.int8).tocsr()
    if (a != a.T).nnz:
        raise ProblemError("adjacency: not symmetric (c(x, y) must equal c(y, x))")
    if a.diagonal().any():
        raise ProblemError("adjacency: a cell cannot neighbour itself (c(x, x) = 0)")
    a.eliminate_zeros()
    return a


def place_centers(points: ArrayLike, count: int, *, method: Literal["kmeans", "grid"] = "kmeans",
                  seed: int | np.random.Generator = 0) -> FloatArray:
    """Cell centres: k-means of ``points`` (traffic concentrations) or a square grid of about
    ``count`` nodes over their bounding box.

    k-means: the coordinates scaled by their standard deviations; ``count`` distinct
    points drawn at random (``seed``) as the start, then :data:`LLOYD_ITERATIONS` Lloyd
    iterations on ALL the points (nearest centre by a k-d tree, O(N log K) per iteration
    instead of the O(N K) of a brute-force search; an empty cluster keeps its centre).
    This is scipy's ``kmeans2(minit="points", iter=20)`` step for step (same start from
    the same generator, same updates): the same centres, bitwise on the tests' cases (test
    ``test_place_centers_equals_scipy_kmeans2``); at N = 2·10⁶, K = 10⁴ it takes 8-9 s on
    2 cores. (k-means++ seeding would be O(N K²).)"""
    fn = "biasfield.place_centers"
    pts = as_finite_array(f"{fn} points", points, ndim=2, max_abs=MAX_MAGNITUDE)
    if pts.shape[1] != 2:
        raise ProblemError(f"{fn} points: expected (N, 2) positions (m), got {pts.shape}")
    count = as_count(f"{fn} count", count, minimum=2)
    method = as_choice(f"{fn} method", method, ("kmeans", "grid"))  # type: ignore[assignment]
    if pts.shape[0] < count:
        raise ProblemError(f"{fn} count: need 2 ≤ count ≤ number of points ({pts.shape[0]}), "
                           f"got {count}")
    if not isinstance(seed, np.random.Generator):
        seed = as_count(f"{fn} seed", seed)
    if method == "kmeans":
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        scale = pts.std(axis=0)
        return _lloyd(pts / scale, count, rng) * scale
    if method == "grid":
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        side = int(np.ceil(np.sqrt(count)))
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], side), np.linspace(lo[1], hi[1], side))
        return np.column_stack([gx.ravel(), gy.ravel()])
    raise ProblemError(f"method: expected 'kmeans' or 'grid', got {method!r}")


#: Lloyd iterations of :func:`place_centers` (as scipy's ``kmeans2(iter=20)``).
LLOYD_ITERATIONS = 20


def _lloyd(pts: FloatArray, count: int, rng: np.random.Generator) -> FloatArray:
    """Lloyd's k-means from ``count`` random distinct points of ``pts`` (N, d); nearest
    centre by cKDTree; an empty cluster keeps its previous centre."""
    cent = pts[rng.choice(pts.shape[0], size=count, replace=False)].copy()
    for _ in range(LLOYD_ITERATIONS):
        label = cKDTree(cent).query(pts, workers=-1)[1]
        n = np.bincount(label, minlength=count)
        has = n > 0
        for c in range(pts.shape[1]):
            sums = np.bincount(label, pts[:, c], minlength=count)
            cent[has, c] = sums[has] / n[has]
    return cent


def neighbours(centers: ArrayLike, *, method: Literal["delaunay", "radius"] = "delaunay",
               radius: float | None = None) -> sparse.csr_matrix:
    """Symmetric 0/1 adjacency c(x, y) (sparse): Delaunay edges, or all pairs within
    ``radius``."""
    fn = "biasfield.neighbours"
    c = as_finite_array(f"{fn} centers", centers, ndim=2, max_abs=MAX_MAGNITUDE)
    if c.shape[1] != 2:
        raise ProblemError(f"{fn} centers: expected (K, 2) positions (m), got {c.shape}")
    k = c.shape[0]
    method = as_choice(f"{fn} method", method, ("delaunay", "radius"))  # type: ignore[assignment]
    if method == "delaunay":
        if k < 3:
            pairs = np.array([[0, 1]]) if k == 2 else np.zeros((0, 2), dtype=int)
        else:
            try:
                simp = Delaunay(c).simplices
            except QhullError as exc:  # collinear / coincident centres
                raise ProblemError(f"{fn} centers: no Delaunay triangulation (the centres are "
                                   f"collinear or coincide: {str(exc).splitlines()[0]}); use "
                                   "method='radius'") from None
            pairs = np.vstack([simp[:, [0, 1]], simp[:, [1, 2]], simp[:, [0, 2]]])
    else:
        r = as_positive(f"{fn} radius (m)", radius)
        pairs = cKDTree(c).query_pairs(r, output_type="ndarray")
    return _as_adjacency(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), k) if k != 2 \
        else _as_adjacency(np.array([[0, 1], [1, 0]]), 2)


def laplacian(centers: ArrayLike, adjacency: ArrayLike) -> sparse.csr_matrix:
    """Q of (9): Q_ij = −a_ij, Q_ii = Σ_j a_ij, a_ij = c_ij/‖x_i − x_j‖² (sparse)."""
    c = as_finite_array("biasfield.laplacian centers", centers, ndim=2, max_abs=MAX_MAGNITUDE)
    adj = sparse.coo_matrix(_as_adjacency(adjacency, c.shape[0]))
    d2 = np.sum((c[adj.row] - c[adj.col]) ** 2, axis=1)
    if np.any(d2 == 0):
        raise ProblemError("biasfield.laplacian centers: two neighbouring centres coincide")
    a = sparse.csr_matrix((1.0 / d2, (adj.row, adj.col)), shape=adj.shape)
    return (sparse.diags(np.asarray(a.sum(axis=1)).ravel()) - a).tocsr()


def uncertainty_sets(data: FieldData, *, space: Literal["polar", "cartesian"] = "polar"
                     ) -> tuple[FloatArray, sparse.csr_matrix]:
    """(Φ0 (2mK,), Φ1 sparse (2mK, 2K)) of (10), ordered cell by cell, radar by radar,
    [range, azimuth]; azimuth differences wrapped. η_k = ξ̂_(k) − x_(k).

    ``space="cartesian"``: the exact sets S_ξ̂ of section 3 in the shift space,
    s = [ξ̂_i(k) − ξ̂_(k)]_i + [I; …; I] η_k (a common shift per cell is free).

    Per-cell subsets (``data.seen``): ξ̂_(k) is the mean over the radars S_k that see cell
    k, and the rows of the radars outside S_k are zero in Φ⁰ and Φ¹ (their φ entries are
    0 and enter neither (9) nor (8)); with every radar in every S_k this is the paper's
    (10) exactly."""
    space = as_choice("biasfield.uncertainty_sets space", space,  # type: ignore[assignment]
                      ("polar", "cartesian"))
    m, k = data.m, data.k
    if data.seen is None:
        mean = data.xi.mean(axis=1)  # ξ̂_(k)
    else:
        w = data.seen.astype(float)
        mean = np.einsum("ki,kia->ka", w, data.xi) / w.sum(axis=1)[:, None]
    if space == "cartesian":
        s0 = (data.xi - mean[:, None, :]).reshape(-1)
        s1 = sparse.block_diag([np.tile(np.eye(2), (m, 1))] * k, format="csr")
        return _mask_sets(data, s0, s1)
    phi0 = np.empty((k, m, 2))
    blocks = []
    if data.geodetic is not None and data.heights is not None:
        # exact 3-D polar maps at each cell's height: slant range, each radar's own north
        from optmodels.biasfield import geometry3d as g3

        lat0, lon0 = g3.plane_to_geodetic(mean, data.origin)
        for i in range(m):
            lat, lon = g3.plane_to_geodetic(data.xi[:, i], data.origin)
            r1, a1 = g3.measure(data.geodetic[i], lat, lon, data.heights)
            r0, a0 = g3.measure(data.geodetic[i], lat0, lon0, data.heights)
            phi0[:, i] = np.column_stack([r1 - r0, wrap_angle(a1 - a0)])
        jac = data.jacobians if data.jacobians is not None else np.stack(
            [g3.polar_jacobian3d(mean, data.heights, data.geodetic[i], data.origin)
             for i in range(m)], axis=1)
    elif data.jacobians is not None:
        # only the Jacobians known: Φ0 linearised, ∇p_i(ξ̂_(k))(ξ̂_i(k) − ξ̂_(k))
        jac = data.jacobians
        phi0[:] = np.einsum("kiab,kib->kia", jac, data.xi - mean[:, None, :])
    else:
        for i in range(m):
            d = to_polar(data.xi[:, i], data.radars[i]) - to_polar(mean, data.radars[i])
            phi0[:, i] = np.column_stack([d[:, 0], wrap_angle(d[:, 1])])
        jac = np.stack([polar_jacobian(mean, data.radars[i]) for i in range(m)], axis=1)
    for kk in range(k):
        blocks.append(jac[kk].reshape(2 * m, 2))
    return _mask_sets(data, phi0.reshape(-1), sparse.block_diag(blocks, format="csr"))


def _mask_sets(data: FieldData, phi0: FloatArray, phi1: sparse.csr_matrix
               ) -> tuple[FloatArray, sparse.csr_matrix]:
    """Zero the rows of (Φ⁰, Φ¹) of the radars outside each cell's subset S_k."""
    if data.seen is None:
        return phi0, phi1
    rows = np.repeat(data.seen.reshape(-1), 2).astype(float)
    phi1 = (sparse.diags(rows) @ phi1).tocsr()
    phi1.eliminate_zeros()
    return phi0 * rows, phi1


@dataclass
class Diagnostics:
    """What :func:`build_field_data` used and dropped: plots dropped by reason, per kept
    cell the averaging instants (``samples_per_cell``), the plots behind them (all radars)
    and the objects, the number of cells dropped for lack of data, and the seconds of
    each stage (``timings``)."""

    dropped_plots: dict[str, int] = field(default_factory=dict)
    samples_per_cell: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    plots_per_cell: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    objects_per_cell: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    dropped_cells: int = 0
    fits: list[TrackFit] = field(default_factory=list, repr=False)
    #: wall seconds of the stages: ``fits``, ``samples``, ``centres``, ``averaging``
    timings: dict[str, float] = field(default_factory=dict)


def build_field_data(plots: PlotTable, radars: RadarSet, *, cells: int | ArrayLike = 50,
                     cell_radius: float | None = None, knot_spacing: float = 20.0,
                     sample_step: float = 5.0, neighbour_method: Literal[
                         "delaunay", "radius"] = "delaunay", neighbour_radius: float | None = None,
                     P: ArrayLike | None = None, exclude_radius: float = 20e3, seed: int = 0,
                     scheduler: Any = None, positions: ArrayLike | None = None,
                     coverage: Literal["all", "union"] = "all", subset_share: float = 0.5,
                     progress: bool = False) -> tuple[FieldData, Diagnostics]:
    """Plots → :class:`FieldData`: track fits (3), cells, averaging (6)-(7), neighbours.

    ``cells``: a number of k-means centres, or the centres (K, 2) themselves.
    ``cell_radius``: samples farther than this from every centre belong to no cell
    (default: 1.5 × the median nearest-neighbour distance of the centres). ``P`` defaults
    to diag(1/σ_r², 1/σ_az²) of each radar (the F norm in noise units). Cells without an
    object seen by all m radars are dropped with a warning (counted in the diagnostics).
    Samples within ``exclude_radius`` of any radar are not used: the paper's neighbourhoods
    B_i, where the field is not smooth and the linearisation of p_i fails.

    3-D radar set (``radars.is_3d``; plots with slant ranges, own-north azimuths and target
    heights): the track fits use the exact plane positions and Jacobians at each plot's
    height; each cell gets its mean target height (the plots' heights, interpolated in time
    per object, averaged with the weights of (6)-(7)) and the exact ∇p_i at its mean
    position and that height (``FieldData.jacobians``, ``heights``, ``geodetic``,
    ``origin``), so that the sets (10) use the exact 3-D maps.

    ``scheduler``: passed to :func:`~optmodels.biasfield.tracks.fit_tracks` (``None``:
    in this process). ``positions`` (n, 2): the plots' positions on the common plane
    (``plots.cartesian(radars)``) if the caller has them already, passed to ``fit_tracks``
    (the exact 3-D placement costs ~11 s per 10⁶ plots: compute it once per chain).

    ``coverage``: ``"all"`` (paper 001's (6)-(7) as printed: samples and cells only where
    every radar sees the object) or ``"union"`` (the field over the union of coverage:
    sampling instants where two radars or more have a fit; the cell centres are placed on
    that shared traffic; each cell k gets a subset S_k (``FieldData.seen``): among the
    radar sets of its samples, the largest set contained in the sets of at least
    ``subset_share`` of the cell's samples (ties: the most samples), and it averages
    (6)-(7) over those samples, for the radars of S_k only). ``progress``: tqdm bars on
    stderr for the per-object loops (off when stderr is not a terminal).

    Units: ``cell_radius``, ``neighbour_radius``, ``exclude_radius`` in metres;
    ``knot_spacing``, ``sample_step`` in seconds.
    """
    fn = "biasfield.build_field_data"
    if np.ndim(cells) == 0:
        cells = as_count(f"{fn} cells", cells, minimum=2)
    if cell_radius is not None:
        cell_radius = as_positive(f"{fn} cell_radius (m)", cell_radius)
    knot_spacing = as_positive(f"{fn} knot_spacing (s)", knot_spacing)
    sample_step = as_positive(f"{fn} sample_step (s)", sample_step)
    neighbour_method = as_choice(f"{fn} neighbour_method",  # type: ignore[assignment]
                                 neighbour_method, ("delaunay", "radius"))
    if neighbour_method == "radius":
        neighbour_radius = as_positive(f"{fn} neighbour_radius (m)", neighbour_radius)
    exclude_radius = as_positive(f"{fn} exclude_radius (m)", exclude_radius, allow_zero=True)
    seed = as_count(f"{fn} seed", seed)
    coverage = as_choice(f"{fn} coverage", coverage,  # type: ignore[assignment]
                         ("all", "union"))
    subset_share = as_positive(f"{fn} subset_share", subset_share)
    if subset_share > 1:
        raise ProblemError(f"{fn} subset_share: expected a share in (0, 1], got "
                           f"{subset_share}")
    check_tables(fn, plots, radars)
    if coverage == "union" and radars.m > MAX_UNION_RADARS:
        raise ProblemError(f"{fn} radars: coverage='union' handles up to {MAX_UNION_RADARS} "
                           f"radars (one bit each), got {radars.m}")
    extra: dict[str, Any] = {} if scheduler is None else {"scheduler": scheduler}
    if positions is not None:
        extra["positions"] = positions
    clock = time.perf_counter()
    fits, dropped = fit_tracks(plots, radars, knot_spacing=knot_spacing, **extra)
    height_of = _height_interpolants(plots) if radars.is_3d else {}
    diag = Diagnostics(dropped_plots=dict(dropped.counts), fits=fits)
    clock = _lap(diag, "fits", clock)
    m = radars.m
    union = coverage == "union"
    by_obj: dict[int, list[list[TrackFit]]] = {}
    for f in fits:
        by_obj.setdefault(f.object, [[] for _ in range(m)])[f.radar].append(f)
    for per_radar in by_obj.values():
        for pieces in per_radar:
            pieces.sort(key=lambda f: f.span[0])
    objects = [p for p in by_obj.values()
               if sum(1 for q in p if q) >= (2 if union else m)]
    # samples: instants where all m radars (union: two or more) have a fit
    all_pos = []
    kept = []
    for per_radar in _bar(objects, progress, "field data: samples"):
        smp = _object_samples(per_radar, sample_step, union)
        if smp is not None:
            kept.append(per_radar)
            all_pos.append(smp[3])
    if not kept:
        raise ProblemError(_no_samples_message(fn, plots, fits, knot_spacing, union, m))
    clock = _lap(diag, "samples", clock)
    if np.ndim(cells) == 0:
        pts = np.vstack(all_pos)
        if pts.shape[0] < int(cells):  # type: ignore[arg-type]
            raise ProblemError(f"{fn} cells: {int(cells)} cells asked for but only "  # type: ignore
                               f"{pts.shape[0]} sampling instants are shared by "
                               f"{'two radars or more' if union else 'all radars'}")
        centers = place_centers(pts, int(cells), seed=seed)  # type: ignore[arg-type]
        del pts
    else:
        centers = as_finite_array(f"{fn} cells", cells, ndim=2, max_abs=MAX_MAGNITUDE)
        if centers.shape[1] != 2 or centers.shape[0] < 2:
            raise ProblemError(f"{fn} cells: expected (K, 2) centres (m) with K ≥ 2, got "
                               f"{centers.shape}")
    del all_pos
    clock = _lap(diag, "centres", clock)
    tree = cKDTree(centers)
    if cell_radius is None:
        nn = tree.query(centers, k=2)[0][:, 1]
        cell_radius = 1.5 * float(np.median(nn))
    k0 = centers.shape[0]
    full = np.uint64((1 << m) - 1) if union else np.uint64(0)
    if union:
        subset = _choose_subsets(kept, sample_step, tree, cell_radius, radars,
                                 exclude_radius, k0, subset_share, progress)
    else:
        subset = np.zeros(k0, dtype=np.uint64)
    sum_xi = np.zeros((k0, m, 2))
    sum_cov = np.zeros((k0, m, 2, 2))
    sum_h = np.zeros(k0)
    n_obj = np.zeros(k0, dtype=int)
    n_smp = np.zeros(k0, dtype=int)
    n_plt = np.zeros(k0, dtype=int)
    plot_times = plots.time
    for per_radar in _bar(kept, progress, "field data: averaging"):
        smp = _object_samples(per_radar, sample_step, union)
        assert smp is not None
        _accumulate(smp, per_radar, tree, cell_radius, radars, exclude_radius,
                    sample_step, plot_times, height_of, subset if union else None,
                    sum_xi, sum_cov, sum_h, n_obj, n_smp, n_plt)
    clock = _lap(diag, "averaging", clock)
    keep = n_obj > 0
    diag.dropped_cells = int(np.sum(~keep))
    who = "two radars or more" if union else "all radars"
    if diag.dropped_cells:
        warnings.warn(f"build_field_data: {diag.dropped_cells} of {k0} cells hold no object "
                      f"seen by {who} and were dropped", stacklevel=2)
    if keep.sum() < 2:
        raise ProblemError(f"cells: fewer than 2 cells hold objects seen by {who}")
    centers = centers[keep]
    seen = None
    if union:
        bits = subset[keep]
        seen = ((bits[:, None] >> np.arange(m, dtype=np.uint64)[None, :]) & np.uint64(1)
                ).astype(bool)
        if np.all(bits == full):
            seen = None  # every cell sees every radar: the paper's case
    xi = sum_xi[keep] / n_obj[keep, None, None]
    xi_cov = sum_cov[keep] / (n_obj[keep, None, None, None] ** 2)
    if seen is not None:
        w = seen.astype(float)
        mean_s = np.einsum("ki,kia->ka", w, xi) / w.sum(axis=1)[:, None]
        xi = np.where(seen[..., None], xi, mean_s[:, None, :])
        eye = np.broadcast_to(np.eye(2) * float(np.median(xi_cov[seen][:, [0, 1], [0, 1]])),
                              xi_cov.shape)
        xi_cov = np.where(seen[..., None, None], xi_cov, eye)
    diag.samples_per_cell = n_smp[keep]
    diag.plots_per_cell = n_plt[keep]
    diag.objects_per_cell = n_obj[keep]
    adj = neighbours(centers, method=neighbour_method, radius=neighbour_radius)
    if P is None:
        p = sparse.block_diag([np.diag([1 / radars.sigma_range[i] ** 2,
                                        1 / radars.sigma_azimuth[i] ** 2])
                               for i in range(m)]).toarray()
    else:
        p = as_finite_array(f"{fn} P", P, ndim=2, max_abs=MAX_MAGNITUDE)
    if not radars.is_3d:
        return FieldData(radars.sites, centers, xi, adj, p, xi_cov, seen=seen), diag
    heights = sum_h[keep] / n_obj[keep]
    if seen is None:
        mean = xi.mean(axis=1)
    else:
        mean = np.einsum("ki,kia->ka", seen.astype(float), xi) / seen.sum(axis=1)[:, None]
    jac = np.stack([radars.polar_jacobian(i, mean, heights) for i in range(m)], axis=1)
    return FieldData(radars.sites, centers, xi, adj, p, xi_cov, jac, heights,
                     radars.geodetic, radars.origin, seen), diag


def _scan_intervals(plots: PlotTable, m: int) -> FloatArray:
    """(m,) each radar's median time between consecutive plots of one object (s; NaN for
    a radar without two plots of an object)."""
    out = np.full(m, np.nan)
    ok = plots.object >= 0
    for i in range(m):
        sel = ok & (plots.radar == i)
        if sel.sum() < 2:
            continue
        o, t = plots.object[sel], plots.time[sel]
        order = np.lexsort((t, o))
        o, t = o[order], t[order]
        d = np.diff(t)[np.diff(o) == 0]
        d = d[d > 0]
        if d.size:
            out[i] = float(np.median(d))
    return out


def _no_samples_message(fn: str, plots: PlotTable, fits: list[TrackFit],
                        knot_spacing: float, union: bool, m: int) -> str:
    """Why no sampling instant was found: a knot spacing shorter than the scans (every
    track split at each plot, no fit), no fit at all, or the geometry (no object seen by
    all m radars / by two radars at the same time)."""
    scans = _scan_intervals(plots, m)
    longest = float(np.nanmax(scans)) if np.isfinite(scans).any() else float("nan")
    if np.isfinite(longest) and knot_spacing < 1.5 * longest:
        return (f"{fn} knot_spacing: {knot_spacing:g} s is not longer than the radars' scan "
                f"intervals (median per radar {np.round(scans, 1).tolist()} s): the track "
                "fits split a track at every silence longer than the knot spacing and "
                f"keep {len(fits)} fits; give at least 2 × the longest scan interval "
                f"(e.g. {2 * longest:.0f} s; 20 s for 4-10 s scans)")
    if not fits:
        return (f"{fn} plots: no track could be fitted (too few plots per track for the "
                f"polyline of knot spacing {knot_spacing:g} s); no cell can be formed")
    if union:
        return ("plots: no object is seen by two radars at the same time (after the "
                "track fits); no cell can be formed")
    return ("plots: no object is seen by all m radars at the same time; no cell can be "
            "formed (coverage='union' forms cells wherever two radars overlap)")


#: Most radars of ``build_field_data(coverage="union")`` (one bit of a uint64 each).
MAX_UNION_RADARS = 63

#: One object's samples: (instants t, the present radars, each present radar's piece per
#: instant (−1: none), the positions (mean over the radars with a piece), the radar bits).
Samples = tuple[FloatArray, list[int], np.ndarray, FloatArray, np.ndarray]


def _bar(items: list[Any], progress: bool, desc: str) -> Any:
    """``items`` wrapped in a tqdm bar on stderr when ``progress`` and stderr is a
    terminal (and tqdm installed)."""
    if not progress:
        return items
    import sys

    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the bench extra
        return items
    return tqdm(items, desc=desc, file=sys.stderr, disable=not sys.stderr.isatty(),
                leave=False)


def _object_samples(per_radar: list[list[TrackFit]], sample_step: float, union: bool
                    ) -> Samples | None:
    """The sampling instants of one object (``sample_step`` s apart): inside the common
    span of all m radars' fits (``union`` False, the paper's case), or wherever two radars
    or more have a fit (``union``); None if there is none."""
    present = [i for i, p in enumerate(per_radar) if p]
    if union:
        lo = min(p[0].span[0] for p in (per_radar[i] for i in present))
        hi = max(max(f.span[1] for f in per_radar[i]) for i in present)
    else:
        lo = max(min(f.span[0] for f in p) for p in per_radar)
        hi = min(max(f.span[1] for f in p) for p in per_radar)
    if hi <= lo:
        return None
    t = np.arange(lo, hi, sample_step)
    pidx = np.full((len(present), t.size), -1, dtype=np.int32)
    for ii, i in enumerate(present):
        for j, f in enumerate(per_radar[i]):
            pidx[ii, (t >= f.span[0]) & (t <= f.span[1])] = j
    act = pidx >= 0
    count = act.sum(axis=0)
    ok = count >= 2 if union else np.all(act, axis=0)
    if not ok.any():
        return None
    t, pidx, count = t[ok], pidx[:, ok], count[ok]
    pos = np.zeros((t.size, 2))
    bits = np.zeros(t.size, dtype=np.uint64)
    for ii, i in enumerate(present):
        for j in np.unique(pidx[ii]):
            if j < 0:
                continue
            sel = pidx[ii] == j
            if union:
                pos[sel] += per_radar[i][j].at(t[sel]) / count[sel, None]
            else:
                pos[sel] += per_radar[i][j].at(t[sel]) / len(per_radar)
        bits[pidx[ii] >= 0] |= np.uint64(1 << i)
    return t, present, pidx, pos, bits


def _sample_cells(pos: FloatArray, tree: cKDTree, cell_radius: float, radars: RadarSet,
                  exclude_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's nearest cell and the samples that count (within ``cell_radius`` of
    it and farther than ``exclude_radius`` from every radar)."""
    dist, cell = tree.query(pos)
    near = np.min(np.linalg.norm(pos[:, None] - radars.sites[None], axis=2), axis=1)
    return cell, np.flatnonzero((dist <= cell_radius) & (near > exclude_radius))


def _choose_subsets(objects: list[list[list[TrackFit]]], sample_step: float,
                    tree: cKDTree, cell_radius: float, radars: RadarSet,
                    exclude_radius: float, k0: int, share: float, progress: bool
                    ) -> np.ndarray:
    """Per cell the radar set S_k (bits): among the radar sets of its samples, the largest
    contained in the sets of ≥ ``share`` of the samples (ties: the most samples); 0 for a
    cell without samples."""
    counts: dict[tuple[int, int], int] = {}
    for per_radar in _bar(objects, progress, "field data: subsets"):
        smp = _object_samples(per_radar, sample_step, True)
        assert smp is not None
        cell, idx = _sample_cells(smp[3], tree, cell_radius, radars, exclude_radius)
        if idx.size == 0:
            continue
        key = np.column_stack([cell[idx].astype(np.uint64), smp[4][idx]])
        uniq, n = np.unique(key, axis=0, return_counts=True)
        for (c, b), v in zip(uniq.tolist(), n.tolist(), strict=True):
            counts[(c, b)] = counts.get((c, b), 0) + v
    per_cell: dict[int, list[tuple[int, int]]] = {}
    for (c, b), v in counts.items():
        per_cell.setdefault(c, []).append((b, v))
    subset = np.zeros(k0, dtype=np.uint64)
    for c, lst in per_cell.items():
        total = sum(v for _, v in lst)
        best = (-1, -1, 0)
        for b, _ in lst:
            support = sum(v for b2, v in lst if b2 & b == b)
            if support >= share * total:
                cand = (int(b).bit_count(), support, b)
                if cand[:2] > best[:2]:
                    best = cand
        if best[0] >= 2:
            subset[c] = np.uint64(best[2])
    return subset


def _lap(diag: Diagnostics, stage: str, since: float) -> float:
    """Record the seconds of ``stage`` since ``since``; return the clock."""
    now = time.perf_counter()
    diag.timings[stage] = now - since
    return now


def _accumulate(smp: Samples, per_radar: list[list[TrackFit]], tree: cKDTree,
                cell_radius: float, radars: RadarSet, exclude_radius: float,
                sample_step: float, plot_times: FloatArray,
                height_of: dict[int, tuple[FloatArray, FloatArray]],
                subset: np.ndarray | None, sum_xi: FloatArray, sum_cov: FloatArray,
                sum_h: FloatArray, n_obj: np.ndarray, n_smp: np.ndarray,
                n_plt: np.ndarray) -> None:
    """One object's share of the averages (6)-(7), added in place to the per-cell sums.

    The object's sampling instants (positions, each present radar's piece) are sorted by
    cell once (stable: time order kept inside a cell); per radar and piece ONE
    :meth:`TrackFit.means_over` gives the means and covariances over all the cells at
    once (the same numbers as one :meth:`TrackFit.mean_over` per cell), and the plots
    behind each (cell, piece) are counted by binary search in the piece's sorted plot
    times: O(samples log) per object instead of O(samples × cells crossed) Python calls.

    ``subset`` (K,) radar bits S_k (union coverage): only the samples whose radar set
    contains S_k count for cell k, and only the radars of S_k are averaged there."""
    t, present, pidx, pos, bits = smp
    cell, idx = _sample_cells(pos, tree, cell_radius, radars, exclude_radius)
    if subset is not None and idx.size:
        need = subset[cell[idx]]
        idx = idx[(need != 0) & ((bits[idx] & need) == need)]
    if idx.size == 0:
        return
    idx = idx[np.argsort(cell[idx], kind="stable")]
    cs = cell[idx]
    first = np.flatnonzero(np.concatenate([[True], cs[1:] != cs[:-1]]))
    cells_here = cs[first]
    n_sel = np.diff(np.append(first, cs.size))
    grp = np.repeat(np.arange(first.size), n_sel)  # cell label 0..G−1 of each sample
    n_obj[cells_here] += 1
    n_smp[cells_here] += n_sel
    ts_all = t[idx]
    if radars.is_3d:
        ht, hv = height_of[per_radar[present[0]][0].object]
        sum_h[cells_here] += np.bincount(grp, np.interp(ts_all, ht, hv)) / n_sel
    for ii, i in enumerate(present):
        pieces_i = pidx[ii, idx]
        if subset is not None:  # radar i only in the cells whose S_k holds it
            mine = ((subset[cs] >> np.uint64(i)) & np.uint64(1)) == 1
            pieces_i = np.where(mine, pieces_i, -1)
        for j in np.unique(pieces_i):
            if j < 0:
                continue
            fit = per_radar[i][j]
            on = pieces_i == j
            ts, g = ts_all[on], grp[on]
            # the cells this piece covers, relabelled 0..G'−1 (g is sorted)
            starts = np.flatnonzero(np.concatenate([[True], g[1:] != g[:-1]]))
            local = np.repeat(np.arange(starts.size), np.diff(np.append(starts, g.size)))
            gs = g[starts]
            kk = cells_here[gs]
            mean_p, cov_p = fit.means_over(ts, local)
            w = np.diff(np.append(starts, g.size)) / n_sel[gs]
            sum_xi[kk, i] += w[:, None] * mean_p
            sum_cov[kk, i] += (w * w)[:, None, None] * cov_p
            pt = plot_times[fit.rows]
            if np.any(pt[1:] < pt[:-1]):
                pt = np.sort(pt)
            lo = np.minimum.reduceat(ts, starts)
            hi = np.maximum.reduceat(ts, starts) + sample_step
            n_plt[kk] += (np.searchsorted(pt, hi, side="right")
                          - np.searchsorted(pt, lo, side="left"))


def _height_interpolants(plots: PlotTable) -> dict[int, tuple[FloatArray, FloatArray]]:
    """Per object: the (time, height) of its plots with a known height (all radars), sorted
    by time, for np.interp (the target's height as ADS-B or a corrected flight level gives
    it, the same for every radar)."""
    if plots.height is None:
        raise ProblemError("biasfield.build_field_data plots: a 3-D radar set needs the "
                           "target heights (PlotTable height)")
    ok = ~np.isnan(plots.height) & (plots.object >= 0)
    obj, t, h = plots.object[ok], plots.time[ok], plots.height[ok]
    order = np.lexsort((t, obj))
    obj, t, h = obj[order], t[order], h[order]
    cuts = np.flatnonzero(np.diff(obj)) + 1
    return {int(o[0]): (tt, hh) for o, tt, hh in zip(np.split(obj, cuts), np.split(t, cuts),
                                                      np.split(h, cuts), strict=True)
            if o.size}


#: Size guard of :func:`synthetic_field_data` (memory grows as cells × radars).
MAX_SYNTHETIC_CELLS = 1_000_000


def synthetic_field_data(seed: int | np.random.Generator, *, cells: int = 200,
                         sites: ArrayLike | None = None, fields: list[Any] | None = None,
                         region: float = 150e3, noise: float = 0.0,
                         exclude_radius: float = 20e3) -> tuple[FieldData, FloatArray]:
    """FieldData without plots: K random cell centres (none within ``exclude_radius`` of a
    radar), true positions x_k at the centres, ξ_i(k) = x_k + s_i(x_k) (+ Gaussian noise of
    ``noise`` metres), Delaunay neighbours and P = diag(1/(50 m)², 1/(1 mrad)²) per radar.
    ``fields`` defaults to smooth random fields. Returns the data and the true field
    (K, m, 2) at the centres."""
    from optmodels.biasfield.fields import BiasField
    from optmodels.biasfield.geometry import shift_from_bias

    fn = "biasfield.synthetic_field_data"
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(
        as_count(f"{fn} seed", seed))
    cells = as_count(f"{fn} cells", cells, minimum=3, maximum=MAX_SYNTHETIC_CELLS)
    region = as_positive(f"{fn} region (m)", region)
    noise = as_positive(f"{fn} noise (m)", noise, allow_zero=True)
    exclude_radius = as_positive(f"{fn} exclude_radius (m)", exclude_radius, allow_zero=True)
    s = (np.array([[-90e3, -60e3], [100e3, -70e3], [80e3, 110e3], [-70e3, 90e3]])
         if sites is None else as_finite_array(f"{fn} sites", sites, ndim=2,
                                               max_abs=MAX_MAGNITUDE))
    if s.shape[1] != 2 or s.shape[0] < 2:
        raise ProblemError(f"{fn} sites: expected (m, 2) with m ≥ 2, got {s.shape}")
    m = s.shape[0]
    if fields is not None and len(fields) != m:
        raise ProblemError(f"{fn} fields: expected {m} fields (one per radar), got "
                           f"{len(fields)}")
    flist = fields or [BiasField.smooth(rng, center=np.zeros(2), scale=region,
                                        range_amplitude=150.0, azimuth_amplitude=np.deg2rad(0.3))
                       for _ in range(m)]
    pts: list[FloatArray] = []
    for _ in range(1000):
        cand = rng.uniform(-region, region, (2 * cells, 2))
        near = np.min(np.linalg.norm(cand[:, None] - s[None], axis=2), axis=1)
        pts.append(cand[near > exclude_radius])
        if sum(len(p) for p in pts) >= cells:
            break
    else:
        raise ProblemError(f"{fn} exclude_radius: no room for cells in the region (±{region:g} "
                           f"m) outside {exclude_radius:g} m of the radars")
    x = np.vstack(pts)[:cells]
    truth = np.stack([flist[i](x) for i in range(m)], axis=1)
    xi = np.stack([x + shift_from_bias(x, s[i], truth[:, i]) for i in range(m)], axis=1)
    if noise > 0:
        xi = xi + rng.normal(0.0, noise, xi.shape)
    p = np.diag([1 / 50.0**2, 1 / 1e-3**2])
    return FieldData(s, x, xi, neighbours(x), p), truth
