"""Checked file-system access: path arguments, input files, output files and folders.

:func:`as_path` turns a path argument into a :class:`~pathlib.Path`; :func:`input_file`
checks an existing readable regular file; :func:`read_text` reads UTF-8 text (BOM dropped),
refusing UTF-16, binary data and non-UTF-8 bytes with the byte offset and line;
:func:`output_file` / :func:`output_dir` prepare a path to write to (missing parent folders
created); :func:`atomic_write` writes a file so that a kill or an error part-way leaves the
previous file untouched (temporary file in the target's folder, flush + fsync,
``os.replace``, the folder fsynced), and :func:`save_npz` writes an ``.npz`` archive through it.
Every writer of the package goes through :func:`atomic_write`. The private ``_read_bytes`` /
``_write_text`` / ``_make_dir`` turn ``OSError`` into one
:class:`~optmodels.core.ProblemError` naming the path. No equations (file handling only).
"""

from __future__ import annotations

import codecs
import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from optmodels.core import ProblemError, as_flag

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
        raise ProblemError(
            f"{name}: expected a file path, got {type(value).__name__} {value!r:.60}"
        )
    text = os.fspath(value)
    if not isinstance(text, str):  # an os.PathLike whose __fspath__ gives bytes
        raise ProblemError(f"{name}: expected a text file path, got {type(text).__name__}")
    if not text or "\x00" in text:
        raise ProblemError(f"{name}: not a usable file path: {text!r:.60}")
    return Path(text)


def input_file(path: str | os.PathLike[str], *, what: str = "file", name: str = "path") -> Path:
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


def read_text(path: str | os.PathLike[str], *, what: str = "text file", name: str = "path") -> str:
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
        from optmodels.io.asterix.framing import BINARY_ACCEPTED, describe_binary

        line = data.count(b"\n", 0, nul) + 1
        known = describe_binary(data[: 1 << 16])
        if known:
            raise ProblemError(f"{p}: {known}")
        raise ProblemError(
            f"{p}: binary data (a NUL byte at byte {nul}, line {line}); "
            f"expected a text {what} ({BINARY_ACCEPTED})"
        )
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
        raise ProblemError(
            f"{d}: cannot create {what} (it, or a parent, is an existing file)"
        ) from None
    except OSError as exc:
        raise ProblemError(f"{d}: cannot create {what} ({exc.strerror or exc})") from None


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike[str],
    *,
    name: str = "path",
    binary: bool = False,
    newline: str | None = None,
) -> Iterator[IO[Any]]:
    """Write a file all or nothing: ``with atomic_write(p) as fh: fh.write(...)``.

    The data go to a temporary file in the target's folder (``.NAME.XXXX.tmp``); when the
    block ends without an exception it is flushed, fsynced and moved onto the target with
    ``os.replace`` (atomic on POSIX), then the folder is fsynced. An exception, a kill or
    Ctrl-C part-way leaves the previous target as it was (and, but for a kill -9, no
    temporary file). The path is checked before anything is written (see
    :func:`output_file`): an existing directory or a parent that is a file is refused.

    Parameters
    ----------
    path
        The file to write.
    name
        The argument's name in messages (e.g. ``"--out"``).
    binary
        Open in binary mode (default text, UTF-8).
    newline
        Passed to :func:`open` in text mode (``""`` for the :mod:`csv` module).

    Raises
    ------
    ProblemError
        Naming the path if it cannot be prepared or written (permission, disk full);
        naming ``binary`` if it is not True/False, ``newline`` if it is not one of
        :func:`open`'s (None, ``""``, ``"\\n"``, ``"\\r"``, ``"\\r\\n"``).
    """
    binary = as_flag("io.atomic_write binary", binary)
    if not (newline is None or (isinstance(newline, str) and newline in _NEWLINES)):
        raise ProblemError(
            f"io.atomic_write newline: expected None or one of {', '.join(map(repr, _NEWLINES))}"
            f", got {type(newline).__name__} {newline!r:.40}"
        )
    p = output_file(path, name=name)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    except OSError as exc:
        raise ProblemError(f"{p}: cannot write ({exc.strerror or exc})") from None
    tmp = Path(tmp_name)
    done = False
    try:
        mode = "wb" if binary else "w"
        kwargs: dict[str, Any] = {} if binary else {"encoding": "utf-8", "newline": newline}
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        with contextlib.suppress(OSError):
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, p)
        done = True
        _fsync_dir(p.parent)
    except OSError as exc:
        raise ProblemError(
            f"{p}: cannot write ({exc.strerror or exc}); the previous file, if any, is unchanged"
        ) from None
    finally:
        if not done:
            with contextlib.suppress(OSError):
                tmp.unlink()


#: the ``newline`` values :func:`open` takes besides None
_NEWLINES = ("", "\n", "\r", "\r\n")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_dir(d: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def save_npz(
    path: str | os.PathLike[str], *, name: str = "path", compressed: bool = True, **arrays: Any
) -> Path:
    """``np.savez_compressed`` (or ``np.savez``) onto exactly ``path``, atomically.

    Unlike NumPy's own function, no ``.npz`` is appended to the name, and a kill part-way
    leaves the previous archive readable (:func:`atomic_write`). Returns the path written.

    Raises
    ------
    ProblemError
        Naming the path if it cannot be written (see :func:`atomic_write`); naming
        ``compressed`` if it is not True/False; naming an array that NumPy would store as
        a pickle (objects, ``None`` entries, a mapping) or cannot make an array of (ragged
        nested lists): :func:`~optmodels.io.read_npz` does not load pickles.
    """
    import numpy as np

    compressed = as_flag("io.save_npz compressed", compressed)
    data = {}
    for key, value in arrays.items():
        try:
            a = np.asanyarray(value)
        except (TypeError, ValueError):  # ragged nested lists
            a = None
        if a is None or a.dtype.hasobject:
            raise ProblemError(
                f"io.save_npz {key}: expected an array of numbers or text, got "
                f"{type(value).__name__} {value!r:.40} (it would be stored as a pickle, "
                "which read_npz does not load)"
            )
        data[key] = a
    p = output_file(path, name=name)
    with atomic_write(p, name=name, binary=True) as fh:
        (np.savez_compressed if compressed else np.savez)(fh, **data)
    return p


def _write_text(p: Path, text: str, *, newline: str | None = None) -> None:
    with atomic_write(p, newline=newline) as fh:
        fh.write(text)
