"""Readers and writers for user data (CSV, ``.npz``) and results (CSV, Markdown, JSON).

Every reader turns a file it cannot use into one :class:`~optmodels.core.ProblemError`
naming the file (and, where it helps, the line, column or byte): a missing file, a
directory, a file without read permission, text that is not UTF-8 (with its byte offset),
binary data, a truncated or foreign archive. CSV files are read as UTF-8 with or without
the byte-order mark that spreadsheet programs write ("CSV UTF-8").

Every writer creates the missing parent folders of its output path and refuses a path
that is an existing directory (or whose parent is a file) with a ProblemError naming it.
"""

from __future__ import annotations

import codecs
import csv
import io as _stdio
import json
import os
import zipfile
import zlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_finite_array

__all__ = [
    "CsvRows",
    "PlaneCsv",
    "as_path",
    "csv_cell",
    "csv_numbers",
    "input_file",
    "json_default",
    "markdown_table",
    "output_dir",
    "output_file",
    "read_csv_rows",
    "read_json",
    "read_npy",
    "read_npz",
    "read_plane_csv",
    "read_text",
    "read_trajectory_csv",
    "write_csv",
    "write_json",
    "write_plane_csv",
]

_COV_COLUMNS = ("cxx", "cxy", "cxz", "cyy", "cyz", "czz")

# signatures of files that are often given where a text CSV is expected
_MAGIC = (
    (b"PAR1", "a Parquet file (give it the .parquet suffix where Parquet is accepted)"),
    (b"PK\x03\x04", "a ZIP archive (an .npz or .xlsx file?), not CSV text"),
    (b"\x93NUMPY", "a NumPy .npy file, not CSV text"),
    (b"\x1f\x8b", "gzip-compressed (decompress it first)"),
)


# --------------------------------------------------------------------------- paths
def as_path(name: str, value: Any) -> Path:
    """A file-system path argument as :class:`~pathlib.Path`.

    Raises
    ------
    ProblemError
        Naming ``name`` if ``value`` is not a ``str``/``os.PathLike`` or is empty.
    """
    if isinstance(value, bytes) or not isinstance(value, str | os.PathLike):
        raise ProblemError(f"{name}: expected a file path, got {type(value).__name__} "
                           f"{value!r:.60}")
    text = os.fspath(value)
    if not text or "\x00" in text:
        raise ProblemError(f"{name}: not a usable file path: {text!r:.60}")
    return Path(text)


def input_file(path: str | os.PathLike[str], *, what: str = "file",
               name: str = "path") -> Path:
    """An existing, readable regular file.

    Raises
    ------
    ProblemError
        Naming the path: no such file, a directory, not readable (permission).
    """
    p = as_path(name, path)
    try:
        if p.is_dir():
            raise ProblemError(f"{p}: is a directory, expected a {what}")
        if not p.exists():
            raise ProblemError(f"{p}: no such file (expected a {what})")
        if not p.is_file():
            raise ProblemError(f"{p}: not a regular file (expected a {what})")
        if not os.access(p, os.R_OK):
            raise ProblemError(f"{p}: permission denied (cannot read the {what})")
    except OSError as exc:  # e.g. a path component that is a file, a name too long
        raise ProblemError(f"{p}: cannot open the {what} ({exc.strerror or exc})") from None
    return p


def _read_bytes(p: Path, what: str) -> bytes:
    try:
        return p.read_bytes()
    except PermissionError:
        raise ProblemError(f"{p}: permission denied (cannot read the {what})") from None
    except IsADirectoryError:
        raise ProblemError(f"{p}: is a directory, expected a {what}") from None
    except FileNotFoundError:
        raise ProblemError(f"{p}: no such file (expected a {what})") from None
    except OSError as exc:
        raise ProblemError(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None


def read_text(path: str | os.PathLike[str], *, what: str = "text file",
              name: str = "path") -> str:
    """The text of a UTF-8 file (a leading byte-order mark is dropped).

    Raises
    ------
    ProblemError
        Naming the file: the path problems of :func:`input_file`; UTF-16 text; binary
        data (a NUL byte, or the signature of a Parquet/ZIP/.npy/gzip file); text that is
        not UTF-8 (Latin-1, Windows-1251, ...), with the byte offset and line of the first
        byte that does not decode.
    """
    p = input_file(path, what=what, name=name)
    data = _read_bytes(p, what)
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise ProblemError(f"{p}: UTF-16 text; save the {what} as UTF-8 (e.g. 'CSV UTF-8')")
    for magic, text in _MAGIC:
        if data.startswith(magic):
            raise ProblemError(f"{p}: {text}")
    nul = data.find(b"\x00")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise ProblemError(f"{p}: binary data (a NUL byte at byte {nul}, line {line}); "
                           f"expected a text {what}")
    skip = len(codecs.BOM_UTF8) if data.startswith(codecs.BOM_UTF8) else 0
    try:
        return data[skip:].decode("utf-8")
    except UnicodeDecodeError as exc:
        pos = skip + exc.start
        line = data.count(b"\n", 0, pos) + 1
        raise ProblemError(
            f"{p}: not UTF-8 text (byte 0x{data[pos]:02x} at byte {pos}, line {line}); "
            f"save the {what} as UTF-8 (e.g. 'CSV UTF-8')"
        ) from None


def output_file(path: str | os.PathLike[str], *, name: str = "path") -> Path:
    """Prepare a path to write a file to: its missing parent folders are created.

    Raises
    ------
    ProblemError
        Naming the path if it is an existing directory, if a parent is an existing file,
        or if the parent folder cannot be created (permission).
    """
    p = as_path(name, path)
    if p.is_dir():
        raise ProblemError(f"{p}: is an existing directory; give a file name to write to")
    _make_dir(p.parent, what="the folder of")
    return p


def output_dir(path: str | os.PathLike[str], *, name: str = "path") -> Path:
    """Prepare a folder to write results into, creating it (and its parents) if missing.

    Raises
    ------
    ProblemError
        Naming the path if it (or a parent) is an existing file, or cannot be created.
    """
    p = as_path(name, path)
    _make_dir(p, what="the output folder")
    return p


def _make_dir(d: Path, *, what: str) -> None:
    try:
        d.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise ProblemError(f"{d}: cannot create {what} (it, or a parent, is an existing "
                           "file)") from None
    except OSError as exc:
        raise ProblemError(f"{d}: cannot create {what} ({exc.strerror or exc})") from None


def _write_text(p: Path, text: str, *, newline: str | None = None) -> None:
    try:
        with p.open("w", encoding="utf-8", newline=newline) as fh:
            fh.write(text)
    except OSError as exc:
        raise ProblemError(f"{p}: cannot write ({exc.strerror or exc})") from None


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
        raise ProblemError(f"{p}: the header {header_row[0]!r} looks semicolon-separated; "
                           "save the file with comma separators (and decimal points)")
    if not rows:
        raise ProblemError(f"{p}: no data rows")
    for r, line in zip(rows, lines, strict=True):
        if len(r) != len(header):
            raise ProblemError(f"{p}: line {line} has {len(r)} fields, the header has "
                               f"{len(header)}")
    keep = [j for j, h in enumerate(header)
            if h or any(r[j].strip() for r in rows)]
    if len(keep) < len(header):
        header = [header[j] for j in keep]
        rows = [[r[j] for j in keep] for r in rows]
    for j, h in enumerate(header):
        if not h:
            raise ProblemError(f"{p}: column {j + 1} has data but no name in the header")
        if h in header[:j]:
            raise ProblemError(f"{p}: column {h!r} appears more than once in the header")
    return CsvRows(header, rows, lines)


def csv_numbers(path: str | os.PathLike[str], column: str, cells: Sequence[Any],
                lines: Sequence[int] | None = None, *, finite: bool = True) -> FloatArray:
    """A column of CSV cells (text) or of a Parquet table (numbers) as floats.

    ``lines`` gives the file line of each cell for the messages (else the row number).

    Raises
    ------
    ProblemError
        Naming the file, the column and the line of the first cell that is not a number
        (or, with ``finite``, is NaN/inf).
    """
    arr = np.asarray(cells)

    def where(i: int) -> str:
        return f"line {lines[i]}" if lines is not None else f"row {i + 1}"

    try:
        values = arr.astype(float)
    except (TypeError, ValueError, OverflowError):
        values = None
    if values is None or values.ndim != 1:
        for i, c in enumerate(arr.reshape(-1) if arr.ndim else [arr.item()]):
            try:
                float(c)
            except (TypeError, ValueError, OverflowError):
                cell = c.item() if isinstance(c, np.generic) else c
                raise ProblemError(f"{path}: {where(i)}, column {column!r}: {cell!r:.40} is "
                                   "not a number") from None
        raise ProblemError(f"{path}: column {column!r} is not a column of numbers")
    if finite:
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise ProblemError(f"{path}: {where(i)}, column {column!r}: {values[i]} (NaN/inf;"
                               f" {bad.size} such value(s) in the column, need finite numbers)")
    return values


def _columns(p: Path, table: CsvRows, names: Sequence[str]) -> dict[str, FloatArray]:
    col = {h: j for j, h in enumerate(table.header)}
    return {c: csv_numbers(p, c, [r[col[c]] for r in table.rows], table.lines) for c in names}


class PlaneCsv(dict):
    """Columns of a plane CSV: ``points`` (N, 3) and optional ``t``, ``alpha2``, ``cov``
    ((N, 3, 3) from ``cxx, cxy, cxz, cyy, cyz, czz``)."""


def read_plane_csv(path: str | os.PathLike[str]) -> PlaneCsv:
    """Read a plane-of-maneuver track (paper 000, the points x_i of (1.2)).

    Columns ``x, y, z`` (m) and optional ``t`` (s), ``alpha2`` (the α_i² of D_i = α_i² D)
    or the per-point covariance ``cxx, cxy, cxz, cyy, cyz, czz`` (m²). Column order is
    free; names are case-blind; other columns are ignored. UTF-8 with or without a BOM.

    Raises
    ------
    ProblemError
        Naming the file: see :func:`read_csv_rows`; a missing column; a cell that is not
        a finite number (with its line and column); an incomplete covariance.
    """
    p = as_path("io.read_plane_csv path", path)
    table = read_csv_rows(p, what="plane CSV")
    col = set(table.header)
    missing = [c for c in ("x", "y", "z") if c not in col]
    if missing:
        raise ProblemError(f"{p}: missing column(s) {', '.join(missing)} (need x, y, z; "
                           f"have {', '.join(table.header)})")
    present = [c for c in _COV_COLUMNS if c in col]
    if present and len(present) != 6:
        raise ProblemError(f"{p}: per-point covariance needs all of {', '.join(_COV_COLUMNS)}"
                           f" (missing {', '.join(c for c in _COV_COLUMNS if c not in col)})")
    names = ["x", "y", "z", *(c for c in ("t", "alpha2") if c in col), *present]
    v = _columns(p, table, names)
    out = PlaneCsv(points=np.column_stack([v["x"], v["y"], v["z"]]))
    if "t" in v:
        out["t"] = v["t"]
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
        "values": [a[:, 1] if nc == 1 else a[:, 1:1 + nc] for a in arrays.values()],
        "sigma2": [a[:, 1 + nc] for a in arrays.values()] if "sigma2" in col else None,
    }


# --------------------------------------------------------------------------- .npz
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a local file header; an empty archive


def _file_head(path: str | os.PathLike[str], what: str, size: int = 6) -> tuple[Path, bytes]:
    """The checked input path and its first ``size`` bytes (the format's magic)."""
    p = input_file(path, what=what)
    try:
        with p.open("rb") as fh:
            return p, fh.read(size)
    except OSError as exc:
        raise ProblemError(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None


def read_npz(path: str | os.PathLike[str], *, what: str = ".npz archive",
             required: Iterable[str] = (), one_of: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """All arrays of a NumPy ``.npz`` archive (pickles refused), checked for keys.

    Parameters
    ----------
    path
        The archive.
    what
        What the file should be, for the messages (e.g. ``"FieldData .npz"``).
    required
        Keys that must all be present.
    one_of
        Keys of which at least one must be present (if any are given).

    Raises
    ------
    ProblemError
        Naming the file: the path problems of :func:`input_file`; an empty file; a file
        that is not a ZIP archive (a text file renamed, a single ``.npy``); a truncated or
        corrupt archive (bad CRC, cut short); object (pickled) arrays; missing keys.
    """
    p, head = _file_head(path, what)
    if not head:
        raise ProblemError(f"{p}: empty file (expected a {what})")
    if not head.startswith(_ZIP_MAGIC):
        kind = ("a single NumPy .npy array" if head.startswith(b"\x93NUMPY")
                else "not a ZIP archive")
        raise ProblemError(f"{p}: {kind}, expected a {what} (written by numpy.savez)")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except ValueError as exc:
        if "pickle" in str(exc).lower() or "object arrays" in str(exc).lower():
            raise ProblemError(f"{p}: holds object (pickled) arrays, which are not loaded; "
                               f"expected a {what} of numeric arrays") from None
        raise ProblemError(f"{p}: corrupt {what} ({exc})") from None
    except (zipfile.BadZipFile, EOFError, zlib.error, OSError, KeyError,
            NotImplementedError) as exc:
        raise ProblemError(f"{p}: truncated or corrupt {what} ({type(exc).__name__}: "
                           f"{exc})") from None
    need = list(required)
    missing = [k for k in need if k not in arrays]
    options = list(one_of)
    if options and not any(k in arrays for k in options):
        missing.append(" or ".join(options))
    if missing:
        raise ProblemError(f"{p}: missing array(s) {', '.join(missing)} (it has "
                           f"{', '.join(sorted(arrays)) or 'none'}); not a {what}?")
    return arrays


# --------------------------------------------------------------------------- JSON, .npy
def read_json(path: str | os.PathLike[str], *, what: str = "JSON file") -> Any:
    """The document of a UTF-8 JSON file (BOM allowed); ``NaN``/``Infinity`` refused.

    Raises
    ------
    ProblemError
        Naming the file: any problem of :func:`read_text`; invalid JSON (with the line
        and column); a non-standard ``NaN``/``Infinity`` constant.
    """
    p = as_path("path", path)
    text = read_text(p, what=what)

    def constant(name: str) -> Any:
        raise ProblemError(f"{p}: {name} is not valid JSON (give a finite number or null)")

    try:
        return json.loads(text, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{p}: not valid JSON (line {exc.lineno}, column {exc.colno}: "
                           f"{exc.msg})") from None
    except RecursionError:
        raise ProblemError(f"{p}: JSON nested too deeply") from None


def read_npy(path: str | os.PathLike[str], *, what: str = ".npy array") -> np.ndarray:
    """A single NumPy ``.npy`` array (pickles refused).

    Raises
    ------
    ProblemError
        Naming the file: the path problems of :func:`input_file`; not an ``.npy`` (an
        ``.npz`` or a text file renamed); truncated or corrupt; object (pickled) arrays.
    """
    p, head = _file_head(path, what)
    if not head.startswith(b"\x93NUMPY"):
        kind = ("an .npz archive" if head.startswith(_ZIP_MAGIC) else
                "an empty file" if not head else "not a NumPy .npy file")
        raise ProblemError(f"{p}: {kind}, expected a {what} (written by numpy.save)")
    try:
        with p.open("rb") as fh:
            return np.load(fh, allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc).lower() or "object arrays" in str(exc).lower():
            raise ProblemError(f"{p}: holds an object (pickled) array, which is not loaded; "
                               f"expected a {what} of numbers") from None
        raise ProblemError(f"{p}: truncated or corrupt {what} ({exc})") from None
    except (EOFError, OSError) as exc:
        raise ProblemError(f"{p}: truncated or corrupt {what} ({type(exc).__name__}: "
                           f"{exc})") from None


# --------------------------------------------------------------------------- writers
def write_plane_csv(path: str | os.PathLike[str], points: FloatArray,
                    **columns: FloatArray) -> None:
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
    cols = [as_finite_array(f"io.write_plane_csv {k}", v, shape=(pts.shape[0],))
            for k, v in columns.items()]
    p = output_file(path, name="io.write_plane_csv path")
    buf = _stdio.StringIO()
    np.savetxt(buf, np.column_stack([pts, *cols]), delimiter=",",
               header=",".join(["x", "y", "z", *columns]), comments="", fmt="%.17g")
    _write_text(p, buf.getvalue())


def write_csv(path: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]]) -> None:
    """Tidy CSV (UTF-8): one row a mapping, columns in first-seen order. Missing parent
    folders are created.

    Raises
    ------
    ProblemError
        Naming the path if it is a directory or cannot be written; if a row is not a
        mapping.
    """
    cols: list[str] = []
    for i, r in enumerate(rows):
        if not isinstance(r, Mapping):
            raise ProblemError(f"io.write_csv rows: row {i} is a {type(r).__name__}, "
                               "expected a mapping")
        cols += [k for k in r if k not in cols]
    p = output_file(path, name="io.write_csv path")
    buf = _stdio.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in rows:
        w.writerow({k: csv_cell(r.get(k)) for k in cols})
    _write_text(p, buf.getvalue(), newline="")


def csv_cell(v: Any) -> Any:
    """A CSV cell: floats with 10 significant digits, anything else as is."""
    if isinstance(v, float | np.floating):
        return f"{float(v):.10g}"
    return v


def write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """``obj`` as indented JSON (NumPy arrays and scalars as lists and numbers). Missing
    parent folders are created.

    Raises
    ------
    ProblemError
        Naming the path if it is a directory or cannot be written.
    """
    p = output_file(path, name="io.write_json path")
    _write_text(p, json.dumps(obj, indent=2, default=json_default) + "\n")


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
