"""``results.csv`` of the comparison harness: its columns, lines, reading and repair.

:data:`COLUMNS` (fixed, in order) and :data:`KEY` (the columns that identify a run, for
resume), one row as one CSV line (:func:`_csv_line`), a line back to a row
(:func:`_parse_line`, :func:`_parse`), the file opened through
:class:`optmodels.montecarlo.LineLog` (header written, unreadable lines moved to
``results.csv.skipped``: :func:`_load_results`) and read-only (:func:`read_results`).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from optmodels.core import ProblemError
from optmodels.execution import LineLog, report_skipped
from optmodels.io import csv_cell

#: Fixed columns of ``results.csv`` (DESIGN.md, "Solver comparison"), in order.
COLUMNS = (
    "problem",
    "instance",
    "size",
    "seed",
    "formulation",
    "solver",
    "settings",
    "status",
    "success",
    "reason",
    "objective",
    "objective_gap",
    "solution_error",
    "max_violation",
    "build_time",
    "solve_time",
    "iterations",
    "message",
    "solver_version",
    "cpu",
    "time_limit",
    "options",
    "repeats",
    "build_again",
    "repeats_done",
    "estimate_sq_error",
    "crb",
)
#: What identifies a run for resume: the case, the formulation and solver, the settings
#: profile, the time limit (s), the options that reach the solver (JSON: the profile's and
#: the back-end's class defaults, :func:`solvers_cmp.harness.profiles.options_key`), the
#: solver's version and the timing repetitions. A rerun recomputes every row whose key
#: differs (issue 27: a rerun with ``--time-limit 5`` used to return the 60 s rows).
KEY = (
    "problem",
    "instance",
    "size",
    "seed",
    "formulation",
    "solver",
    "settings",
    "time_limit",
    "options",
    "solver_version",
    "repeats",
)


def _header_line() -> str:
    return _csv_line(dict(zip(COLUMNS, COLUMNS, strict=True)))


def _csv_line(row: Mapping[str, Any]) -> str:
    """One CSV line, newlines in cells replaced by spaces (a row is always one line)."""
    buf = io.StringIO()
    cells = [csv_cell(row.get(c)) for c in COLUMNS]
    cells = [" ".join(str(v).splitlines()) if isinstance(v, str) else v for v in cells]
    csv.writer(buf, lineterminator="").writerow(cells)
    return buf.getvalue()


def _parse_line(raw: bytes) -> dict[str, Any] | None:
    """A row of ``results.csv``, or None if the line is not a complete, readable row."""
    try:
        cells = next(csv.reader([raw.decode()]))
        if len(cells) != len(COLUMNS):
            return None
        return {k: _parse(k, v) for k, v in zip(COLUMNS, cells, strict=True)}
    except (UnicodeDecodeError, ValueError, csv.Error, StopIteration):
        return None


def _load_results(rl: LineLog) -> list[dict[str, Any]]:
    """The readable rows of ``results.csv`` (held by ``rl``); writes the header of a new
    or empty file and moves unreadable lines to ``results.csv.skipped`` (logged)."""
    head = _header_line()
    lines, tail = rl.open_with_header(head, "a results file of this harness")
    if not lines:
        return []
    first = lines[0].decode(errors="replace").strip()
    if first != head and _older_header(first):
        # a results file of an earlier version of this harness (fewer columns, issue 27
        # added the efficiency ones): its rows cannot be reused, they are moved to
        # results.csv.skipped and run again -- never silently mixed in
        moved = rl.rewrite([head], lines[1:] + ([tail] if tail else []))
        report_skipped(rl.what, rl.path, len(lines) - 1, len(tail), moved)
        return []
    if first != head:
        raise ProblemError(
            f"{rl.what}: {rl.path} has other columns than this harness "
            f"writes ({', '.join(COLUMNS)}); use another --out or delete it"
        )
    rows, keep, dropped = [], [head], []
    for raw in lines[1:]:
        if not raw.strip():
            continue
        row = _parse_line(raw)
        if row is None:
            dropped.append(raw)
        else:
            rows.append(row)
            keep.append(raw.decode())
    rl.keep(keep, dropped, tail)
    return rows


def _older_header(first: str) -> bool:
    """``first`` is the header of an earlier version of this harness: its columns are a
    strict prefix of :data:`COLUMNS`, from ``problem`` to at least ``repeats_done``."""
    try:
        cols = next(csv.reader([first]))
    except (csv.Error, StopIteration):
        return False
    return (
        0 < len(cols) < len(COLUMNS) and tuple(cols) == COLUMNS[: len(cols)] and "message" in cols
    )


def read_results(path: Path) -> list[dict[str, Any]]:
    """Rows of an existing ``results.csv`` (numbers parsed), or [] if there is none.
    Read-only: unreadable lines (a row cut short, garbage) are left out, not repaired."""
    path = Path(path)
    if not path.exists():
        return []
    if path.is_dir():
        raise ProblemError(f"compare results: {path} is a directory, expected a file")
    data = path.read_bytes()
    lines = data[: data.rfind(b"\n") + 1].split(b"\n")[:-1]  # without a cut-short tail
    rows = [_parse_line(raw) for raw in lines[1:] if raw.strip()]
    return [r for r in rows if r is not None]


def _parse(key: str, v: str) -> Any:
    if key in ("size", "seed", "repeats"):
        return int(v)
    if key == "repeats_done":
        return int(float(v)) if v not in ("", "None") else None
    if key == "iterations":
        return int(float(v)) if v not in ("", "None") else None
    if key == "success":
        if v not in ("True", "False"):
            raise ValueError(f"success: {v!r}")
        return v == "True"
    if key in (
        "objective",
        "objective_gap",
        "solution_error",
        "max_violation",
        "build_time",
        "solve_time",
        "time_limit",
        "build_again",
        "estimate_sq_error",
        "crb",
    ):
        return float(v) if v not in ("", "None") else float("nan")
    return v


def _key(row: dict[str, Any]) -> tuple[Any, ...]:
    return tuple(f"{float(row[k]):.6g}" if k == "time_limit" else str(row[k]) for k in KEY)
