r"""Least-squares estimation of dependent linear trajectories (paper 002, Simonova).

Paper: ``shared/papers/002_7b4fdec12ab33196.txt``, equations (1)-(20).

Problem as posed
----------------
Object :math:`j = 1..Q` moves along the line :math:`y_j(t) = y_{0j} + V_j t` and is measured
:math:`N_j` times, :math:`y_{ji} = y_{0j} + V_j t_{ji} + \Delta y_{ji}`, with independent
errors :math:`\Delta y \sim N(0, \sigma^2)` (classified sample: every measurement is known
to belong to its object). Least squares (1):

.. math::
    W = \sum_j \sum_i w_{ji}\,(y_{ji} - y_{0j} - V_j t_{ji})^2 \to \min,
    \qquad w_{ji} = 1/\sigma_{ji}^2

over the ``2Q`` parameters of ``Q`` lines, **subject to** the equality constraints of the
family:

* diverging (РТ): :math:`y_{01} = \dots = y_{0Q}`, :math:`\theta = (y_0, V_1..V_Q)` (4)-(5);
* parallel (ПТ): :math:`V_1 = \dots = V_Q`, :math:`\theta = (y_{01}..y_{0Q}, V)` (10)-(11);
* independent: no constraint, :math:`\theta = (y_{01}..y_{0Q}, V_1..V_Q)`;
* any :class:`Family` of shared starts and shared velocities (objects 1-3 share a start,
  4-5 share a velocity, ...).

The paper writes ``W`` in the constrained parameters directly: :math:`W = \|Y - A\theta\|^2`
with the design matrix ``A`` (2), (5), (11), whose solution is (3)
:math:`\hat\theta = (A^TA)^{-1}A^TY` with covariance (14) :math:`\Psi = \sigma^2(A^TA)^{-1}`.
Values may be vectors (``d = 2`` or ``3`` coordinates with the same dependence): each
coordinate is its own problem with the same ``A``.

Entry points
------------
:func:`solve` (CVXPY: the ``Q`` lines with the family's equality constraints,
``formulation="constrained"``, or the unconstrained problem in θ, ``"reduced"``),
:func:`closed_form` (the paper's route: (8)-(9) diverging, (12)-(13) parallel; the normal
equations (3) for other families), :func:`covariance` (Ψ (14) from the design matrix),
:func:`paper_covariance` ((16)-(20), printed and corrected), :func:`variance_ratios`,
:func:`eta` / :func:`eta0` (the conclusions' ratios for any ``Q`` and ``N``),
:func:`independent_variances` (the introduction's single-line values),
:func:`family_test` (does a dependent family fit as well as independent lines?).

Errata (details and tests in ``docs/errata.md``)
------------------------------------------------
* (13): ``E`` is printed :math:`\sum_j\sum_i t_{ji}`; it is :math:`\sum_j\sum_i t_{ji}^2`.
* (18) and (20) are printed without the inverse in the first equality; (18) drops
  :math:`\sigma^2` in the second; in (18) the elements (2,1), (3,1) have the wrong sign and
  (2,3), (3,2) are wrong; in (20) the element (1,2) is wrong (see :func:`paper_covariance`).
* "Ψ does not depend on the time origin" (before (17)) is false: :math:`y_0` is the position
  at ``t = 0`` and the diverging family's common start *is* the instant ``t = 0``. (16)-(20)
  and the ratios hold for :math:`t_i = (i-1)\Delta T`, i.e. the first measurement at the
  common start.
* The introduction's "СКО" :math:`2(2N-1)/(N(N+1))` and :math:`12/(N(N^2-1)T_0^2)` are
  **variances in units of** :math:`\sigma^2`; the conclusions' η, η0 are ratios of
  variances (the RMS ratio is √η), for ``Q = 2``; for ``Q`` objects η0 = 1/Q and
  η = 1 - r(1 - 1/Q), r = 3(N-1)/(2(2N-1)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy import linalg, stats

from optmodels.backends.cvxpy_backend import solve_problem
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    Solution,
    Status,
    as_finite_array,
    timed,
)

__all__ = [
    "FAMILIES",
    "Family",
    "FamilyTest",
    "TrajectoryData",
    "TrajectorySolution",
    "closed_form",
    "constraint_residuals",
    "covariance",
    "design_matrix",
    "eta",
    "eta0",
    "family_test",
    "independent_variances",
    "objective",
    "paper_covariance",
    "predict",
    "solve",
    "variance_ratios",
]

FAMILIES = ("diverging", "parallel", "independent")
FamilyName = Literal["diverging", "parallel", "independent"]

#: Default solver options. The QP has equality constraints only, so OSQP's polishing step
#: (one solve of the KKT system once ADMM has converged) lands on the exact solution
#: (~1e-15 relative) already from eps = 1e-6; asking ADMM itself for 1e-10 costs 12 525
#: iterations (22 s) on the parallel family with Q = 100 × 1000 points, for nothing. Every
#: generic solution is verified afterwards (:data:`VERIFY_TOL`), so a failed polish shows.
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = {
    "OSQP": {"eps_abs": 1e-6, "eps_rel": 1e-6, "polishing": True, "max_iter": 200_000},
    "CLARABEL": {"tol_gap_abs": 1e-12, "tol_gap_rel": 1e-12, "tol_feas": 1e-12},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 200_000},
}


#: Relative violation (equalities, stationarity of the reduced gradient) above which a
#: solver's claimed optimum is downgraded: OPTIMAL → OPTIMAL_INACCURATE, and
#: OPTIMAL_INACCURATE → ERROR (never returned as a solution). Above REJECT_TOL a claimed
#: OPTIMAL becomes ERROR too.
VERIFY_TOL = 1e-6
REJECT_TOL = 1e-3


# --------------------------------------------------------------------------- data
@dataclass(frozen=True, eq=False)
class TrajectoryData:
    """Classified measurements of ``Q`` objects moving along lines.

    Parameters
    ----------
    times : sequence of Q 1-D arrays
        Measurement times of each object (s); unequal lengths and times are allowed, the
        order within an object is free.
    values : sequence of Q arrays, (N_j,) or (N_j, d)
        Measured coordinate(s); ``d = 2`` or ``3`` coordinates share the dependence (each
        coordinate is its own least-squares problem with the same design matrix).
    sigma2 : float or sequence of Q arrays, default 1.0
        Error variance: one number for all measurements (the paper's σ²), or per
        measurement ((N_j,) or (N_j, d)) for weighted least squares.
    epoch : float, default 0.0
        The instant at which ``start`` is defined: the model is
        ``y = start + velocity * (t - epoch)``. The paper uses ``epoch = 0``; for a family
        with a common start it is the common instant (launch, release).

    Raises
    ------
    ProblemError
        No objects, mismatched lengths, an object with fewer than 2 distinct times,
        NaN/inf, non-positive variances, inconsistent ``d``.
    """

    times: Sequence[ArrayLike]
    values: Sequence[ArrayLike]
    sigma2: float | Sequence[ArrayLike] = 1.0
    epoch: float = 0.0
    # derived, stacked object by object in the paper's order (5), (11)
    t: FloatArray = field(init=False, repr=False)
    y: FloatArray = field(init=False, repr=False)
    w: FloatArray = field(init=False, repr=False)
    obj: np.ndarray = field(init=False, repr=False)
    counts: np.ndarray = field(init=False, repr=False)
    offsets: np.ndarray = field(init=False, repr=False)
    vector: bool = field(init=False, repr=False)
    scalar_sigma2: float | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.times, np.ndarray) and self.times.ndim == 1:
            raise ProblemError("times: expected a sequence of per-object arrays, got one array")
        q = len(self.times)
        if q == 0:
            raise ProblemError("times: no objects (Q = 0)")
        if len(self.values) != q:
            raise ProblemError(f"values: {len(self.values)} objects, times has {q}")
        epoch = float(self.epoch)
        if not np.isfinite(epoch):
            raise ProblemError("epoch: not finite")
        ts, ys, ws = [], [], []
        dims = set()
        for j in range(q):
            t = as_finite_array(f"times[{j}]", self.times[j], ndim=1, max_abs=MAX_MAGNITUDE)
            y = as_finite_array(f"values[{j}]", self.values[j], ndim=(1, 2),
                                max_abs=MAX_MAGNITUDE)
            if t.size == 0:
                raise ProblemError(f"times[{j}]: object {j} has no measurements")
            if y.shape[0] != t.size:
                raise ProblemError(
                    f"values[{j}]: {y.shape[0]} values for {t.size} times (object {j})"
                )
            if np.unique(t).size < 2:
                raise ProblemError(
                    f"times[{j}]: object {j} has fewer than 2 distinct times; its line is "
                    "not identified"
                )
            dims.add(1 if y.ndim == 1 else y.shape[1])
            if y.ndim == 2 and y.shape[1] not in (1, 2, 3):
                raise ProblemError(f"values[{j}]: expected d = 1, 2 or 3 columns, got {y.shape}")
            ts.append(t - epoch)
            ys.append(y.reshape(t.size, -1))
        if len(dims) != 1:
            raise ProblemError(f"values: objects have different numbers of coordinates {dims}")
        vector = any(np.ndim(v) == 2 for v in self.values)
        d = dims.pop()
        scalar = None
        if np.isscalar(self.sigma2) or (
            isinstance(self.sigma2, np.ndarray) and self.sigma2.ndim == 0
        ):
            s2 = float(as_finite_array("sigma2", self.sigma2))
            if not 1 / MAX_MAGNITUDE <= s2 <= MAX_MAGNITUDE:
                raise ProblemError(f"sigma2: must be in [1e-100, 1e100] (positive, and its "
                                   f"inverse a usable weight), got {s2}")
            scalar = s2
            ws = [np.full((t.size, d), 1.0 / s2) for t in ts]
        else:
            if len(self.sigma2) != q:
                raise ProblemError(f"sigma2: {len(self.sigma2)} objects, times has {q}")
            for j in range(q):
                s2 = as_finite_array(f"sigma2[{j}]", self.sigma2[j], ndim=(0, 1, 2))
                try:
                    s2 = np.broadcast_to(s2.reshape(s2.shape + (1,) * (s2.ndim == 1)),
                                         (ts[j].size, d))
                except ValueError:
                    raise ProblemError(
                        f"sigma2[{j}]: shape {s2.shape} does not match ({ts[j].size}, {d})"
                    ) from None
                if np.any(s2 < 1 / MAX_MAGNITUDE) or np.any(s2 > MAX_MAGNITUDE):
                    raise ProblemError(
                        f"sigma2[{j}]: variances must be positive, in [1e-100, 1e100]")
                ws.append(1.0 / s2)
        object.__setattr__(self, "t", np.concatenate(ts))
        object.__setattr__(self, "y", np.concatenate(ys))
        object.__setattr__(self, "w", np.concatenate(ws))
        object.__setattr__(self, "obj", np.repeat(np.arange(q), [t.size for t in ts]))
        object.__setattr__(self, "counts", np.array([t.size for t in ts]))
        object.__setattr__(self, "offsets", np.concatenate([[0], np.cumsum(self.counts)[:-1]]))
        object.__setattr__(self, "vector", vector)
        object.__setattr__(self, "scalar_sigma2", scalar)

    @property
    def n_objects(self) -> int:
        """Q."""
        return int(self.counts.size)

    @property
    def n_measurements(self) -> int:
        """Σ N_j."""
        return int(self.t.size)

    @property
    def dim(self) -> int:
        """Number of coordinates d (1 for scalar values)."""
        return int(self.y.shape[1])


# --------------------------------------------------------------------------- families
@dataclass(frozen=True)
class Family:
    """Which objects share a start and which share a velocity.

    ``start_groups`` and ``velocity_groups`` are partitions of ``range(Q)``. The parameter
    vector θ lists one start per start group, then one velocity per velocity group, each
    in the order of the group's first object: the paper's orderings
    ``(y0, V_1..V_Q)`` (diverging) and ``(y0_1..y0_Q, V)`` (parallel) are special cases.
    Build with :meth:`diverging`, :meth:`parallel`, :meth:`independent` or :meth:`custom`.
    """

    name: str
    n_objects: int
    start_groups: tuple[tuple[int, ...], ...]
    velocity_groups: tuple[tuple[int, ...], ...]

    @classmethod
    def diverging(cls, q: int) -> Family:
        """All objects share the start (4)-(5)."""
        return cls("diverging", q, (tuple(range(q)),), tuple((j,) for j in range(q)))

    @classmethod
    def parallel(cls, q: int) -> Family:
        """All objects share the velocity (10)-(11)."""
        return cls("parallel", q, tuple((j,) for j in range(q)), (tuple(range(q)),))

    @classmethod
    def independent(cls, q: int) -> Family:
        """Nothing shared: Q separate lines."""
        return cls("independent", q, tuple((j,) for j in range(q)),
                   tuple((j,) for j in range(q)))

    @classmethod
    def custom(cls, q: int, *, shared_start: Sequence[Sequence[int]] = (),
               shared_velocity: Sequence[Sequence[int]] = (), name: str = "custom") -> Family:
        """Objects in each group of ``shared_start`` share a start, in each group of
        ``shared_velocity`` a velocity; every other object has its own.

        Raises
        ------
        ProblemError
            An index out of range or an object in two groups of the same kind.
        """
        return cls(name, q, _partition(q, shared_start, "shared_start"),
                   _partition(q, shared_velocity, "shared_velocity"))

    @property
    def n_params(self) -> int:
        """R, the number of free parameters per coordinate."""
        return len(self.start_groups) + len(self.velocity_groups)

    @property
    def start_index(self) -> np.ndarray:
        """(Q,) index in θ of each object's start."""
        idx = np.empty(self.n_objects, dtype=int)
        for k, g in enumerate(self.start_groups):
            idx[list(g)] = k
        return idx

    @property
    def velocity_index(self) -> np.ndarray:
        """(Q,) index in θ of each object's velocity."""
        idx = np.empty(self.n_objects, dtype=int)
        for k, g in enumerate(self.velocity_groups):
            idx[list(g)] = len(self.start_groups) + k
        return idx

    @property
    def n_constraints(self) -> int:
        """Equality constraints tying the 2Q line parameters: 2Q − R."""
        return 2 * self.n_objects - self.n_params


def _partition(q: int, groups: Sequence[Sequence[int]], name: str) -> tuple[tuple[int, ...], ...]:
    seen: dict[int, int] = {}
    out = []
    for k, g in enumerate(groups):
        g = tuple(int(i) for i in g)
        for i in g:
            if not 0 <= i < q:
                raise ProblemError(f"{name}[{k}]: object {i} out of range 0..{q - 1}")
            if i in seen:
                raise ProblemError(f"{name}: object {i} is in groups {seen[i]} and {k}")
            seen[i] = k
        if g:
            out.append(g)
    out += [(i,) for i in range(q) if i not in seen]
    return tuple(sorted(out, key=min))


def resolve_family(family: FamilyName | Family, q: int) -> Family:
    """A :class:`Family` for ``Q`` objects from a name or a Family (checked against Q)."""
    if isinstance(family, Family):
        if family.n_objects != q:
            raise ProblemError(f"family: built for {family.n_objects} objects, data has {q}")
        return family
    if family == "diverging":
        return Family.diverging(q)
    if family == "parallel":
        return Family.parallel(q)
    if family == "independent":
        return Family.independent(q)
    raise ProblemError(f"family: expected one of {FAMILIES} or a Family, got {family!r}")


# --------------------------------------------------------------------------- solution
@dataclass
class TrajectorySolution(Solution):
    """Estimated family of lines.

    Attributes
    ----------
    family : Family
    theta : (R,) or (R, d)
        Parameters in the paper's ordering (see :class:`Family`).
    start, velocity : (Q,) or (Q, d)
        Each object's start (at ``epoch``) and velocity.
    covariance : (R, R) or (d, R, R)
        Ψ (14): σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement variances; one per coordinate
        for vector values.
    objective : float
        Σ w (y − ŷ)², the χ² statistic of the fit (with σ² known), on ``dof`` degrees of
        freedom.
    dof : int
        (Σ N_j − R)·d.
    """

    family: Family | None = None
    theta: FloatArray = field(default_factory=lambda: np.empty(0))
    start: FloatArray = field(default_factory=lambda: np.empty(0))
    velocity: FloatArray = field(default_factory=lambda: np.empty(0))
    covariance: FloatArray = field(default_factory=lambda: np.empty(0))
    dof: int = 0
    _data: TrajectoryData | None = field(default=None, repr=False)

    @property
    def design_matrix(self) -> sp.csr_matrix:
        """A ((5), (11)) of this family for this data (sparse, Σ N_j × R)."""
        assert self._data is not None and self.family is not None
        return design_matrix(self._data, self.family)

    @property
    def std(self) -> FloatArray:
        """Standard deviations of θ (square roots of Ψ's diagonal), shaped like θ."""
        diag = np.diagonal(self.covariance, axis1=-2, axis2=-1)
        return np.sqrt(diag.T if diag.ndim == 2 else diag)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out.pop("_data", None)
        fam = self.family
        out["family"] = None if fam is None else {
            "name": fam.name, "start_groups": fam.start_groups,
            "velocity_groups": fam.velocity_groups}
        return out


def _shape(data: TrajectoryData, arr: FloatArray) -> FloatArray:
    """(k, d) → (k,) for scalar values."""
    return arr if data.vector else arr[:, 0]


def _finish(data: TrajectoryData, fam: Family, theta: FloatArray, cov: FloatArray,
            common: dict[str, Any]) -> TrajectorySolution:
    """Re-check θ against the original form and package it."""
    starts = theta[fam.start_index]
    vels = theta[fam.velocity_index]
    res = constraint_residuals(data, fam, starts, vels)
    res["stationarity"] = _stationarity(data, fam, theta)
    return TrajectorySolution(
        objective=objective(data, starts, vels), residuals=res, family=fam,
        theta=_shape(data, theta), start=_shape(data, starts), velocity=_shape(data, vels),
        covariance=cov if data.vector else cov[0],
        dof=(data.n_measurements - fam.n_params) * data.dim, _data=data, **common)


# --------------------------------------------------------------------------- original form
def _per_object(data: TrajectoryData, a: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(a, dtype=float)
    arr = arr.reshape(data.n_objects, -1)
    if arr.shape[1] != data.dim:
        raise ProblemError(f"{name}: expected ({data.n_objects}, {data.dim}), got {arr.shape}")
    return arr


def predict(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> FloatArray:
    """Model values ŷ = start_j + velocity_j (t − epoch) at the data's times, (Σ N_j, d)."""
    s = _per_object(data, start, "start")
    v = _per_object(data, velocity, "velocity")
    return s[data.obj] + v[data.obj] * data.t[:, None]


def objective(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> float:
    """W (4), (10) of the Q lines, weighted: Σ w (y − y0_j − V_j t)²."""
    r = data.y - predict(data, start, velocity)
    return float(np.sum(data.w * r * r))


def constraint_residuals(data: TrajectoryData, family: FamilyName | Family,
                         start: ArrayLike, velocity: ArrayLike) -> dict[str, float]:
    """Largest violation of the family's equalities (y0_j = y0_k, V_j = V_k in a group),
    relative to the size of the parameters."""
    fam = resolve_family(family, data.n_objects)
    s = _per_object(data, start, "start")
    v = _per_object(data, velocity, "velocity")
    out = {}
    for key, arr, groups in (("start", s, fam.start_groups), ("velocity", v, fam.velocity_groups)):
        worst = 0.0
        scale = max(float(np.max(np.abs(arr))), 1.0)
        for g in groups:
            if len(g) > 1:
                worst = max(worst, float(np.max(np.abs(arr[list(g)] - arr[g[0]]))) / scale)
        out[f"shared_{key}"] = worst
    return out


def _stationarity(data: TrajectoryData, fam: Family, theta: FloatArray) -> float:
    """Largest relative entry of the reduced gradient Aᵀ W (y − Aθ) (entry-wise scaled by
    |A|ᵀ|W y|): zero at the least-squares optimum of the family, an optimality check
    independent of how θ was found."""
    r = data.w * (data.y - theta[fam.start_index][data.obj]
                  - theta[fam.velocity_index][data.obj] * data.t[:, None])
    ay = np.abs(data.w * data.y)
    at = np.abs(data.t)[:, None]
    g = _param_sums(data, fam, _object_sums(data, r), _object_sums(data, r * data.t[:, None]))
    ref = _param_sums(data, fam, _object_sums(data, ay), _object_sums(data, ay * at))
    return float(np.max(np.abs(g) / (ref + 1e-300)))


def _object_sums(data: TrajectoryData, x: FloatArray) -> FloatArray:
    """Σ over each object's measurements (rows are stored object by object): (Q, d)."""
    return np.add.reduceat(x, data.offsets, axis=0)


def _param_sums(data: TrajectoryData, fam: Family, on_start: FloatArray,
                on_velocity: FloatArray) -> FloatArray:
    """Aᵀx from per-object sums: add each object's sums into its θ entries, (R, d)."""
    out = np.zeros((fam.n_params, data.dim))
    np.add.at(out, fam.start_index, on_start)
    np.add.at(out, fam.velocity_index, on_velocity)
    return out


def design_matrix(data: TrajectoryData, family: FamilyName | Family) -> sp.csr_matrix:
    """The design matrix A (2) of the family, rows object by object: (5) for diverging,
    (11) for parallel (returned as A, the paper prints Aᵀ). Sparse, Σ N_j × R."""
    fam = resolve_family(family, data.n_objects)
    n = data.n_measurements
    rows = np.concatenate([np.arange(n), np.arange(n)])
    cols = np.concatenate([fam.start_index[data.obj], fam.velocity_index[data.obj]])
    vals = np.concatenate([np.ones(n), data.t])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, fam.n_params))


def _normal_matrices(data: TrajectoryData, fam: Family) -> tuple[FloatArray, FloatArray]:
    """(d, R, R) AᵀWA and (R, d) AᵀWy per coordinate, from the sparse design matrix."""
    a = design_matrix(data, fam)
    mats = np.stack([(a.T @ sp.diags(data.w[:, k]) @ a).toarray() for k in range(data.dim)])
    rhs = a.T @ (data.w * data.y)
    return mats, np.asarray(rhs)


def _inv_spd(mats: FloatArray, what: str) -> FloatArray:
    out = np.empty_like(mats)
    for k, m in enumerate(mats):
        scale = np.sqrt(np.diag(m))
        ms = m / np.outer(scale, scale)  # Jacobi scaling: condition of the geometry only
        w = np.linalg.eigvalsh(ms)
        if w[0] <= 1e-13 * w[-1]:
            raise ProblemError(
                f"{what}: AᵀA is singular (condition {w[-1] / max(w[0], 1e-300):.2g}); the "
                "data cannot identify this family -- are the times far from the epoch?"
            )
        out[k] = linalg.cho_solve(linalg.cho_factor(ms), np.eye(len(m))) / np.outer(scale, scale)
    return out


def covariance(data: TrajectoryData, family: FamilyName | Family) -> FloatArray:
    """Ψ (14) from the generic design matrix: σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement
    variances. (R, R) for scalar values, (d, R, R) for vector values."""
    fam = resolve_family(family, data.n_objects)
    cov = _covariance3(data, fam)
    return cov if data.vector else cov[0]


def _covariance3(data: TrajectoryData, fam: Family) -> FloatArray:
    """Ψ per coordinate, always (d, R, R)."""
    return _inv_spd(_normal_matrices(data, fam)[0], "family")


# --------------------------------------------------------------------------- generic solve
@dataclass(frozen=True)
class _Units:
    """Change of units for the solvers: t' = t/ts, y' = y/ys, w' = w/mean(w), so that
    start' = start/ys and velocity' = velocity·ts/ys are O(1) whatever the user's units
    (seconds over half an hour, kilometres of along-track position). The problem is the
    same; only its numbers are scaled (first-order solvers such as OSQP/SCS need it)."""

    ts: float
    ys: float

    @classmethod
    def of(cls, data: TrajectoryData) -> _Units:
        ts = float(np.max(np.abs(data.t))) or 1.0
        ys = float(np.max(np.abs(data.y))) or 1.0
        return cls(ts, ys)

    def back(self, start: FloatArray, velocity: FloatArray) -> tuple[FloatArray, FloatArray]:
        return start * self.ys, velocity * self.ys / self.ts


def _cvxpy_problem(data: TrajectoryData, fam: Family, formulation: str, u: _Units
                   ) -> tuple[cp.Problem, cp.Variable, cp.Variable | None]:
    n, q, d = data.n_measurements, data.n_objects, data.dim
    t, y = data.t / u.ts, data.y / u.ys
    # objective / (n d) with weights of mean 1: O(1) for the solvers' tolerances
    sw = np.sqrt(data.w / np.mean(data.w) / (n * d))
    if formulation == "constrained":
        # the original problem: Q free lines + the family's equality constraints
        sel0 = sp.csr_matrix((np.ones(n), (np.arange(n), data.obj)), shape=(n, q))
        sel1 = sp.csr_matrix((t, (np.arange(n), data.obj)), shape=(n, q))
        y0 = cp.Variable((q, d), name="start")
        v = cp.Variable((q, d), name="velocity")
        pred = sel0 @ y0 + sel1 @ v
        cons = []
        for var, groups in ((y0, fam.start_groups), (v, fam.velocity_groups)):
            for g in groups:
                if len(g) > 1:
                    cons.append(var[list(g[1:])] == np.ones((len(g) - 1, 1)) @ var[[g[0]]])
        obj = cp.sum_squares(cp.multiply(sw, y - pred))
        return cp.Problem(cp.Minimize(obj), cons), y0, v
    if formulation == "reduced":
        # (1): the unconstrained least squares in θ with the design matrix A
        theta = cp.Variable((fam.n_params, d), name="theta")
        a = design_matrix(data, fam)
        a = a @ sp.diags(np.where(np.arange(fam.n_params) < len(fam.start_groups), 1.0,
                                  1.0 / u.ts))
        obj = cp.sum_squares(cp.multiply(sw, y - a @ theta))
        return cp.Problem(cp.Minimize(obj)), theta, None
    raise ProblemError(f"formulation: expected 'constrained' or 'reduced', got {formulation!r}")


def solve(data: TrajectoryData, family: FamilyName | Family = "diverging", *,
          formulation: Literal["constrained", "reduced"] = "constrained",
          solver: str | None = None, **solver_options: Any) -> TrajectorySolution:
    """Least squares of the family, written as is and solved by a CVXPY solver.

    Parameters
    ----------
    data : TrajectoryData
    family : "diverging", "parallel", "independent" or a :class:`Family`
    formulation : {"constrained", "reduced"}
        ``"constrained"``: the original problem -- ``Q`` lines (2Q·d variables) with the
        family's equality constraints; ``"reduced"``: (1) in θ with the design matrix A.
    solver : str, optional
        Any installed CVXPY QP/conic solver; default Clarabel.
    **solver_options
        Passed to the solver, over :data:`SOLVER_DEFAULTS`.

    Returns
    -------
    TrajectorySolution
        ``covariance`` is Ψ (14) at the data's design; ``residuals`` are the equality
        violations and the stationarity of the reduced gradient, re-computed in NumPy.
        A failed solve keeps its status and carries NaN estimates.
    """
    fam = resolve_family(family, data.n_objects)
    name = (solver or "CLARABEL").upper()
    opts = {**SOLVER_DEFAULTS.get(name, {}), **solver_options}
    with timed() as tb:
        units = _Units.of(data)
        prob, x1, x2 = _cvxpy_problem(data, fam, formulation, units)
    res = solve_problem(prob, name, **opts)
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = f"{res.method} ({formulation})"
    cov = _covariance3(data, fam)
    nan = np.full((fam.n_params, data.dim), np.nan)
    if not res.status.ok or x1.value is None:
        sol = _finish(data, fam, nan, cov, common)
        sol.status = res.status if not res.status.ok else Status.ERROR
        return sol
    lines = None
    if x2 is None:
        ns = len(fam.start_groups)
        theta = np.vstack(units.back(*np.split(np.asarray(x1.value).reshape(
            fam.n_params, data.dim), [ns])))
    else:
        # θ from the constrained solution: each group's parameter as the group mean
        s, v = units.back(np.asarray(x1.value), np.asarray(x2.value))
        theta = np.vstack([[s[list(g)].mean(axis=0) for g in fam.start_groups],
                           [v[list(g)].mean(axis=0) for g in fam.velocity_groups]])
        lines = (s, v)
    sol = _finish(data, fam, theta, cov, common)
    if lines is not None:
        # the solver's own lines (not the averaged θ) against the equality constraints
        sol.residuals.update(constraint_residuals(data, fam, *lines))
        sol.info["lines"] = {"start": lines[0], "velocity": lines[1]}
    # independent verification: a claimed optimum must satisfy the normal equations
    if sol.max_residual > VERIFY_TOL:
        worst = max(sol.residuals, key=sol.residuals.__getitem__)
        note = f"; verification failed: {worst} = {sol.residuals[worst]:.2e} > {VERIFY_TOL:g}"
        if sol.status is Status.OPTIMAL and sol.max_residual <= REJECT_TOL:
            sol.status = Status.OPTIMAL_INACCURATE
        else:
            bad = _finish(data, fam, nan, cov, common)
            bad.status, bad.residuals = Status.ERROR, sol.residuals
            bad.info["rejected_theta"] = theta
            sol = bad
        sol.message += note
    return sol


# --------------------------------------------------------------------------- closed forms
@dataclass(frozen=True)
class _Sums:
    """Weighted per-object sums (Q, d): Σw, Σwt, Σwt², Σwy, Σwty."""

    s0: FloatArray
    s1: FloatArray
    s2: FloatArray
    y0: FloatArray
    y1: FloatArray


def _sums(data: TrajectoryData) -> _Sums:
    w, t, y = data.w, data.t[:, None], data.y
    wt, wy = w * t, w * y

    def per(x: FloatArray) -> FloatArray:
        return _object_sums(data, x)

    return _Sums(per(w), per(wt), per(wt * t), per(wy), per(wy * t))


def _kind(fam: Family) -> str:
    """The paper's family this one is (by structure, whatever its name), or "custom"."""
    q = fam.n_objects
    for name in FAMILIES:
        ref = resolve_family(name, q)  # type: ignore[arg-type]
        if (fam.start_groups, fam.velocity_groups) == (ref.start_groups, ref.velocity_groups):
            return name
    return "custom"


def closed_form(data: TrajectoryData, family: FamilyName | Family = "diverging", *,
                printed: bool = False) -> TrajectorySolution:
    """The paper's closed forms, in its own notation (weighted sums where variances differ).

    * diverging (8)-(9): :math:`y_0 = (D - A_C)/(E - B_C)`, :math:`V_j = (A_j - y_0B_j)/C_j`
      with :math:`D = \\sum y`, :math:`E = \\sum N_j`, :math:`A_j = \\sum_i y t`,
      :math:`B_j = \\sum_i t`, :math:`C_j = \\sum_i t^2`, :math:`A_C = \\sum_j A_jB_j/C_j`,
      :math:`B_C = \\sum_j B_j^2/C_j`;
    * parallel (12)-(13): :math:`V = (D - A_N)/(E - B_N)`,
      :math:`y_{0j} = (A_j - VB_j)/N_j` with :math:`D = \\sum y t`, :math:`A_j = \\sum_i y`,
      :math:`B_j = \\sum_i t`, :math:`A_N = \\sum_j A_jB_j/N_j`, :math:`B_N = \\sum_j B_j^2/N_j`
      and :math:`E = \\sum t^2` (printed: :math:`\\sum t`, erratum; ``printed=True``
      reproduces it);
    * independent: the single-line formulas per object; any other :class:`Family`: the
      normal equations (3).

    Ψ is computed along the same route (Schur complements of the block-diagonal part), so
    that it can be checked against :func:`covariance` from the design matrix.
    """
    fam = resolve_family(family, data.n_objects)
    with timed() as tm:
        s = _sums(data)
        kind = _kind(fam)
        if printed and kind != "parallel":
            raise ProblemError("printed: only the parallel family (13) has a misprint")
        if kind == "diverging":
            theta, cov = _diverging(s)
        elif kind == "parallel":
            theta, cov = _parallel(s, printed=printed)
        elif kind == "independent":
            theta, cov = _independent(s)
        else:
            mats, rhs = _normal_matrices(data, fam)
            cov = _inv_spd(mats, "family")
            theta = np.einsum("krs,sk->rk", cov, rhs)
    common = {"status": Status.OPTIMAL, "method": "closed_form", "solve_time": tm.elapsed,
              "message": {"diverging": "(8)-(9)", "parallel": "(12)-(13)",
                          "independent": "single-line LSQ"}.get(kind, "normal equations (3)")
              + (" as printed" if printed else "")}
    if not np.all(np.isfinite(theta)):
        raise ProblemError("family: the data cannot identify this family (singular sums)")
    return _finish(data, fam, theta, cov, common)


def _diverging(s: _Sums) -> tuple[FloatArray, FloatArray]:
    """(8)-(9) and Ψ via the Schur complement on y0."""
    d_ = s.y0.sum(axis=0)                       # D
    e = s.s0.sum(axis=0)                        # E = Σ N_j (weighted)
    a, b, c = s.y1, s.s1, s.s2                  # A_j, B_j, C_j
    a_c = np.sum(a * b / c, axis=0)             # A_C = Σ_j Σ_i (A_j/C_j) t_ij
    b_c = np.sum(b * b / c, axis=0)             # B_C = Σ_j Σ_i (B_j/C_j) t_ij
    y0 = (d_ - a_c) / (e - b_c)
    v = (a - y0 * b) / c
    q, d = a.shape
    var0 = 1.0 / (e - b_c)                      # Var(y0): Schur complement
    g = -b / c                                   # ∂V_j/∂y0
    cov = np.zeros((d, q + 1, q + 1))
    for k in range(d):
        cov[k, 0, 0] = var0[k]
        cov[k, 0, 1:] = cov[k, 1:, 0] = g[:, k] * var0[k]
        cov[k, 1:, 1:] = np.diag(1.0 / c[:, k]) + np.outer(g[:, k], g[:, k]) * var0[k]
    return np.vstack([y0, v]), cov


def _parallel(s: _Sums, *, printed: bool = False) -> tuple[FloatArray, FloatArray]:
    """(12)-(13) and Ψ via the Schur complement on V."""
    d_ = s.y1.sum(axis=0)                       # D = Σ y t
    a, b, n = s.y0, s.s1, s.s0                  # A_j = Σ y, B_j = Σ t, N_j
    a_n = np.sum(a * b / n, axis=0)             # A_N
    b_n = np.sum(b * b / n, axis=0)             # B_N
    e = s.s1.sum(axis=0) if printed else s.s2.sum(axis=0)   # (13): Σ t printed, Σ t² right
    v = (d_ - a_n) / (e - b_n)
    y0 = (a - v * b) / n
    q, d = a.shape
    varv = 1.0 / (s.s2.sum(axis=0) - b_n)
    g = -b / n
    cov = np.zeros((d, q + 1, q + 1))
    for k in range(d):
        cov[k, q, q] = varv[k]
        cov[k, q, :q] = cov[k, :q, q] = g[:, k] * varv[k]
        cov[k, :q, :q] = np.diag(1.0 / n[:, k]) + np.outer(g[:, k], g[:, k]) * varv[k]
    return np.vstack([y0, v]), cov


def _independent(s: _Sums) -> tuple[FloatArray, FloatArray]:
    """Single-line least squares per object."""
    det = s.s0 * s.s2 - s.s1**2
    v = (s.s0 * s.y1 - s.s1 * s.y0) / det
    y0 = (s.y0 - v * s.s1) / s.s0
    q, d = det.shape
    cov = np.zeros((d, 2 * q, 2 * q))
    idx = np.arange(q)
    for k in range(d):
        cov[k, idx, idx] = s.s2[:, k] / det[:, k]
        cov[k, q + idx, q + idx] = s.s0[:, k] / det[:, k]
        cov[k, idx, q + idx] = cov[k, q + idx, idx] = -s.s1[:, k] / det[:, k]
    return np.vstack([y0, v]), cov


# --------------------------------------------------------------------------- covariances
def independent_variances(n: int, dt: float = 1.0, sigma2: float = 1.0) -> tuple[float, float]:
    """Variances of a single line's (y0, V) from ``N`` equally spaced measurements
    ``t_i = (i − 1)·dt`` (the introduction): σ²·2(2N−1)/(N(N+1)) and σ²·12/(N(N²−1)dt²).

    The paper calls these "СКО" and omits σ²; they are variances (y0 at the first
    measurement)."""
    _check_n(n, 2)
    return (sigma2 * 2 * (2 * n - 1) / (n * (n + 1)),
            sigma2 * 12 / (n * (n * n - 1) * dt * dt))


def _check_n(n: int, least: int) -> None:
    if int(n) != n or n < least:
        raise ProblemError(f"n: need an integer >= {least}, got {n}")


def paper_covariance(family: Literal["diverging", "parallel"], n: int, dt: float = 1.0,
                     sigma2: float = 1.0, *, printed: bool = False) -> FloatArray:
    """Ψ* of two objects measured together at ``t_i = (i − 1)·dt``, ``i = 1..N``:
    (18) for the diverging family (θ = y0, V1, V2), (20) for the parallel one
    (θ = y01, y02, V).

    ``printed=True`` returns the matrices exactly as printed (with σ² restored in (18),
    whose second equality drops it); ``False`` the corrected ones. Corrections
    (C = dt·N(N−1)/2, D = dt²·N(N−1)(2N−1)/6 as in (17)):

    * (18): elements (2,1), (3,1) are −3/(dt·N(N+1)) (printed +); (2,3) and (3,2) are
      9/(dt²·N(N+1)(2N−1)) (printed 3/(dt·N(N+1)) and 3(5N−1)/(dt²·N(N+1)(2N−1)));
    * (20): element (1,2) is 3(N−1)/(2N(N+1)) (printed 3/(dt·N(N+1))).
    """
    _check_n(n, 2)
    nn, t = float(n), float(dt)
    k = 3 / (t * nn * (nn + 1))
    if family == "diverging":
        d0 = (2 * nn - 1) / (nn * (nn + 1))
        dv = 3 * (5 * nn - 1) / (t * t * nn * (nn * nn - 1) * (2 * nn - 1))
        if printed:
            m = [[d0, -k, -k],
                 [k, dv, k],
                 [k, 3 * (5 * nn - 1) / (t * t * nn * (nn + 1) * (2 * nn - 1)), dv]]
        else:
            c = 9 / (t * t * nn * (nn + 1) * (2 * nn - 1))
            m = [[d0, -k, -k], [-k, dv, c], [-k, c, dv]]
    elif family == "parallel":
        d0 = (5 * nn - 1) / (2 * nn * (nn + 1))
        dv = 6 / (t * t * nn * (nn * nn - 1))
        c01 = k if printed else 3 * (nn - 1) / (2 * nn * (nn + 1))
        m = [[d0, c01, -k], [3 * (nn - 1) / (2 * nn * (nn + 1)), d0, -k], [-k, -k, dv]]
    else:
        raise ProblemError(f"family: expected 'diverging' or 'parallel', got {family!r}")
    return sigma2 * np.array(m)


def eta0(q: int = 2) -> float:
    """The conclusions' ratio for the **shared** parameter (y0 of a diverging family, V of
    a parallel one): Var(shared, dependent LSQ) / Var(same parameter from one object's
    independent line), ``Q`` objects measured at the same times: 1/Q (printed 0.5 for
    Q = 2). It equals the gain of simply averaging the Q independent estimates."""
    _check_n(q, 1)
    return 1.0 / q


def eta(n: int, q: int = 2) -> float:
    """The conclusions' ratio for the **unique** parameters (V_j of a diverging family,
    y0_j of a parallel one): Var(dependent LSQ) / Var(independent line), ``Q`` objects
    each measured at ``t_i = (i − 1)·ΔT``, ``i = 1..N`` (first measurement at the common
    start):

    η = 1 − r(1 − 1/Q),  r = (Σt)²/(N Σt²) = 3(N − 1)/(2(2N − 1));

    for Q = 2 this is the printed (5N − 1)/(4(2N − 1)) (0.7 at N = 3 → 0.625). A ratio
    of variances; the ratio of RMS errors is √η."""
    _check_n(n, 2)
    _check_n(q, 1)
    r = 3 * (n - 1) / (2 * (2 * n - 1))
    return 1.0 - r * (1.0 - 1.0 / q)


def variance_ratios(data: TrajectoryData, family: FamilyName | Family) -> dict[str, FloatArray]:
    """Var(start_j), Var(velocity_j) under the family divided by the same variances from
    object j's own independent line, for the data's actual times and variances: the
    general form of the conclusions' η and η0. Arrays (Q,) or (Q, d)."""
    fam = resolve_family(family, data.n_objects)
    q = data.n_objects
    dep = _covariance3(data, fam)
    ind = _covariance3(data, Family.independent(q))
    dv = np.diagonal(dep, axis1=1, axis2=2)   # (d, R)
    iv = np.diagonal(ind, axis1=1, axis2=2)   # (d, 2Q)
    rs = dv[:, fam.start_index] / iv[:, :q]
    rv = dv[:, fam.velocity_index] / iv[:, q:]
    return {"start": _shape(data, rs.T), "velocity": _shape(data, rv.T)}


# --------------------------------------------------------------------------- model choice
@dataclass(frozen=True)
class FamilyTest:
    """Does the family fit as well as independent lines?

    ``statistic``: with σ² known, Λ = W_family − W_independent ~ χ²(dof); with σ² estimated
    from the independent fit, F = (Λ/dof)/(W_independent/dof2) ~ F(dof, dof2). ``reject``:
    the family is rejected at ``level``.
    """

    family: str
    sigma2: str
    statistic: float
    dof: int
    dof2: int | None
    threshold: float
    p_value: float
    level: float
    reject: bool
    objective_family: float
    objective_independent: float

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def family_test(data: TrajectoryData, family: FamilyName | Family = "diverging", *,
                level: float = 0.95, sigma2: Literal["known", "estimated"] = "known"
                ) -> FamilyTest:
    """Likelihood-ratio test of the family's equality constraints against independent lines.

    The family imposes ``q = 2Q − R`` linear constraints per coordinate. Under the family
    and Gaussian errors, ``Λ = W_family − W_independent`` (both in units of σ², the
    objectives of :func:`closed_form`) is χ² with ``q·d`` degrees of freedom when the
    variances are known (``sigma2="known"``); when they are known only up to a common
    factor (``"estimated"``), ``F = (Λ/(q d)) / (W_independent/((Σ N_j − 2Q) d))`` is
    F(q d, (Σ N_j − 2Q) d).
    """
    if not 0.0 < level < 1.0:
        raise ProblemError(f"level: must be in (0, 1), got {level}")
    fam = resolve_family(family, data.n_objects)
    if fam.n_constraints == 0:
        raise ProblemError("family: independent lines impose no constraint to test")
    wf = closed_form(data, fam).objective
    wi = closed_form(data, "independent").objective
    lam = max(wf - wi, 0.0)
    dof = fam.n_constraints * data.dim
    if sigma2 == "known":
        stat, dist, dof2 = lam, stats.chi2(dof), None
    elif sigma2 == "estimated":
        dof2 = (data.n_measurements - 2 * data.n_objects) * data.dim
        if dof2 <= 0:
            raise ProblemError("sigma2: estimating σ² needs more than 2 measurements on "
                               "some object (Σ N_j > 2Q)")
        stat, dist = (lam / dof) / (wi / dof2), stats.f(dof, dof2)
    else:
        raise ProblemError(f"sigma2: expected 'known' or 'estimated', got {sigma2!r}")
    thr = float(dist.ppf(level))
    return FamilyTest(family=fam.name, sigma2=sigma2, statistic=float(stat), dof=dof,
                      dof2=dof2, threshold=thr, p_value=float(dist.sf(stat)), level=level,
                      reject=bool(stat > thr), objective_family=wf, objective_independent=wi)
