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

Numerics (clock origin, conditioning)
------------------------------------
Estimates do not depend on the clock's origin. Every fit works in per-object centred
times: object j's line is first written as its position at its own weighted mean time
T_j and its velocity, from the centred moments Σw, Σw(t − T_j)², Σw(t − T_j)(y − ȳ_j);
the paper's sums (8)-(9), (12)-(13) are those moments recombined without the cancellation
that loses (|t − epoch| / spread)² digits (POSIX times: 14 of 16). The start at ``epoch``
is obtained last, as the extrapolation ``p_j − (T_j − epoch)·V_j``, and Ψ is transformed
with it. Every answer, closed form or generic, ends in a re-check against the original
problem: the exact distance to the least-squares optimum (one Newton step of the
quadratic, Ψ·∇W, computed in the centred coordinates) relative to the size of each
parameter (or its standard deviation if larger), the "stationarity" residual; with
:func:`optmodels.core.verified_status` (closed forms) or :func:`solve`'s stricter rule.
Data whose float64 times cannot resolve an object's spread (``eps·|t| / std(t)`` above
1e-3) are refused as numerically singular; above 1e-6, and when the epoch is so far from
the data that the reported start cannot carry the line to 1 % of its standard deviation
(``eps·|V_j (T_j − epoch)| ·√Σw > 0.01``), the status is downgraded to
OPTIMAL_INACCURATE; beyond one standard deviation ``epoch`` is refused.

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
    as_choice,
    as_count,
    as_finite_array,
    as_number,
    as_positive,
    as_probability,
    timed,
    verified_status,
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


#: Relative violation (equalities, stationarity) above which a solver's claimed optimum
#: is downgraded by :func:`solve`: OPTIMAL → OPTIMAL_INACCURATE, and OPTIMAL_INACCURATE →
#: ERROR (never returned as a solution). Above REJECT_TOL a claimed OPTIMAL becomes ERROR
#: too. The closed forms use :func:`optmodels.core.verified_status` (same thresholds).
VERIFY_TOL = 1e-6
REJECT_TOL = 1e-3

#: float64 relative precision.
EPS = float(np.finfo(float).eps)

#: Time resolution ``eps·max|t_j| / std(t_j)`` of an object's float64 times (the relative
#: precision to which their spread, hence the velocity, is carried): above
#: TIME_RESOLUTION_WARN the status is at best OPTIMAL_INACCURATE, above
#: TIME_RESOLUTION_MAX the data are refused as numerically singular.
TIME_RESOLUTION_WARN = 1e-6
TIME_RESOLUTION_MAX = 1e-3

#: Rounding of the reported start at ``epoch`` in units of the standard deviation of the
#: object's position at its data, ``eps·|V_j (T_j − epoch)|·√Σw``, counted when the epoch
#: is more than 10 spans from the data: above EXTRAPOLATION_WARN the status is at best
#: OPTIMAL_INACCURATE, above EXTRAPOLATION_MAX ``epoch`` is refused (the reported start
#: and velocity no longer reproduce the fitted line at the data).
EXTRAPOLATION_WARN = 1e-2
EXTRAPOLATION_MAX = 1.0


# --------------------------------------------------------------------------- data
@dataclass(frozen=True, eq=False)
class TrajectoryData:
    """Classified measurements of ``Q`` objects moving along lines.

    Parameters
    ----------
    times : sequence of Q 1-D arrays
        Measurement times of each object (s), on any clock (POSIX time is fine: the fits
        work in centred times); unequal lengths and times are allowed, the order within an
        object is free.
    values : sequence of Q arrays, (N_j,) or (N_j, d)
        Measured coordinate(s) (m); ``d = 2`` or ``3`` coordinates share the dependence
        (each coordinate is its own least-squares problem with the same design matrix).
    sigma2 : float or sequence of Q arrays, default 1.0
        Error variance (m²): one number for all measurements (the paper's σ²), or per
        measurement ((N_j,) or (N_j, d)) for weighted least squares; in [1e-100, 1e100].
    epoch : float, default 0.0
        The instant (s, same clock as ``times``) at which ``start`` is defined: the model is
        ``y = start + velocity * (t - epoch)``. The paper uses ``epoch = 0``; for a family
        with a common start it is the common instant (launch, release), part of the
        hypothesis. Velocities of families without a shared start do not depend on it.

    Raises
    ------
    ProblemError
        No objects, mismatched lengths, an object with fewer than 2 distinct times,
        NaN/inf or complex entries, magnitudes above 1e100, non-positive variances,
        inconsistent ``d``, a non-numeric ``epoch`` or ``sigma2``.
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
    #: the times as given (s), stacked like ``t``; ``t`` is ``raw_t - epoch``
    raw_t: FloatArray = field(init=False, repr=False)
    _cache: dict[str, Any] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        where = "trajectories.TrajectoryData"
        if isinstance(self.times, np.ndarray) and self.times.ndim == 1:
            raise ProblemError(f"{where} times: expected a sequence of per-object arrays, "
                               "got one array")
        for name, seq in (("times", self.times), ("values", self.values)):
            if isinstance(seq, str | bytes) or not hasattr(seq, "__len__"):
                raise ProblemError(f"{where} {name}: expected a sequence of per-object "
                                   f"arrays, got {type(seq).__name__}")
        q = len(self.times)
        if q == 0:
            raise ProblemError(f"{where} times: no objects (Q = 0)")
        if len(self.values) != q:
            raise ProblemError(f"{where} values: {len(self.values)} objects, times has {q}")
        epoch = as_number(f"{where} epoch", self.epoch, low=-MAX_MAGNITUDE, high=MAX_MAGNITUDE)
        object.__setattr__(self, "epoch", epoch)
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
            ts.append(t)
            ys.append(y.reshape(t.size, -1))
        if len(dims) != 1:
            raise ProblemError(f"values: objects have different numbers of coordinates {dims}")
        vector = any(np.ndim(v) == 2 for v in self.values)
        d = dims.pop()
        scalar = None
        s2_in = self.sigma2
        if isinstance(s2_in, str | bytes | bool | np.bool_) or np.isscalar(s2_in) or (
            isinstance(s2_in, np.ndarray) and s2_in.ndim == 0
        ):
            s2 = as_number(f"{where} sigma2", s2_in)
            if not 1 / MAX_MAGNITUDE <= s2 <= MAX_MAGNITUDE:
                raise ProblemError(f"{where} sigma2: must be positive, in [1e-100, 1e100] "
                                   f"(its inverse is a usable weight), got {s2:g}")
            scalar = s2
            ws = [np.full((t.size, d), 1.0 / s2) for t in ts]
        else:
            if not hasattr(s2_in, "__len__") or len(s2_in) != q:
                n_s2 = len(s2_in) if hasattr(s2_in, "__len__") else type(s2_in).__name__
                raise ProblemError(f"sigma2: {n_s2} objects, times has {q}")
            for j in range(q):
                s2 = as_finite_array(f"sigma2[{j}]", s2_in[j], ndim=(0, 1, 2))
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
        raw = np.concatenate(ts)
        object.__setattr__(self, "raw_t", raw)
        object.__setattr__(self, "t", raw - epoch)
        object.__setattr__(self, "y", np.concatenate(ys))
        object.__setattr__(self, "w", np.concatenate(ws))
        object.__setattr__(self, "obj", np.repeat(np.arange(q), [t.size for t in ts]))
        object.__setattr__(self, "counts", np.array([t.size for t in ts]))
        object.__setattr__(self, "offsets", np.concatenate([[0], np.cumsum(self.counts)[:-1]]))
        object.__setattr__(self, "vector", vector)
        object.__setattr__(self, "scalar_sigma2", scalar)
        object.__setattr__(self, "_cache", {})

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
        q = as_count("trajectories.Family.diverging q", q, minimum=1)
        return cls("diverging", q, (tuple(range(q)),), tuple((j,) for j in range(q)))

    @classmethod
    def parallel(cls, q: int) -> Family:
        """All objects share the velocity (10)-(11)."""
        q = as_count("trajectories.Family.parallel q", q, minimum=1)
        return cls("parallel", q, tuple((j,) for j in range(q)), (tuple(range(q)),))

    @classmethod
    def independent(cls, q: int) -> Family:
        """Nothing shared: Q separate lines."""
        q = as_count("trajectories.Family.independent q", q, minimum=1)
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
            An index out of range or not a whole number, an object in two groups of the
            same kind, a ``name`` that is not a string.
        """
        q = as_count("trajectories.Family.custom q", q, minimum=1)
        if not isinstance(name, str):
            raise ProblemError(f"trajectories.Family.custom name: expected a string, got "
                               f"{type(name).__name__}")
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
    if isinstance(groups, str | bytes) or not hasattr(groups, "__iter__"):
        raise ProblemError(f"{name}: expected a list of groups of object indices")
    for k, grp in enumerate(groups):
        if isinstance(grp, str | bytes) or not hasattr(grp, "__iter__"):
            raise ProblemError(f"{name}[{k}]: expected a group of object indices, got {grp!r:.40}")
        g = tuple(as_count(f"{name}[{k}]", i) for i in grp)
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
        for kind, groups in (("start_groups", family.start_groups),
                             ("velocity_groups", family.velocity_groups)):
            flat = sorted(i for g in groups for i in g)
            if flat != list(range(q)) or any(len(g) == 0 for g in groups):
                raise ProblemError(f"family: {kind} {groups} is not a partition of the "
                                   f"{q} objects (build it with Family.custom)")
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
        Each object's start (at ``epoch``, m) and velocity (m/s).
    covariance : (R, R) or (d, R, R)
        Ψ (14): σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement variances; one per coordinate
        for vector values. With an epoch far from the data the start's variance is that
        of the extrapolation, σ²(start) ≈ (T_j − epoch)²·σ²(velocity).
    objective : float
        Σ w (y − ŷ)², the χ² statistic of the fit (with σ² known), on ``dof`` degrees of
        freedom, evaluated at the returned lines in centred times.
    dof : int
        (Σ N_j − R)·d.
    residuals : dict
        ``shared_start``, ``shared_velocity`` (relative violation of the family's
        equalities by the lines found) and ``stationarity`` (relative distance to the exact
        least-squares optimum, see the module notes).
    info : dict
        ``time_resolution`` (largest ``eps·|t|/std(t)`` of an object) and
        ``extrapolation`` (rounding of the reported starts in standard deviations of the
        lines at the data), the quantities behind a downgraded status.
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
        with np.errstate(invalid="ignore"):
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


# --------------------------------------------------------------------------- centred moments
@dataclass(frozen=True)
class _Stats:
    """Per-object centred moments, (Q, d) per coordinate (the weights may differ).

    ``T_j`` is object j's weighted mean time (not stored: ``tbar + tcorr``, a float and a
    small correction), ``u = T_j − epoch`` the lever from the epoch, ``p`` and ``vhat``
    object j's own least-squares line (position at T_j, velocity), ``m2 = Σw(t − T_j)²``,
    ``tau`` (n, d) the centred times t − T_j and ``ry`` (n, d) the values minus ``p``.
    """

    s0: FloatArray
    tbar: FloatArray
    tcorr: FloatArray
    u: FloatArray
    m2: FloatArray
    p: FloatArray
    vhat: FloatArray
    tau: FloatArray
    ry: FloatArray
    span: FloatArray
    kappa: FloatArray


def _per(data: TrajectoryData, x: FloatArray) -> FloatArray:
    """Σ over each object's measurements (rows are stored object by object): (Q, ...)."""
    return np.add.reduceat(x, data.offsets, axis=0)


def _stats(data: TrajectoryData) -> _Stats:
    """The centred moments of ``data`` (cached on it).

    Raises
    ------
    ProblemError
        An object's times are not resolved by float64 at their magnitude (the design is
        numerically singular), or the moments overflow/underflow float64.
    """
    cached = data._cache.get("stats")
    if cached is not None:
        return cached
    obj, w, y = data.obj, data.w, data.y
    t = data.raw_t
    with np.errstate(all="ignore"):
        s0 = _per(data, w)
        t0 = t[data.offsets]
        tbar = t0[:, None] + _per(data, w * (t - t0[obj])[:, None]) / s0
        taup = t[:, None] - tbar[obj]
        tcorr = _per(data, w * taup) / s0
        tau = taup - tcorr[obj]
        y0 = y[data.offsets]
        ybar = y0 + _per(data, w * (y - y0[obj])) / s0
        ryp = y - ybar[obj]
        ycorr = _per(data, w * ryp) / s0
        p = ybar + ycorr
        ry = ryp - ycorr[obj]
        m2 = _per(data, w * tau * tau)
        sxy = _per(data, w * tau * ry)
        vhat = sxy / m2
        u = (tbar - data.epoch) + tcorr
        tmax = np.maximum.reduceat(np.abs(t), data.offsets)
        span = np.maximum.reduceat(t, data.offsets) - np.minimum.reduceat(t, data.offsets)
        kappa = EPS * tmax[:, None] / np.sqrt(m2 / s0)
    arrays = (s0, tbar, tcorr, u, m2, p, vhat, tau, ry, kappa)
    if not all(np.all(np.isfinite(a)) for a in arrays) or np.any(
            m2 < np.finfo(float).tiny * 1e16 * s0):
        raise ProblemError(
            "times/values: the least-squares moments over- or underflow float64 (times "
            f"spread down to {np.min(span):.3g} s, weights {np.min(w):.3g}..{np.max(w):.3g}, "
            f"|values| up to {np.max(np.abs(y)):.3g}); change units")
    worst = int(np.argmax(np.max(kappa, axis=1)))
    if float(np.max(kappa)) > TIME_RESOLUTION_MAX:
        raise ProblemError(
            f"times[{worst}]: AᵀA is numerically singular at the precision of the times: "
            f"object {worst}'s times spread over {span[worst]:.3g} s at |t| up to "
            f"{float(tmax[worst]):.3g} s, which float64 resolves only to "
            f"{float(np.max(kappa[worst])):.2g} relative; measure time from an origin nearer "
            "the data")
    st = _Stats(s0, tbar, tcorr, u, m2, p, vhat, tau, ry, span, kappa)
    data._cache["stats"] = st
    return st


# --------------------------------------------------------------------------- the fits
@dataclass
class _Fit:
    """θ (R, d) and Ψ (d, R, R) of a family, with what the Newton re-check needs."""

    theta: FloatArray
    cov: FloatArray
    kind: str
    ctx: dict[str, Any] = field(default_factory=dict)


def _kind(fam: Family) -> str:
    """The paper's family this one is (by structure, whatever its name), or "custom"."""
    q = fam.n_objects
    for name in FAMILIES:
        ref = resolve_family(name, q)  # type: ignore[arg-type]
        if (fam.start_groups, fam.velocity_groups) == (ref.start_groups, ref.velocity_groups):
            return name
    return "custom"


def _fit(data: TrajectoryData, fam: Family, *, printed: bool = False) -> _Fit:
    """The family's least-squares estimate and Ψ along the paper's route (or the generic
    one for a custom family), in centred moments."""
    key = ("fit", fam.start_groups, fam.velocity_groups, printed)
    cached = data._cache.get(key)
    if cached is not None:
        return cached
    st = _stats(data)
    kind = _kind(fam)
    with np.errstate(all="ignore"):
        if kind == "diverging":
            fit = _diverging(st)
        elif kind == "parallel":
            fit = _parallel(st, printed=printed)
        elif kind == "independent":
            fit = _independent(st)
        else:
            fit = _generic(st, fam)
    if not (np.all(np.isfinite(fit.theta)) and np.all(np.isfinite(fit.cov))):
        raise ProblemError("family: the data cannot identify this family (the least-squares "
                           "sums over- or underflow float64); change units")
    data._cache[key] = fit
    return fit


def _diverging(st: _Stats) -> _Fit:
    """(8)-(9) and Ψ via the Schur complement on y0.

    With B_j = Σw(t − epoch) = N_j u_j and C_j = Σw(t − epoch)² = N_j u_j² + M2_j
    (N_j = Σw, M2_j = Σw(t − T_j)², u_j = T_j − epoch), the printed quotient is evaluated
    as E − B_C = Σ_j N_jM2_j/C_j and D − A_C = Σ_j (N_jM2_j/C_j)·(ȳ_j − u_jV̂_j): y0 is the
    weighted mean of each object's own line extrapolated to the epoch, no cancellation.
    """
    s0, m2, u = st.s0, st.m2, st.u
    c = s0 * u * u + m2                          # C_j
    k = s0 * m2 / c                              # N_j − B_j²/C_j
    z = st.p - u * st.vhat                       # object j's own start at the epoch
    kk = k.sum(axis=0)                           # E − B_C
    y0 = (k * z).sum(axis=0) / kk                # (8)
    g = s0 * u / c                               # B_j/C_j
    v = st.vhat + g * (z - y0)                   # (9): (A_j − y0 B_j)/C_j
    q, d = s0.shape
    var0 = 1.0 / kk                              # Var(y0): Schur complement
    cov = np.zeros((d, q + 1, q + 1))
    for i in range(d):
        cov[i, 0, 0] = var0[i]
        cov[i, 0, 1:] = cov[i, 1:, 0] = -g[:, i] * var0[i]
        cov[i, 1:, 1:] = np.diag(1.0 / c[:, i]) + np.outer(g[:, i], g[:, i]) * var0[i]
    return _Fit(np.vstack([y0, v]), cov, "diverging",
                {"c": c, "g": g, "var0": var0, "lam": (k * (z - y0) ** 2).sum()})


def _parallel(st: _Stats, *, printed: bool = False) -> _Fit:
    """(12)-(13) and Ψ via the Schur complement on V.

    D − A_N = Σ_j Σw(t − T_j)(y − ȳ_j) and E − B_N = Σ_j M2_j (E = ΣΣ w(t − epoch)²);
    printed, E = ΣΣ w(t − epoch), so E − B_N = Σ_j N_j u_j (1 − u_j).
    """
    s0, m2, u = st.s0, st.m2, st.u
    num = (m2 * st.vhat).sum(axis=0)             # D − A_N
    den = (s0 * u * (1.0 - u)).sum(axis=0) if printed else m2.sum(axis=0)
    v = num / den
    y0 = st.p - u * v                            # (12): (A_j − V B_j)/N_j
    q, d = s0.shape
    varv = 1.0 / m2.sum(axis=0)
    cov = np.zeros((d, q + 1, q + 1))
    for i in range(d):
        cov[i, q, q] = varv[i]
        cov[i, q, :q] = cov[i, :q, q] = -u[:, i] * varv[i]
        cov[i, :q, :q] = np.diag(1.0 / s0[:, i]) + np.outer(u[:, i], u[:, i]) * varv[i]
    return _Fit(np.vstack([y0, v]), cov, "parallel",
                {"lam": (m2 * (st.vhat - v) ** 2).sum()})


def _independent(st: _Stats) -> _Fit:
    """Single-line least squares per object, moved from T_j to the epoch."""
    s0, m2, u = st.s0, st.m2, st.u
    v = st.vhat
    y0 = st.p - u * v
    q, d = s0.shape
    cov = np.zeros((d, 2 * q, 2 * q))
    idx = np.arange(q)
    for i in range(d):
        cov[i, idx, idx] = 1.0 / s0[:, i] + u[:, i] ** 2 / m2[:, i]
        cov[i, q + idx, q + idx] = 1.0 / m2[:, i]
        cov[i, idx, q + idx] = cov[i, q + idx, idx] = -u[:, i] / m2[:, i]
    return _Fit(np.vstack([y0, v]), cov, "independent", {"lam": 0.0})


def _anchors(st: _Stats, fam: Family, k: int) -> tuple[FloatArray, FloatArray]:
    """Well-conditioned parameters for coordinate k: a start group whose objects share one
    velocity is parametrised by its position at the group's mean time (lever ``b_j`` of
    each object from it, ``a_g`` from the epoch to it); any other start group keeps its
    start at the epoch (lever ``u_j``, ``a_g = 0``): that constraint is tied to the epoch.
    Returns (lever (Q,), a (G,))."""
    lever = st.u[:, k].copy()
    a = np.zeros(len(fam.start_groups))
    vi = fam.velocity_index
    for gi, g in enumerate(fam.start_groups):
        members = list(g)
        if len({int(vi[j]) for j in members}) != 1:
            continue
        r = members[0]
        dlt = (st.tbar[members, k] - st.tbar[r, k]) + (st.tcorr[members, k] - st.tcorr[r, k])
        beta = float(np.sum(st.s0[members, k] * dlt) / np.sum(st.s0[members, k]))
        lever[members] = dlt - beta
        a[gi] = st.u[r, k] + beta
    return lever, a


def _generic(st: _Stats, fam: Family) -> _Fit:
    """Normal equations (3) of any family, solved by QR of the 2Q-row reduction
    (√N_j (ȳ_j − p_j), √M2_j (V̂_j − V_j)) in the anchored parameters of :func:`_anchors`,
    then moved to θ (starts at the epoch). Refuses a numerically singular design."""
    q, d = st.s0.shape
    r = fam.n_params
    si, vi = fam.start_index, fam.velocity_index
    theta = np.empty((r, d))
    cov = np.empty((d, r, r))
    ctx: dict[str, Any] = {"psic": [], "jac": [], "lever": []}
    rows = np.arange(q)
    for k in range(d):
        lever, a = _anchors(st, fam, k)
        g = np.zeros((2 * q, r))
        sq0, sqm = np.sqrt(st.s0[:, k]), np.sqrt(st.m2[:, k])
        g[rows, si] = sq0
        g[rows, vi] = sq0 * lever
        g[q + rows, vi] = sqm
        rhs = np.concatenate([sq0 * st.p[:, k], sqm * st.vhat[:, k]])
        cs = np.sqrt(np.sum(g * g, axis=0))
        qm, rm = np.linalg.qr(g / cs)
        sv = np.linalg.svd(rm, compute_uv=False)
        cond = sv[0] / sv[-1] if sv[-1] > 0 else np.inf
        if not cond < 1e13:
            raise ProblemError(
                f"family: AᵀA is singular (condition {cond:.2g} of the scaled design); the "
                "data cannot identify this family -- are the times far from the epoch?")
        rinv = linalg.solve_triangular(rm, np.eye(r))
        thc = (rinv @ (qm.T @ rhs)) / cs
        psic = (rinv @ rinv.T) / np.outer(cs, cs)
        jac = np.eye(r)
        for gi, grp in enumerate(fam.start_groups):
            if a[gi] != 0.0:
                jac[gi, vi[grp[0]]] = -a[gi]
        theta[:, k] = jac @ thc
        cov[k] = jac @ psic @ jac.T
        ctx["psic"].append(psic)
        ctx["jac"].append(jac)
        ctx["lever"].append(lever)
    return _Fit(theta, cov, "custom", ctx)


# --------------------------------------------------------------------------- re-check
def _lines(st: _Stats, fam: Family, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each object's line (position at T_j, velocity) implied by θ, (Q, d) each."""
    v = theta[fam.velocity_index]
    return theta[fam.start_index] + v * st.u, v


def _newton(st: _Stats, fam: Family, fit: _Fit, gp: FloatArray, gv: FloatArray
            ) -> FloatArray:
    """Ψ·∇(−W/2) at a point whose per-object gradients are ``gp = Σw r``,
    ``gv = Σw(t − T_j) r``: the exact step to the family's least-squares optimum (W is
    quadratic), computed without forming the ill-conditioned products of θ's basis."""
    si, vi = fam.start_index, fam.velocity_index
    s0, m2, u = st.s0, st.m2, st.u
    if fit.kind in ("independent", "parallel"):
        dp = gp / s0
        dv = gv / m2 if fit.kind == "independent" else (gv.sum(axis=0) / m2.sum(axis=0))[None]
        dvj = dv[vi - len(fam.start_groups)]
        return np.vstack([dp - u * dvj, dv])
    if fit.kind == "diverging":
        c, g, var0 = fit.ctx["c"], fit.ctx["g"], fit.ctx["var0"]
        ds = var0 * np.sum(gp * m2 / c - g * gv, axis=0)
        dv = (gv + u * gp) / c - g * ds
        return np.vstack([ds, dv])
    out = np.empty((fam.n_params, st.s0.shape[1]))
    for k in range(out.shape[1]):
        lever = fit.ctx["lever"][k]
        gc = np.zeros(fam.n_params)
        np.add.at(gc, si, gp[:, k])
        np.add.at(gc, vi, gv[:, k] + lever * gp[:, k])
        out[:, k] = fit.ctx["jac"][k] @ (fit.ctx["psic"][k] @ gc)
    return out


def _recheck(data: TrajectoryData, fam: Family, fit: _Fit, theta: FloatArray
             ) -> tuple[float, float, dict[str, Any]]:
    """Objective, stationarity and diagnostics of θ against the original problem, in
    centred times. Stationarity: max over θ of |Δθ_k| / max(max |θ| of its kind, std_k),
    Δθ the exact step to the optimum."""
    st = _stats(data)
    p, v = _lines(st, fam, theta)
    w = data.w
    with np.errstate(all="ignore"):
        r = st.ry + (st.p - p)[data.obj] - v[data.obj] * st.tau
        obj = float(np.sum(w * r * r))
        gp, gv = _per(data, w * r), _per(data, w * r * st.tau)
        step = _newton(st, fam, fit, gp, gv)
        std = np.sqrt(np.diagonal(fit.cov, axis1=1, axis2=2)).T      # (R, d)
        ns = len(fam.start_groups)
        size = np.empty_like(theta)
        size[:ns] = np.max(np.abs(theta[:ns]))
        size[ns:] = np.max(np.abs(theta[ns:]))
        stat = float(np.max(np.abs(step) / np.maximum(size, std)))
        far = np.abs(st.u) > 10.0 * st.span[:, None]
        xr = np.where(far, EPS * np.abs(v * st.u) * np.sqrt(st.s0), 0.0)
    if not (np.isfinite(stat) and np.isfinite(obj)):
        stat = float("inf")
    diag = {"time_resolution": float(np.max(st.kappa)), "extrapolation": float(np.max(xr)),
            "extrapolation_object": int(np.argmax(np.max(xr, axis=1)))}
    return obj, stat, diag


def _downgrade(data: TrajectoryData, status: Status, diag: dict[str, Any]
               ) -> tuple[Status, str]:
    """OPTIMAL → OPTIMAL_INACCURATE for coarse times or a far epoch; refuse an epoch whose
    start cannot carry the line."""
    notes = []
    if diag["extrapolation"] > EXTRAPOLATION_MAX:
        j = diag["extrapolation_object"]
        raise ProblemError(
            f"trajectories epoch: {data.epoch:.6g} s is so far from the data that the start "
            f"there cannot carry the fitted line: rounding the reported start of object {j} "
            f"moves its line at the data by {diag['extrapolation']:.3g} standard deviations; "
            "use an epoch nearer the data")
    if diag["extrapolation"] > EXTRAPOLATION_WARN:
        notes.append(f"epoch {data.epoch:.6g} s is far from the data: the reported starts are "
                     f"extrapolations whose rounding moves the lines at the data by up to "
                     f"{diag['extrapolation']:.2g} standard deviations")
    if diag["time_resolution"] > TIME_RESOLUTION_WARN:
        notes.append(f"float64 resolves the times' spread only to "
                     f"{diag['time_resolution']:.2g} relative (|t| large against the spread)")
    if notes and status is Status.OPTIMAL:
        status = Status.OPTIMAL_INACCURATE
    return status, "; ".join(notes)


def _package(data: TrajectoryData, fam: Family, fit: _Fit, theta: FloatArray,
             residuals: dict[str, float], objective: float, common: dict[str, Any]
             ) -> TrajectorySolution:
    cov = fit.cov
    return TrajectorySolution(
        objective=objective, residuals=residuals, family=fam, theta=_shape(data, theta),
        start=_shape(data, theta[fam.start_index]),
        velocity=_shape(data, theta[fam.velocity_index]),
        covariance=cov if data.vector else cov[0],
        dof=(data.n_measurements - fam.n_params) * data.dim, _data=data, **common)


def _nan_solution(data: TrajectoryData, fam: Family, fit: _Fit, residuals: dict[str, float],
                  common: dict[str, Any], rejected: FloatArray | None) -> TrajectorySolution:
    nan = np.full((fam.n_params, data.dim), np.nan)
    sol = _package(data, fam, fit, nan, residuals, float("nan"), common)
    sol.status = Status.ERROR if common["status"].ok else common["status"]
    if rejected is not None:
        sol.info["rejected_theta"] = rejected
    return sol


# --------------------------------------------------------------------------- original form
def _per_object(data: TrajectoryData, a: ArrayLike, name: str) -> FloatArray:
    arr = as_finite_array(name, a)
    if arr.size != data.n_objects * data.dim:
        raise ProblemError(f"{name}: expected ({data.n_objects}, {data.dim}), got {arr.shape}")
    return arr.reshape(data.n_objects, data.dim)


def predict(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> FloatArray:
    """Model values ŷ = start_j + velocity_j (t − epoch) at the data's times, (Σ N_j, d)."""
    s = _per_object(data, start, "trajectories.predict start")
    v = _per_object(data, velocity, "trajectories.predict velocity")
    return s[data.obj] + v[data.obj] * data.t[:, None]


def objective(data: TrajectoryData, start: ArrayLike, velocity: ArrayLike) -> float:
    """W (4), (10) of the Q lines, weighted: Σ w (y − y0_j − V_j (t − epoch))², evaluated
    in centred times (y − p_j − V_j (t − T_j), p_j = y0_j + V_j (T_j − epoch))."""
    s = _per_object(data, start, "trajectories.objective start")
    v = _per_object(data, velocity, "trajectories.objective velocity")
    st = _stats(data)
    p = s + v * st.u
    r = st.ry + (st.p - p)[data.obj] - v[data.obj] * st.tau
    return float(np.sum(data.w * r * r))


def constraint_residuals(data: TrajectoryData, family: FamilyName | Family,
                         start: ArrayLike, velocity: ArrayLike) -> dict[str, float]:
    """Largest violation of the family's equalities (y0_j = y0_k, V_j = V_k in a group),
    relative to the size of the parameters."""
    fam = resolve_family(family, data.n_objects)
    s = _per_object(data, start, "trajectories.constraint_residuals start")
    v = _per_object(data, velocity, "trajectories.constraint_residuals velocity")
    out = {}
    for key, arr, groups in (("start", s, fam.start_groups), ("velocity", v, fam.velocity_groups)):
        worst = 0.0
        scale = max(float(np.max(np.abs(arr))), 1.0)
        for g in groups:
            if len(g) > 1:
                worst = max(worst, float(np.max(np.abs(arr[list(g)] - arr[g[0]]))) / scale)
        out[f"shared_{key}"] = worst
    return out


def _line_residuals(st: _Stats, fam: Family, p: FloatArray, v: FloatArray, u: FloatArray,
                    dt: FloatArray, std: FloatArray) -> dict[str, float]:
    """Violation of the family's equalities by Q lines given at reference times
    (position ``p`` at T0_j, velocity ``v``; ``u = T0_j − epoch``, ``dt`` (Q,) T0_j − T0_0):
    velocities relative to max(|V|, σ_V); starts of objects that also share a velocity as
    positions at the data (p_j − p_k = (T0_j − T0_k)V), relative to max(|p|, σ_p); other
    shared starts at the epoch, relative to max(|y0|, σ_y0)."""
    ns = len(fam.start_groups)
    vi = fam.velocity_index
    sv = max(float(np.max(np.abs(v))), float(np.max(std[ns:])))
    sp_ = max(float(np.max(np.abs(p))), float(np.max(1.0 / np.sqrt(st.s0))))
    s = p - v * u
    ss = max(float(np.max(np.abs(s))), float(np.max(std[:ns])))
    wv = max((float(np.max(np.abs(v[list(g)] - v[g[0]]))) for g in fam.velocity_groups
              if len(g) > 1), default=0.0) / sv
    ws = 0.0
    for g in fam.start_groups:
        r = g[0]
        for j in g[1:]:
            if vi[j] == vi[r]:
                gap = np.abs(p[j] - p[r] - (dt[j] - dt[r]) * v[r]) / sp_
            else:
                gap = np.abs(s[j] - s[r]) / ss
            ws = max(ws, float(np.max(gap)))
    return {"shared_start": ws, "shared_velocity": wv}


def design_matrix(data: TrajectoryData, family: FamilyName | Family) -> sp.csr_matrix:
    """The design matrix A (2) of the family, rows object by object: (5) for diverging,
    (11) for parallel (returned as A, the paper prints Aᵀ). Sparse, Σ N_j × R, velocity
    columns t − epoch (s)."""
    fam = resolve_family(family, data.n_objects)
    n = data.n_measurements
    rows = np.concatenate([np.arange(n), np.arange(n)])
    cols = np.concatenate([fam.start_index[data.obj], fam.velocity_index[data.obj]])
    vals = np.concatenate([np.ones(n), data.t])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, fam.n_params))


def covariance(data: TrajectoryData, family: FamilyName | Family) -> FloatArray:
    """Ψ (14): σ²(AᵀA)⁻¹, or (AᵀWA)⁻¹ with per-measurement variances, with A the design
    matrix, computed from centred moments (Schur complements of the paper's families, QR of
    the reduced design for a custom one). (R, R) for scalar values, (d, R, R) for vector
    values.

    Raises
    ------
    ProblemError
        The design is numerically singular (see :class:`TrajectoryData`).
    """
    fam = resolve_family(family, data.n_objects)
    cov = _fit(data, fam).cov
    return cov.copy() if data.vector else cov[0].copy()


# --------------------------------------------------------------------------- generic solve
def _cvxpy_problem(data: TrajectoryData, fam: Family, formulation: str
                   ) -> tuple[cp.Problem, Any]:
    """The CVXPY model in centred, scaled units, and a function mapping the solved
    variables to (θ (R, d), lines (p, v, u, dt) or None).

    Each object's line is parametrised by its position at its own mean time T0_j
    (coordinate 0's weights) and its velocity -- the same lines, so the same problem; the
    shared-start equalities are written at the epoch (p_j − u_jV_j = p_k − u_kV_k), or as
    p_j − p_k = (T0_j − T0_k)V when the two objects also share the velocity. Times are
    divided by ts = max |t − T0_j|, values shifted by each object's mean and divided by
    their spread, weights by their mean, objective by N d: O(1) numbers for the solvers'
    tolerances (first-order solvers such as OSQP/SCS need it)."""
    st = _stats(data)
    n, q, d = data.n_measurements, data.n_objects, data.dim
    si, vi = fam.start_index, fam.velocity_index
    tau0 = st.tau[:, 0]
    u0 = st.u[:, 0]
    dt0 = (st.tbar[:, 0] - st.tbar[0, 0]) + (st.tcorr[:, 0] - st.tcorr[0, 0])
    sw = np.sqrt(data.w / np.mean(data.w) / (n * d))
    ts = float(np.max(np.abs(tau0))) or 1.0
    if formulation == "constrained":
        off = st.p                                          # (Q, d)
        yo = data.y - off[data.obj]
        ys = max(float(np.max(np.abs(yo))), float(np.max(np.abs(off - off[0]))),
                 float(np.max(np.abs(st.vhat))) * ts) or 1.0
        sel0 = sp.csr_matrix((np.ones(n), (np.arange(n), data.obj)), shape=(n, q))
        sel1 = sp.csr_matrix((tau0 / ts, (np.arange(n), data.obj)), shape=(n, q))
        pv = cp.Variable((q, d), name="position")
        v = cp.Variable((q, d), name="velocity")
        cons = []
        for g in fam.velocity_groups:
            if len(g) > 1:
                cons.append(v[list(g[1:])] == np.ones((len(g) - 1, 1)) @ v[[g[0]]])
        for g in fam.start_groups:
            r = g[0]
            for j in g[1:]:
                const = (off[j] - off[r]) / ys
                if vi[j] == vi[r]:
                    cons.append(pv[j] - pv[r] + const == ((dt0[j] - dt0[r]) / ts) * v[r])
                else:
                    cons.append(pv[j] - pv[r] + const == (u0[j] / ts) * v[j]
                                - (u0[r] / ts) * v[r])
        obj = cp.sum_squares(cp.multiply(sw, yo / ys - sel0 @ pv - sel1 @ v))

        def back_c() -> tuple[FloatArray, Any]:
            pl = np.asarray(pv.value) * ys + off
            vl = np.asarray(v.value) * ys / ts
            vel = np.vstack([vl[list(g)].mean(axis=0) for g in fam.velocity_groups])
            vj = vel[vi - len(fam.start_groups)]
            s = pl - vj * u0[:, None]
            theta = np.vstack([[s[list(g)].mean(axis=0) for g in fam.start_groups], vel])
            return theta, (pl, vl, u0[:, None], dt0)

        return cp.Problem(cp.Minimize(obj), cons), back_c
    if formulation == "reduced":
        # (1): the unconstrained least squares in θ, anchored parameters (see _anchors)
        lever, a = _anchors(st, fam, 0)
        col = lever[data.obj] + tau0
        tsr = float(np.max(np.abs(col))) or 1.0
        ns = len(fam.start_groups)
        grp_off = np.vstack([[np.mean(st.p[list(g)], axis=0)] for g in fam.start_groups])
        yo = data.y - grp_off[si[data.obj]]
        ys = float(np.max(np.abs(yo))) or 1.0
        rows = np.concatenate([np.arange(n), np.arange(n)])
        cols = np.concatenate([si[data.obj], vi[data.obj]])
        am = sp.csr_matrix((np.concatenate([np.ones(n), col / tsr]), (rows, cols)),
                           shape=(n, fam.n_params))
        th = cp.Variable((fam.n_params, d), name="theta")
        obj = cp.sum_squares(cp.multiply(sw, yo / ys - am @ th))

        def back_r() -> tuple[FloatArray, Any]:
            thc = np.asarray(th.value) * ys
            thc[ns:] /= tsr
            thc[:ns] += grp_off
            for gi, g in enumerate(fam.start_groups):
                if a[gi] != 0.0:
                    thc[gi] -= a[gi] * thc[vi[g[0]]]
            return thc, None

        return cp.Problem(cp.Minimize(obj)), back_r
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
        ``"constrained"``: the original problem -- ``Q`` lines (2Q·d variables, each line
        by its position at its object's mean time and its velocity) with the family's
        equality constraints; ``"reduced"``: (1) in θ with the design matrix A (starts of
        groups whose objects share a velocity taken at the group's mean time, then moved
        to the epoch).
    solver : str, optional
        Any installed CVXPY QP/conic solver; default Clarabel.
    **solver_options
        Passed to the solver, over :data:`SOLVER_DEFAULTS` (an option the solver rejects
        is a ProblemError).

    Returns
    -------
    TrajectorySolution
        ``covariance`` is Ψ (14) at the data's design; ``residuals`` are the equality
        violations of the solver's lines and the stationarity (relative distance to the
        exact optimum), re-computed in NumPy in centred times. A claimed optimum above
        :data:`VERIFY_TOL` becomes OPTIMAL_INACCURATE (≤ :data:`REJECT_TOL`) or ERROR; a
        failed solve keeps its status and carries NaN estimates.

    Raises
    ------
    ProblemError
        Bad arguments, a numerically singular design, an epoch too far from the data.
    """
    fam = resolve_family(family, data.n_objects)
    form = as_choice("trajectories.solve formulation", formulation, ("constrained", "reduced"))
    if solver is None:
        name = "CLARABEL"
    elif isinstance(solver, str):
        name = solver.upper()
    else:
        raise ProblemError(f"trajectories.solve solver: expected a solver name (str), got "
                           f"{type(solver).__name__}")
    opts = {**SOLVER_DEFAULTS.get(name, {}), **solver_options}
    with timed() as tb:
        fit = _fit(data, fam)
        prob, back = _cvxpy_problem(data, fam, form)
    res = solve_problem(prob, name, **opts)
    common = res.common()
    common["build_time"] += tb.elapsed
    common["method"] = f"{res.method} ({form})"
    first = prob.variables()[0]
    if not res.status.ok or first.value is None:
        return _nan_solution(data, fam, fit, {}, common, None)
    theta, lines = back()
    if not np.all(np.isfinite(theta)):
        common["message"] += "; the solver returned non-finite values"
        return _nan_solution(data, fam, fit, {}, common, None)
    obj, stat, diag = _recheck(data, fam, fit, theta)
    std = np.sqrt(np.diagonal(fit.cov, axis1=1, axis2=2)).T
    residuals = ({"shared_start": 0.0, "shared_velocity": 0.0} if lines is None
                 else _line_residuals(_stats(data), fam, *lines, std))
    residuals["stationarity"] = stat
    status = common["status"]
    worst_key = max(residuals, key=residuals.__getitem__)
    worst = residuals[worst_key]
    if not np.isfinite(worst) or worst > VERIFY_TOL:
        note = f"; verification failed: {worst_key} = {worst:.2e} > {VERIFY_TOL:g}"
        common["message"] += note
        if status is Status.OPTIMAL and worst <= REJECT_TOL:
            common["status"] = Status.OPTIMAL_INACCURATE
        else:
            return _nan_solution(data, fam, fit, residuals, common, theta)
    common["status"], note = _downgrade(data, common["status"], diag)
    if note:
        common["message"] += "; " + note
    sol = _package(data, fam, fit, theta, residuals, obj, common)
    sol.info.update(diag)
    if lines is not None:
        sol.info["lines"] = {"position": lines[0], "velocity": lines[1],
                             "at_time": (lines[2][:, 0] + data.epoch)}
    return sol


# --------------------------------------------------------------------------- closed forms
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

    Here t is ``t − epoch``. The differences D − A_C, E − B_C, D − A_N, E − B_N are
    evaluated from per-object centred moments (see the module notes), which is the same
    algebra without its cancellation. Ψ is computed along the same route (Schur complements
    of the block-diagonal part), so that it can be checked against the design matrix.

    The answer is re-checked against the original problem
    (:func:`optmodels.core.verified_status` on the equalities and the stationarity): an
    answer that cannot be trusted is OPTIMAL_INACCURATE, or ERROR with NaN estimates (the
    rejected θ in ``info["rejected_theta"]``). ``printed=True`` returns the misprinted (13)'s
    numbers with status ERROR: they are not the least-squares optimum.

    Raises
    ------
    ProblemError
        Bad arguments, a numerically singular design, an epoch too far from the data.
    """
    fam = resolve_family(family, data.n_objects)
    if not isinstance(printed, bool | np.bool_):
        raise ProblemError(f"trajectories.closed_form printed: expected True or False, got "
                           f"{printed!r:.40}")
    with timed() as tm:
        kind = _kind(fam)
        if printed and kind != "parallel":
            raise ProblemError("printed: only the parallel family (13) has a misprint")
        fit = _fit(data, fam, printed=bool(printed))
        ref = _fit(data, fam) if printed else fit
        obj, stat, diag = _recheck(data, fam, ref, fit.theta)
    residuals = {"shared_start": 0.0, "shared_velocity": 0.0, "stationarity": stat}
    message = {"diverging": "(8)-(9)", "parallel": "(12)-(13)",
               "independent": "single-line LSQ"}.get(kind, "normal equations (3)")
    status = verified_status(Status.OPTIMAL, stat)
    common: dict[str, Any] = {"status": status, "method": "closed_form",
                              "solve_time": tm.elapsed,
                              "message": message + (" as printed" if printed else "")}
    if status is Status.ERROR:
        common["message"] += (f"; verification failed: stationarity = {stat:.2e} > "
                              f"{REJECT_TOL:g}")
        if printed:
            sol = _package(data, fam, ref, fit.theta, residuals, obj, common)
            sol.info.update(diag)
            return sol
        sol = _nan_solution(data, fam, fit, residuals, common, fit.theta)
        sol.status = Status.ERROR
        sol.info.update(diag)
        return sol
    if status is Status.OPTIMAL_INACCURATE:
        common["message"] += f"; stationarity = {stat:.2e} > {VERIFY_TOL:g}"
    common["status"], note = _downgrade(data, status, diag)
    if note:
        common["message"] += "; " + note
    sol = _package(data, fam, fit, fit.theta, residuals, obj, common)
    sol.info.update(diag)
    return sol


# --------------------------------------------------------------------------- covariances
def independent_variances(n: int, dt: float = 1.0, sigma2: float = 1.0) -> tuple[float, float]:
    """Variances of a single line's (y0, V) from ``N`` equally spaced measurements
    ``t_i = (i − 1)·dt`` (the introduction): σ²·2(2N−1)/(N(N+1)) and σ²·12/(N(N²−1)dt²).

    The paper calls these "СКО" and omits σ²; they are variances (y0 at the first
    measurement)."""
    n = as_count("trajectories.independent_variances n", n, minimum=2)
    dt = as_positive("trajectories.independent_variances dt", dt)
    sigma2 = as_positive("trajectories.independent_variances sigma2", sigma2)
    return (sigma2 * 2 * (2 * n - 1) / (n * (n + 1)),
            sigma2 * 12 / (n * (n * n - 1) * dt * dt))


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
    where = "trajectories.paper_covariance"
    family = as_choice(f"{where} family", family, ("diverging", "parallel"))  # type: ignore
    n = as_count(f"{where} n", n, minimum=2)
    dt = as_positive(f"{where} dt", dt)
    sigma2 = as_positive(f"{where} sigma2", sigma2)
    if not isinstance(printed, bool | np.bool_):
        raise ProblemError(f"{where} printed: expected True or False, got {printed!r:.40}")
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
    q = as_count("trajectories.eta0 q", q, minimum=1)
    return 1.0 / q


def eta(n: int, q: int = 2) -> float:
    """The conclusions' ratio for the **unique** parameters (V_j of a diverging family,
    y0_j of a parallel one): Var(dependent LSQ) / Var(independent line), ``Q`` objects
    each measured at ``t_i = (i − 1)·ΔT``, ``i = 1..N`` (first measurement at the common
    start):

    η = 1 − r(1 − 1/Q),  r = (Σt)²/(N Σt²) = 3(N − 1)/(2(2N − 1));

    for Q = 2 this is the printed (5N − 1)/(4(2N − 1)) (0.7 at N = 3 → 0.625). A ratio
    of variances; the ratio of RMS errors is √η."""
    n = as_count("trajectories.eta n", n, minimum=2)
    q = as_count("trajectories.eta q", q, minimum=1)
    r = 3 * (n - 1) / (2 * (2 * n - 1))
    return 1.0 - r * (1.0 - 1.0 / q)


def variance_ratios(data: TrajectoryData, family: FamilyName | Family) -> dict[str, FloatArray]:
    """Var(start_j), Var(velocity_j) under the family divided by the same variances from
    object j's own independent line, for the data's actual times and variances: the
    general form of the conclusions' η and η0. Arrays (Q,) or (Q, d)."""
    fam = resolve_family(family, data.n_objects)
    q = data.n_objects
    dep = _fit(data, fam).cov
    ind = _fit(data, Family.independent(q)).cov
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
    the family is rejected at ``level``. ``message`` carries the fits' notes when one of
    them is OPTIMAL_INACCURATE.
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
    message: str = ""

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
    F(q d, (Σ N_j − 2Q) d). Λ is computed as the constraint penalty
    Σ_j Σw_j (ȳ_j − p_j)² + Σw(t − T_j)²(V̂_j − V_j)² (each object's own line against the
    family's), which equals the difference of the objectives without its cancellation.

    Raises
    ------
    ProblemError
        ``level`` not in (0, 1), ``sigma2`` not "known"/"estimated", an independent family
        (nothing to test), too few measurements to estimate σ², data on which the
        independent lines fit exactly (W_independent at the rounding level: σ² cannot be
        estimated and F is undefined), or a fit that fails its re-check.
    """
    level = as_probability("trajectories.family_test level", level, low_open=True,
                           high_open=True)
    mode = as_choice("trajectories.family_test sigma2", sigma2, ("known", "estimated"))
    fam = resolve_family(family, data.n_objects)
    if fam.n_constraints == 0:
        raise ProblemError("family: independent lines impose no constraint to test")
    fits = {}
    notes = []
    for key, f in (("family", fam), ("independent", Family.independent(data.n_objects))):
        sol = closed_form(data, f)
        if not sol.ok:
            raise ProblemError(f"family: the {key} fit fails its re-check ({sol.message}); "
                               "the test would be meaningless")
        if sol.status is not Status.OPTIMAL:
            notes.append(f"{key} fit {sol.status.value}: {sol.message}")
        fits[key] = sol
    wf, wi = fits["family"].objective, fits["independent"].objective
    lam = float(max(_fit(data, fam).ctx.get("lam", wf - wi), 0.0))
    if _kind(fam) == "custom":
        lam = _custom_penalty(data, fam)
    dof = fam.n_constraints * data.dim
    if mode == "known":
        stat, dist, dof2 = lam, stats.chi2(dof), None
    else:
        dof2 = (data.n_measurements - 2 * data.n_objects) * data.dim
        if dof2 <= 0:
            raise ProblemError("sigma2: estimating σ² needs more than 2 measurements on "
                               "some object (Σ N_j > 2Q)")
        st = _stats(data)
        resid_scale = float(np.sum(data.w * (np.abs(st.ry) + np.abs(st.vhat[data.obj]
                                                                     * st.tau)) ** 2))
        if not wi > (1e3 * EPS) ** 2 * resid_scale:
            raise ProblemError(
                f"trajectories.family_test sigma2: the independent lines fit the data "
                f"exactly (W_independent = {wi:.3g}, at the float64 rounding level of the "
                "data), so σ² cannot be estimated and the F test is undefined; use "
                "sigma2='known' with the measurement variances")
        stat, dist = (lam / dof) / (wi / dof2), stats.f(dof, dof2)
    thr = float(dist.ppf(level))
    return FamilyTest(family=fam.name, sigma2=mode, statistic=float(stat), dof=dof,
                      dof2=dof2, threshold=thr, p_value=float(dist.sf(stat)), level=level,
                      reject=bool(stat > thr), objective_family=wf, objective_independent=wi,
                      message="; ".join(notes))


def _custom_penalty(data: TrajectoryData, fam: Family) -> float:
    """Λ of a custom family: Σ_j N_j (ȳ_j − p_j)² + M2_j (V̂_j − V_j)² at its fit."""
    st = _stats(data)
    p, v = _lines(st, fam, _fit(data, fam).theta)
    return float(np.sum(st.s0 * (st.p - p) ** 2 + st.m2 * (st.vhat - v) ** 2))
