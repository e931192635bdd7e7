"""Data and families of dependent linear trajectories (paper 002).

:class:`TrajectoryData` holds the classified measurements of the ``Q`` objects, stacked
object by object in the paper's order (5), (11); :class:`Family` says which objects share a
start and which a velocity -- diverging (4)-(5), parallel (10)-(11), independent, or any
grouping (:meth:`Family.custom`) -- and :func:`resolve_family` turns a name into one.
"""

from __future__ import annotations

from collections.abc import Sequence, Sized
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_number,
)

FAMILIES = ("diverging", "parallel", "independent")
FamilyName = Literal["diverging", "parallel", "independent"]


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
    _cache: dict[Any, Any] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        where = "trajectories.TrajectoryData"
        if isinstance(self.times, np.ndarray) and self.times.ndim == 1:
            raise ProblemError(
                f"{where} times: expected a sequence of per-object arrays, got one array"
            )
        for name, seq in (("times", self.times), ("values", self.values)):
            if isinstance(seq, str | bytes) or not hasattr(seq, "__len__"):
                raise ProblemError(
                    f"{where} {name}: expected a sequence of per-object "
                    f"arrays, got {type(seq).__name__}"
                )
        q = len(self.times)
        if q == 0:
            raise ProblemError(f"{where} times: no objects (Q = 0)")
        if len(self.values) != q:
            raise ProblemError(f"{where} values: {len(self.values)} objects, times has {q}")
        epoch = as_number(f"{where} epoch", self.epoch, low=-MAX_MAGNITUDE, high=MAX_MAGNITUDE)
        object.__setattr__(self, "epoch", epoch)
        ts: list[FloatArray] = []
        ys: list[FloatArray] = []
        dims = set()
        for j in range(q):
            t = as_finite_array(f"times[{j}]", self.times[j], ndim=1, max_abs=MAX_MAGNITUDE)
            y = as_finite_array(f"values[{j}]", self.values[j], ndim=(1, 2), max_abs=MAX_MAGNITUDE)
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
        ws, scalar = _weights(where, self.sigma2, ts, d)
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
        return cls("independent", q, tuple((j,) for j in range(q)), tuple((j,) for j in range(q)))

    @classmethod
    def custom(
        cls,
        q: int,
        *,
        shared_start: Sequence[Sequence[int]] = (),
        shared_velocity: Sequence[Sequence[int]] = (),
        name: str = "custom",
    ) -> Family:
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
            raise ProblemError(
                f"trajectories.Family.custom name: expected a string, got {type(name).__name__}"
            )
        return cls(
            name,
            q,
            _partition(q, shared_start, "shared_start"),
            _partition(q, shared_velocity, "shared_velocity"),
        )

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
        for kind, groups in (
            ("start_groups", family.start_groups),
            ("velocity_groups", family.velocity_groups),
        ):
            flat = sorted(i for g in groups for i in g)
            if flat != list(range(q)) or any(len(g) == 0 for g in groups):
                raise ProblemError(
                    f"family: {kind} {groups} is not a partition of the "
                    f"{q} objects (build it with Family.custom)"
                )
        return family
    if family == "diverging":
        return Family.diverging(q)
    if family == "parallel":
        return Family.parallel(q)
    if family == "independent":
        return Family.independent(q)
    raise ProblemError(f"family: expected one of {FAMILIES} or a Family, got {family!r}")


def _weights(
    where: str, sigma2: float | Sequence[ArrayLike], ts: list[FloatArray], d: int
) -> tuple[list[FloatArray], float | None]:
    """The weights 1/σ² of (4), (10) per object, (N_j, d) each, from ``sigma2``: one
    variance for every measurement (returned as the second value too), or one entry per
    object (a scalar, (N_j,) or (N_j, d)); every variance in [1e-100, 1e100]."""
    q = len(ts)
    if (
        isinstance(sigma2, str | bytes | bool | np.bool_)
        or np.isscalar(sigma2)
        or (isinstance(sigma2, np.ndarray) and sigma2.ndim == 0)
    ):
        s2 = as_number(f"{where} sigma2", sigma2)
        if not 1 / MAX_MAGNITUDE <= s2 <= MAX_MAGNITUDE:
            raise ProblemError(
                f"{where} sigma2: must be positive, in [1e-100, 1e100] "
                f"(its inverse is a usable weight), got {s2:g}"
            )
        return [np.full((t.size, d), 1.0 / s2) for t in ts], s2
    if not isinstance(sigma2, Sized) or len(sigma2) != q:
        n_s2 = len(sigma2) if isinstance(sigma2, Sized) else type(sigma2).__name__
        raise ProblemError(f"sigma2: {n_s2} objects, times has {q}")
    ws: list[FloatArray] = []
    for j in range(q):
        var = as_finite_array(f"sigma2[{j}]", sigma2[j], ndim=(0, 1, 2))
        try:
            var = np.broadcast_to(var.reshape(var.shape + (1,) * (var.ndim == 1)), (ts[j].size, d))
        except ValueError:
            raise ProblemError(
                f"sigma2[{j}]: shape {var.shape} does not match ({ts[j].size}, {d})"
            ) from None
        if np.any(var < 1 / MAX_MAGNITUDE) or np.any(var > MAX_MAGNITUDE):
            raise ProblemError(f"sigma2[{j}]: variances must be positive, in [1e-100, 1e100]")
        ws.append(1.0 / var)
    return ws, None
