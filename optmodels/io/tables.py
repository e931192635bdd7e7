"""CSV tables: the generic reader and the plane and trajectory track files.

:func:`read_csv_rows` reads a comma-separated UTF-8 file (BOM allowed) into a header and
its non-blank rows with their file lines (:class:`CsvRows`); :func:`csv_numbers` turns a
column into floats, naming the first bad cell. :func:`read_plane_csv` reads the points x_i
of paper 000, (1.2) (with optional ``t``, α_i² or per-point covariance, :class:`PlaneCsv`);
:func:`read_trajectory_csv` reads the classified measurements of paper 002.
(Named ``tables`` so that it does not shadow the standard-library ``csv``.)
"""

from __future__ import annotations

import csv
import datetime as _dt
import io as _stdio
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_flag
from optmodels.io.paths import as_path, read_text

_COV_COLUMNS = ("cxx", "cxy", "cxz", "cyy", "cyz", "czz")


# --------------------------------------------------------------------------- CSV
class CsvRows(NamedTuple):
    """A CSV file as text: ``header`` (names stripped, lower-case), the non-blank data
    ``rows`` (lists of cells, each as long as the header) and the 1-based file ``lines``
    where each row starts."""

    header: list[str]
    rows: list[list[str]]
    lines: list[int]


def read_csv_rows(path: str | os.PathLike[str], *, what: str = "CSV file") -> CsvRows:
    """Header and non-blank data rows of a comma-separated UTF-8 file (BOM allowed).

    Columns with an empty header and no data (a trailing separator written by spreadsheet
    programs) are dropped.

    Raises
    ------
    ProblemError
        Naming the file: any problem of :func:`read_text`; malformed CSV (with the line);
        an empty file or no data rows; an unnamed column with data; a duplicate column
        name (case-blind); a row whose number of fields differs from the header's.
    """
    p = as_path("path", path)
    text = read_text(p, what=what)
    reader = csv.reader(_stdio.StringIO(text, newline=""), strict=True)
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        header_row = next(reader, None)
        if header_row is None:
            raise ProblemError(f"{p}: empty file (expected a header line)")
        while True:
            start = reader.line_num + 1
            r = next(reader, None)
            if r is None:
                break
            if "".join(r).strip():  # not a blank line (C-level test, fast)
                rows.append(r)
                lines.append(start)
    except csv.Error as exc:
        raise ProblemError(f"{p}: line {reader.line_num}: malformed CSV ({exc})") from None
    header = [h.strip().lower() for h in header_row]
    if len(header) == 1 and ";" in header[0]:
        raise ProblemError(
            f"{p}: the header {header_row[0]!r} looks semicolon-separated; "
            "save the file with comma separators (and decimal points)"
        )
    if not rows:
        raise ProblemError(f"{p}: no data rows")
    for r, line in zip(rows, lines, strict=True):
        if len(r) != len(header):
            raise ProblemError(
                f"{p}: line {line} has {len(r)} fields, the header has {len(header)}"
            )
    keep = [j for j, h in enumerate(header) if h or any(r[j].strip() for r in rows)]
    if len(keep) < len(header):
        header = [header[j] for j in keep]
        rows = [[r[j] for j in keep] for r in rows]
    for j, h in enumerate(header):
        if not h:
            raise ProblemError(f"{p}: column {j + 1} has data but no name in the header")
        if h in header[:j]:
            raise ProblemError(f"{p}: column {h!r} appears more than once in the header")
    return CsvRows(header, rows, lines)


def csv_numbers(
    path: str | os.PathLike[str],
    column: str,
    cells: Sequence[Any] | np.ndarray,
    lines: Sequence[int] | None = None,
    *,
    finite: bool = True,
) -> FloatArray:
    """A column of CSV cells (text) or of a Parquet table (numbers) as floats.

    ``path`` and ``column`` name the file and the column in the messages; ``lines`` gives
    the file line of each cell for the messages (else the row number). The columns named
    in :data:`TIME_COLUMNS` may hold ISO 8601 date-times (read by :func:`csv_times`).

    Raises
    ------
    ProblemError
        Naming the file, the column and the line of the first cell that is not a number
        (or, with ``finite``, is NaN/inf); naming the argument for a ``column`` that is
        not text, ``cells`` that are not one cell per row (text, a mapping, ragged or
        nested lists), ``lines`` that are not one whole number per cell, or a ``finite``
        that is not True/False.
    """
    arr, lines = _cells("io.csv_numbers", column, cells, lines)
    return _numbers(path, column, arr, lines, finite=as_flag("io.csv_numbers finite", finite))


def _cells(fn: str, column: Any, cells: Any, lines: Any) -> tuple[np.ndarray, Sequence[int] | None]:
    """The arguments of :func:`csv_numbers` / :func:`csv_times` checked: ``cells`` as a
    1-D array, ``lines`` one whole number per cell (or None)."""
    if not isinstance(column, str):
        raise ProblemError(
            f"{fn} column: expected the column's name (text), got "
            f"{type(column).__name__} {column!r:.40}"
        )
    for name, v in (("cells", cells), ("lines", lines)):
        if isinstance(v, str | bytes | Mapping):
            raise ProblemError(
                f"{fn} {name}: expected one value per row (a list or 1-D array), got "
                f"{type(v).__name__} {v!r:.40}"
            )
    try:
        arr = np.asarray(cells)
    except (TypeError, ValueError):  # ragged nested lists
        raise ProblemError(
            f"{fn} cells: expected one cell per row (a list or 1-D array), got "
            f"nested lists of different lengths {cells!r:.40}"
        ) from None
    if arr.ndim != 1:
        raise ProblemError(
            f"{fn} cells: expected one cell per row (a list or 1-D array), got shape {arr.shape}"
        )
    if lines is not None:
        try:
            ln = np.asarray(lines)
        except (TypeError, ValueError):
            ln = np.zeros((0, 0))
        if ln.ndim != 1 or (ln.size and ln.dtype.kind not in "iu") or ln.size != arr.size:
            raise ProblemError(
                f"{fn} lines: expected {arr.size} file line numbers (whole numbers, one per "
                f"cell), got {type(lines).__name__} {lines!r:.40}"
            )
    return arr, lines


def _numbers(
    path: Any, column: str, arr: np.ndarray, lines: Sequence[int] | None, *, finite: bool
) -> FloatArray:
    """:func:`csv_numbers` of checked arguments."""

    def where(i: int) -> str:
        return f"line {lines[i]}" if lines is not None else f"row {i + 1}"

    if column in TIME_COLUMNS and (
        arr.dtype.kind == "M"
        or (arr.size and isinstance(arr.flat[0], str) and _ISO.match(arr.flat[0].strip()))
    ):
        return _times(path, column, arr, lines, None)[0]
    if arr.dtype.kind == "M":
        raise ProblemError(f"{path}: column {column!r} holds date-times, expected numbers")
    values = None
    if arr.dtype.kind != "c":  # complex: refused cell by cell below, not cast
        try:
            values = arr.astype(float)
        except (TypeError, ValueError, OverflowError):
            values = None
    if values is None:
        for i, c in enumerate(arr):
            cell = c.item() if isinstance(c, np.generic) else c
            try:
                float(cell)  # a complex cell: TypeError
            except (TypeError, ValueError, OverflowError):
                raise ProblemError(
                    f"{path}: {where(i)}, column {column!r}: {cell!r:.40} is not a number"
                ) from None
        raise ProblemError(f"{path}: column {column!r} is not a column of numbers")
    if finite:
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise ProblemError(
                f"{path}: {where(i)}, column {column!r}: {values[i]} (NaN/inf;"
                f" {bad.size} such value(s) in the column, need finite numbers)"
            )
    return values


#: columns read as times: numbers (s) or ISO 8601 date-times (see :func:`csv_times`)
TIME_COLUMNS = ("time", "t", "timestamp")
_ISO = re.compile(
    r"^\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?)?"
    r"(Z|[+-]\d{2}:?\d{2})?$"
)


def csv_times(
    path: str | os.PathLike[str],
    column: str,
    cells: Sequence[Any] | np.ndarray,
    lines: Sequence[int] | None = None,
    *,
    epoch: Any = None,
) -> tuple[FloatArray, np.datetime64 | None]:
    """A time column as seconds: numbers (s, returned as they are, epoch None) or ISO 8601
    date-times (``2026-03-01T12:00:05.25``, a space for the ``T``, ``Z`` or ``±HH:MM``
    offsets; naive times are UTC, as :func:`optmodels.biasfield.frames.from_frame` takes
    them), or numpy ``datetime64`` cells (a Parquet timestamp column): seconds since
    ``epoch`` (an ISO 8601 text, a ``datetime.date``/``datetime`` or a ``datetime64``;
    default: UTC midnight of the earliest time), returned with the epoch
    (``datetime64[ns]``). :func:`csv_numbers` reads the columns named in
    :data:`TIME_COLUMNS` through this (dropping the epoch).

    Raises
    ------
    ProblemError
        Naming the file, the column and the line of the first cell that is neither a
        number nor an ISO date-time, or a column that mixes the two; naming the argument
        for an ``epoch`` that is not a date-time (a number, NaT, other text) and for the
        bad ``column``, ``cells`` and ``lines`` of :func:`csv_numbers`.
    """
    arr, lines = _cells("io.csv_times", column, cells, lines)
    e = None if epoch is None else _epoch("io.csv_times epoch", epoch)
    return _times(path, column, arr, lines, e)


def _iso_ns(text: str) -> np.datetime64:
    """An ISO 8601 date-time (checked against :data:`_ISO`) as UTC ``datetime64[ns]``."""
    d = _dt.datetime.fromisoformat(text.replace(" ", "T", 1))
    if d.tzinfo is not None:
        d = d.astimezone(_dt.UTC).replace(tzinfo=None)
    return np.datetime64(d, "ns")


def _epoch(name: str, epoch: Any) -> np.datetime64:
    """``epoch`` as ``datetime64[ns]`` (UTC): ISO 8601 text, a date/datetime (an aware one
    converted to UTC) or a datetime64; numbers, NaT and other text refused."""
    why = "a number" if isinstance(epoch, bool | int | float | complex | np.number) else None
    e: np.datetime64 = np.datetime64("NaT", "ns")
    if why is None:
        try:
            if isinstance(epoch, str):
                if not _ISO.match(epoch.strip()):
                    raise ValueError("not ISO 8601")
                e = _iso_ns(epoch.strip())
            else:
                if isinstance(epoch, _dt.datetime) and epoch.tzinfo is not None:
                    epoch = epoch.astimezone(_dt.UTC).replace(tzinfo=None)
                e = np.datetime64(epoch, "ns")
        except (TypeError, ValueError, OverflowError) as exc:
            why = str(exc)
    if why is None and np.isnat(e):
        why = "NaT"
    if why is not None:
        raise ProblemError(
            f"{name}: expected a date-time (ISO 8601 text such as '2026-03-01', a "
            f"datetime.date/datetime or a numpy datetime64), got {epoch!r:.40} ({why:.60})"
        )
    return e


def _times(
    path: Any,
    column: str,
    arr: np.ndarray,
    lines: Sequence[int] | None,
    epoch: np.datetime64 | None,
) -> tuple[FloatArray, np.datetime64 | None]:
    """:func:`csv_times` of checked arguments."""

    def where(i: int) -> str:
        return f"line {lines[i]}" if lines is not None else f"row {i + 1}"

    if arr.dtype.kind == "M":
        ns = arr.astype("datetime64[ns]")
        if np.isnat(ns).any():
            i = int(np.flatnonzero(np.isnat(ns))[0])
            raise ProblemError(f"{path}: {where(i)}, column {column!r}: missing time (NaT)")
    else:
        first = str(arr.flat[0]).strip() if arr.size else ""
        if not _ISO.match(first):
            return _numbers(path, column, arr, lines, finite=True), None
        out = np.empty(arr.size, "datetime64[ns]")
        for i, c in enumerate(arr):
            text = str(c).strip()
            if not _ISO.match(text):
                raise ProblemError(
                    f"{path}: {where(i)}, column {column!r}: {text!r:.40} is "
                    "not an ISO 8601 date-time (the column starts with one; "
                    "give all times as date-times or all as seconds)"
                )
            try:
                out[i] = _iso_ns(text)
            except ValueError as exc:
                raise ProblemError(
                    f"{path}: {where(i)}, column {column!r}: {text!r:.40}: {exc}"
                ) from None
        ns = out
    if epoch is None and not ns.size:  # no times: no earliest day to count from
        return np.zeros(0), None
    e = ns.min().astype("datetime64[D]").astype("datetime64[ns]") if epoch is None else epoch
    return (ns - e).astype("timedelta64[ns]").astype(np.int64) / 1e9, e


def _columns(p: Path, table: CsvRows, names: Sequence[str]) -> dict[str, FloatArray]:
    col = {h: j for j, h in enumerate(table.header)}
    return {c: csv_numbers(p, c, [r[col[c]] for r in table.rows], table.lines) for c in names}


class PlaneCsv(dict[str, FloatArray]):
    """Columns of a plane CSV: ``points`` (N, 3) and optional ``t``, ``alpha2``, ``cov``
    ((N, 3, 3) from ``cxx, cxy, cxz, cyy, cyz, czz``)."""


def read_plane_csv(path: str | os.PathLike[str], *, require_time: bool = False) -> PlaneCsv:
    """Read a plane-of-maneuver track (paper 000, the points x_i of (1.2)).

    Columns ``x, y, z`` (m) and optional ``t`` (s), ``alpha2`` (the α_i² of D_i = α_i² D)
    or the per-point covariance ``cxx, cxy, cxz, cyy, cyz, czz`` (m²). Column order is
    free; names are case-blind; other columns are ignored. UTF-8 with or without a BOM.
    With ``require_time`` (``optmodels plane track``) the ``t`` column must be present
    and strictly increasing.

    Raises
    ------
    ProblemError
        Naming the file: see :func:`read_csv_rows`; a missing column; a cell that is not
        a finite number (with its line and column); an incomplete covariance; with
        ``require_time``, no ``t`` or a time not after the previous one (with its line).
    """
    p = as_path("io.read_plane_csv path", path)
    table = read_csv_rows(p, what="plane CSV")
    col = set(table.header)
    if require_time and "t" not in col:
        raise ProblemError(
            f"{p}: missing column t (the measurement times, s, are needed "
            f"for a track; have {', '.join(table.header)})"
        )
    missing = [c for c in ("x", "y", "z") if c not in col]
    if missing:
        raise ProblemError(
            f"{p}: missing column(s) {', '.join(missing)} (need x, y, z; "
            f"have {', '.join(table.header)})"
        )
    present = [c for c in _COV_COLUMNS if c in col]
    if present and len(present) != 6:
        raise ProblemError(
            f"{p}: per-point covariance needs all of {', '.join(_COV_COLUMNS)}"
            f" (missing {', '.join(c for c in _COV_COLUMNS if c not in col)})"
        )
    names = ["x", "y", "z", *(c for c in ("t", "alpha2") if c in col), *present]
    v = _columns(p, table, names)
    out = PlaneCsv(points=np.column_stack([v["x"], v["y"], v["z"]]))
    if "t" in v:
        out["t"] = v["t"]
        if require_time:
            back = np.flatnonzero(np.diff(v["t"]) <= 0)
            if back.size:
                i = int(back[0]) + 1
                raise ProblemError(
                    f"{p}: line {table.lines[i]}, column 't': {v['t'][i]:.17g} s is not after "
                    f"the previous row's {v['t'][i - 1]:.17g} s (times must be strictly "
                    "increasing; sort the file by t)"
                )
    if "alpha2" in v:
        out["alpha2"] = v["alpha2"]
    if present:
        out["cov"] = np.stack(
            [
                np.stack([v["cxx"], v["cxy"], v["cxz"]], axis=-1),
                np.stack([v["cxy"], v["cyy"], v["cyz"]], axis=-1),
                np.stack([v["cxz"], v["cyz"], v["czz"]], axis=-1),
            ],
            axis=-2,
        )
    return out


def read_trajectory_csv(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read classified measurements for the dependent-trajectories problem (paper 002).

    Columns ``object, t, y`` (1-D) or ``object, t, x, y`` / ``object, t, x, y, z`` (m,
    t in s), optional ``sigma2`` (per-row variance, m²). ``object`` is any non-empty
    label; objects keep the order of their first row. UTF-8 with or without a BOM.

    Returns
    -------
    dict
        ``objects`` (labels), ``coordinates``, ``times``, ``values`` (lists per object)
        and ``sigma2`` (list per object or None).

    Raises
    ------
    ProblemError
        Naming the file: see :func:`read_csv_rows`; a missing column; an empty label; a
        cell that is not a finite number (with its line and column).
    """
    p = as_path("io.read_trajectory_csv path", path)
    table = read_csv_rows(p, what="trajectory CSV")
    col = {h: i for i, h in enumerate(table.header)}
    for need in ("object", "t"):
        if need not in col:
            raise ProblemError(f"{p}: missing column {need!r} (need object, t, y or x, y[, z])")
    coords = ["x", "y", "z"] if "z" in col else ["x", "y"] if "x" in col else ["y"]
    missing = [c for c in coords if c not in col]
    if missing:
        raise ProblemError(f"{p}: missing column(s) {', '.join(missing)}")
    num = ["t", *coords] + (["sigma2"] if "sigma2" in col else [])
    v = _columns(p, table, num)
    labels = [r[col["object"]].strip() for r in table.rows]
    if "" in labels:
        raise ProblemError(f"{p}: line {table.lines[labels.index('')]}: empty 'object' label")
    data = np.column_stack([v[c] for c in num])
    groups: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        groups.setdefault(label, []).append(i)
    arrays = {k: data[idx] for k, idx in groups.items()}
    nc = len(coords)
    return {
        "objects": list(arrays),
        "coordinates": coords,
        "times": [a[:, 0] for a in arrays.values()],
        "values": [a[:, 1] if nc == 1 else a[:, 1 : 1 + nc] for a in arrays.values()],
        "sigma2": [a[:, 1 + nc] for a in arrays.values()] if "sigma2" in col else None,
    }
