"""Line-oriented files one process at a time appends to: the Monte Carlo checkpoints and
the comparison harness's ``results.csv``.

:class:`LineLog` (an ``fcntl.flock`` on ``PATH.lock`` for its life, whole lines appended
with flush + fsync, unreadable lines moved to ``PATH.skipped``) and :func:`report_skipped`
(the one warning line, logger ``optmodels``).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from optmodels.core import ProblemError

__all__ = ["LineLog", "log", "report_skipped"]


#: The package's logger (name ``optmodels``).
log = logging.getLogger("optmodels")


class LineLog:
    """A line-oriented file (JSON lines, CSV) that one process at a time appends to.

    Opening takes an exclusive ``fcntl.flock`` on ``PATH.lock`` for the object's life
    (:class:`~optmodels.core.ProblemError` if another process holds it; the kernel
    releases it when the holder dies, so a stale lock never blocks). :meth:`read` returns
    the complete lines and the bytes after the last newline (a write cut short by a kill);
    :meth:`rewrite` atomically replaces the file by the valid lines, moving the others to
    ``PATH.skipped``; :meth:`append` writes whole lines with flush + fsync.

    ``what`` names the argument in messages, e.g. ``"montecarlo.run checkpoint"``.
    """

    def __init__(self, path: str | os.PathLike[str], what: str) -> None:
        try:
            self.path = Path(path)
        except TypeError:
            raise ProblemError(f"{what}: expected a file path, got {type(path).__name__}") from None
        self.what = what
        self._fh: Any = None
        self._lock_fd: int | None = None
        if self.path.is_dir():
            raise ProblemError(f"{what}: {self.path} is a directory, expected a file")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ProblemError(f"{what}: cannot create the folder of {self.path} ({exc})") from None
        self._lock()

    def _lock(self) -> None:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no locking
            return
        lock = Path(str(self.path) + ".lock")
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise ProblemError(f"{self.what}: cannot create the lock file {lock} ({exc})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
            os.close(fd)
            raise ProblemError(
                f"{self.what}: {self.path} is in use by another process"
                + (f" (pid {holder})" if holder else "")
                + f"; wait for it to finish or use another path (lock: {lock})"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._lock_fd = fd

    def read(self) -> tuple[list[bytes], bytes]:
        """Complete lines (without their newline) and the incomplete tail."""
        try:
            data = self.path.read_bytes() if self.path.exists() else b""
        except OSError as exc:
            raise ProblemError(f"{self.what}: cannot read {self.path} ({exc})") from None
        cut = data.rfind(b"\n") + 1
        return data[:cut].split(b"\n")[:-1], data[cut:]

    def open_with_header(self, head: str, foreign: str) -> tuple[list[bytes], bytes]:
        """The file's lines after ensuring it starts with a header: a new or empty file,
        or one whose header a crash cut short, is (re)started with ``head`` and gives
        ``([], b"")``; a file with no header line is refused with ``foreign`` (what it is
        not, e.g. "a Monte Carlo checkpoint"). Otherwise :meth:`read`'s lines and tail."""
        lines, tail = self.read()
        if lines:
            return lines, tail
        if tail and not (head + "\n").encode().startswith(tail):
            raise ProblemError(
                f"{self.what}: {self.path} is not {foreign} (no header "
                "line); use another path or delete it"
            )
        if tail:
            self.rewrite([], [])  # a header cut short by a crash: start afresh
        self.append([head])
        return [], b""

    def keep(self, keep: list[str], dropped: list[bytes], tail: bytes) -> int:
        """After parsing: if any line was unreadable (or the last cut short), rewrite the
        file with the ``keep`` lines, move the rest to ``PATH.skipped`` and say so
        (:func:`report_skipped`). Returns the number of lines skipped."""
        if dropped or tail:
            moved = self.rewrite(keep, dropped + ([tail] if tail else []))
            report_skipped(self.what, self.path, len(dropped), len(tail), moved)
        return len(dropped) + bool(tail)

    def rewrite(self, lines: list[str], dropped: list[bytes]) -> Path:
        """Replace the file by ``lines`` (atomically: a temporary file, fsync, rename);
        append ``dropped`` to ``PATH.skipped``, which is returned."""
        skipped = Path(str(self.path) + ".skipped")
        with skipped.open("ab") as fh:
            fh.write(b"".join(d + b"\n" for d in dropped))
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("wb") as fh:
            fh.write("".join(line + "\n" for line in lines).encode())
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        return skipped

    def append(self, lines: list[str]) -> None:
        """Append whole lines (one write), then flush and fsync."""
        if self._fh is None:
            try:
                self._fh = self.path.open("ab")
            except OSError as exc:
                raise ProblemError(f"{self.what}: cannot write {self.path} ({exc})") from None
        if lines:
            self._fh.write("".join(line + "\n" for line in lines).encode())
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file and release the lock."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def __enter__(self) -> LineLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def report_skipped(what: str, path: Path, bad: int, tail: int, moved: Path) -> None:
    """One warning line (logger ``optmodels``) for lines that could not be read."""
    parts = ([f"{bad} unreadable line{'s' * (bad != 1)}"] if bad else []) + (
        [f"a last line cut short ({tail} bytes)"] if tail else []
    )
    log.warning("%s: %s: skipped %s (moved to %s)", what, path, " and ".join(parts), moved)
