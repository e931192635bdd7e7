"""A corrected CAT048 recording (issue 24 item 3): every record as read, only I048/040
(RHO, THETA) of the records named replaced."""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import ProblemError
from optmodels.io.asterix.encode import _item, _raw, _real, _where
from optmodels.io.asterix.framing import _frame
from optmodels.io.asterix.layout import NM, _Layout, _spec, as_editions
from optmodels.io.asterix.read import _paths, _source
from optmodels.io.asterix.reports import RECORD_SHIFT


def _ids(
    fn: str, record_id: Any, range_m: Any, azimuth_rad: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        ids = np.asarray(record_id)
    except (TypeError, ValueError):  # ragged nested lists
        ids = np.zeros((0, 0))
    if ids.ndim != 1 or not (ids.size == 0 or np.issubdtype(ids.dtype, np.integer)):
        raise ProblemError(
            f"asterix.{fn} record_id: expected a 1-D integer array "
            "(Cat048Reports.record_id), got "
            f"{type(record_id).__name__} {record_id!r:.40}"
        )
    rng = _real(fn, "range_m", range_m)
    az = _real(fn, "azimuth_rad", azimuth_rad)
    for name, a in (("range_m", rng), ("azimuth_rad", az)):
        if a.shape != ids.shape:
            raise ProblemError(
                f"asterix.{fn} {name}: expected {ids.size} values (one per "
                f"record_id), got shape {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise ProblemError(
                f"asterix.{fn} {name}: {int((~np.isfinite(a)).sum())} non-finite values"
            )
    if np.any(rng < 0):
        raise ProblemError(
            f"asterix.{fn} range_m: need slant ranges ≥ 0 m, got {float(rng[rng < 0][0]):.8g}"
        )
    ids = ids.astype(np.int64)
    if ids.size and (ids.min() < 0 or np.unique(ids).size != ids.size):
        raise ProblemError(f"asterix.{fn} record_id: negative or repeated identifiers")
    return ids, rng, az


def rewrite_cat048_positions(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    out_path: str | os.PathLike[str],
    record_id: Any,
    range_m: Any,
    azimuth_rad: Any,
    *,
    editions: dict[int, tuple[int, int]] | None = None,
) -> Path:
    """Write the recording ``paths`` again to ``out_path`` with new polar positions.

    Every datablock and record of ``paths`` (as :func:`~optmodels.io.asterix.read_asterix`
    reads them, in the same order; a capture contributes its ASTERIX UDP payloads) is
    written as read, as raw ASTERIX datablocks, except I048/040 of the CAT048 records named
    by ``record_id``: RHO becomes ``range_m`` and THETA ``azimuth_rad`` (rounded to the
    item's LSB, 1/256 NM and 360°/2¹⁶; I040 has a fixed size, so no length changes). The
    output goes through :func:`~optmodels.io.atomic_write` (all or nothing).

    Parameters
    ----------
    paths
        The recording, the same files in the same order as given to ``read_asterix``.
    out_path
        The corrected recording (a file; checked before any work).
    record_id
        :attr:`~optmodels.io.asterix.Cat048Reports.record_id` of the rows to change
        (unique; records not named are copied unchanged).
    range_m
        New slant range (m), one per identifier; 0 to 65 535/256 NM.
    azimuth_rad
        New azimuth (rad clockwise from the radar's north), one per identifier; wrapped
        into [0, 2π).
    editions
        As for ``read_asterix``.

    Returns
    -------
    Path
        ``out_path``.

    Raises
    ------
    ProblemError
        Naming the argument: identifiers that name no CAT048 record with I040 (or a file
        index beyond ``paths``), values outside I040, mismatched lengths; the reader's
        refusals for the input files; an output path that cannot be written.
    """
    from optmodels.io.paths import atomic_write, output_file

    fn = "rewrite_cat048_positions"
    output_file(out_path, name=f"asterix.{fn} out_path")
    ids, rng, az = _ids(fn, record_id, range_m, azimuth_rad)
    editions = as_editions(f"asterix.{fn} editions", editions)
    files = _paths(paths)
    spec = _spec(48, editions)
    frho, fth = _where(spec, ("040", "RHO")), _where(spec, ("040", "THETA"))
    rho = _raw(fn, "range_m", rng / NM, frho, unit="m", per=NM)
    theta = _raw(
        fn, "azimuth_rad", np.degrees(np.mod(az, 2 * math.pi)), fth, unit="°", per=1.0, wrap=True
    )
    which = ids >> RECORD_SHIFT
    if ids.size and which.max() >= len(files):
        raise ProblemError(
            f"asterix.{fn} record_id: file index {int(which.max())} but {len(files)} file(s) given"
        )
    layouts = {c: _Layout(_spec(c, editions)) for c in (48, 21)}
    with atomic_write(out_path, name=f"asterix.{fn} out_path", binary=True) as fh:
        for k, path in enumerate(files):
            buf, _ = _source(path, editions)
            mine = which == k
            fh.write(
                _patched(
                    fn,
                    buf,
                    str(path),
                    layouts,
                    ids[mine] & ((1 << RECORD_SHIFT) - 1),
                    rho[mine],
                    theta[mine],
                )
            )
    return Path(out_path)


def _patched(
    fn: str,
    buf: Any,
    name: str,
    layouts: dict[int, _Layout],
    offsets: np.ndarray,
    rho: np.ndarray,
    theta: np.ndarray,
) -> bytes:
    """The stream ``buf`` with the I040 of the records at ``offsets`` replaced."""
    out = np.frombuffer(bytes(buf), np.uint8).copy()
    if offsets.size == 0:
        return out.tobytes()
    lay = layouts[48]
    slot = lay.slot["040"]
    recs, i040 = [], []
    for framed in _frame(buf, name, layouts, "layouts", {}):
        r, flat = framed[48]
        if len(r):
            recs.append(np.frombuffer(r, np.int64))
            i040.append(np.frombuffer(flat, np.int64).reshape(-1, len(lay.items))[:, slot])
    rec = np.concatenate(recs) if recs else np.zeros(0, np.int64)
    at = np.concatenate(i040) if i040 else np.zeros(0, np.int64)
    j = np.searchsorted(rec, offsets)
    ok = (
        (j < rec.size) & (rec[np.minimum(j, rec.size - 1)] == offsets)
        if rec.size
        else np.zeros(offsets.shape, bool)
    )
    ok[ok] &= at[j[ok]] >= 0
    if not ok.all():
        raise ProblemError(
            f"asterix.{fn} record_id: {int((~ok).sum())} identifiers name no "
            f"CAT048 record with I040 in {name} (e.g. offset "
            f"{int(offsets[~ok][0])})"
        )
    q = at[j]
    spec = lay.spec
    val = _item(
        0, 4, [(_where(spec, ("040", "RHO")), rho), (_where(spec, ("040", "THETA")), theta)]
    ).raw
    for b in range(4):
        out[q + b] = (val >> np.uint64(8 * (3 - b))) & np.uint64(0xFF)
    return out.tobytes()
