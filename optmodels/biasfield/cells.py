r"""The field-data stage (paper 001, section 3): track fits → cells → averages (6)-(7) →
:class:`~optmodels.biasfield.data.FieldData`.

* Cell centres x̌_(k): a grid, or k-means of the fitted positions (where traffic is),
  :func:`place_centers`. A sample belongs to the cell of its nearest centre if it lies
  within ``cell_radius``.
* Averaging (6)-(7) (:mod:`~optmodels.biasfield.averaging`): for every object seen by
  **all** m radars in cell k, the fitted ξ̂_i^a(t) are averaged over the instants the
  object spent in the cell, then over the objects, with their exact covariance.
* Neighbours, the Laplacian Q of (9) and the uncertainty sets (10) belong to the data:
  :mod:`~optmodels.biasfield.data`.

:func:`build_field_data` reads validate (:func:`_settings`) → build (the fits, the sampled
objects, the centres) → run (the per-cell sums) → finish (:func:`_field_data`).
"""

from __future__ import annotations

import inspect
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.spatial import cKDTree

from optmodels.biasfield.averaging import (
    MAX_UNION_RADARS,
    CellSums,
    average_cells,
    choose_subsets,
    height_interpolants,
    no_samples_message,
    object_samples,
    progress_bar,
)
from optmodels.biasfield.data import FieldData, neighbours
from optmodels.biasfield.tables import PlotTable, RadarSet, check_tables
from optmodels.biasfield.tracks import TrackFit, fit_tracks
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_flag,
    as_positive,
    check_spd,
)

__all__ = [
    "MAX_UNION_RADARS",
    "Diagnostics",
    "build_field_data",
    "check_build_arguments",
    "place_centers",
]


def place_centers(
    points: ArrayLike,
    count: int,
    *,
    method: Literal["kmeans", "grid"] = "kmeans",
    seed: int | np.random.Generator = 0,
) -> FloatArray:
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
    as_choice(f"{fn} method", method, ("kmeans", "grid"))
    if pts.shape[0] < count:
        raise ProblemError(
            f"{fn} count: need 2 ≤ count ≤ number of points ({pts.shape[0]}), got {count}"
        )
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


def build_field_data(
    plots: PlotTable,
    radars: RadarSet,
    *,
    cells: int | ArrayLike = 50,
    cell_radius: float | None = None,
    knot_spacing: float = 20.0,
    sample_step: float = 5.0,
    neighbour_method: Literal["delaunay", "radius"] = "delaunay",
    neighbour_radius: float | None = None,
    P: ArrayLike | None = None,
    exclude_radius: float = 20e3,
    seed: int = 0,
    scheduler: Any = None,
    positions: ArrayLike | None = None,
    coverage: Literal["all", "union"] = "all",
    subset_share: float = 0.5,
    progress: bool = False,
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
    s = _settings(
        fn,
        plots,
        radars,
        cells=cells,
        cell_radius=cell_radius,
        knot_spacing=knot_spacing,
        sample_step=sample_step,
        neighbour_method=neighbour_method,
        neighbour_radius=neighbour_radius,
        P=P,
        exclude_radius=exclude_radius,
        seed=seed,
        coverage=coverage,
        subset_share=subset_share,
        progress=progress,
    )
    extra: dict[str, Any] = {} if scheduler is None else {"scheduler": scheduler}
    if positions is not None:
        extra["positions"] = positions
    clock = time.perf_counter()
    fits, dropped = fit_tracks(plots, radars, knot_spacing=s.knot_spacing, **extra)
    height_of = height_interpolants(plots) if radars.is_3d else {}
    diag = Diagnostics(dropped_plots=dict(dropped.counts), fits=fits)
    clock = _lap(diag, "fits", clock)
    kept, all_pos = _sampled_objects(fits, radars.m, s)
    if not kept:
        raise ProblemError(no_samples_message(fn, plots, fits, s.knot_spacing, s.union, radars.m))
    clock = _lap(diag, "samples", clock)
    centers = _centres(fn, s, all_pos)
    del all_pos
    clock = _lap(diag, "centres", clock)
    tree = cKDTree(centers)
    radius = s.cell_radius
    if radius is None:
        radius = 1.5 * float(np.median(tree.query(centers, k=2)[0][:, 1]))
    k0 = centers.shape[0]
    subset = (
        choose_subsets(
            kept,
            s.sample_step,
            tree,
            radius,
            radars,
            s.exclude_radius,
            k0,
            s.subset_share,
            s.progress,
        )
        if s.union
        else None
    )
    sums = average_cells(
        kept,
        k=k0,
        tree=tree,
        cell_radius=radius,
        radars=radars,
        exclude_radius=s.exclude_radius,
        sample_step=s.sample_step,
        union=s.union,
        plot_times=plots.time,
        height_of=height_of,
        subset=subset,
        progress=s.progress,
    )
    _lap(diag, "averaging", clock)
    return _field_data(fn, sums, centers, subset, radars, s, diag), diag


@dataclass(frozen=True)
class _Settings:
    """The checked arguments of :func:`build_field_data` (units as there)."""

    cells: int | FloatArray
    cell_radius: float | None
    knot_spacing: float
    sample_step: float
    neighbour_method: Literal["delaunay", "radius"]
    neighbour_radius: float | None
    P: ArrayLike | None
    exclude_radius: float
    seed: int
    union: bool
    subset_share: float
    progress: bool


def _settings(
    fn: str,
    plots: PlotTable,
    radars: RadarSet,
    *,
    cells: Any,
    cell_radius: Any,
    knot_spacing: Any,
    sample_step: Any,
    neighbour_method: Any,
    neighbour_radius: Any,
    P: Any,
    exclude_radius: Any,
    seed: Any,
    coverage: Any,
    subset_share: Any,
    progress: bool,
) -> _Settings:
    """Validate the arguments of :func:`build_field_data` (one ProblemError naming the
    argument)."""
    if isinstance(cells, list | tuple) or (isinstance(cells, np.ndarray) and cells.ndim):
        cells = _given_centres(fn, cells)
    else:  # a number of k-means centres
        cells = as_count(f"{fn} cells", cells, minimum=2)
    if cell_radius is not None:
        cell_radius = as_positive(f"{fn} cell_radius (m)", cell_radius)
    knot_spacing = as_positive(f"{fn} knot_spacing (s)", knot_spacing)
    sample_step = as_positive(f"{fn} sample_step (s)", sample_step)
    neighbour_method = as_choice(f"{fn} neighbour_method", neighbour_method, ("delaunay", "radius"))
    if neighbour_method == "radius" or neighbour_radius is not None:
        neighbour_radius = as_positive(f"{fn} neighbour_radius (m)", neighbour_radius)
    exclude_radius = as_positive(f"{fn} exclude_radius (m)", exclude_radius, allow_zero=True)
    seed = as_count(f"{fn} seed", seed)
    coverage = as_choice(f"{fn} coverage", coverage, ("all", "union"))
    subset_share = as_positive(f"{fn} subset_share", subset_share)
    if subset_share > 1:
        raise ProblemError(f"{fn} subset_share: expected a share in (0, 1], got {subset_share}")
    check_tables(fn, plots, radars)
    if P is not None:  # checked here, not after the fits and the averaging
        P = as_finite_array(f"{fn} P", P, ndim=2, max_abs=MAX_MAGNITUDE)
        if P.shape not in ((2, 2), (2 * radars.m, 2 * radars.m)):
            raise ProblemError(
                f"{fn} P: expected (2, 2) or ({2 * radars.m}, {2 * radars.m}), got {P.shape}"
            )
        check_spd(f"{fn} P", P)
    if coverage == "union" and radars.m > MAX_UNION_RADARS:
        raise ProblemError(
            f"{fn} radars: coverage='union' handles up to {MAX_UNION_RADARS} "
            f"radars (one bit each), got {radars.m}"
        )
    return _Settings(
        cells,
        cell_radius,
        knot_spacing,
        sample_step,
        neighbour_method,
        neighbour_radius,
        P,
        exclude_radius,
        seed,
        coverage == "union",
        subset_share,
        as_flag(f"{fn} progress", progress),
    )


def check_build_arguments(fn: str, plots: Any, radars: Any, **kwargs: Any) -> None:
    """The checks of :func:`build_field_data`'s arguments (its defaults for those not
    given), for a caller that does work before calling it
    (:func:`~optmodels.biasfield.pipeline.field_data_from_plots`): one ProblemError naming
    ``fn`` and the argument, also for a name that is not an argument of
    :func:`build_field_data`."""
    params = inspect.signature(build_field_data).parameters
    unknown = sorted(set(kwargs) - set(params))
    if unknown:
        raise ProblemError(
            f"{fn} {unknown[0]}: not an option of biasfield.build_field_data (it takes "
            f"{', '.join(k for k in params if k not in ('plots', 'radars'))})"
        )
    names = [k for k in inspect.signature(_settings).parameters if k in params]
    args = {k: kwargs.get(k, params[k].default) for k in names if k not in ("plots", "radars")}
    _settings(fn, plots, radars, **args)


def _sampled_objects(
    fits: list[TrackFit], m: int, s: _Settings
) -> tuple[list[list[list[TrackFit]]], list[FloatArray]]:
    """The objects with sampling instants (per object its fits per radar, sorted by time)
    and the positions of those instants: where all m radars (union: two or more) have a
    fit."""
    by_obj: dict[int, list[list[TrackFit]]] = {}
    for f in fits:
        by_obj.setdefault(f.object, [[] for _ in range(m)])[f.radar].append(f)
    for per_radar in by_obj.values():
        for pieces in per_radar:
            pieces.sort(key=lambda f: f.span[0])
    objects = [p for p in by_obj.values() if sum(1 for q in p if q) >= (2 if s.union else m)]
    all_pos = []
    kept = []
    for per_radar in progress_bar(objects, s.progress, "field data: samples"):
        smp = object_samples(per_radar, s.sample_step, s.union)
        if smp is not None:
            kept.append(per_radar)
            all_pos.append(smp[3])
    return kept, all_pos


def _centres(fn: str, s: _Settings, all_pos: list[FloatArray]) -> FloatArray:
    """The cell centres: k-means of the sampled positions, or the centres given."""
    cells = s.cells
    if isinstance(cells, int):  # a count (checked by as_count): k-means
        pts = np.vstack(all_pos)
        if pts.shape[0] < cells:
            raise ProblemError(
                f"{fn} cells: {cells} cells asked for but only "
                f"{pts.shape[0]} sampling instants are shared by "
                f"{'two radars or more' if s.union else 'all radars'}"
            )
        return place_centers(pts, cells, seed=s.seed)
    return cells  # the centres given, checked by _given_centres


def _given_centres(fn: str, cells: Any) -> FloatArray:
    """The cell centres given as ``cells`` (K, 2) (m, K ≥ 2), or ProblemError."""
    centers = as_finite_array(f"{fn} cells", cells, ndim=2, max_abs=MAX_MAGNITUDE)
    if centers.shape[1] != 2 or centers.shape[0] < 2:
        raise ProblemError(
            f"{fn} cells: expected (K, 2) centres (m) with K ≥ 2, got {centers.shape}"
        )
    return centers


def _field_data(
    fn: str,
    sums: CellSums,
    centers: FloatArray,
    subset: np.ndarray | None,
    radars: RadarSet,
    s: _Settings,
    diag: Diagnostics,
) -> FieldData:
    """The sums → :class:`FieldData`: cells without an object dropped (a warning, counted
    in ``diag``), the averages (6)-(7), the subsets S_k, the neighbours, P and the 3-D
    geometry."""
    m, k0 = radars.m, centers.shape[0]
    keep = sums.objects > 0
    diag.dropped_cells = int(np.sum(~keep))
    who = "two radars or more" if s.union else "all radars"
    if diag.dropped_cells:
        warnings.warn(
            f"build_field_data: {diag.dropped_cells} of {k0} cells hold no object "
            f"seen by {who} and were dropped",
            stacklevel=3,
        )
    if keep.sum() < 2:
        raise ProblemError(f"cells: fewer than 2 cells hold objects seen by {who}")
    centers = centers[keep]
    n_obj = sums.objects[keep]
    seen = None
    if subset is not None:
        bits = subset[keep]
        seen = ((bits[:, None] >> np.arange(m, dtype=np.uint64)[None, :]) & np.uint64(1)).astype(
            bool
        )
        if np.all(bits == np.uint64((1 << m) - 1)):
            seen = None  # every cell sees every radar: the paper's case
    xi = sums.xi[keep] / n_obj[:, None, None]
    xi_cov = sums.cov[keep] / (n_obj[:, None, None, None] ** 2)
    if seen is not None:
        w = seen.astype(float)
        mean_s = np.einsum("ki,kia->ka", w, xi) / w.sum(axis=1)[:, None]
        xi = np.where(seen[..., None], xi, mean_s[:, None, :])
        eye = np.broadcast_to(
            np.eye(2) * float(np.median(xi_cov[seen][:, [0, 1], [0, 1]])), xi_cov.shape
        )
        xi_cov = np.where(seen[..., None, None], xi_cov, eye)
    diag.samples_per_cell = sums.samples[keep]
    diag.plots_per_cell = sums.plots[keep]
    diag.objects_per_cell = n_obj
    adj = neighbours(centers, method=s.neighbour_method, radius=s.neighbour_radius)
    if s.P is None:
        p = sparse.block_diag(
            [
                np.diag([1 / radars.sigma_range[i] ** 2, 1 / radars.sigma_azimuth[i] ** 2])
                for i in range(m)
            ]
        ).toarray()
    else:
        p = np.asarray(s.P, dtype=float)  # checked by _settings
    assert radars.sites is not None  # set by RadarSet.__post_init__
    if radars.geodetic is None or radars.origin is None:  # 2-D
        return FieldData(radars.sites, centers, xi, adj, p, xi_cov, seen=seen)
    heights = sums.height[keep] / n_obj
    if seen is None:
        mean = xi.mean(axis=1)
    else:
        mean = np.einsum("ki,kia->ka", seen.astype(float), xi) / seen.sum(axis=1)[:, None]
    jac = np.stack([radars.polar_jacobian(i, mean, heights) for i in range(m)], axis=1)
    return FieldData(
        radars.sites,
        centers,
        xi,
        adj,
        p,
        xi_cov,
        jac,
        heights,
        radars.geodetic,
        radars.origin,
        seen,
    )


def _lap(diag: Diagnostics, stage: str, since: float) -> float:
    """Record the seconds of ``stage`` since ``since``; return the clock."""
    now = time.perf_counter()
    diag.timings[stage] = now - since
    return now
