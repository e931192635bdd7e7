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

from optmodels.checks import (
    MAX_MAGNITUDE as MAX_MAGNITUDE,
)
from optmodels.checks import (
    FloatArray as FloatArray,
)
from optmodels.checks import (
    as_choice as as_choice,
)
from optmodels.checks import (
    as_count as as_count,
)
from optmodels.checks import (
    as_finite_array as as_finite_array,
)
from optmodels.checks import (
    as_flag as as_flag,
)
from optmodels.checks import (
    as_float_array as as_float_array,
)
from optmodels.checks import (
    as_generator as as_generator,
)
from optmodels.checks import (
    as_instance as as_instance,
)
from optmodels.checks import (
    as_number as as_number,
)
from optmodels.checks import (
    as_positive as as_positive,
)
from optmodels.checks import (
    as_probability as as_probability,
)
from optmodels.checks import (
    check_spd as check_spd,
)
from optmodels.checks import (
    check_spd_stack as check_spd_stack,
)
from optmodels.errors import OptModelsError as OptModelsError
from optmodels.errors import ProblemError as ProblemError
from optmodels.errors import SolveError as SolveError
from optmodels.errors import SolverNotAvailable as SolverNotAvailable

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


def gate(
    status: Status,
    residuals: Mapping[str, float],
    *,
    ignore: Iterable[str] = (),
    strict: bool = False,
) -> Verdict:
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
    if (
        strict
        and new == Status.OPTIMAL_INACCURATE
        and status == Status.OPTIMAL_INACCURATE
        and worst > VERIFY_TOL
    ):
        new = Status.ERROR
    return Verdict(status=new, before=status, worst=worst, key=key)


S = TypeVar("S", bound="Solution")


def finish(
    solution: S,
    checks: Mapping[str, float] | None = None,
    *,
    ignore: Iterable[str] = (),
    strict: bool = False,
    reject: Callable[[S], S | None] | None = None,
    note: Callable[[Verdict], str] | None = None,
) -> S:
    """End of every solve and closed form: :func:`gate` on ``checks`` (default: the
    solution's own ``residuals``), the status set on ``solution``, and, if the gate changed
    it, ``note(verdict)`` appended to the message (default: "<key> <worst> fails the NumPy
    check" / "(NumPy check)"). A result that is not OK after the gate (refused by it, or
    not OK from the solver) is replaced by the problem's failure form: ``reject(solution)``
    (mutates it, or returns the replacement; without ``reject`` the numbers stay, for
    diagnosis, under a status that is not OK). Returns the solution."""
    verdict = gate(
        solution.status,
        solution.residuals if checks is None else checks,
        ignore=ignore,
        strict=strict,
    )
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
    return (
        f"{v.key} residual {v.worst:.1e} fails the NumPy check"
        if v.status == Status.ERROR
        else f"{v.key} residual {v.worst:.1e} (NumPy check)"
    )


def failure(
    cls: type[S], method: str, message: str, *, status: Status = Status.ERROR, **fields: Any
) -> S:
    """The one failure constructor: a ``cls`` solution with no estimate (objective NaN,
    the estimate fields at their NaN/empty defaults unless given in ``fields``) and a
    status that is not OK (an OK ``status`` becomes ERROR)."""
    return cls(
        status=status if not status.ok else Status.ERROR,
        objective=float("nan"),
        method=method,
        message=message,
        **fields,
    )


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
            raise ProblemError(
                f"{name}.to_rows: this result is not a table (no per-item fields); use to_dict()"
            )
        arrays = {c.field: np.asarray(getattr(self, c.field)) for c in spec.columns}
        empty = any(a.size == 0 for a in arrays.values())
        n = 0 if empty or not arrays else next(iter(arrays.values())).shape[0]
        out: dict[str, np.ndarray] = {spec.index: np.arange(n)}
        for col in spec.columns:
            arr = arrays[col.field]
            if n == 0:  # a failure form: no rows (the columns of its arrays' shapes)
                arr = arr[:0] if arr.ndim and arr.shape[0] == 0 else np.empty(0, arr.dtype)
            if arr.ndim == 0 or arr.shape[0] != n:
                raise ProblemError(
                    f"{name}.to_rows: {col.field} has shape {arr.shape}, not {n} items"
                )
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
            raise ProblemError(
                f"{type(self).__name__}.to_frame: pandas is needed (pip install pandas)"
            ) from exc
        df = pd.DataFrame(self.table_columns())
        df.attrs.update(
            status=self.status.value, method=self.method, objective=float(self.objective)
        )
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
        labels = (
            self.labels
            if self.labels is not None and len(self.labels) == k
            else tuple(str(i) for i in range(k))
        )
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
    "optmodels.plane.solution.PlaneSolution": TableSpec(
        "point", (Column("projected", "", ("x_m", "y_m", "z_m")),)
    ),
    "optmodels.biasfield.solution.FieldSolution": TableSpec(
        "cell",
        (
            Column("centers", "", ("x_m", "y_m")),
            Column("field", "radar", ("range_bias_m", "azimuth_bias_rad")),
            Column("active", "radar", ("range_active", "azimuth_active")),
        ),
    ),
    "optmodels.trajectories.solution.TrajectorySolution": TableSpec(
        "object", (Column("start"), Column("velocity"))
    ),
    "optmodels.assignment.solution.AssignmentSolution": TableSpec(
        "measurement", (Column("assignment", "group"),)
    ),
    "optmodels.fusion.two_site_ml.JointMLSolution": TableSpec(
        "trial", (Column("estimate", "", ("x_m", "y_m")), Column("stationarity"))
    ),
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
                raise ProblemError(
                    f"{where}: the key {key!r} is given twice in one JSON "
                    f"object (which one is meant?)"
                )
            out[key] = value
        return out

    try:
        return json.loads(text, parse_constant=constant, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        raise ProblemError(
            f"{where}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
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
