r"""The problem's data (paper 001, section 3 and (9)-(10)): :class:`FieldData`, its
neighbour graph and the uncertainty sets (10).

* :class:`FieldData`: per cell k the averaged biased positions ξ̂_i(k) of the m radars, the
  cell centres x̌_(k), the neighbour pairs c(x, y) (sparse, symmetric), the weight P of
  ‖·‖_F; optionally their covariances, the exact 3-D geometry and per-cell radar subsets.
  Made from plots by :func:`~optmodels.biasfield.cells.build_field_data` (the field-data
  stage), without plots by :func:`synthetic_field_data`, or read with :meth:`FieldData.load`.
* Neighbours c(x, y): Delaunay edges (or all pairs within a radius, :func:`neighbours`);
  weights a_ij = 1/‖x_i − x_j‖²; Q the graph Laplacian of (9) (:func:`laplacian`).
* Uncertainty sets (10) in the polar space F, linearised at ξ̂_(k) = mean_i ξ̂_i(k):

  .. math::
      \varphi = \Phi^0 + \Phi^1\eta,\quad \Phi^0_k = [p_i(\hat\xi_{i(k)}) - p_i(\hat\xi_{(k)})]_i,
      \quad \Phi^1 = \operatorname{blockdiag}_k [\nabla p_i(\hat\xi_{(k)})]_i,

  η_k = ξ̂_(k) − x_(k) ∈ R² per cell, so Φ¹ is 2mK × 2K and **block-diagonal** (the
  printed (10) stacks the blocks in one column, which does not fit η ∈ R^{2K}).

The problem package's ``data.py`` (the one skeleton, docs/architecture.md): the data class
the registry's card names. The original problem (8)-(10) on it is
:mod:`~optmodels.biasfield.problem`; the selection stage reads this module only, never the
track fits.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse
from scipy.spatial import Delaunay, QhullError, cKDTree

from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.fields import BiasField
from optmodels.biasfield.geometry import polar_jacobian, shift_from_bias, to_polar, wrap_angle
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_float_array,
    as_instance,
    as_positive,
    check_spd,
    check_spd_stack,
)
from optmodels.io import read_npz

__all__ = [
    "MAX_SYNTHETIC_CELLS",
    "FieldData",
    "as_adjacency",
    "laplacian",
    "neighbours",
    "synthetic_field_data",
    "uncertainty_sets",
]


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
        if k < 1:
            raise ProblemError(
                "biasfield.FieldData centers: no cell (K = 0); the field needs "
                "at least one cell centre"
            )
        self.xi = as_finite_array("xi", self.xi, shape=(k, m, 2), max_abs=MAX_MAGNITUDE)
        self.adjacency = as_adjacency(self.adjacency, k, "biasfield.FieldData adjacency")
        if self.centers.shape[1] != 2:
            raise ProblemError(f"centers: expected (K, 2), got {self.centers.shape}")
        upper = sparse.triu(self.adjacency, k=1).tocoo()
        d2 = np.sum((self.centers[upper.row] - self.centers[upper.col]) ** 2, axis=1)
        if np.any(d2 <= 0):
            e = int(np.flatnonzero(d2 <= 0)[0])
            # found by the robustness sweep: a_ij = 1/‖x̌_i − x̌_j‖² divided by zero
            raise ProblemError(
                f"centers: neighbours {upper.row[e]} and {upper.col[e]} "
                "coincide (a_ij = 1/‖x̌_i − x̌_j‖² is undefined); merge the cells"
            )
        p = as_finite_array("P", self.P, ndim=2, max_abs=MAX_MAGNITUDE)
        if p.shape not in ((2, 2), (2 * m, 2 * m)):
            raise ProblemError(f"P: expected (2, 2) or ({2 * m}, {2 * m}), got {p.shape}")
        # Cholesky, as the solver will use it (the robustness sweep found a P whose smallest
        # eigenvalue was positive but whose Cholesky factorisation failed)
        check_spd("P", p)
        self.P = p
        if self.xi_cov is not None:
            cov = as_finite_array(
                "biasfield.FieldData xi_cov", self.xi_cov, shape=(k, m, 2, 2), max_abs=MAX_MAGNITUDE
            )
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
            raise ProblemError(
                f"biasfield.FieldData seen: expected a ({k}, {m}) boolean "
                f"array (radar i sees cell k), got shape {arr.shape}"
            )
        arr = arr.astype(bool)
        few = np.flatnonzero(arr.sum(axis=1) < 2)
        if few.size:
            raise ProblemError(
                f"biasfield.FieldData seen: cells {few[:10].tolist()} are seen "
                "by fewer than 2 radars (a cell needs two radars to carry a "
                "set (10))"
            )
        p = self.P
        if p.shape == (2 * m, 2 * m):
            off = p.copy()
            for i in range(m):
                off[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = 0.0
            if np.any(off != 0.0):
                raise ProblemError(
                    "biasfield.FieldData P: with per-cell radar subsets (seen) "
                    "P must be block-diagonal per radar (2 × 2 blocks)"
                )
        self.seen = arr

    @property
    def subsets(self) -> np.ndarray:
        """(K, m) bool: radar i sees cell k (all True without ``seen``)."""
        if self.seen is None:
            return np.ones((self.k, self.m), dtype=bool)
        return self.seen

    def _check_geometry3d(self, k: int, m: int) -> None:
        if self.jacobians is not None:
            jac = as_finite_array(
                "biasfield.FieldData jacobians",
                self.jacobians,
                shape=(k, m, 2, 2),
                max_abs=MAX_MAGNITUDE,
            )
            det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
            scale = np.abs(jac).max(axis=(-1, -2)) ** 2
            if np.any(np.abs(det) <= 1e-12 * scale):
                raise ProblemError(
                    "biasfield.FieldData jacobians: a singular ∇p_i (a cell at a radar site?)"
                )
            self.jacobians = jac
        if self.heights is not None:
            self.heights = as_finite_array(
                "biasfield.FieldData heights", self.heights, shape=(k,), max_abs=1e6
            )
        if (self.geodetic is None) != (self.origin is None):
            raise ProblemError(
                "biasfield.FieldData geodetic: give both the geodetic sites "
                "and the origin, or neither"
            )
        if self.geodetic is not None and self.origin is not None:
            geo = as_finite_array("biasfield.FieldData geodetic", self.geodetic, shape=(m, 3))
            for j in range(m):
                g3.site_geodetic(f"biasfield.FieldData geodetic[{j}]", geo[j])
            self.geodetic = geo
            self.origin = g3.site_geodetic("biasfield.FieldData origin", self.origin)
            if self.heights is None:
                raise ProblemError(
                    "biasfield.FieldData heights: the 3-D sets need the cell "
                    "heights (K,) with the geodetic sites"
                )

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

    def npz_arrays(self) -> dict[str, Any]:
        """The arrays of the ``.npz`` :meth:`load` reads: radars, centers, xi, edges (E, 2),
        P, and those of xi_cov, jacobians, heights, geodetic, origin, seen that are set."""
        upper = sparse.triu(self.adjacency, k=1).tocoo()
        arrays: dict[str, Any] = {
            "radars": self.radars,
            "centers": self.centers,
            "xi": self.xi,
            "edges": np.column_stack([upper.row, upper.col]).astype(np.int64),
            "P": self.P,
        }
        for name in ("xi_cov", "jacobians", "heights", "geodetic", "origin", "seen"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        return arrays

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (:meth:`npz_arrays`) onto exactly ``path``, atomically
        (:func:`optmodels.io.save_npz`)."""
        from optmodels.io import save_npz

        # exactly ``path`` (no ``.npz`` appended), all or nothing (a kill keeps the old file)
        save_npz(path, name="biasfield.FieldData.save path", compressed=True, **self.npz_arrays())

    @classmethod
    def load(cls, path: str | Path) -> FieldData:
        """Read an ``.npz`` written by :meth:`save` (or by hand with the same keys; the
        neighbours as ``edges`` (E, 2) or a dense ``adjacency`` (K, K)); the optional keys
        ``xi_cov``, ``jacobians``, ``heights``, ``geodetic``, ``origin`` (files of the 2-D
        chain have none of these four), ``seen`` (per-cell radar subsets)."""
        if not isinstance(path, str | Path):
            raise ProblemError(
                f"biasfield.FieldData.load path: expected a file name, got {type(path).__name__}"
            )
        d = read_npz(
            path,
            what="FieldData .npz",
            required=("radars", "centers", "xi", "P"),
            one_of=("edges", "adjacency"),
        )
        adj = d["edges"] if "edges" in d else d["adjacency"]
        try:
            return cls(
                d["radars"],
                d["centers"],
                d["xi"],
                adj,
                d["P"],
                d.get("xi_cov"),
                d.get("jacobians"),
                d.get("heights"),
                d.get("geodetic"),
                d.get("origin"),
                d.get("seen"),
            )
        except ProblemError as exc:
            raise ProblemError(f"{path}: {exc}") from None


def as_adjacency(adj: Any, k: int, name: str = "adjacency") -> sparse.csr_matrix:
    """Dense/sparse (K, K) 0/1 matrix or (E, 2) edge list → symmetric CSR int8; a bad one
    is one :class:`ProblemError` naming ``name``."""
    if sparse.issparse(adj):
        a = sparse.csr_matrix(adj)
    else:
        as_float_array(name, adj)  # text, mappings, ragged rows, None entries, complex: refused
        arr = np.asarray(adj)
        if (
            arr.ndim == 2
            and arr.shape[1] == 2
            and arr.shape != (k, k)
            and np.issubdtype(arr.dtype, np.integer)
        ):
            if arr.size and (arr.min() < 0 or arr.max() >= k):
                raise ProblemError(f"{name}: edge list refers to cells outside 0..{k - 1}")
            a = sparse.csr_matrix((np.ones(arr.shape[0]), (arr[:, 0], arr[:, 1])), shape=(k, k))
            a = a + a.T
        else:
            a = sparse.csr_matrix(arr)
    if a.shape != (k, k):
        raise ProblemError(f"{name}: expected ({k}, {k}) or an (E, 2) edge list, got {a.shape}")
    a = (a != 0).astype(np.int8).tocsr()
    if (a != a.T).nnz:
        raise ProblemError(f"{name}: not symmetric (c(x, y) must equal c(y, x))")
    if a.diagonal().any():
        raise ProblemError(f"{name}: a cell cannot neighbour itself (c(x, x) = 0)")
    a.eliminate_zeros()
    return a


def neighbours(
    centers: ArrayLike,
    *,
    method: Literal["delaunay", "radius"] = "delaunay",
    radius: float | None = None,
) -> sparse.csr_matrix:
    """Symmetric 0/1 adjacency c(x, y) (sparse): Delaunay edges, or all pairs within
    ``radius``."""
    fn = "biasfield.neighbours"
    c = as_finite_array(f"{fn} centers", centers, ndim=2, max_abs=MAX_MAGNITUDE)
    if c.shape[1] != 2:
        raise ProblemError(f"{fn} centers: expected (K, 2) positions (m), got {c.shape}")
    k = c.shape[0]
    as_choice(f"{fn} method", method, ("delaunay", "radius"))
    if method == "delaunay":
        if k < 3:
            pairs = np.array([[0, 1]]) if k == 2 else np.zeros((0, 2), dtype=int)
        else:
            try:
                simp = Delaunay(c).simplices
            except QhullError as exc:  # collinear / coincident centres
                raise ProblemError(
                    f"{fn} centers: no Delaunay triangulation (the centres are "
                    f"collinear or coincide: {str(exc).splitlines()[0]}); use "
                    "method='radius'"
                ) from None
            pairs = np.vstack([simp[:, [0, 1]], simp[:, [1, 2]], simp[:, [0, 2]]])
    else:
        r = as_positive(f"{fn} radius (m)", radius)
        pairs = cKDTree(c).query_pairs(r, output_type="ndarray")
    return (
        as_adjacency(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), k)
        if k != 2
        else as_adjacency(np.array([[0, 1], [1, 0]]), 2)
    )


def laplacian(centers: ArrayLike, adjacency: ArrayLike) -> sparse.csr_matrix:
    """Q of (9): Q_ij = −a_ij, Q_ii = Σ_j a_ij, a_ij = c_ij/‖x_i − x_j‖² (sparse)."""
    c = as_finite_array("biasfield.laplacian centers", centers, ndim=2, max_abs=MAX_MAGNITUDE)
    adj = sparse.coo_matrix(as_adjacency(adjacency, c.shape[0], "biasfield.laplacian adjacency"))
    d2 = np.sum((c[adj.row] - c[adj.col]) ** 2, axis=1)
    if np.any(d2 == 0):
        raise ProblemError("biasfield.laplacian centers: two neighbouring centres coincide")
    a = sparse.csr_matrix((1.0 / d2, (adj.row, adj.col)), shape=adj.shape)
    return (sparse.diags(np.asarray(a.sum(axis=1)).ravel()) - a).tocsr()


def uncertainty_sets(
    data: FieldData, *, space: Literal["polar", "cartesian"] = "polar"
) -> tuple[FloatArray, sparse.csr_matrix]:
    """(Φ0 (2mK,), Φ1 sparse (2mK, 2K)) of (10), ordered cell by cell, radar by radar,
    [range, azimuth]; azimuth differences wrapped. η_k = ξ̂_(k) − x_(k).

    ``space="cartesian"``: the exact sets S_ξ̂ of section 3 in the shift space,
    s = [ξ̂_i(k) − ξ̂_(k)]_i + [I; …; I] η_k (a common shift per cell is free).

    Per-cell subsets (``data.seen``): ξ̂_(k) is the mean over the radars S_k that see cell
    k, and the rows of the radars outside S_k are zero in Φ⁰ and Φ¹ (their φ entries are
    0 and enter neither (9) nor (8)); with every radar in every S_k this is the paper's
    (10) exactly."""
    as_instance("biasfield.uncertainty_sets data", data, FieldData)
    as_choice("biasfield.uncertainty_sets space", space, ("polar", "cartesian"))
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
    if data.geodetic is not None and data.origin is not None and data.heights is not None:
        # exact 3-D polar maps at each cell's height: slant range, each radar's own north
        lat0, lon0 = g3.plane_to_geodetic(mean, data.origin)
        for i in range(m):
            lat, lon = g3.plane_to_geodetic(data.xi[:, i], data.origin)
            r1, a1 = g3.measure(data.geodetic[i], lat, lon, data.heights)
            r0, a0 = g3.measure(data.geodetic[i], lat0, lon0, data.heights)
            phi0[:, i] = np.column_stack([r1 - r0, wrap_angle(a1 - a0)])
        jac = (
            data.jacobians
            if data.jacobians is not None
            else np.stack(
                [
                    g3.polar_jacobian3d(mean, data.heights, data.geodetic[i], data.origin)
                    for i in range(m)
                ],
                axis=1,
            )
        )
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


def _mask_sets(
    data: FieldData, phi0: FloatArray, phi1: sparse.csr_matrix
) -> tuple[FloatArray, sparse.csr_matrix]:
    """Zero the rows of (Φ⁰, Φ¹) of the radars outside each cell's subset S_k."""
    if data.seen is None:
        return phi0, phi1
    rows = np.repeat(data.seen.reshape(-1), 2).astype(float)
    phi1 = (sparse.diags(rows) @ phi1).tocsr()
    phi1.eliminate_zeros()
    return phi0 * rows, phi1


#: Size guard of :func:`synthetic_field_data` (memory grows as cells × radars).
MAX_SYNTHETIC_CELLS = 1_000_000


def synthetic_field_data(
    seed: int | np.random.Generator,
    *,
    cells: int = 200,
    sites: ArrayLike | None = None,
    fields: list[Any] | None = None,
    region: float = 150e3,
    noise: float = 0.0,
    exclude_radius: float = 20e3,
) -> tuple[FieldData, FloatArray]:
    """FieldData without plots: K random cell centres (none within ``exclude_radius`` of a
    radar), true positions x_k at the centres, ξ_i(k) = x_k + s_i(x_k) (+ Gaussian noise of
    ``noise`` metres), Delaunay neighbours and P = diag(1/(50 m)², 1/(1 mrad)²) per radar.
    ``fields`` defaults to smooth random fields. Returns the data and the true field
    (K, m, 2) at the centres."""
    fn = "biasfield.synthetic_field_data"
    rng = (
        seed
        if isinstance(seed, np.random.Generator)
        else np.random.default_rng(as_count(f"{fn} seed", seed))
    )
    cells = as_count(f"{fn} cells", cells, minimum=3, maximum=MAX_SYNTHETIC_CELLS)
    region = as_positive(f"{fn} region (m)", region)
    noise = as_positive(f"{fn} noise (m)", noise, allow_zero=True)
    exclude_radius = as_positive(f"{fn} exclude_radius (m)", exclude_radius, allow_zero=True)
    s = (
        np.array([[-90e3, -60e3], [100e3, -70e3], [80e3, 110e3], [-70e3, 90e3]])
        if sites is None
        else as_finite_array(f"{fn} sites", sites, ndim=2, max_abs=MAX_MAGNITUDE)
    )
    if s.shape[1] != 2 or s.shape[0] < 2:
        raise ProblemError(f"{fn} sites: expected (m, 2) with m ≥ 2, got {s.shape}")
    m = s.shape[0]
    if fields is not None and len(fields) != m:
        raise ProblemError(f"{fn} fields: expected {m} fields (one per radar), got {len(fields)}")
    flist = fields or [
        BiasField.smooth(
            rng,
            center=np.zeros(2),
            scale=region,
            range_amplitude=150.0,
            azimuth_amplitude=np.deg2rad(0.3),
        )
        for _ in range(m)
    ]
    pts: list[FloatArray] = []
    for _ in range(1000):
        cand = rng.uniform(-region, region, (2 * cells, 2))
        near = np.min(np.linalg.norm(cand[:, None] - s[None], axis=2), axis=1)
        pts.append(cand[near > exclude_radius])
        if sum(len(p) for p in pts) >= cells:
            break
    else:
        raise ProblemError(
            f"{fn} exclude_radius: no room for cells in the region (±{region:g} "
            f"m) outside {exclude_radius:g} m of the radars"
        )
    x = np.vstack(pts)[:cells]
    truth = np.stack([flist[i](x) for i in range(m)], axis=1)
    xi = np.stack([x + shift_from_bias(x, s[i], truth[:, i]) for i in range(m)], axis=1)
    if noise > 0:
        xi = xi + rng.normal(0.0, noise, xi.shape)
    p = np.diag([1 / 50.0**2, 1 / 1e-3**2])
    return FieldData(s, x, xi, neighbours(x), p), truth
