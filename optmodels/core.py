"""Shared types of optmodels: :class:`Status`, :class:`Solution`, exceptions, timing and
the small input checks every problem module uses.

Every solver back-end maps its own status codes onto :class:`Status` through an explicit
table (an unknown code maps to ``Status.ERROR``), and every problem module returns a
subclass of :class:`Solution` carrying the common fields below plus its own.
"""

from __future__ import annotations

import datetime
import enum
import json
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from typing import Any, Self, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "TABLES",
    "Column",
    "OptModelsError",
    "ProblemError",
    "Solution",
    "SolveError",
    "SolverNotAvailable",
    "Status",
    "TableSpec",
    "Timer",
    "Verdict",
    "as_choice",
    "as_count",
    "as_finite_array",
    "as_float_array",
    "as_instance",
    "as_number",
    "as_positive",
    "as_probability",
    "check_spd",
    "check_spd_stack",
    "failure",
    "finish",
    "gate",
    "json_document",
    "json_text",
    "to_jsonable",
]

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- errors
class OptModelsError(Exception):
    """Base class of every exception raised by optmodels."""


class ProblemError(OptModelsError, ValueError):
    """Bad input: wrong shape, non-finite values, a covariance that is not SPD,
    degenerate geometry, too few points, an infeasible specification."""


class SolverNotAvailable(OptModelsError, ImportError):
    """The requested solver is not installed; the message carries the install hint."""


class SolveError(OptModelsError, RuntimeError):
    """The solver failed and the caller asked for a solution (``Solution.require_ok``)."""

    def __init__(self, message: str, solution: Solution | None = None) -> None:
        super().__init__(message)
        self.solution = solution


# --------------------------------------------------------------------------- status
class Status(enum.Enum):
    """Outcome of a solve, common to all back-ends."""

    OPTIMAL = "optimal"
    OPTIMAL_INACCURATE = "optimal_inaccurate"
    INFEASIBLE = "infeasible"
    UNBOUNDED = "unbounded"
    ITERATION_LIMIT = "iteration_limit"
    ERROR = "error"

    @property
    def ok(self) -> bool:
        """True for OPTIMAL and OPTIMAL_INACCURATE: the returned point is a solution."""
        return self in (Status.OPTIMAL, Status.OPTIMAL_INACCURATE)


#: A generic solve's claimed optimum is re-checked in NumPy against the original problem:
#: a residual above VERIFY_TOL makes it OPTIMAL_INACCURATE, above REJECT_TOL an ERROR.
VERIFY_TOL, REJECT_TOL = 1e-6, 1e-3


def verified_status(status: Status, worst: float) -> Status:
    """The status after the NumPy re-check with largest residual ``worst``: ERROR if it is
    non-finite or above :data:`REJECT_TOL`, OPTIMAL → OPTIMAL_INACCURATE above
    :data:`VERIFY_TOL`; a status that was not OK stays as it is."""
    if not status.ok:
        return status
    if not np.isfinite(worst) or worst > REJECT_TOL:
        return Status.ERROR
    if worst > VERIFY_TOL and status == Status.OPTIMAL:
        return Status.OPTIMAL_INACCURATE
    return status


# --------------------------------------------------------------------------- the gate
@dataclass(frozen=True)
class Verdict:
    """What :func:`gate` decided: the status ``before`` and after the re-check, the largest
    residual ``worst`` (NaN if any residual is NaN) and its name ``key``."""

    status: Status
    before: Status
    worst: float
    key: str

    @property
    def changed(self) -> bool:
        return self.status != self.before

    @property
    def rejected(self) -> bool:
        """A claimed solution refused by the re-check (OK before, ERROR after)."""
        return self.before.ok and self.status == Status.ERROR


def _worst(residuals: Mapping[str, float], ignore: Iterable[str]) -> tuple[str, float]:
    """Name and value of the largest residual; NaN ranks lowest for the name but makes the
    value NaN (an unknown residual is not a small one)."""
    skip = set(ignore)
    vals = {k: float(v) for k, v in residuals.items() if k not in skip}
    if not vals:
        return "residual", 0.0
    key = max(vals, key=lambda k: -np.inf if np.isnan(vals[k]) else vals[k])
    worst = float("nan") if any(np.isnan(v) for v in vals.values()) else vals[key]
    return key, worst


def gate(status: Status, residuals: Mapping[str, float], *, ignore: Iterable[str] = (),
         strict: bool = False) -> Verdict:
    """The one verification gate: the status of a claimed solution after the NumPy re-check
    whose residuals (dimensionless, by name) are ``residuals``.

    :func:`verified_status` of the largest residual (names in ``ignore`` are diagnostics,
    not residuals): ERROR if it is NaN, infinite or above :data:`REJECT_TOL`, OPTIMAL →
    OPTIMAL_INACCURATE above :data:`VERIFY_TOL`. With ``strict`` a solver's own
    OPTIMAL_INACCURATE above VERIFY_TOL is refused too (an inexact claim that also fails
    the check is not a solution). A status that was not OK stays as it is.
    """
    key, worst = _worst(residuals, ignore)
    new = verified_status(status, worst)
    if strict and new == Status.OPTIMAL_INACCURATE and status == Status.OPTIMAL_INACCURATE \
            and worst > VERIFY_TOL:
        new = Status.ERROR
    return Verdict(status=new, before=status, worst=worst, key=key)


S = TypeVar("S", bound="Solution")


def finish(solution: S, checks: Mapping[str, float] | None = None, *,
           ignore: Iterable[str] = (), strict: bool = False,
           reject: Callable[[S], S | None] | None = None,
           note: Callable[[Verdict], str] | None = None) -> S:
    """End of every solve and closed form: :func:`gate` on ``checks`` (default: the
    solution's own ``residuals``), the status set on ``solution``, and, if the gate changed
    it, ``note(verdict)`` appended to the message (default: "<key> <worst> fails the NumPy
    check" / "(NumPy check)"). A result that is not OK after the gate (refused by it, or
    not OK from the solver) is replaced by the problem's failure form: ``reject(solution)``
    (mutates it, or returns the replacement; without ``reject`` the numbers stay, for
    diagnosis, under a status that is not OK). Returns the solution."""
    verdict = gate(solution.status, solution.residuals if checks is None else checks,
                   ignore=ignore, strict=strict)
    solution.status = verdict.status
    if verdict.changed:
        text = (note or _default_note)(verdict)
        if text:
            solution.message = f"{solution.message}; {text}" if solution.message else text
    if not verdict.status.ok and reject is not None:
        out = reject(solution)
        if out is not None:
            solution = out
    return solution


def _default_note(v: Verdict) -> str:
    return (f"{v.key} residual {v.worst:.1e} fails the NumPy check" if v.status == Status.ERROR
            else f"{v.key} residual {v.worst:.1e} (NumPy check)")


def failure(cls: type[S], method: str, message: str, *, status: Status = Status.ERROR,
            **fields: Any) -> S:
    """The one failure constructor: a ``cls`` solution with no estimate (objective NaN,
    the estimate fields at their NaN/empty defaults unless given in ``fields``) and a
    status that is not OK (an OK ``status`` becomes ERROR)."""
    return cls(status=status if not status.ok else Status.ERROR, objective=float("nan"),
               method=method, message=message, **fields)


@dataclass
class Solution:
    """Common part of every solution.

    Attributes
    ----------
    status : Status
        Outcome, mapped from the solver's own code (see the back-ends' tables).
    objective : float
        Objective of the *original* problem at the returned point (re-evaluated in NumPy,
        not the solver's internal value).
    method : str
        ``"closed_form"``, ``"casadi:ipopt"``, ``"cvxpy:CLARABEL"``, ...
    build_time, solve_time : float
        Seconds spent building the model (CVXPY canonicalisation, CasADi graph and
        derivative construction) and inside the solver.
    iterations : int or None
        Solver iterations where the solver reports them.
    residuals : dict
        Maximum violation of each constraint group of the original problem at the
        returned point, re-computed in NumPy.
    message : str
        The solver's own status text, or a note.
    info : dict
        Anything else a method reports (starts tried, second-order check, ...).
    """

    status: Status
    objective: float
    method: str
    build_time: float = 0.0
    solve_time: float = 0.0
    iterations: int | None = None
    residuals: dict[str, float] = field(default_factory=dict)
    message: str = ""
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status.ok

    @property
    def max_residual(self) -> float:
        return max(self.residuals.values(), default=0.0)

    def require_ok(self) -> Self:
        """Return ``self`` if the solve succeeded, else raise :class:`SolveError`."""
        if not self.ok:
            raise SolveError(
                f"{self.method} did not solve the problem: status {self.status.value}"
                f" ({self.message})",
                self,
            )
        return self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of every field through the package's one encoder
        :func:`to_jsonable` (arrays become lists, NaN and ±inf ``None``)."""
        return {f.name: to_jsonable(getattr(self, f.name)) for f in fields(self)}

    # ------------------------------------------------------------------ tables
    def table_spec(self) -> TableSpec | None:
        """The :class:`TableSpec` of this solution's per-item results (``None``: not
        tabular). A subclass declares it as the class attribute ``table`` (the problem
        packages' specs are in :data:`TABLES` until they carry their own)."""
        spec = getattr(type(self), "table", None)
        if spec is None:
            spec = TABLES.get(f"{type(self).__module__}.{type(self).__qualname__}")
        return spec

    def table_columns(self) -> dict[str, np.ndarray]:
        """The per-item results as named 1-D columns of one length (the row index first):
        see :class:`TableSpec` for the names. A failure form (no estimate) has no rows.

        Raises
        ------
        ProblemError
            ``<Class>.to_rows``: the solution is not tabular (one vector and its
            covariance, e.g. a fused estimate: use :meth:`to_dict`), or its per-item fields
            disagree on the number of items.
        """
        name = type(self).__name__
        spec = self.table_spec()
        if spec is None:
            raise ProblemError(f"{name}.to_rows: this result is not a table (no per-item "
                               f"fields); use to_dict()")
        arrays = {c.field: np.asarray(getattr(self, c.field)) for c in spec.columns}
        empty = any(a.size == 0 for a in arrays.values())
        n = 0 if empty or not arrays else next(iter(arrays.values())).shape[0]
        out: dict[str, np.ndarray] = {spec.index: np.arange(n)}
        for col in spec.columns:
            arr = arrays[col.field]
            if n == 0:  # a failure form: no rows (the columns of its arrays' shapes)
                arr = arr[:0] if arr.ndim and arr.shape[0] == 0 else np.empty(0, arr.dtype)
            if arr.ndim == 0 or arr.shape[0] != n:
                raise ProblemError(f"{name}.to_rows: {col.field} has shape {arr.shape}, not "
                                   f"{n} items")
            out.update(col.split(arr, n))
        return out

    def to_rows(self) -> list[dict[str, Any]]:
        """One dict per item (point, cell, object, measurement: :class:`TableSpec`'s
        ``index``), with Python numbers (NaN kept), e.g. for :func:`csv.DictWriter`.
        Solution-level values (status, objective, method) are not repeated per row; see
        :meth:`to_frame`'s ``attrs``. Raises :class:`ProblemError` if not tabular."""
        cols = self.table_columns()
        names = list(cols)
        lists = [cols[k].tolist() for k in names]
        return [dict(zip(names, vals, strict=True)) for vals in zip(*lists, strict=True)]

    def to_frame(self) -> Any:
        """The :meth:`to_rows` table as a ``pandas.DataFrame`` (one row per item, columns
        in the same order, units in the column names), with ``attrs`` holding ``status``,
        ``method`` and ``objective``. Needs pandas (``pip install optmodels[frames]``).
        Raises :class:`ProblemError` if not tabular."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - pandas comes with the extras
            raise ProblemError(f"{type(self).__name__}.to_frame: pandas is needed (pip "
                               f"install pandas)") from exc
        df = pd.DataFrame(self.table_columns())
        df.attrs.update(status=self.status.value, method=self.method,
                        objective=float(self.objective))
        return df


@dataclass(frozen=True)
class Column:
    """One per-item field of a :class:`TableSpec`: the solution's attribute ``field``
    (first axis: the items). A 1-D field is one column ``name`` (default: ``field``); a
    field (n, k) gives ``labels`` (k of them, units in the names) prefixed by ``name``
    (``""``: the labels alone), a field (n, m, k) one group per middle index ``j``:
    ``{name}{j}_{label}`` (``radar0_range_bias_m``). Without ``labels`` the last axis is
    numbered (``start_0``, ``start_1``)."""

    field: str
    name: str | None = None
    labels: tuple[str, ...] | None = None

    def split(self, arr: np.ndarray, n: int) -> dict[str, np.ndarray]:
        """The columns of ``arr`` (n, ...)."""
        base = self.field if self.name is None else self.name
        if arr.ndim == 1:
            return {base: arr}
        flat = arr.reshape(n, int(np.prod(arr.shape[1:-1])), arr.shape[-1])
        k = arr.shape[-1]
        labels = self.labels if self.labels is not None and len(self.labels) == k else \
            tuple(str(i) for i in range(k))
        out: dict[str, np.ndarray] = {}
        for j in range(flat.shape[1]):
            mid = "" if arr.ndim == 2 else str(j)
            head = f"{base}{mid}"
            for i, lab in enumerate(labels):
                key = f"{head}_{lab}" if head else lab
                out[key] = flat[:, j, i]
        return out


@dataclass(frozen=True)
class TableSpec:
    """How a solution is a table: ``index`` names the row-number column (``"point"``,
    ``"cell"``, ``"object"``, ``"measurement"``), ``columns`` the per-item fields
    (:class:`Column`), all with the same first axis."""

    index: str
    columns: tuple[Column, ...]


#: The tabular solutions of the problem packages, by ``module.QualName`` (a subclass's own
#: ``table`` class attribute takes precedence): per point of a plane fit its projection,
#: per cell of a bias field its centre and the field per radar (range m, azimuth rad) with
#: the active bounds, per object of a family of lines its start and velocity, per
#: measurement of an assignment its group (index into ``partition``, −1 background), per
#: trial of the two-site joint ML its position.
TABLES: dict[str, TableSpec] = {
    "optmodels.plane.data.PlaneSolution": TableSpec("point", (
        Column("projected", "", ("x_m", "y_m", "z_m")),)),
    "optmodels.biasfield.problem.FieldSolution": TableSpec("cell", (
        Column("centers", "", ("x_m", "y_m")),
        Column("field", "radar", ("range_bias_m", "azimuth_bias_rad")),
        Column("active", "radar", ("range_active", "azimuth_active")))),
    "optmodels.trajectories.solution.TrajectorySolution": TableSpec("object", (
        Column("start"), Column("velocity"))),
    "optmodels.assignment.data.AssignmentSolution": TableSpec("measurement", (
        Column("assignment", "group"),)),
    "optmodels.fusion.two_site_ml.JointMLSolution": TableSpec("trial", (
        Column("estimate", "", ("x_m", "y_m")), Column("stationarity"))),
}


# --------------------------------------------------------------------------- JSON
def to_jsonable(value: Any) -> Any:
    """The package's one JSON encoder (``Solution.to_dict``, the CLI's ``--json``, the
    JSON files it writes): plain Python values for strict JSON. NumPy arrays become
    (nested) lists, NumPy scalars numbers, enums their value, paths text, mappings dicts
    with text keys, tuples/lists/sets lists; NaN **and ±inf become** ``None`` (strict JSON
    has neither; README, "Command line"). Other objects are returned as they are
    (:func:`json_text` then refuses them with ``TypeError``)."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, float | np.floating):
        x = float(value)
        return x if np.isfinite(x) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value)
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "biu":
            return value.tolist()
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, datetime.date):
        return value.isoformat()
    if isinstance(value, complex):
        return None if not np.isfinite(value) else [value.real, value.imag]
    return value


def json_text(obj: Any, *, indent: int | None = 2) -> str:
    """``obj`` as one strict JSON document (``allow_nan=False``) through
    :func:`to_jsonable`; ``TypeError`` for an object it cannot encode."""
    return json.dumps(to_jsonable(obj), indent=indent, allow_nan=False)


def json_document(text: str, *, where: str) -> Any:
    """The one strict JSON reader: the document of ``text``, or one :class:`ProblemError`
    naming ``where`` (the file or the flag) for invalid JSON (with line and column), a
    non-standard ``NaN``/``Infinity`` constant, a key given twice in one object (the
    standard library keeps the last silently; issue 28) or nesting too deep."""

    def constant(name: str) -> Any:
        raise ProblemError(f"{where}: {name} is not valid JSON (give a finite number or null)")

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in items:
            if key in out:
                raise ProblemError(f"{where}: the key {key!r} is given twice in one JSON "
                                   f"object (which one is meant?)")
            out[key] = value
        return out

    try:
        return json.loads(text, parse_constant=constant, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{where}: not valid JSON (line {exc.lineno}, column {exc.colno}: "
                           f"{exc.msg})") from None
    except RecursionError:
        raise ProblemError(f"{where}: JSON nested too deeply") from None


# --------------------------------------------------------------------------- timing
class Timer:
    """Accumulating wall-clock timer: ``with timer: ...`` adds to ``timer.elapsed``."""

    def __init__(self) -> None:
        self.elapsed = 0.0
        self._t0 = 0.0

    def __enter__(self) -> Self:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.elapsed += time.perf_counter() - self._t0


@contextmanager
def timed() -> Iterator[Timer]:
    """``with timed() as t: ...`` then ``t.elapsed`` seconds."""
    t = Timer()
    with t:
        yield t


# --------------------------------------------------------------------------- checks
def _entries(n: int | None) -> str:
    return "a scalar" if n is None else f"{n} entr{'y' if n == 1 else 'ies'}"


def _ragged_text(value: Any, depth: int = 0) -> str:
    """Where a nested sequence stops being rectangular ("item 1 has 2 entries, item 0 has
    3", "in item 4: ..."), for the message of a ragged input; "" if it cannot tell."""
    if depth > 8 or not isinstance(value, list | tuple | np.ndarray):
        return ""
    lens = [len(v) if isinstance(v, list | tuple) or (isinstance(v, np.ndarray) and v.ndim)
            else None for v in value]
    for j, n in enumerate(lens):
        if n != lens[0]:
            return f"item {j} has {_entries(n)}, item 0 has {_entries(lens[0])}"
    for i, item in enumerate(value):
        inner = _ragged_text(item, depth + 1)
        if inner:
            return f"in item {i}: {inner}"
    return ""


_REAL_TYPES = (bool, int, float, np.bool_, np.integer, np.floating)


def as_float_array(name: str, value: Any) -> FloatArray:
    """``value`` as a float64 array, or one :class:`ProblemError` naming ``name``: the root
    of every array check (:func:`as_finite_array` and the data classes' ``__post_init__``).

    Refused: ragged nested sequences (rows of different lengths, which NumPy ≥ 1.24 turns
    into a raw ``ValueError``, or an object array of rows), object arrays holding anything
    but real numbers, strings and bytes (``"1.5"`` would otherwise be parsed silently),
    ``None`` entries, complex values, dates and mappings. Booleans are read as 0/1. Shape
    and finiteness are not checked here.
    """
    if value is None:
        raise ProblemError(f"{name}: not a numeric array (got None)")
    if isinstance(value, str | bytes | Mapping | set | frozenset):
        raise ProblemError(f"{name}: not a numeric array (got {type(value).__name__} "
                           f"{_scalar_text(value)})")
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        where = _ragged_text(value)
        if "inhomogeneous" in str(exc) or where:
            raise ProblemError(f"{name}: a ragged nested sequence (rows of different "
                               f"lengths{': ' + where if where else ''}); give a "
                               f"rectangular array") from None
        raise ProblemError(f"{name}: not a numeric array ({exc})") from None
    kind = raw.dtype.kind
    if kind == "c":
        raise ProblemError(f"{name}: complex values are not accepted (give real numbers)")
    if kind in "USV":
        raise ProblemError(f"{name}: not a numeric array (text entries, dtype {raw.dtype}: "
                           f"text is not parsed here, convert it first)")
    if kind in "mM":
        raise ProblemError(f"{name}: not a numeric array (dtype {raw.dtype}: convert "
                           f"times to seconds first)")
    if kind == "O":
        # one pass over the entries' types (C speed), not over the entries
        for typ in set(map(type, raw.flat)):
            if issubclass(typ, _REAL_TYPES):
                continue
            if issubclass(typ, np.ndarray | list | tuple):
                where = _ragged_text(value)
                raise ProblemError(f"{name}: a ragged nested sequence (rows of different "
                                   f"lengths{': ' + where if where else ''}); give a "
                                   f"rectangular array")
            if issubclass(typ, complex | np.complexfloating):
                raise ProblemError(f"{name}: complex values are not accepted (give real "
                                   f"numbers)")
            raise ProblemError(f"{name}: not a numeric array (an entry of type "
                               f"{typ.__name__})")
    try:
        return np.asarray(raw, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ProblemError(f"{name}: not a numeric array ({exc})") from None


def as_finite_array(
    name: str,
    value: ArrayLike,
    *,
    ndim: int | tuple[int, ...] | None = None,
    shape: tuple[int | None, ...] | None = None,
    max_abs: float | None = None,
) -> FloatArray:
    """Convert ``value`` to a float64 array and check shape and finiteness (and, with
    ``max_abs``, magnitude: see :data:`MAX_MAGNITUDE`).

    Raises
    ------
    ProblemError
        Naming ``name``, if the value is not numeric, has the wrong number of dimensions
        or shape (``None`` in ``shape`` matches any length), or has NaN/inf entries.
    """
    arr = as_float_array(name, value)
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in allowed:
            raise ProblemError(
                f"{name}: expected {' or '.join(map(str, allowed))} dimensions, "
                f"got shape {arr.shape}"
            )
    if shape is not None:
        ok = arr.ndim == len(shape) and all(
            s is None or s == a for s, a in zip(shape, arr.shape, strict=True)
        )
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise ProblemError(f"{name}: expected shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ProblemError(f"{name}: {bad} entries are NaN or infinite")
    if max_abs is not None and arr.size and float(np.max(np.abs(arr))) > max_abs:
        raise ProblemError(f"{name}: |entries| up to {float(np.max(np.abs(arr))):.3g}, above "
                           f"{max_abs:.0e} (squares and sums of squares would overflow "
                           "float64; change units)")
    return arr


#: Largest magnitude accepted where a problem squares its inputs (least-squares sums):
#: (1e100)² · N stays far below float64's 1.8e308. Found by the robustness sweep
#: (tests/test_robustness.py): 1e150-scale times overflowed Σt² into inf.
MAX_MAGNITUDE = 1e100


def check_spd_stack(name: str, mats: FloatArray, *, rtol: float = 1e-10) -> None:
    """Check that every matrix of a stack (..., d, d) is symmetric positive definite.

    Symmetry is checked relative to the matrix's largest entry (``rtol``); definiteness
    by a Cholesky factorisation. Raises :class:`ProblemError` naming ``name`` and the
    index of the first offending matrix.
    """
    if mats.ndim < 2 or mats.shape[-1] != mats.shape[-2]:
        raise ProblemError(f"{name}: expected square matrices, got shape {mats.shape}")
    if mats.shape[-1] == 0:  # found by the sweep: a raw "cannot reshape" from fuse((0, 0))
        raise ProblemError(f"{name}: empty (0 × 0) matrices (shape {mats.shape}): a "
                           f"covariance needs a dimension ≥ 1")
    if mats.size == 0:  # a stack of no matrices: nothing to check
        return
    flat = mats.reshape(-1, mats.shape[-1], mats.shape[-1])
    scale = np.max(np.abs(flat), axis=(1, 2))
    asym = np.max(np.abs(flat - flat.transpose(0, 2, 1)), axis=(1, 2))
    bad = np.flatnonzero(asym > rtol * np.maximum(scale, np.finfo(float).tiny))
    if bad.size:
        where = _index_text(name, mats, int(bad[0]))
        raise ProblemError(f"{where} is not symmetric (max |A - A^T| = {asym[bad[0]]:.3g})")
    sym = 0.5 * (flat + flat.transpose(0, 2, 1))
    # Cholesky of the whole stack at once; on failure find the first bad matrix.
    try:
        np.linalg.cholesky(sym)
    except np.linalg.LinAlgError:
        for i, m in enumerate(sym):
            try:
                np.linalg.cholesky(m)
            except np.linalg.LinAlgError:
                w = np.linalg.eigvalsh(m)
                where = _index_text(name, mats, i)
                raise ProblemError(
                    f"{where} is not positive definite (smallest eigenvalue {w[0]:.3g})"
                ) from None
    # Cholesky accepts matrices that are PD only to round-off; demand a sane condition.
    w = np.linalg.eigvalsh(sym)
    cond_bad = np.flatnonzero(w[:, 0] <= 1e-14 * w[:, -1])
    if cond_bad.size:
        i = int(cond_bad[0])
        where = _index_text(name, mats, i)
        raise ProblemError(
            f"{where} is numerically singular (eigenvalues {w[i, 0]:.3g} ... {w[i, -1]:.3g})"
        )


def check_spd(name: str, mat: FloatArray, *, rtol: float = 1e-10) -> None:
    """:func:`check_spd_stack` for a single matrix."""
    check_spd_stack(name, np.asarray(mat), rtol=rtol)


def _index_text(name: str, mats: FloatArray, flat_index: int) -> str:
    if mats.ndim == 2:
        return name
    idx = np.unravel_index(flat_index, mats.shape[:-2])
    return f"{name}[{', '.join(map(str, idx))}]"


# --------------------------------------------------------------------------- scalars
# One small set of scalar checks used by every entry point: a scalar argument of the wrong
# type or value becomes a ProblemError naming the argument, never a raw TypeError from
# float()/int(), a silent truncation (k=2.5 -> 2) or a NaN that propagates.


def _scalar_text(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def as_number(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    allow_inf: bool = False,
) -> float:
    """A real scalar as ``float``, checked against ``[low, high]`` (open ends with
    ``low_open``/``high_open``).

    Booleans, strings, ``None``, complex numbers, arrays of size ≠ 1 and NaN are refused;
    ±inf only with ``allow_inf``.

    Raises
    ------
    ProblemError
        Naming ``name`` and the value received.
    """
    if isinstance(value, bool | np.bool_) or value is None or isinstance(value, str | bytes):
        raise ProblemError(f"{name}: expected a real number, got {_scalar_text(value)}")
    if isinstance(value, complex | np.complexfloating):
        raise ProblemError(f"{name}: expected a real number, got complex {value!r}")
    if isinstance(value, np.ndarray):
        if value.size != 1 or np.iscomplexobj(value):
            raise ProblemError(f"{name}: expected a real number, got an array {value.shape}")
        value = value.reshape(()).item()
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ProblemError(f"{name}: expected a real number, got {_scalar_text(value)}") from None
    if np.isnan(x):
        raise ProblemError(f"{name}: got NaN")
    if np.isinf(x) and not allow_inf:
        raise ProblemError(f"{name}: got {x} (must be finite)")
    if low is not None and (x < low or (low_open and x == low)):
        raise ProblemError(f"{name}: must be {'>' if low_open else '>='} {low:g}, got {x:g}")
    if high is not None and (x > high or (high_open and x == high)):
        raise ProblemError(f"{name}: must be {'<' if high_open else '<='} {high:g}, got {x:g}")
    return x


def as_positive(name: str, value: Any, *, allow_zero: bool = False,
                allow_inf: bool = False) -> float:
    """A scalar > 0 (≥ 0 with ``allow_zero``); see :func:`as_number`."""
    return as_number(name, value, low=0.0, low_open=not allow_zero, allow_inf=allow_inf)


def as_probability(name: str, value: Any, *, low_open: bool = False,
                   high_open: bool = False) -> float:
    """A probability in [0, 1] (ends excluded on request); see :func:`as_number`."""
    return as_number(name, value, low=0.0, high=1.0, low_open=low_open, high_open=high_open)


def as_count(name: str, value: Any, *, minimum: int = 0, maximum: int | None = None) -> int:
    """A whole number ≥ ``minimum`` (and ≤ ``maximum``) as ``int``.

    Integral floats (``3.0``) are accepted; ``2.5``, NaN, inf, booleans and strings are
    refused rather than truncated.
    """
    if isinstance(value, bool | np.bool_) or value is None or isinstance(value, str | bytes):
        raise ProblemError(f"{name}: expected a whole number, got {_scalar_text(value)}")
    if isinstance(value, int | np.integer):
        n = int(value)
    else:
        x = as_number(name, value)
        if x != np.floor(x):
            raise ProblemError(f"{name}: expected a whole number, got {x:g}")
        n = int(x)
    if n < minimum:
        raise ProblemError(f"{name}: must be >= {minimum}, got {n}")
    if maximum is not None and n > maximum:
        raise ProblemError(f"{name}: must be <= {maximum}, got {n}")
    return n


def as_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """One of ``choices`` (exact string match); the message lists them."""
    options = tuple(choices)
    if not isinstance(value, str) or value not in options:
        raise ProblemError(
            f"{name}: expected one of {', '.join(map(repr, options))}, got {_scalar_text(value)}"
        )
    return value


def as_flag(name: str, value: Any) -> bool:
    """A boolean switch: ``True``/``False`` (NumPy's too) only; ``1``, ``"yes"`` or ``None``
    are refused rather than read as truthy."""
    if not isinstance(value, bool | np.bool_):
        raise ProblemError(f"{name}: expected True or False, got {_scalar_text(value)}")
    return bool(value)


def as_generator(where: str, seed: Any) -> np.random.Generator:
    """A ``numpy.random.Generator`` as given, or seeded from a whole number ≥ 0 (or a
    sequence of them); anything else is one :class:`ProblemError` "<where> seed: ..."."""
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool | np.bool_ | float | str | bytes) or seed is None:
        raise ProblemError(f"{where} seed: expected a whole number >= 0 or a "
                           f"numpy.random.Generator, got {seed!r}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"{where} seed: expected a whole number >= 0 or a "
                           f"numpy.random.Generator, got {seed!r} ({exc})") from None


def as_instance(name: str, value: Any, cls: type) -> Any:
    """``value`` if it is a ``cls`` (the problem's data object), else a ProblemError naming
    ``name`` and the type received (instead of an AttributeError deep inside)."""
    if not isinstance(value, cls):
        raise ProblemError(f"{name}: expected a {cls.__name__}, got {type(value).__name__}")
    return value
