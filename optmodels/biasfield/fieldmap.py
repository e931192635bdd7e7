r"""The bias field between its cells (paper 001, after section 4): :class:`FieldMap`,
the P1 interpolant of the cell values on the Delaunay triangulation of the centres (see
:mod:`optmodels.biasfield.usage` for the whole account), and :func:`field_map`, the map of a
solution. Split out of ``usage.py``; the names are re-exported there unchanged."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import Delaunay, QhullError, cKDTree

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.data import FieldData
from optmodels.biasfield.tables import RadarSet
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_finite_array,
    as_instance,
    as_positive,
)

__all__ = ["FieldMap", "field_map"]


# ----------------------------------------------------------------------------- the map
class Triangles:
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
        self.inv = (
            np.stack(
                [np.stack([b[:, 1], -b[:, 0]], axis=1), np.stack([-a[:, 1], a[:, 0]], axis=1)],
                axis=1,
            )
            / det[:, None, None]
        )
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
    _tri: Any = dataclasses.field(default=None, repr=False, compare=False)
    _tree: Any = dataclasses.field(default=None, repr=False, compare=False)
    _own: Any = dataclasses.field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        c = as_finite_array(
            "biasfield.FieldMap centers (m)", self.centers, ndim=2, max_abs=MAX_MAGNITUDE
        )
        if c.shape[1] != 2 or c.shape[0] < 3:
            raise ProblemError(
                f"biasfield.FieldMap centers (m): expected (K, 2) with K ≥ 3, got {c.shape}"
            )
        f = as_finite_array("biasfield.FieldMap field", self.field, ndim=3, max_abs=MAX_MAGNITUDE)
        if f.shape[0] != c.shape[0] or f.shape[2] != 2:
            raise ProblemError(
                f"biasfield.FieldMap field: expected ({c.shape[0]}, m, 2), got {f.shape}"
            )
        self._set_frame(f.shape[1])
        try:
            tri = Triangles(c)
        except QhullError as exc:
            raise ProblemError(
                "biasfield.FieldMap centers (m): the centres span no area "
                f"(collinear or repeated: {str(exc).splitlines()[0]})"
            ) from None
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
            raise ProblemError(
                f"biasfield.FieldMap seen: expected {f.shape[:2]} (cells, radars), got {seen.shape}"
            )
        seen = seen.astype(bool)
        own: dict[int, Any] = {}
        for i in range(f.shape[1]):
            if seen[:, i].all():
                continue
            idx = np.flatnonzero(seen[:, i])
            entry = None
            if idx.size >= 3:
                try:
                    entry = (idx, Triangles(c[idx]), cKDTree(c[idx]))
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
            object.__setattr__(
                self,
                "sites",
                as_finite_array(f"{fn} sites (m)", self.sites, shape=(m, 2), max_abs=MAX_MAGNITUDE),
            )
        if (self.geodetic is None) != (self.origin is None):
            raise ProblemError(
                f"{fn} geodetic: give the geodetic sites and the origin "
                "together (a field of the 3-D chain) or neither"
            )
        chain = as_choice(f"{fn} chain", str(self.chain), ("", "2d", "3d"))
        if self.geodetic is not None and chain == "2d":
            raise ProblemError(f"{fn} chain: a field with geodetic sites is of the 3-D chain")
        object.__setattr__(self, "chain", "3d" if self.geodetic is not None else chain)
        if self.geodetic is not None and self.origin is not None:
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
            raise ProblemError(f"{where} field: a field of {self.m} radars for {radars.m} radars")
        if self.names and tuple(radars.names) and tuple(radars.names) != self.names:
            raise ProblemError(
                f"{where} field: estimated for radars {list(self.names)}, "
                f"given {list(radars.names)}"
            )
        tol = np.array([1e-7, 1e-7, 1.0])
        if self.is_3d:
            if not radars.is_3d:
                raise ProblemError(
                    f"{where} radars: the field comes from the exact 3-D chain "
                    "(geodetic sites, origin); give the radar set with "
                    "geodetic= and origin="
                )
            assert self.geodetic is not None and self.origin is not None
            # the origin's height does not move the plane (East/North of a footprint in the
            # ENU frame of the origin do not depend on it): latitude and longitude only
            if np.any(np.abs(np.asarray(radars.origin)[:2] - self.origin[:2]) > 1e-7):
                raise ProblemError(
                    f"{where} radars: origin {np.asarray(radars.origin).tolist()}"
                    f" differs from the field's {self.origin.tolist()} (the "
                    "common plane of its cells)"
                )
            bad = np.any(np.abs(np.asarray(radars.geodetic) - self.geodetic) > tol, axis=1)
            if bad.any():
                raise ProblemError(
                    f"{where} radars: sites {np.flatnonzero(bad).tolist()} "
                    "differ from those the field was estimated for"
                )
        elif self.sites is not None:
            if radars.is_3d and self.chain == "2d":
                raise ProblemError(
                    f"{where} radars: the field comes from the 2-D chain (flat "
                    "plane of the sites); a 3-D radar set measures slant "
                    "ranges in another frame"
                )
            bad = np.linalg.norm(np.asarray(radars.sites) - self.sites, axis=1) > 1.0
            if bad.any():  # (a 3-D set's sites: their East-North on its common plane)
                raise ProblemError(
                    f"{where} radars: sites {np.flatnonzero(bad).tolist()} "
                    "differ from those the field was estimated for"
                )

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
            raise ProblemError(
                f"biasfield.FieldMap.at_radar radar: indices outside 0..{self.m - 1}"
            )
        out = np.full((p.shape[0], 2), np.nan)
        for i in np.unique(r):
            sel = np.flatnonzero(r == i)
            out[sel] = self._at_one(p[sel], int(i))
        return out

    def _at_one(self, p: FloatArray, i: int) -> FloatArray:
        extend = self.seen is not None
        if i not in self._own:
            return self._interp(p, self._tri, self._tree, self.field[:, i : i + 1], extend)[:, 0]
        entry = self._own[i]
        if entry is None:
            return np.full((p.shape[0], 2), np.nan)
        idx, tri, tree = entry
        return self._interp(p, tri, tree, self.field[idx, i : i + 1], extend)[:, 0]

    def _interp(
        self, p: FloatArray, tri: Triangles, tree: cKDTree, values: FloatArray, extend: bool = False
    ) -> FloatArray:
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
        ``.npz``, exactly at ``path`` (no suffix appended), atomically: a kill or an error
        part-way leaves the previous file as it was."""
        extra: dict[str, np.ndarray] = {"chain": np.array(self.chain)}
        if self.names:
            extra["names"] = np.array(self.names, dtype=str)
        for key, val in (
            ("radars", self.sites),
            ("geodetic", self.geodetic),
            ("origin", self.origin),
            ("seen", self.seen),
        ):
            if val is not None:
                extra[key] = np.asarray(val)
        from optmodels.io import save_npz

        # atomic (optmodels.io.atomic_write): a kill part-way leaves the previous file
        save_npz(
            path,
            name="biasfield.FieldMap.save path",
            compressed=True,
            centers=self.centers,
            field=self.field,
            max_distance=np.array(self.max_distance),
            **extra,
        )

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
            return cls(
                d["centers"],
                d["field"],
                dmax,
                names,
                d.get("radars"),
                d.get("geodetic"),
                d.get("origin"),
                chain,
                d.get("seen"),
            )
        except ProblemError as exc:
            raise ProblemError(f"{path}: {exc}") from None


def _points(name: str, points: ArrayLike) -> FloatArray:
    p = as_finite_array(name, points, max_abs=MAX_MAGNITUDE)
    if p.ndim == 1 and p.shape == (2,):
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 2:
        raise ProblemError(f"{name}: expected points (n, 2), got shape {p.shape}")
    return p


def field_map(
    solution: Any,
    data: FieldData,
    *,
    max_distance: float | None = None,
    names: tuple[str, ...] | list[str] = (),
) -> FieldMap:
    """The :class:`FieldMap` of a solution (``solution.field`` (K, m, 2)) on the cells of
    ``data``, with the data's frame (sites; geodetic sites and origin in 3-D) and the
    radars' ``names`` if given. A solution without a field (status not OK) is refused."""
    data = as_instance("biasfield.field_map data", data, FieldData)
    f = np.asarray(getattr(solution, "field", np.empty(0)), dtype=float)
    status = getattr(solution, "status", None)
    if status is not None and not status.ok:
        raise ProblemError(
            f"biasfield.field_map solution: status {status.value} has no field to use"
        )
    if f.shape != (data.k, data.m, 2):
        raise ProblemError(
            f"biasfield.field_map solution: field of shape {f.shape} does not "
            f"match the data's ({data.k}, {data.m}, 2)"
        )
    dmax = (
        float("nan")
        if max_distance is None
        else as_positive("biasfield.field_map max_distance (m)", max_distance)
    )
    three = data.geodetic is not None and data.origin is not None
    return FieldMap(
        data.centers,
        f,
        dmax,
        tuple(names),
        data.radars,
        data.geodetic if three else None,
        data.origin if three else None,
        "3d" if three else "2d",
        data.seen,
    )
