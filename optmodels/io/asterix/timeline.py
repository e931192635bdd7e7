"""One continuous time axis for a recording in several files and from several radars
(issue 28 item 1).

ASTERIX carries only the time of day (I048/140, I021/073, I021/071). The times are placed
per *stream* — one (category, SAC/SIC) — in file order:

- a stream seen before continues from its own last time: ``numpy.unwrap`` with period
  86 400 s (a step back of more than 12 h is the next day), across chunks and files; so a
  day recorded in hourly files and a day boundary (23:00 → 01:00) stay continuous;
- a stream met for the first time is put on the day that brings its first time within
  12 h of its file's *reference*: the time of the file's first record (so a file written
  radar by radar, each radar longer than 12 h, keeps every radar on the same day); the
  reference of a file is placed by its first record's stream if that stream was seen
  before, else within 12 h of the previous file's reference (the first file: day 0);
- a capture with a known epoch (``date`` given or the first file a capture) puts every
  record on the day of its packet's capture time (UTC) instead: nearest within 12 h.

What cannot be placed is refused, naming the file: a stream that starts more than
:data:`BACKSTEP` before its own last time in an earlier file (files out of order), or
whose continuation lands more than 12 h from its file's reference (the streams of a file
disagree on the day: a stream paused for about 12 h or more).
"""

from __future__ import annotations

import numpy as np

from optmodels.core import ProblemError

DAY = 86400.0
#: largest step back (s) of a stream from one file to the next (overlapping hourly files);
#: a larger one means the files are not in time order
BACKSTEP = 1800.0


def _near(ref: float, t: float) -> float:
    """``t`` moved by whole days to within 12 h of ``ref``."""
    return t + DAY * float(np.round((ref - t) / DAY))


def _clock(t: float) -> str:
    s = t % DAY
    return f"{int(s // 3600):02d}:{int(s % 3600 // 60):02d}:{s % 60:06.3f}"


class Timeline:
    """The placing state across the files of one :func:`read_asterix` call."""

    def __init__(self) -> None:
        self.last: dict[tuple[int, int], float] = {}  # (cat, 256·SAC+SIC) → last time
        self.ref: float | None = None  # reference of the current file
        self.prev: float | None = None  # of the previous file
        self.name = ""
        self.seen: set[tuple[int, int]] = set()  # streams met in the current file

    def start_file(self, name: str) -> None:
        if self.ref is not None:
            self.prev = self.ref
        self.ref, self.name, self.seen = None, name, set()

    def reference(self, cat: int, key: int, tod: float, hint: float | None) -> None:
        """Place the file's reference from its first kept record."""
        if hint is not None:
            self.ref = _near(hint, tod)
        elif (cat, key) in self.last:
            self.ref = _near(self.last[(cat, key)], tod)
        elif self.prev is not None:
            self.ref = _near(self.prev, tod)
        else:
            self.ref = tod

    def place(
        self, cat: int, key: np.ndarray, tod: np.ndarray, hint: np.ndarray | None
    ) -> np.ndarray:
        """Times (s from midnight of day 0) of one chunk's rows of category ``cat``, in file
        order; ``key`` = 256·SAC + SIC; ``hint``: capture times in the same axis."""
        assert self.ref is not None
        if hint is not None:
            out = tod + DAY * np.round((hint - tod) / DAY)
            for k in np.unique(key):
                self.last[(cat, int(k))] = float(out[key == k][-1])
                self.seen.add((cat, int(k)))
            return out
        out = np.empty_like(tod)
        keys, first = np.unique(key, return_index=True)
        for k in keys[np.argsort(first)]:
            m = slice(None) if keys.size == 1 else key == k
            u = np.unwrap(tod[m], period=DAY)
            stream = (cat, int(k))
            if stream in self.last:
                start = _near(self.last[stream], float(u[0]))
                if stream not in self.seen:
                    self._check(stream, start)
            else:
                start = _near(self.ref, float(u[0]))
            self.seen.add(stream)
            u += start - u[0]
            out[m] = u
            self.last[stream] = float(u[-1])
        return out

    def _check(self, stream: tuple[int, int], start: float) -> None:
        cat, k = stream
        who = f"CAT{cat:03d} SAC/SIC {k // 256}/{k % 256}"
        last = self.last[stream]
        assert self.ref is not None
        if start < last - BACKSTEP:
            raise ProblemError(
                f"asterix.read {self.name}: cannot place its times: {who} starts at "
                f"{_clock(start)}, {last - start:.0f} s before its last report in the files "
                f"before ({_clock(last)}); give the files in time order"
            )
        if abs(start - self.ref) > DAY / 2:
            raise ProblemError(
                f"asterix.read {self.name}: cannot place its times: {who} continues at "
                f"{_clock(start)}, more than 12 h from the file's first record "
                f"({_clock(self.ref)}); read the files of that period separately"
            )
