"""Writers of results: tidy CSV, plane CSV, JSON and Markdown tables.

:func:`write_plane_csv` writes the format :func:`~optmodels.io.read_plane_csv` reads
(paper 000 points, 17 digits so floats round-trip); :func:`write_csv` writes tidy rows
(cells by :func:`csv_cell`); :func:`write_json` writes indented JSON (NumPy values by
:func:`json_default`); :func:`markdown_table` formats rows as a GitHub-flavoured table.
Every writer creates missing parent folders (:func:`~optmodels.io.output_file`).
"""

from __future__ import annotations

import csv
import io as _stdio
import os
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_finite_array,
    as_instance,
    json_text,
    to_jsonable,
)
from optmodels.io.paths import _write_text, output_file


# --------------------------------------------------------------------------- writers
def write_plane_csv(
    path: str | os.PathLike[str], points: FloatArray, **columns: FloatArray
) -> None:
    """Write points (N, 3) (m) and optional per-point columns (``t``, ``alpha2``, the
    covariance ``cxx``...) in the format :func:`read_plane_csv` reads (17 digits: floats
    round-trip exactly). Missing parent folders are created.

    Raises
    ------
    ProblemError
        Naming the argument for points not (N, 3) finite or a column not (N,); naming
        the path if it cannot be written (see :func:`output_file`).
    """
    pts = as_finite_array("io.write_plane_csv points", points, ndim=2)
    if pts.shape[1] != 3:
        raise ProblemError(f"io.write_plane_csv points: expected (N, 3), got {pts.shape}")
    cols = [
        as_finite_array(f"io.write_plane_csv {k}", v, shape=(pts.shape[0],))
        for k, v in columns.items()
    ]
    p = output_file(path, name="io.write_plane_csv path")
    buf = _stdio.StringIO()
    np.savetxt(
        buf,
        np.column_stack([pts, *cols]),
        delimiter=",",
        header=",".join(["x", "y", "z", *columns]),
        comments="",
        fmt="%.17g",
    )
    _write_text(p, buf.getvalue())


def write_csv(path: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]]) -> None:
    """Tidy CSV (UTF-8): one row a mapping, columns in first-seen order. Missing parent
    folders are created.

    Raises
    ------
    ProblemError
        Naming the path if it is a directory or cannot be written; naming ``rows`` if it
        is not a sequence of mappings (text, a single mapping, a row of another type).
    """
    rows = _mapping_rows("io.write_csv rows", rows)
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    p = output_file(path, name="io.write_csv path")
    buf = _stdio.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in rows:
        w.writerow({k: csv_cell(r.get(k)) for k in cols})
    _write_text(p, buf.getvalue(), newline="")


def _mapping_rows(name: str, rows: Any) -> list[Mapping[str, Any]]:
    """``rows`` as a list of mappings (one a row), or one :class:`ProblemError` naming
    ``name``: text (read letter by letter), a single mapping (read key by key), a
    non-iterable or a row that is not a mapping is refused."""
    if isinstance(rows, str | bytes | Mapping) or not isinstance(rows, Iterable):
        raise ProblemError(
            f"{name}: expected a sequence of mappings (one a row), got {type(rows).__name__}"
        )
    out = list(rows)
    for i, r in enumerate(out):
        if not isinstance(r, Mapping):
            raise ProblemError(f"{name}: row {i} is a {type(r).__name__}, expected a mapping")
    return out


def csv_cell(v: Any) -> Any:
    """A CSV cell: floats with 10 significant digits, anything else as is."""
    if isinstance(v, float | np.floating):
        return f"{float(v):.10g}"
    return v


def write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """``obj`` as indented strict JSON through the package's one encoder
    (:func:`optmodels.core.to_jsonable`: NumPy arrays and scalars as lists and numbers,
    NaN and ±inf as ``null``). Missing parent folders are created.

    Raises
    ------
    ProblemError
        Naming the path if it is a directory or cannot be written; naming ``obj`` if it
        holds a value JSON has no form for (an object of another type, a reference cycle);
        nothing is written then.
    """
    p = output_file(path, name="io.write_json path")
    try:
        text = json_text(obj)
    except (TypeError, ValueError, RecursionError) as exc:
        why = "a reference cycle" if isinstance(exc, RecursionError) else str(exc)
        raise ProblemError(f"io.write_json obj: not JSON serialisable ({why:.80})") from None
    _write_text(p, text + "\n")


def json_default(o: Any) -> Any:
    """``json.dumps(default=...)`` for NumPy arrays and scalars, through the package's one
    encoder (:func:`optmodels.core.to_jsonable`; NaN and ±inf become ``null``)."""
    out = to_jsonable(o)
    if out is o:
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")
    return out


def markdown_table(
    rows: Iterable[Mapping[str, Any]],
    columns: Sequence[str],
    formats: Mapping[str, str] | None = None,
) -> str:
    """A GitHub-flavoured Markdown table of ``rows`` restricted to ``columns``.

    Raises
    ------
    ProblemError
        Naming ``rows`` if it is not a sequence of mappings; naming ``columns`` if it is
        not a list of names (text or a mapping would be read letter by letter, key by key).
    """
    rows = _mapping_rows("io.markdown_table rows", rows)
    if isinstance(columns, str | bytes | Mapping) or not isinstance(columns, Iterable):
        raise ProblemError(
            f"io.markdown_table columns: expected a sequence of column names, "
            f"got {type(columns).__name__}"
        )
    columns = list(columns)
    for i, c in enumerate(columns):
        as_instance(f"io.markdown_table columns[{i}]", c, str)
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
