"""Readers and writers for user data (CSV) and results (CSV, Markdown, JSON)."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import FloatArray, ProblemError

__all__ = [
    "PlaneCsv",
    "json_default",
    "markdown_table",
    "read_plane_csv",
    "read_trajectory_csv",
    "write_csv",
    "write_json",
]

_COV_COLUMNS = ("cxx", "cxy", "cxz", "cyy", "cyz", "czz")


class PlaneCsv(dict):
    """Columns of a plane CSV: ``points`` (N, 3) and optional ``t``, ``alpha2``, ``cov``
    ((N, 3, 3) from ``cxx, cxy, cxz, cyy, cyz, czz``)."""


def _read_rows(path: str | Path) -> tuple[list[str], list[list[str]]]:
    """Header (stripped, lower-case) and the non-blank data rows of a CSV file, as text."""
    p = Path(path)
    if not p.is_file():
        raise ProblemError(f"{p}: no such file")
    with p.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip().lower() for h in next(reader)]
        except StopIteration:
            raise ProblemError(f"{p}: empty file") from None
        rows = [r for r in reader if r and any(c.strip() for c in r)]
    if not rows:
        raise ProblemError(f"{p}: no data rows")
    return header, rows


def _read_columns(path: str | Path) -> tuple[list[str], np.ndarray]:
    p = Path(path)
    header, rows = _read_rows(p)
    try:
        values = np.array([[float(c) for c in r] for r in rows], dtype=float)
    except ValueError as exc:
        raise ProblemError(f"{p}: non-numeric value ({exc})") from exc
    if values.shape[1] != len(header):
        raise ProblemError(f"{p}: rows have {values.shape[1]} fields, header has {len(header)}")
    return header, values


def read_plane_csv(path: str | Path) -> PlaneCsv:
    """Read ``x, y, z`` (m) and optional ``t`` (s), ``alpha2``, or the per-point covariance
    ``cxx, cxy, cxz, cyy, cyz, czz`` (m²). Column order is free; names are case-blind."""
    header, values = _read_columns(path)
    col = {name: i for i, name in enumerate(header)}
    missing = [c for c in ("x", "y", "z") if c not in col]
    if missing:
        raise ProblemError(f"{path}: missing column(s) {', '.join(missing)} (need x, y, z)")
    out = PlaneCsv(points=values[:, [col["x"], col["y"], col["z"]]])
    if "t" in col:
        out["t"] = values[:, col["t"]]
    if "alpha2" in col:
        out["alpha2"] = values[:, col["alpha2"]]
    present = [c for c in _COV_COLUMNS if c in col]
    if present:
        if len(present) != 6:
            raise ProblemError(
                f"{path}: per-point covariance needs all of {', '.join(_COV_COLUMNS)}"
            )
        v = {c: values[:, col[c]] for c in _COV_COLUMNS}
        out["cov"] = np.stack(
            [
                np.stack([v["cxx"], v["cxy"], v["cxz"]], axis=-1),
                np.stack([v["cxy"], v["cyy"], v["cyz"]], axis=-1),
                np.stack([v["cxz"], v["cyz"], v["czz"]], axis=-1),
            ],
            axis=-2,
        )
    return out


def read_trajectory_csv(path: str | Path) -> dict[str, Any]:
    """Read classified measurements: columns ``object, t, y`` (1-D) or ``object, t, x, y``
    / ``object, t, x, y, z``, optional ``sigma2`` (per-row variance). ``object`` is any
    label; objects keep the order of their first row. Returns ``objects`` (labels),
    ``times``, ``values`` (lists per object) and ``sigma2`` (list per object or None)."""
    p = Path(path)
    header, rows = _read_rows(p)
    col = {h: i for i, h in enumerate(header)}
    for need in ("object", "t"):
        if need not in col:
            raise ProblemError(f"{p}: missing column {need!r} (need object, t, y or x, y[, z])")
    coords = ["x", "y", "z"] if "z" in col else ["x", "y"] if "x" in col else ["y"]
    missing = [c for c in coords if c not in col]
    if missing:
        raise ProblemError(f"{p}: missing column(s) {', '.join(missing)}")
    num = ["t", *coords] + (["sigma2"] if "sigma2" in col else [])
    groups: dict[str, list[list[float]]] = {}
    for k, r in enumerate(rows, start=2):
        if len(r) != len(header):
            raise ProblemError(f"{p}: line {k} has {len(r)} fields, header has {len(header)}")
        try:
            vals = [float(r[col[c]]) for c in num]
        except ValueError as exc:
            raise ProblemError(f"{p}: line {k}: non-numeric value ({exc})") from None
        groups.setdefault(r[col["object"]].strip(), []).append(vals)
    arrays = {k: np.array(v) for k, v in groups.items()}
    nc = len(coords)
    return {
        "objects": list(arrays),
        "coordinates": coords,
        "times": [a[:, 0] for a in arrays.values()],
        "values": [a[:, 1] if nc == 1 else a[:, 1:1 + nc] for a in arrays.values()],
        "sigma2": [a[:, 1 + nc] for a in arrays.values()] if "sigma2" in col else None,
    }


def write_plane_csv(path: str | Path, points: FloatArray, **columns: FloatArray) -> None:
    """Write points (and optional ``t``, ``alpha2`` columns) in the format read above."""
    names = ["x", "y", "z", *columns]
    data = np.column_stack([points, *columns.values()]) if columns else points
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")


def write_csv(path: str | Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Tidy CSV: one row a mapping, columns in first-seen order."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    with Path(path).open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: csv_cell(r.get(k)) for k in cols})


def csv_cell(v: Any) -> Any:
    """A CSV cell: floats with 10 significant digits, anything else as is."""
    if isinstance(v, float | np.floating):
        return f"{float(v):.10g}"
    return v


def write_json(path: str | Path, obj: Any) -> None:
    Path(path).write_text(json.dumps(obj, indent=2, default=json_default) + "\n")


def json_default(o: Any) -> Any:
    """``json.dumps(default=...)`` for NumPy arrays and scalars."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def markdown_table(rows: Iterable[Mapping[str, Any]], columns: Sequence[str],
                   formats: Mapping[str, str] | None = None) -> str:
    """A GitHub-flavoured Markdown table of ``rows`` restricted to ``columns``."""
    fmts = formats or {}
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        cells = []
        for c in columns:
            v = r.get(c, "")
            if isinstance(v, float | np.floating) and c in fmts:
                cells.append(format(float(v), fmts[c]))
            elif isinstance(v, float | np.floating):
                cells.append(f"{float(v):.4g}")
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
