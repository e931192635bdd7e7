"""read_asterix: CAT048 / CAT021 records of ASTERIX recordings (raw datablocks or pcap /
pcapng captures) into SI tables, times on one continuous axis."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import mmap
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import ProblemError, as_choice
from optmodels.io.asterix.capture import Capture, capture_kind, read_capture
from optmodels.io.asterix.framing import _frame, _gather, diagnose, is_asterix
from optmodels.io.asterix.layout import DAY, _Layout, _spec, as_editions
from optmodels.io.asterix.reports import AsterixData, Cat021Reports, Cat048Reports
from optmodels.io.asterix.timeline import Timeline


def _as_date(date: Any) -> np.datetime64 | None:
    """``date`` as the datetime64[ns] of its UTC midnight (None: unknown)."""
    if date is None:
        return None
    if isinstance(date, bool | int | float | np.number):
        raise ProblemError(
            f"asterix.read date: expected a date (YYYY-MM-DD, datetime.date "
            f"or numpy datetime64), got the number {date!r:.60}"
        )
    try:
        if isinstance(date, _dt.datetime):
            date = date.date()
        d = np.datetime64(date, "D")
    except (TypeError, ValueError) as exc:
        raise ProblemError(
            f"asterix.read date: expected a date (YYYY-MM-DD, datetime.date "
            f"or numpy datetime64), got {date!r:.60}"
        ) from exc
    if np.isnat(d):
        raise ProblemError("asterix.read date: NaT is not a date")
    return d.astype("datetime64[ns]")


def _paths(paths: Any) -> list[Path]:
    from optmodels.io.paths import as_path, input_file

    name = "asterix.read paths"
    if isinstance(paths, str | Path) or hasattr(paths, "__fspath__"):
        paths = [paths]
    elif paths is None or isinstance(paths, bytes) or not isinstance(paths, Iterable):
        raise ProblemError(
            f"{name}: expected a file path or a list of them, got "
            f"{type(paths).__name__} {paths!r:.60}"
        )
    files = [input_file(as_path(name, p), what="recording (ASTERIX)", name=name) for p in paths]
    if not files:
        raise ProblemError(f"{name}: no file given")
    return files


def _source(path: Path, editions: dict[int, tuple[int, int]] | None) -> tuple[Any, Capture | None]:
    """The ASTERIX byte stream of one file (memory-mapped raw datablocks, or a capture's
    UDP payloads) after the content check."""
    buf = _map(path)
    if not len(buf):
        raise ProblemError(
            f"asterix.read {path}: empty file (expected a recording: raw ASTERIX "
            "datablocks or a pcap/pcapng capture of ASTERIX over UDP)"
        )
    if capture_kind(bytes(buf[:4])):
        cap = read_capture(path)
        if not cap.stream:
            counts = ", ".join(f"{v} {k}" for k, v in cap.counts.items()) or "no packets"
            raise ProblemError(
                f"asterix.read {path}: a {cap.kind} capture without ASTERIX over UDP ({counts})"
            )
        return cap.stream, cap
    if not is_asterix(path, editions=editions):
        why = diagnose(bytes(buf[: 1 << 16]))
        if why:
            raise ProblemError(f"asterix.read {path}: damaged ASTERIX: {why}")
        raise ProblemError(
            f"asterix.read {path}: not ASTERIX (byte 0: CAT {buf[0]}, the "
            "datablock lengths do not chain or the first record does not "
            "parse); accepted: raw ASTERIX datablocks (CAT048/CAT021) and "
            "pcap/pcapng captures of ASTERIX over UDP"
        )
    return buf, None


def read_asterix(
    paths: str | Path | Iterable[str | Path],
    *,
    date: Any = None,
    editions: dict[int, tuple[int, int]] | None = None,
    check: str = "layouts",
) -> AsterixData:
    """Read CAT048 and CAT021 records of one or more ASTERIX recordings: raw datablocks as
    recorded, or pcap/pcapng captures of ASTERIX over UDP (detected from content, read
    through dpkt: the UDP payloads that are whole datablocks, in capture order). Other
    categories are skipped (counted in ``skipped``).

    Parameters
    ----------
    paths
        One file or several; they are read in the given order.
    date
        UTC date of the first record of the first file (``"YYYY-MM-DD"``,
        ``datetime.date``, ``numpy.datetime64``). ASTERIX carries only the time of day
        (I048/140, I021/073, I021/071, s since UTC midnight, LSB 1/128 s); the times are
        placed on one axis per (category, SAC/SIC) in file order, continuing across files
        (a step back of more than 12 h is the next day; see
        :mod:`optmodels.io.asterix.timeline` for the rules, and what is refused, naming
        the file). A capture carries the date: its records are put on their packets' UTC
        day, and without ``date`` a first file that is a capture gives the epoch.
        ``time`` counts from midnight of the epoch (``AsterixData.epoch``); with neither
        it counts from midnight of the (unknown) first day and ``epoch`` is None.
    editions
        Category → (major, minor) edition to read, default :data:`EDITIONS` (CAT048 1.32,
        CAT021 2.7; libasterix ships CAT048 1.27-1.32, CAT021 0.23-2.7; the CAT021 0.2x
        editions have another position item and are not read).
    check
        ``"layouts"`` (default): the first record of each FSPEC layout is also parsed by
        libasterix and must agree; ``"all"``: every record is (slow).

    Raises
    ------
    ProblemError
        Naming the file and the byte offset: a missing or unreadable file, an empty
        file, a file that is not ASTERIX (or damaged ASTERIX), a truncated datablock or
        record, a record libasterix refuses, times that cannot be placed; bad arguments.
    """
    check = as_choice("asterix.read check", check, ("layouts", "all"))
    epoch = _as_date(date)
    editions = as_editions("asterix.read editions", editions)
    layouts = {c: _Layout(_spec(c, editions)) for c in (48, 21)}
    files = _paths(paths)
    counts: dict[int, int] = {48: 0, 21: 0}
    skipped: dict[int, int] = {}
    per_cat: dict[int, list[dict[str, np.ndarray]]] = {48: [], 21: []}
    dropped: dict[str, int] = {}
    captures: dict[str, int] = {}
    timeline = Timeline()
    epoch_s: float | None = (
        None if epoch is None else float(epoch.astype("datetime64[s]").astype(np.int64))
    )
    for k, path in enumerate(files):
        buf, cap = _source(path, editions)
        if cap is not None:
            for why, v in cap.counts.items():
                captures[why] = captures.get(why, 0) + v
            if k == 0 and epoch is None and cap.times.size:
                epoch_s = DAY * math.floor(cap.times[0] / DAY)
                epoch = np.datetime64(int(epoch_s), "s").astype("datetime64[ns]")
        hints = cap if cap is not None and epoch_s is not None else None
        timeline.start_file(str(path))
        for rows in _chunks(buf, k, str(path), layouts, check, skipped, counts, dropped):
            _place(rows, timeline, hints, epoch_s)
            for cat, r in rows.items():
                per_cat[cat].append(r)
    cat048 = Cat048Reports(**_join(per_cat[48], Cat048Reports))
    cat021 = Cat021Reports(**_join(per_cat[21], Cat021Reports))
    return AsterixData(
        cat048,
        cat021,
        epoch,
        tuple(str(p) for p in files),
        dict(sorted(counts.items())),
        dropped,
        dict(sorted(skipped.items())),
        captures,
    )


def _chunks(
    buf: Any,
    k: int,
    name: str,
    layouts: dict[int, _Layout],
    check: str,
    skipped: dict[int, int],
    counts: dict[int, int],
    dropped: dict[str, int],
) -> Any:
    """Per framing chunk, the kept rows of each category in SI (``time``: time of day)."""
    arr = np.frombuffer(buf, dtype=np.uint8) if len(buf) else np.zeros(0, np.uint8)
    rows_of = {48: _cat048, 21: _cat021}
    for framed in _frame(buf, name, layouts, check, skipped):
        out = {}
        for cat, (recs, flat) in framed.items():
            lay = layouts[cat]
            counts[cat] += len(recs)
            offs = (
                np.frombuffer(flat, dtype=np.int64).reshape(-1, len(lay.items))
                if len(flat)
                else np.zeros((0, len(lay.items)), np.int64)
            )
            cols: dict[str, Any] = {}
            for f in lay.fields:
                cols[f.name] = (*_gather(arr, offs[:, lay.slot[f.item]], f), f.scale)
            del offs, flat
            # the kept rows in SI now (the chunk's raw columns are freed)
            out[cat] = rows_of[cat](k, np.array(recs, dtype=np.int64), cols, dropped)
            del cols
        yield out
    del arr


def _place(
    rows: dict[int, dict[str, np.ndarray]],
    timeline: Timeline,
    cap: Capture | None,
    epoch_s: float | None,
) -> None:
    """Times of day of one chunk → the recording's time axis (in place)."""

    def hint(r: dict[str, np.ndarray]) -> np.ndarray | None:
        if cap is None or epoch_s is None:
            return None
        return cap.time_of(r["offset"]) - epoch_s

    if timeline.ref is None:
        firsts = [(int(r["offset"][0]), cat) for cat, r in rows.items() if r["time"].size]
        if not firsts:
            return
        cat = min(firsts)[1]
        r = rows[cat]
        h = hint({"offset": r["offset"][:1]})
        timeline.reference(
            cat,
            int(256 * r["sac"][0] + r["sic"][0]),
            float(r["time"][0]),
            None if h is None else float(h[0]),
        )
    for cat, r in rows.items():
        if r["time"].size:
            r["time"] = timeline.place(cat, 256 * r["sac"] + r["sic"], r["time"], hint(r))


def _join(parts: list[dict[str, np.ndarray]], cls: type | None = None) -> dict[str, np.ndarray]:
    """Column-wise concatenation (no copy for a single part); empty tables typed."""
    if len(parts) == 1:
        return parts[0]
    if parts:  # column by column, freeing the parts' columns as it goes (peak: + 1 column)
        out = {}
        for name in list(parts[0]):
            out[name] = np.concatenate([p.pop(name) for p in parts])
        return out
    assert cls is not None
    ints = ("sac", "sic", "address", "mode3a", "offset", "file")
    return {
        name: np.zeros(0, np.int64 if name in ints else float)
        for name in (f.name for f in dataclasses.fields(cls))
    }


def _map(path: Path) -> Any:
    """The file's bytes, memory-mapped read-only (empty files: ``b""``)."""
    try:
        with open(path, "rb") as fh:
            if fh.seek(0, 2) == 0:
                return b""
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as exc:
        raise ProblemError(
            f"{path}: cannot read the recording (ASTERIX) ({exc.strerror or exc})"
        ) from None


def _tod(cat: int, cols: dict[str, Any], n: int) -> np.ndarray:
    names = ("tod",) if cat == 48 else ("t073", "t071")
    t = np.full(n, np.nan)
    for nm in reversed(names):
        if nm in cols:
            raw, have, scale = cols[nm]
            t = np.where(have, raw * scale, t)
    return t


def _val(cols: dict[str, Any], name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    if name not in cols:
        return np.full(n, np.nan), np.zeros(n, bool)
    raw, have, scale = cols[name]
    return np.where(have, raw * scale, np.nan), have


def _int(cols: dict[str, Any], name: str, n: int) -> np.ndarray:
    if name not in cols:
        return np.full(n, -1, np.int64)
    raw, have, _ = cols[name]
    return np.where(have, raw, -1)


def _count(dropped: dict[str, int], reason: str, mask: np.ndarray) -> None:
    if mask.any():
        dropped[reason] = dropped.get(reason, 0) + int(mask.sum())


def _cat048(
    k: int, recs: np.ndarray, cols: dict[str, Any], dropped: dict[str, int]
) -> dict[str, np.ndarray]:
    """The kept CAT048 rows of one chunk in SI (``time``: the time of day, unwrapped
    later); drops counted."""
    n = recs.size
    sac = _int(cols, "sac", n)
    t = _tod(48, cols, n)
    rng, have_r = _val(cols, "rho", n)
    keep = (sac >= 0) & have_r & np.isfinite(t)
    _count(dropped, "cat048 no I010 (SAC/SIC)", sac < 0)
    _count(dropped, "cat048 no I140 (time)", ~np.isfinite(t))
    _count(dropped, "cat048 no I040 (polar position)", ~have_r)
    fl, have_fl = _val(cols, "fl", n)
    bad_fl = (_int(cols, "fl_v", n) == 1) | (_int(cols, "fl_g", n) == 1)
    _count(
        dropped,
        "cat048 I090 not validated or garbled (flight level unused)",
        bad_fl & have_fl & keep,
    )
    fl[bad_fl] = np.nan
    sel = slice(None) if keep.all() else keep
    out = {
        "time": t[sel],
        "sac": sac[sel],
        "sic": _int(cols, "sic", n)[sel],
        "range": rng[sel],
        "azimuth": _val(cols, "theta", n)[0][sel],
        "pressure_altitude": fl[sel],
        "address": _int(cols, "address", n)[sel],
        "mode3a": _int(cols, "mode3a", n)[sel],
        "offset": recs[sel],
    }
    out["file"] = np.full(out["time"].size, k, np.int64)
    return out


def _cat021(
    k: int, recs: np.ndarray, cols: dict[str, Any], dropped: dict[str, int]
) -> dict[str, np.ndarray]:
    """The kept CAT021 rows of one chunk in SI (``time``: the time of day)."""
    n = recs.size
    lat_hi, have_hi = _val(cols, "lat_hi", n)
    lat_lo, have_lo = _val(cols, "lat_lo", n)
    t = _tod(21, cols, n)
    have_pos = have_hi | have_lo
    keep = have_pos & np.isfinite(t)
    _count(dropped, "cat021 no I073/I071 (time)", ~np.isfinite(t))
    _count(dropped, "cat021 no I131/I130 (position)", ~have_pos)
    sel = slice(None) if keep.all() else keep
    deg = 180.0 / math.pi
    lat = np.where(have_hi, lat_hi, lat_lo)[sel] * deg
    lon = np.where(have_hi, _val(cols, "lon_hi", n)[0], _val(cols, "lon_lo", n)[0])[sel] * deg
    out = {
        "time": t[sel],
        "sac": _int(cols, "sac", n)[sel],
        "sic": _int(cols, "sic", n)[sel],
        "latitude": lat,
        "longitude": lon,
        "height": _val(cols, "gh", n)[0][sel],
        "pressure_altitude": _val(cols, "fl", n)[0][sel],
        "address": _int(cols, "address", n)[sel],
        "offset": recs[sel],
    }
    out["file"] = np.full(out["time"].size, k, np.int64)
    return out
