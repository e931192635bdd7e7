r"""Using an estimated bias field (paper 001, after section 4): evaluate it anywhere in the
covered area, correct plots with it, measure what registration buys, and score it against
a known field.

* :class:`FieldMap` / :func:`field_map`: the field of a solution on its cells, extended to
  the covered area by the piecewise-linear interpolant on the Delaunay triangulation of the
  cell centres (consistent with the smoothness functional (9): with weights
  1/‖x̌_i − x̌_j‖², J is a sum of squared difference quotients along the edges, a discrete
  Dirichlet energy, and the P1 interpolant is the finite-element function of that energy
  with the cell values at the nodes; unlike the graph's own harmonic extension — the
  1/d²-weighted mean of the neighbours, flat at every centre — it is exact for linear
  fields). It reproduces the cell values at the centres exactly (bit for bit), a linear
  field everywhere, and a smooth field to ½·h²·max‖∇²f‖ (h the longest edge of the
  triangle holding the point; docs/formulations.md). Outside the convex hull of the
  centres, or farther than ``max_distance`` from every centre, the field is not defined:
  NaN, and :meth:`FieldMap.covered` says where. A map carries the frame it was estimated
  in (radar names, sites; geodetic sites and origin for the exact 3-D chain), saved with
  it, and refuses a radar set that differs (:meth:`FieldMap.check_radars`).
  :meth:`~optmodels.biasfield.problem.FieldSolution.at` is this map of a solution.
* :func:`correct_plots`: f_i subtracted from radar i's (range, azimuth) at each plot's
  position (fixed point: the bias is a function of the *true* position x, evaluated at the
  corrected position; two passes change it by O(‖∇f‖·‖s‖), below 1e-6 of the bias for
  fields smooth over ≥ 10 km).
* :func:`registration_error`: the disagreement between radars that see the same aircraft at
  the same time: radar i's plot positions against radar j's track interpolated at those
  times (a local quadratic in time through radar j's plots, which follows turns), averaged
  per area (a square grid) so that the measurement noise averages out, per radar pair and
  overall.
* :func:`score`: the RMS error of a field against a known one at the cell centres, split
  into the per-cell common shift (unobservable without a reference: paper 001, section 3)
  and the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import Delaunay, QhullError, cKDTree

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.cells import FieldData, uncertainty_sets
from optmodels.biasfield.data import PlotTable, RadarSet
from optmodels.biasfield.geometry import wrap_angle
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_instance,
    as_positive,
)

__all__ = ["REASONS", "FieldMap", "FieldScore", "RegistrationError", "correct_plots",
           "field_map", "registration_error", "score", "seen_by_others"]


# ----------------------------------------------------------------------------- the map
class _Triangles:
    """The Delaunay triangulation of the centres with its own point location and
    barycentric coordinates.

    scipy's ``Delaunay.find_simplex`` / ``LinearNDInterpolator`` first compute every
    simplex's barycentric transform through one small LAPACK call per simplex; with a
    multi-threaded OpenBLAS on a loaded machine that first call was measured at ≈ 2 s for
    40 centres (0.2 ms single-threaded), paid by every new map. Here the transforms are
    the closed-form inverses of the 2 × 2 edge matrices (NumPy) and the point location is
    matplotlib's trapezoid map (exact, O(log K) per point), scipy's walk as a fallback."""

    def __init__(self, centers: FloatArray) -> None:
        self.tri = Delaunay(centers)
        simp = self.tri.simplices
        v = centers[simp]  # (S, 3, 2)
        a = v[:, 0] - v[:, 2]
        b = v[:, 1] - v[:, 2]
        det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        good = np.abs(det) > 1e-12 * np.maximum(np.sum(a * a, axis=1), np.sum(b * b, axis=1))
        det = np.where(good, det, np.inf)
        # inverse of [[a_x, b_x], [a_y, b_y]]: rows give the first two barycentric weights
        self.inv = np.stack([np.stack([b[:, 1], -b[:, 0]], axis=1),
                             np.stack([-a[:, 1], a[:, 0]], axis=1)], axis=1) / det[:, None, None]
        self.origin = v[:, 2]
        self.simplices = simp
        self._finder: Any = None
        try:
            import matplotlib.tri as mtri

            tri = mtri.Triangulation(centers[:, 0], centers[:, 1], simp[good])
            self._finder = (mtri.TrapezoidMapTriFinder(tri), np.flatnonzero(good))
        except (ImportError, RuntimeError, ValueError):  # pragma: no cover - fallback
            self._finder = None

    def find(self, p: FloatArray) -> np.ndarray:
        """(n,) the simplex holding each point, −1 outside the triangulation."""
        if self._finder is None:  # pragma: no cover - fallback
            return np.asarray(self.tri.find_simplex(p))
        finder, index = self._finder
        s = np.asarray(finder(p[:, 0], p[:, 1]), dtype=np.int64)
        return np.where(s >= 0, index[np.maximum(s, 0)], -1)

    def barycentric(self, p: FloatArray, simplex: np.ndarray) -> FloatArray:
        """(n, 3) barycentric weights of the points in their simplices (≥ 0)."""
        b2 = np.einsum("nij,nj->ni", self.inv[simplex], p - self.origin[simplex])
        return np.column_stack([b2, 1.0 - b2.sum(axis=1)])


@dataclass(frozen=True)
class FieldMap:
    """A bias field known at cell centres and interpolated between them.

    ``centers`` (K, 2) East/North on the common plane (m); ``field`` (K, m, 2) = [range
    bias (m), azimuth bias (rad)] per cell and radar; ``max_distance`` (m): points farther
    than this from every centre are outside the covered area (default: 1.5 × the largest
    nearest-neighbour distance between centres).

    The frame the field was estimated in (optional; carried so that a saved field can be
    applied to a recording later and refused on another network): ``names`` of the
    radars, ``sites`` (m, 2) their East/North on the common plane (m), and for a field of
    the exact 3-D chain ``geodetic`` (m, 3) the sites (lat deg, lon deg, h m above the
    WGS-84 ellipsoid) and ``origin`` (3,) the common plane's origin. The plane coordinates
    of ``centers`` mean nothing without that origin, and the polar biases belong to those
    sites: :meth:`check_radars` refuses a radar set that differs. ``chain``: ``"3d"`` (set
    by ``geodetic``), ``"2d"`` (a field of the flat 2-D chain: refused on a 3-D radar set,
    whose slant ranges it was not estimated from) or ``""`` (unknown, e.g. a file written
    before the frame was saved: only the sites are compared).

    ``seen`` (K, m) bool (per-cell radar subsets, the field over the union of coverage):
    radar i's field is served over its own cells only -- the P1 interpolant on the
    Delaunay triangulation of the centres radar i sees, NaN elsewhere for that radar
    (:meth:`covered_for`); ``None``: every radar on every cell (the paper's case).
    """

    centers: FloatArray
    field: FloatArray
    max_distance: float = float("nan")
    names: tuple[str, ...] = ()
    sites: FloatArray | None = None
    geodetic: FloatArray | None = None
    origin: FloatArray | None = None
    chain: str = ""
    seen: np.ndarray | None = None
    _tri: Any = field(default=None, repr=False, compare=False)
    _tree: Any = field(default=None, repr=False, compare=False)
    _own: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        c = as_finite_array("biasfield.FieldMap centers (m)", self.centers, ndim=2,
                            max_abs=MAX_MAGNITUDE)
        if c.shape[1] != 2 or c.shape[0] < 3:
            raise ProblemError(f"biasfield.FieldMap centers (m): expected (K, 2) with K ≥ 3, "
                               f"got {c.shape}")
        f = as_finite_array("biasfield.FieldMap field", self.field, ndim=3,
                            max_abs=MAX_MAGNITUDE)
        if f.shape[0] != c.shape[0] or f.shape[2] != 2:
            raise ProblemError(f"biasfield.FieldMap field: expected ({c.shape[0]}, m, 2), got "
                               f"{f.shape}")
        self._set_frame(f.shape[1])
        try:
            tri = _Triangles(c)
        except QhullError as exc:
            raise ProblemError("biasfield.FieldMap centers (m): the centres span no area "
                               f"(collinear or repeated: {str(exc).splitlines()[0]})") from None
        tree = cKDTree(c)
        dmax = self.max_distance
        if not np.isfinite(dmax):
            dmax = 1.5 * float(np.max(tree.query(c, k=2)[0][:, 1]))
        dmax = as_positive("biasfield.FieldMap max_distance (m)", dmax)
        object.__setattr__(self, "centers", c)
        object.__setattr__(self, "field", f)
        object.__setattr__(self, "max_distance", dmax)
        object.__setattr__(self, "_tri", tri)
        object.__setattr__(self, "_tree", tree)
        self._set_seen(c, f)

    def _set_seen(self, c: FloatArray, f: FloatArray) -> None:
        """Per radar with a partial subset: (its cells, triangulation, k-d tree) or None
        (fewer than 3 cells or no area: the radar is served nowhere)."""
        if self.seen is None:
            object.__setattr__(self, "_own", {})
            return
        seen = np.asarray(self.seen)
        if seen.shape != f.shape[:2]:
            raise ProblemError(f"biasfield.FieldMap seen: expected {f.shape[:2]} (cells, "
                               f"radars), got {seen.shape}")
        seen = seen.astype(bool)
        own: dict[int, Any] = {}
        for i in range(f.shape[1]):
            if seen[:, i].all():
                continue
            idx = np.flatnonzero(seen[:, i])
            entry = None
            if idx.size >= 3:
                try:
                    entry = (idx, _Triangles(c[idx]), cKDTree(c[idx]))
                except QhullError:
                    entry = None
            own[i] = entry
        object.__setattr__(self, "seen", seen)
        object.__setattr__(self, "_own", own)

    def _set_frame(self, m: int) -> None:
        fn = "biasfield.FieldMap"
        names = tuple(str(v) for v in self.names)
        if names and len(names) != m:
            raise ProblemError(f"{fn} names: {len(names)} names for a field of {m} radars")
        object.__setattr__(self, "names", names)
        if self.sites is not None:
            object.__setattr__(self, "sites", as_finite_array(
                f"{fn} sites (m)", self.sites, shape=(m, 2), max_abs=MAX_MAGNITUDE))
        if (self.geodetic is None) != (self.origin is None):
            raise ProblemError(f"{fn} geodetic: give the geodetic sites and the origin "
                               "together (a field of the 3-D chain) or neither")
        chain = as_choice(f"{fn} chain", str(self.chain), ("", "2d", "3d"))
        if self.geodetic is not None and chain == "2d":
            raise ProblemError(f"{fn} chain: a field with geodetic sites is of the 3-D chain")
        object.__setattr__(self, "chain", "3d" if self.geodetic is not None else chain)
        if self.geodetic is not None:
            geo = as_finite_array(f"{fn} geodetic", self.geodetic, shape=(m, 3))
            for j in range(m):
                g3.site_geodetic(f"{fn} geodetic[{j}]", geo[j])
            object.__setattr__(self, "geodetic", geo)
            object.__setattr__(self, "origin", g3.site_geodetic(f"{fn} origin", self.origin))

    @property
    def m(self) -> int:
        return int(self.field.shape[1])

    @property
    def is_3d(self) -> bool:
        """The field carries the frame of the exact 3-D chain (geodetic sites, origin)."""
        return self.origin is not None

    def check_radars(self, radars: RadarSet, where: str = "biasfield.FieldMap") -> None:
        """Refuse (:class:`~optmodels.core.ProblemError` naming ``where``) a radar set the
        field does not belong to: another number of radars; other names (when both have
        them); for a 3-D field, a 2-D set, another origin latitude or longitude (> 1e-7°; its
        height does not move the plane) or other sites
        (> 1e-7° or 1 m in height); for a 2-D field with sites, a 3-D set or sites moved by
        more than 1 m. A field without a frame (e.g. ``FieldMap(centers, field)``) is only
        checked for the number of radars."""
        if self.m != radars.m:
            raise ProblemError(f"{where} field: a field of {self.m} radars for {radars.m} "
                               "radars")
        if self.names and tuple(radars.names) and tuple(radars.names) != self.names:
            raise ProblemError(f"{where} field: estimated for radars {list(self.names)}, "
                               f"given {list(radars.names)}")
        tol = np.array([1e-7, 1e-7, 1.0])
        if self.is_3d:
            if not radars.is_3d:
                raise ProblemError(f"{where} radars: the field comes from the exact 3-D chain "
                                   "(geodetic sites, origin); give the radar set with "
                                   "geodetic= and origin=")
            assert self.geodetic is not None and self.origin is not None
            # the origin's height does not move the plane (East/North of a footprint in the
            # ENU frame of the origin do not depend on it): latitude and longitude only
            if np.any(np.abs(np.asarray(radars.origin)[:2] - self.origin[:2]) > 1e-7):
                raise ProblemError(f"{where} radars: origin {np.asarray(radars.origin).tolist()}"
                                   f" differs from the field's {self.origin.tolist()} (the "
                                   "common plane of its cells)")
            bad = np.any(np.abs(np.asarray(radars.geodetic) - self.geodetic) > tol, axis=1)
            if bad.any():
                raise ProblemError(f"{where} radars: sites {np.flatnonzero(bad).tolist()} "
                                   "differ from those the field was estimated for")
        elif self.sites is not None:
            if radars.is_3d and self.chain == "2d":
                raise ProblemError(f"{where} radars: the field comes from the 2-D chain (flat "
                                   "plane of the sites); a 3-D radar set measures slant "
                                   "ranges in another frame")
            bad = np.linalg.norm(np.asarray(radars.sites) - self.sites, axis=1) > 1.0
            if bad.any():  # (a 3-D set's sites: their East-North on its common plane)
                raise ProblemError(f"{where} radars: sites {np.flatnonzero(bad).tolist()} "
                                   "differ from those the field was estimated for")

    def covered(self, points: ArrayLike) -> np.ndarray:
        """(n,) True where ``points`` (n, 2) (m, common plane) lie in the covered area:
        inside the triangulation of the centres and within ``max_distance`` of one."""
        p = _points("biasfield.FieldMap.covered points (m)", points)
        inside = self._tri.find(p) >= 0
        near = self._tree.query(p)[0] <= self.max_distance
        return np.asarray(inside & near)

    def covered_for(self, points: ArrayLike, radar: ArrayLike) -> np.ndarray:
        """(n,) True where radar ``radar[n]`` (an index, or one index for all points) is
        served at ``points`` (n, 2): inside the triangulation of the cells it sees and
        within ``max_distance`` of one of them."""
        p = _points("biasfield.FieldMap.covered_for points (m)", points)
        return np.all(np.isfinite(self.at_radar(p, radar)), axis=1)

    def at_radar(self, points: ArrayLike, radar: ArrayLike) -> FloatArray:
        """Radar ``radar[n]``'s field at ``points`` (n, 2): (n, 2) = [range bias (m),
        azimuth bias (rad)]; NaN where that radar is not served (outside its own cells)."""
        p = _points("biasfield.FieldMap.at_radar points (m)", points)
        r = np.broadcast_to(np.asarray(radar, dtype=np.int64), (p.shape[0],))
        if r.size and (r.min() < 0 or r.max() >= self.m):
            raise ProblemError(f"biasfield.FieldMap.at_radar radar: indices outside "
                               f"0..{self.m - 1}")
        out = np.full((p.shape[0], 2), np.nan)
        for i in np.unique(r):
            sel = np.flatnonzero(r == i)
            out[sel] = self._at_one(p[sel], int(i))
        return out

    def _at_one(self, p: FloatArray, i: int) -> FloatArray:
        extend = self.seen is not None
        if i not in self._own:
            return self._interp(p, self._tri, self._tree, self.field[:, i:i + 1],
                                extend)[:, 0]
        entry = self._own[i]
        if entry is None:
            return np.full((p.shape[0], 2), np.nan)
        idx, tri, tree = entry
        return self._interp(p, tri, tree, self.field[idx, i:i + 1], extend)[:, 0]

    def _interp(self, p: FloatArray, tri: _Triangles, tree: cKDTree, values: FloatArray,
                extend: bool = False) -> FloatArray:
        """P1 interpolant of ``values`` (K', q, 2) on ``tri``; NaN outside it or farther
        than ``max_distance`` from every node; a node's value bit for bit. ``extend``
        (maps with per-cell subsets): outside the triangulation but within
        ``max_distance`` of a node, that nearest node's value (a radar's cells lie inside
        its coverage by about half a cell; the constant extension errs by ‖∇f‖·d)."""
        simplex = tri.find(p)
        dist, idx = tree.query(p)
        ok = (simplex >= 0) & (dist <= self.max_distance)
        out = np.full((p.shape[0], *values.shape[1:]), np.nan)
        if extend:
            ext = (simplex < 0) & (dist <= self.max_distance)
            out[ext] = values[idx[ext]]
        if ok.any():
            bary = tri.barycentric(p[ok], simplex[ok])
            verts = tri.simplices[simplex[ok]]
            out[ok] = np.einsum("nj,njab->nab", bary, values[verts])
        on = dist == 0.0
        out[on] = values[idx[on]]
        return out

    def at(self, points: ArrayLike) -> FloatArray:
        """The field at ``points`` (n, 2) (m, common plane): (n, m, 2) = [range bias (m),
        azimuth bias (rad)] per radar; NaN outside the covered area (:meth:`covered`),
        and, with per-cell subsets, for a radar outside its own cells.
        At a cell centre it is that cell's value, exactly."""
        p = _points("biasfield.FieldMap.at points (m)", points)
        if self._own:
            return np.stack([self._at_one(p, i) for i in range(self.m)], axis=1)
        simplex = self._tri.find(p)
        dist, idx = self._tree.query(p)
        ok = (simplex >= 0) & (dist <= self.max_distance)
        out = np.full((p.shape[0], self.m, 2), np.nan)
        if ok.any():
            bary = self._tri.barycentric(p[ok], simplex[ok])
            verts = self._tri.simplices[simplex[ok]]
            out[ok] = np.einsum("nj,njab->nab", bary, self.field[verts])
        on = dist == 0.0  # at a centre: its value bit for bit (no barycentric rounding)
        out[on] = self.field[idx[on]]
        return out

    def save(self, path: str | Path) -> None:
        """Write ``centers``, ``field``, ``max_distance`` and the frame (``chain``,
        ``names``, ``radars`` = the sites, ``geodetic``, ``origin``, those given) to an
        ``.npz``."""
        extra: dict[str, np.ndarray] = {"chain": np.array(self.chain)}
        if self.names:
            extra["names"] = np.array(self.names, dtype=str)
        for key, val in (("radars", self.sites), ("geodetic", self.geodetic),
                         ("origin", self.origin), ("seen", self.seen)):
            if val is not None:
                extra[key] = np.asarray(val)
        try:
            np.savez_compressed(path, centers=self.centers, field=self.field,
                                max_distance=np.array(self.max_distance), **extra)
        except (OSError, TypeError) as exc:
            raise ProblemError(f"biasfield.FieldMap.save path: cannot write {path} ({exc})"
                               ) from None

    @classmethod
    def load(cls, path: str | Path) -> FieldMap:
        """Read a field written by :meth:`save` or by ``optmodels biasfield solve``
        (``DIR/field.npz``: ``centers``, ``field``; the frame keys ``radars`` (sites),
        ``chain``, ``names``, ``geodetic``, ``origin`` where present)."""
        from optmodels.io import read_npz

        d = read_npz(path, what="field .npz", required=("centers", "field"))
        dmax = float(d["max_distance"]) if "max_distance" in d else float("nan")
        names = tuple(str(v) for v in d["names"]) if "names" in d else ()
        chain = str(d["chain"]) if "chain" in d else ""
        try:
            return cls(d["centers"], d["field"], dmax, names, d.get("radars"),
                       d.get("geodetic"), d.get("origin"), chain, d.get("seen"))
        except ProblemError as exc:
            raise ProblemError(f"{path}: {exc}") from None


def _points(name: str, points: ArrayLike) -> FloatArray:
    p = as_finite_array(name, points, max_abs=MAX_MAGNITUDE)
    if p.ndim == 1 and p.shape == (2,):
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 2:
        raise ProblemError(f"{name}: expected points (n, 2), got shape {p.shape}")
    return p


def field_map(solution: Any, data: FieldData, *, max_distance: float | None = None,
              names: tuple[str, ...] | list[str] = ()) -> FieldMap:
    """The :class:`FieldMap` of a solution (``solution.field`` (K, m, 2)) on the cells of
    ``data``, with the data's frame (sites; geodetic sites and origin in 3-D) and the
    radars' ``names`` if given. A solution without a field (status not OK) is refused."""
    data = as_instance("biasfield.field_map data", data, FieldData)
    f = np.asarray(getattr(solution, "field", np.empty(0)), dtype=float)
    status = getattr(solution, "status", None)
    if status is not None and not status.ok:
        raise ProblemError(f"biasfield.field_map solution: status {status.value} has no "
                           "field to use")
    if f.shape != (data.k, data.m, 2):
        raise ProblemError(f"biasfield.field_map solution: field of shape {f.shape} does not "
                           f"match the data's ({data.k}, {data.m}, 2)")
    dmax = float("nan") if max_distance is None else as_positive(
        "biasfield.field_map max_distance (m)", max_distance)
    three = data.geodetic is not None and data.origin is not None
    return FieldMap(data.centers, f, dmax, tuple(names), data.radars,
                    data.geodetic if three else None, data.origin if three else None,
                    "3d" if three else "2d", data.seen)


# ----------------------------------------------------------------------------- correct
@dataclass(frozen=True)
class Corrected:
    """:func:`correct_plots`' result: the corrected ``plots`` (same rows and order), the
    ``bias`` (n, 2) subtracted from each (range m, azimuth rad; 0 where not corrected) and
    ``covered`` (n,) where the field was defined (elsewhere the plot is left as read);
    ``reason`` (n,) str, why (:data:`REASONS`): ``"covered"``, ``"one radar only"`` (no
    other radar has a plot of the same object within ``window`` s: no cross-radar data
    can place a field there) or ``"outside every cell"`` (seen by two radars or more, or
    of an unknown object, but outside the cells of its radar)."""

    plots: PlotTable
    bias: FloatArray
    covered: np.ndarray
    reason: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype="<U18"))

    @property
    def n_uncovered(self) -> int:
        return int(np.sum(~self.covered))


#: The values of :attr:`Corrected.reason`.
REASONS = ("covered", "one radar only", "outside every cell")


def seen_by_others(plots: PlotTable, window: float = 60.0) -> np.ndarray:
    """(n,) True where another radar has a plot of the same object (``plots.object`` ≥ 0)
    within ``window`` seconds: the plot is seen by two radars or more."""
    window = as_positive("biasfield.seen_by_others window (s)", window)
    out = np.zeros(len(plots), dtype=bool)
    known = np.flatnonzero(plots.object >= 0)
    if known.size == 0:
        return out
    t = plots.time[known]
    # one sorted key per (object, time): objects spaced farther apart than any time gap
    span = float(t.max() - t.min()) + 4.0 * window + 1.0
    key = plots.object[known].astype(np.float64) * span + (t - t.min())
    r = plots.radar[known]
    for i in np.unique(r):
        other = np.sort(key[r != i])
        mine = np.flatnonzero(r == i)
        if other.size == 0:
            continue
        lo = np.searchsorted(other, key[mine] - window, side="left")
        hi = np.searchsorted(other, key[mine] + window, side="right")
        out[known[mine]] = hi > lo
    return out


def correct_plots(plots: PlotTable, radars: RadarSet, field: FieldMap, *,
                  passes: int = 2, window: float = 60.0) -> Corrected:
    """Plots with the estimated bias removed: range − f_r(x), azimuth − f_α(x) for each
    plot of radar i, x its position on the common plane.

    The bias is a function of the true position; it is evaluated at the plot's position,
    then (``passes`` ≥ 2) again at the corrected position (a fixed-point iteration that
    converges at the rate ‖∇f‖ ≈ 1e-3 per pass). Plots outside the covered area are left
    uncorrected and flagged in ``covered``, with the ``reason`` per plot
    (:attr:`Corrected.reason`; ``window`` (s) the time within which another radar's plot
    of the same object counts as seeing it). With per-cell subsets (``field.seen``) each
    radar is corrected over its own cells. Heights and every other column are kept.
    """
    fn = "biasfield.correct_plots"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    field = as_instance(f"{fn} field", field, FieldMap)
    passes = as_count(f"{fn} passes", passes, minimum=1, maximum=10)
    field.check_radars(radars, fn)
    n = len(plots)
    bias = np.zeros((n, 2))
    out = plots
    covered = np.ones(n, dtype=bool)
    for _ in range(passes):
        pos = out.cartesian(radars)
        b = field.at_radar(pos, plots.radar)  # (n, 2), each plot's own radar
        covered = np.all(np.isfinite(b), axis=1)
        bias = np.where(covered[:, None], b, 0.0)
        out = replace(plots, range=np.abs(plots.range - bias[:, 0]),
                      azimuth=wrap_angle(plots.azimuth - bias[:, 1]))
    reason = np.full(n, REASONS[0], dtype="<U18")
    if not covered.all():
        miss = ~covered
        single = miss & ~seen_by_others(plots, window) & (plots.object >= 0)
        reason[miss] = REASONS[2]
        reason[single] = REASONS[1]
    return Corrected(out, bias, covered, reason)


# ----------------------------------------------------------------------------- registration
@dataclass(frozen=True)
class RegistrationError:
    """Cross-radar disagreement (m) on the common plane.

    ``overall`` and ``pairs[(a, b)]`` (radar names): the RMS over areas of the per-area
    mean horizontal difference between the two radars' positions of the same aircraft at
    the same time, with the noise part of each squared mean (its sample variance / n)
    removed (so that a perfectly registered network scores ≈ 0, not σ/√n); areas weighted
    by their sample counts (areas seen by fewer than 2 aircraft are left out).
    ``noise`` / ``noise_pairs``: the RMS standard error of the area means, the scale below
    which a disagreement is not seen (a perfectly registered network reads 0 to ~this).
    ``raw_overall`` / ``raw_pairs``: the plain RMS of the
    per-sample differences (noise included). ``samples`` per pair, ``areas`` per pair.
    """

    overall: float
    pairs: dict[tuple[str, str], float]
    raw_overall: float
    raw_pairs: dict[tuple[str, str], float]
    samples: dict[tuple[str, str], int]
    areas: dict[tuple[str, str], int]
    area: float
    noise: float = float("nan")
    noise_pairs: dict[tuple[str, str], float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        def key(p: tuple[str, str]) -> str:
            return f"{p[0]}-{p[1]}"

        return {"overall_m": self.overall, "raw_overall_m": self.raw_overall,
                "noise_m": self.noise, "area_m": self.area,
                "pairs": {key(p): {"rms_m": v, "raw_rms_m": self.raw_pairs[p],
                                   "noise_m": self.noise_pairs.get(p, float("nan")),
                                   "samples": self.samples[p], "areas": self.areas[p]}
                          for p, v in self.pairs.items()}}


def _plane_positions(fn: str, plots: PlotTable, radars: RadarSet,
                     positions: ArrayLike | None) -> FloatArray:
    """The plots' positions (n, 2) on the common plane: ``positions`` checked, or computed
    (``plots.cartesian(radars)``, exact in 3-D)."""
    if positions is None:
        return plots.cartesian(radars)
    return as_finite_array(f"{fn} positions (m)", positions, shape=(len(plots), 2),
                           max_abs=MAX_MAGNITUDE)


def _local_quadratic(t: FloatArray, z: FloatArray, tq: FloatArray, half: float
                     ) -> tuple[FloatArray, np.ndarray]:
    """Radar j's track at times ``tq``: a least-squares quadratic in time through its plots
    (t, z) within ±``half`` s of each query time (≥ 2 plots on each side). Returns (q, 2)
    positions and the mask of the times that could be served."""
    lo = np.searchsorted(t, tq - half, side="left")
    hi = np.searchsorted(t, tq + half, side="right")
    mid = np.searchsorted(t, tq, side="left")
    ok = ((mid - lo) >= 2) & ((hi - mid) >= 2)
    out = np.full((tq.size, 2), np.nan)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return out, ok
    # batched: every query's window padded to the widest, 3x3 normal equations per query
    width = int(np.max(hi[idx] - lo[idx]))
    take = lo[idx, None] + np.arange(width)[None, :]
    mask = take < hi[idx, None]
    take = np.minimum(take, t.size - 1)
    dt = np.where(mask, t[take] - tq[idx, None], 0.0)
    w = mask.astype(float)
    basis = np.stack([w, w * dt, w * dt * dt], axis=-1)  # (q, width, 3), zero rows padded
    normal = np.einsum("qwa,qwb->qab", basis, basis)
    rhs = np.einsum("qwa,qwc->qac", basis, z[take] * w[..., None])
    out[idx] = (np.linalg.pinv(normal) @ rhs)[:, 0, :]  # pinv: robust to repeated times
    return out, ok


def _systematic_square(d: FloatArray, obj: np.ndarray) -> tuple[float, float] | None:
    """|d̄|² less its noise, an unbiased estimate of the squared systematic difference (it
    can be negative; only sums of it are clipped at 0): the area mean d̄ over every
    sample, and its variance estimated from the scatter of the per-aircraft means about
    it (aircraft are independent; the samples of one aircraft are not: neighbouring plots
    share the interpolating track). Returns (that estimate, var(d̄)); None with fewer than 2
    aircraft."""
    labels, inv, counts = np.unique(obj, return_inverse=True, return_counts=True)
    if labels.size < 2:
        return None
    sums = np.zeros((labels.size, 2))
    np.add.at(sums, inv.ravel(), d)
    n = float(counts.sum())
    mean = sums.sum(axis=0) / n
    dev = sums - counts[:, None] * mean  # n_o (d̄_o − d̄)
    var = float(np.sum(dev * dev)) / n**2 * labels.size / (labels.size - 1)
    return float(mean @ mean) - var, var


def registration_error(plots: PlotTable, radars: RadarSet, *, area: float = 25e3,
                       window: float | None = None, min_samples: int = 20,
                       within: FieldMap | None = None,
                       positions: ArrayLike | None = None) -> RegistrationError:
    """RMS horizontal distance (m) between two radars' positions of the same aircraft at
    the same time, per radar pair and overall, measured on per-area means.

    For each aircraft (``object`` ≥ 0) and ordered pair of radars (a, b), b's track is
    interpolated at a's plot times (local quadratic through b's plots within ±``window``
    s; default 2.5 × b's median scan interval) and the difference d = z_a − ẑ_b taken on
    the common plane. The differences are grouped by area (squares of side ``area`` m on
    the common plane, about each plot's position); in each area with ≥ ``min_samples``
    differences from ≥ 2 aircraft, the mean d̄ less its noise variance (estimated from the
    scatter of the per-aircraft means, which are independent) gives the systematic part
    |d̄|² − var(d̄). The pair's figure is the sample-weighted RMS of these over its
    areas (the weighted mean of the squares, clipped at 0 before the root; both orders
    (a, b) and (b, a) pooled), the overall figure the same over every pair. ``within``:
    only positions in the covered area of this :class:`FieldMap` (to compare before and
    after a correction on the same area). ``positions`` (n, 2) m: the plots' plane
    positions if already computed (``plots.cartesian(radars)``; in 3-D ~11 s per 10⁶ plots).
    """
    fn = "biasfield.registration_error"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    area = as_positive(f"{fn} area (m)", area)
    if window is not None:
        window = as_positive(f"{fn} window (s)", window)
    min_samples = as_count(f"{fn} min_samples", min_samples, minimum=2)
    if within is not None:
        within = as_instance(f"{fn} within", within, FieldMap)
        within.check_radars(radars, f"{fn} within")
    plots.check(radars)
    z = _plane_positions(fn, plots, radars, positions)
    inside = np.ones(len(plots), dtype=bool) if within is None else within.covered(z)
    keep = plots.object >= 0
    tracks: dict[tuple[int, int], np.ndarray] = {}
    for idx in np.flatnonzero(keep):
        tracks.setdefault((int(plots.object[idx]), int(plots.radar[idx])), []).append(idx)
    for key, rows in tracks.items():
        r = np.asarray(rows)
        tracks[key] = r[np.argsort(plots.time[r], kind="stable")]
    half = {}
    for i in range(radars.m):
        gaps = [np.diff(plots.time[r]) for (_, j), r in tracks.items() if j == i and r.size > 1]
        g = np.concatenate(gaps) if gaps else np.array([])
        g = g[g > 0]
        half[i] = window if window is not None else (2.5 * float(np.median(g)) if g.size
                                                     else 1.0)
    diffs: dict[tuple[int, int], list[FloatArray]] = {}
    where: dict[tuple[int, int], list[FloatArray]] = {}
    owner: dict[tuple[int, int], list[np.ndarray]] = {}
    for (obj, a), ra in tracks.items():
        for b in range(radars.m):
            if b == a or (obj, b) not in tracks:
                continue
            rb = tracks[(obj, b)]
            if rb.size < 4:
                continue
            zb, ok = _local_quadratic(plots.time[rb], z[rb], plots.time[ra], half[b])
            ok &= inside[ra]
            if not ok.any():
                continue
            pair = (min(a, b), max(a, b))
            sign = 1.0 if a < b else -1.0  # both orders as z_min(a,b) − z_max(a,b)
            diffs.setdefault(pair, []).append(sign * (z[ra][ok] - zb[ok]))
            where.setdefault(pair, []).append(z[ra][ok])
            owner.setdefault(pair, []).append(np.full(int(ok.sum()), obj))
    names = radars.names
    pairs: dict[tuple[str, str], float] = {}
    raw: dict[tuple[str, str], float] = {}
    count: dict[tuple[str, str], int] = {}
    areas: dict[tuple[str, str], int] = {}
    floor: dict[tuple[str, str], float] = {}
    tot_sys = tot_raw = tot_var = 0.0
    tot_n = tot_raw_n = 0
    for pair in sorted(diffs):
        d = np.vstack(diffs[pair])
        pos = np.vstack(where[pair])
        cell = np.floor(pos / area).astype(np.int64)
        _, label = np.unique(cell, axis=0, return_inverse=True)
        label = label.ravel()
        sys_sum = var_sum = 0.0
        n_used = 0
        n_areas = 0
        obj = np.concatenate(owner[pair])
        for c in np.unique(label):
            sel = label == c
            dc, oc = d[sel], obj[sel]
            if dc.shape[0] < min_samples:
                continue
            est = _systematic_square(dc, oc)
            if est is None:
                continue
            sys_sum += dc.shape[0] * est[0]
            var_sum += dc.shape[0] * est[1]
            n_used += dc.shape[0]
            n_areas += 1
        key = (names[pair[0]], names[pair[1]])
        raw[key] = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
        pairs[key] = float(np.sqrt(max(sys_sum, 0.0) / n_used)) if n_used else float("nan")
        count[key] = int(d.shape[0])
        areas[key] = n_areas
        floor[key] = float(np.sqrt(var_sum / n_used)) if n_used else float("nan")
        tot_var += var_sum
        tot_sys += sys_sum
        tot_n += n_used
        tot_raw += float(np.sum(d * d))
        tot_raw_n += d.shape[0]
    if not pairs:
        raise ProblemError(f"{fn} plots: no aircraft is seen by two radars at the same time "
                           "(nothing to register)")
    overall = float(np.sqrt(max(tot_sys, 0.0) / tot_n)) if tot_n else float("nan")
    noise = float(np.sqrt(tot_var / tot_n)) if tot_n else float("nan")
    return RegistrationError(overall, pairs, float(np.sqrt(tot_raw / tot_raw_n)), raw, count,
                             areas, area, noise, floor)


# ----------------------------------------------------------------------------- score
@dataclass(frozen=True)
class FieldScore:
    """RMS error of a field against the truth at the cell centres, per component.

    ``total``, ``shift`` and ``rest``: (2,) RMS over cells and radars of [range (m),
    azimuth (rad)]; ``shift`` is the part of the error that a per-cell common Cartesian
    shift of all radars explains (the unobservable η_k of (10), fitted in the P metric),
    ``rest`` what remains (what the data do determine). ``*_m``: the same as horizontal
    distances on the common plane (m), each radar's polar error mapped through its
    Jacobian.
    """

    total: FloatArray
    shift: FloatArray
    rest: FloatArray
    total_m: float
    shift_m: float
    rest_m: float

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in ("total", "shift", "rest"):
            v = getattr(self, name)
            out[name] = {"range_m": float(v[0]), "azimuth_deg": float(np.rad2deg(v[1])),
                         "horizontal_m": float(getattr(self, f"{name}_m"))}
        return out


def score(field: ArrayLike, truth: ArrayLike, data: FieldData) -> FieldScore:
    """Error of ``field`` (K, m, 2) — e.g. ``solution.field`` — against ``truth`` (K, m, 2),
    the true [range, azimuth] biases at the cell centres, split into the per-cell common
    shift and the rest.

    In cell k the error e_k (2m,) is projected on the columns of Φ¹_k (10) (the polar
    image of a common shift δη of every radar) in the metric P of (9):
    δη_k = (Φ¹_kᵀ P Φ¹_k)⁻¹ Φ¹_kᵀ P e_k; shift = Φ¹_k δη_k, rest = e_k − shift.
    """
    fn = "biasfield.score"
    data = as_instance(f"{fn} data", data, FieldData)
    k, m = data.k, data.m
    f = as_finite_array(f"{fn} field", field, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
    t = as_finite_array(f"{fn} truth", truth, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
    e = f - t
    e[..., 1] = wrap_angle(e[..., 1])
    seen = data.subsets
    e[~seen] = 0.0  # a radar's error counts only on the cells it sees
    _, phi1 = uncertainty_sets(data)
    coo = phi1.tocoo()  # block-diagonal, (2m, 2) blocks; never densified (K may be 1e4)
    jac = np.zeros((k, 2 * m, 2))
    kk = coo.col // 2
    jac[kk, coo.row - 2 * m * kk, coo.col % 2] = coo.data
    p = data.P if data.P.shape == (2 * m, 2 * m) else np.kron(np.eye(m), data.P)
    ev = e.reshape(k, 2 * m)
    a = np.einsum("kia,ij,kjb->kab", jac, p, jac)
    rhs = np.einsum("kia,ij,kj->ka", jac, p, ev)
    try:
        deta = np.linalg.solve(a, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        raise ProblemError(f"{fn} data: a cell's common shift is not determined (Φ¹_kᵀPΦ¹_k "
                           "singular)") from None
    sh = np.einsum("kia,ka->ki", jac, deta).reshape(k, m, 2)
    rest = e - sh
    rest[~seen] = 0.0
    jb = jac.reshape(k, m, 2, 2).copy()  # ∂(r, α)/∂(x, y) of radar i at cell k
    jb[~seen] = np.eye(2)  # (zero rows of the radars outside S_k; their errors are 0)

    def metres(err: FloatArray) -> float:
        d = np.linalg.solve(jb, err[..., None])[..., 0]
        return float(np.sqrt(np.sum(d * d) / seen.sum()))

    def rms(err: FloatArray) -> FloatArray:
        return np.sqrt(np.sum(err.reshape(-1, 2) ** 2, axis=0) / seen.sum())

    return FieldScore(rms(e), rms(sh), rms(rest), metres(e), metres(sh), metres(rest))
