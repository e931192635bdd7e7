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

from optmodels.biasfield.data import PlotTable, RadarSet
from optmodels.biasfield.geometry import polar_jacobian, to_polar, wrap_angle
from optmodels.biasfield.tracks import TrackFit, _check_tables, fit_tracks
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
        for name in ("xi_cov", "jacobians", "heights", "geodetic", "origin"):
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
        chain have none of the last four)."""
        if not isinstance(path, str | Path):
            raise ProblemError(f"biasfield.FieldData.load path: expected a file name, got "
                               f"{type(path).__name__}")
        d = read_npz(path, what="FieldData .npz", required=("radars", "centers", "xi", "P"),
                     one_of=("edges", "adjacency"))
        adj = d["edges"] if "edges" in d else d["adjacency"]
        try:
            return cls(d["radars"], d["centers"], d["xi"], adj, d["P"], d.get("xi_cov"),
                       d.get("jacobians"), d.get("heights"), d.get("geodetic"),
                       d.get("origin"))
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
    s = [ξ̂_i(k) − ξ̂_(k)]_i + [I; …; I] η_k (a common shift per cell is free)."""
    space = as_choice("biasfield.uncertainty_sets space", space,  # type: ignore[assignment]
                      ("polar", "cartesian"))
    m, k = data.m, data.k
    mean = data.xi.mean(axis=1)  # ξ̂_(k)
    if space == "cartesian":
        s0 = (data.xi - mean[:, None, :]).reshape(-1)
        return s0, sparse.block_diag([np.tile(np.eye(2), (m, 1))] * k, format="csr")
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
    return phi0.reshape(-1), sparse.block_diag(blocks, format="csr")


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
                     scheduler: Any = None, positions: ArrayLike | None = None
                     ) -> tuple[FieldData, Diagnostics]:
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
    _check_tables(fn, plots, radars)
    extra: dict[str, Any] = {} if scheduler is None else {"scheduler": scheduler}
    if positions is not None:
        extra["positions"] = positions
    clock = time.perf_counter()
    fits, dropped = fit_tracks(plots, radars, knot_spacing=knot_spacing, **extra)
    height_of = _height_interpolants(plots) if radars.is_3d else {}
    diag = Diagnostics(dropped_plots=dict(dropped.counts), fits=fits)
    clock = _lap(diag, "fits", clock)
    m = radars.m
    by_obj: dict[int, list[list[TrackFit]]] = {}
    for f in fits:
        by_obj.setdefault(f.object, [[] for _ in range(m)])[f.radar].append(f)
    # samples: instants where all m radars have a fit, with each radar's piece
    samples: list[tuple[FloatArray, list[list[TrackFit]], np.ndarray]] = []
    all_pos = []
    for per_radar in by_obj.values():
        if any(not p for p in per_radar):
            continue
        lo = max(min(f.span[0] for f in p) for p in per_radar)
        hi = min(max(f.span[1] for f in p) for p in per_radar)
        if hi <= lo:
            continue
        t = np.arange(lo, hi, sample_step)
        pidx = np.full((m, t.size), -1, dtype=np.int32)  # each radar's piece per instant
        for i, pieces in enumerate(per_radar):
            pieces.sort(key=lambda f: f.span[0])
            for j, f in enumerate(pieces):
                pidx[i, (t >= f.span[0]) & (t <= f.span[1])] = j
        ok = np.all(pidx >= 0, axis=0)
        if not ok.any():
            continue
        t, pidx = t[ok], pidx[:, ok]
        pos = np.zeros((t.size, 2))
        for i, pieces in enumerate(per_radar):
            for j in np.unique(pidx[i]):
                sel = pidx[i] == j
                pos[sel] += pieces[j].at(t[sel]) / m
        samples.append((t, per_radar, pidx))
        all_pos.append(pos)
    if not samples:
        raise ProblemError("plots: no object is seen by all m radars at the same time; "
                           "no cell can be formed")
    clock = _lap(diag, "samples", clock)
    if np.ndim(cells) == 0:
        centers = place_centers(np.vstack(all_pos), int(cells),  # type: ignore[arg-type]
                                seed=seed)
    else:
        centers = as_finite_array(f"{fn} cells", cells, ndim=2, max_abs=MAX_MAGNITUDE)
        if centers.shape[1] != 2 or centers.shape[0] < 2:
            raise ProblemError(f"{fn} cells: expected (K, 2) centres (m) with K ≥ 2, got "
                               f"{centers.shape}")
    clock = _lap(diag, "centres", clock)
    tree = cKDTree(centers)
    if cell_radius is None:
        nn = tree.query(centers, k=2)[0][:, 1]
        cell_radius = 1.5 * float(np.median(nn))
    k0 = centers.shape[0]
    sum_xi = np.zeros((k0, m, 2))
    sum_cov = np.zeros((k0, m, 2, 2))
    sum_h = np.zeros(k0)
    n_obj = np.zeros(k0, dtype=int)
    n_smp = np.zeros(k0, dtype=int)
    n_plt = np.zeros(k0, dtype=int)
    plot_times = plots.time
    for (t, per_radar, pidx), pos in zip(samples, all_pos, strict=True):
        _accumulate(t, per_radar, pidx, pos, tree, cell_radius, radars, exclude_radius,
                    sample_step, plot_times, height_of, sum_xi, sum_cov, sum_h, n_obj,
                    n_smp, n_plt)
    clock = _lap(diag, "averaging", clock)
    keep = n_obj > 0
    diag.dropped_cells = int(np.sum(~keep))
    if diag.dropped_cells:
        warnings.warn(f"build_field_data: {diag.dropped_cells} of {k0} cells hold no object "
                      "seen by all radars and were dropped", stacklevel=2)
    if keep.sum() < 2:
        raise ProblemError("cells: fewer than 2 cells hold objects seen by all radars")
    centers = centers[keep]
    xi = sum_xi[keep] / n_obj[keep, None, None]
    xi_cov = sum_cov[keep] / (n_obj[keep, None, None, None] ** 2)
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
        return FieldData(radars.sites, centers, xi, adj, p, xi_cov), diag
    heights = sum_h[keep] / n_obj[keep]
    mean = xi.mean(axis=1)
    jac = np.stack([radars.polar_jacobian(i, mean, heights) for i in range(m)], axis=1)
    return FieldData(radars.sites, centers, xi, adj, p, xi_cov, jac, heights,
                     radars.geodetic, radars.origin), diag


def _lap(diag: Diagnostics, stage: str, since: float) -> float:
    """Record the seconds of ``stage`` since ``since``; return the clock."""
    now = time.perf_counter()
    diag.timings[stage] = now - since
    return now


def _accumulate(t: FloatArray, per_radar: list[list[TrackFit]], pidx: np.ndarray,
                pos: FloatArray, tree: cKDTree, cell_radius: float, radars: RadarSet,
                exclude_radius: float, sample_step: float, plot_times: FloatArray,
                height_of: dict[int, tuple[FloatArray, FloatArray]], sum_xi: FloatArray,
                sum_cov: FloatArray, sum_h: FloatArray, n_obj: np.ndarray, n_smp: np.ndarray,
                n_plt: np.ndarray) -> None:
    """One object's share of the averages (6)-(7), added in place to the per-cell sums.

    The object's sampling instants ``t`` (positions ``pos``, each radar's piece ``pidx``)
    are sorted by cell once (stable: time order kept inside a cell); per radar and piece
    ONE :meth:`TrackFit.means_over` gives the means and covariances over all the cells at
    once (the same numbers as one :meth:`TrackFit.mean_over` per cell), and the plots
    behind each (cell, piece) are counted by binary search in the piece's sorted plot
    times: O(samples log) per object instead of O(samples × cells crossed) Python calls."""
    m = radars.m
    dist, cell = tree.query(pos)
    near = np.min(np.linalg.norm(pos[:, None] - radars.sites[None], axis=2), axis=1)
    idx = np.flatnonzero((dist <= cell_radius) & (near > exclude_radius))
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
        ht, hv = height_of[per_radar[0][0].object]
        sum_h[cells_here] += np.bincount(grp, np.interp(ts_all, ht, hv)) / n_sel
    for i in range(m):
        pieces_i = pidx[i, idx]
        for j in np.unique(pieces_i):
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
