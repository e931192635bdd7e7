"""NumPy archives and arrays (``.npz``, ``.npy``) and JSON documents, read with checks.

:func:`read_npz` and :func:`read_npy` check the format's magic bytes before loading (pickles
refused), turning a truncated, foreign or object-array file into one
:class:`~optmodels.core.ProblemError` naming it; :func:`read_json` reads a UTF-8 JSON
document (``NaN``/``Infinity`` refused). No equations (file handling only).
"""

from __future__ import annotations

import os
import zipfile
import zlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import ProblemError, json_document
from optmodels.io.paths import as_path, input_file, read_text

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


def read_npz(
    path: str | os.PathLike[str],
    *,
    what: str = ".npz archive",
    required: Iterable[str] = (),
    one_of: Iterable[str] = (),
) -> dict[str, np.ndarray]:
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
        kind = "a single NumPy .npy array" if head.startswith(b"\x93NUMPY") else "not a ZIP archive"
        raise ProblemError(f"{p}: {kind}, expected a {what} (written by numpy.savez)")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except ValueError as exc:
        if "pickle" in str(exc).lower() or "object arrays" in str(exc).lower():
            raise ProblemError(
                f"{p}: holds object (pickled) arrays, which are not loaded; "
                f"expected a {what} of numeric arrays"
            ) from None
        raise ProblemError(f"{p}: corrupt {what} ({exc})") from None
    except (
        zipfile.BadZipFile,
        EOFError,
        zlib.error,
        OSError,
        KeyError,
        NotImplementedError,
    ) as exc:
        raise ProblemError(
            f"{p}: truncated or corrupt {what} ({type(exc).__name__}: {exc})"
        ) from None
    need = list(required)
    missing = [k for k in need if k not in arrays]
    options = list(one_of)
    if options and not any(k in arrays for k in options):
        missing.append(" or ".join(options))
    if missing:
        raise ProblemError(
            f"{p}: missing array(s) {', '.join(missing)} (it has "
            f"{', '.join(sorted(arrays)) or 'none'}); not a {what}?"
        )
    return arrays


# --------------------------------------------------------------------------- JSON, .npy
def read_json(path: str | os.PathLike[str], *, what: str = "JSON file") -> Any:
    """The document of a UTF-8 JSON file (BOM allowed), read by the package's one strict
    reader (:func:`optmodels.core.json_document`): ``NaN``/``Infinity`` and a key given twice
    in one object refused.

    Raises
    ------
    ProblemError
        Naming the file: any problem of :func:`read_text`; invalid JSON (with the line
        and column); a non-standard ``NaN``/``Infinity`` constant; a duplicated key.
    """
    p = as_path("path", path)
    return json_document(read_text(p, what=what), where=str(p))


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
        kind = (
            "an .npz archive"
            if head.startswith(_ZIP_MAGIC)
            else "an empty file"
            if not head
            else "not a NumPy .npy file"
        )
        raise ProblemError(f"{p}: {kind}, expected a {what} (written by numpy.save)")
    try:
        with p.open("rb") as fh:
            return np.load(fh, allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc).lower() or "object arrays" in str(exc).lower():
            raise ProblemError(
                f"{p}: holds an object (pickled) array, which is not loaded; "
                f"expected a {what} of numbers"
            ) from None
        raise ProblemError(f"{p}: truncated or corrupt {what} ({exc})") from None
    except (EOFError, OSError) as exc:
        raise ProblemError(
            f"{p}: truncated or corrupt {what} ({type(exc).__name__}: {exc})"
        ) from None
