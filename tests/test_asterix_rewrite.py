"""The corrected CAT048 recording (issue 24 item 3): rewrite_cat048_positions keeps every
byte of the recording but the I040 of the records named; read back, the new positions are
within half an LSB of the values given, every other field and byte is unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax
from optmodels.io import rewrite_cat048_positions

NM = 1852.0


def _recording(tmp_path, rng: np.random.Generator) -> list:
    """Two files: CAT048 of two radars (with and without optional items) and CAT021."""
    paths = []
    for j in range(2):
        n = 300
        t = 1000.0 * j + np.arange(n)
        blocks = [
            ax.encode_cat048(
                t,
                1,
                s,
                rng.uniform(1e3, 4e5, n),
                rng.uniform(0, 6.28, n),
                flight_level=rng.uniform(0, 400, n),
                address=np.where(rng.random(n) < 0.2, -1, 77 + s),
                mode3a=rng.integers(0, 4096, n),
                per_block=9,
            )
            for s in (1, 2)
        ]
        blocks.insert(
            1,
            ax.encode_cat021(t, 9, 1, rng.uniform(40, 50, n), rng.uniform(10, 20, n), per_block=5),
        )
        p = tmp_path / f"r{j}.ast"
        p.write_bytes(b"".join(blocks))
        paths.append(p)
    return paths


def test_rewrite_changes_only_i040(tmp_path) -> None:
    rng = np.random.default_rng(2403)
    paths = _recording(tmp_path, rng)
    d = ax.read_asterix(paths)
    c = d.cat048
    pick = rng.random(len(c)) < 0.7  # a subset of the plots corrected
    rng_new = np.clip(c.range[pick] + rng.normal(0, 300, pick.sum()), 0, 4.7e5)
    az_new = c.azimuth[pick] + rng.normal(0, 0.01, pick.sum())  # some wrap below 0
    out = tmp_path / "out" / "corrected.ast"
    assert rewrite_cat048_positions(paths, out, c.record_id[pick], rng_new, az_new) == out
    src = b"".join(p.read_bytes() for p in paths)
    new = out.read_bytes()
    assert len(new) == len(src)
    # the bytes that differ are all inside I040 of the picked records (4 bytes each)
    diff = np.flatnonzero(np.frombuffer(src, np.uint8) != np.frombuffer(new, np.uint8))
    sizes = np.cumsum([0] + [p.stat().st_size for p in paths])
    lay = ax.read_asterix(out)
    e = lay.cat048
    # one output file: the records at their offsets in the concatenation of the inputs
    np.testing.assert_array_equal(e.record_id, sizes[c.file] + c.offset)
    for name in ("time", "sac", "sic", "pressure_altitude", "address", "mode3a"):
        np.testing.assert_array_equal(getattr(e, name), getattr(c, name))
    for name in ("time", "latitude", "longitude", "address"):
        np.testing.assert_array_equal(getattr(lay.cat021, name), getattr(d.cat021, name))
    np.testing.assert_array_equal(e.range[~pick], c.range[~pick])
    np.testing.assert_array_equal(e.azimuth[~pick], c.azimuth[~pick])
    assert np.max(np.abs(e.range[pick] - rng_new)) <= NM / 256 / 2 + 1e-6
    dz = (e.azimuth[pick] - az_new + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(dz)) <= np.pi / 2**16 + 1e-12
    assert np.all((e.azimuth >= 0) & (e.azimuth < 2 * np.pi))
    # I040 sits 3 bytes (FSPEC with I220: 2; I010: 2; I140: 3 ...) after the record start:
    # locate each picked record's I040 by its FSPEC and compare with the differing bytes
    starts = sizes[c.file[pick]] + c.offset[pick]
    fs_len = 1 + (np.frombuffer(src, np.uint8)[starts] & 1)
    i040 = starts + fs_len + 2 + 3 + 1  # FSPEC, I010, I140, I020 (1 byte)
    allowed = np.concatenate([i040 + b for b in range(4)])
    assert np.isin(diff, allowed).all() and diff.size > 0.5 * allowed.size


def test_rewrite_refusals(tmp_path) -> None:
    rng = np.random.default_rng(2404)
    paths = _recording(tmp_path, rng)
    c = ax.read_asterix(paths).cat048
    ids = c.record_id[:3]
    out = tmp_path / "o.ast"
    with pytest.raises(ProblemError, match=r"rewrite_cat048_positions range_m: need 0 to"):
        rewrite_cat048_positions(paths, out, ids, [1e3, 1e3, 5e5], [0.0, 0.0, 0.0])
    with pytest.raises(
        ProblemError,
        match=r"rewrite_cat048_positions azimuth_rad: "
        r"expected 3 values",
    ):
        rewrite_cat048_positions(paths, out, ids, [1e3] * 3, [0.0])
    with pytest.raises(
        ProblemError,
        match=r"record_id: \d+ identifiers name no CAT048 "
        r"record with I040 in .*r0\.ast",
    ):
        rewrite_cat048_positions(paths, out, ids + 1, [1e3] * 3, [0.0] * 3)
    with pytest.raises(ProblemError, match=r"record_id: file index 1 but 1 file"):
        rewrite_cat048_positions(paths[:1], out, c.record_id[-1:], [1e3], [0.0])
    with pytest.raises(ProblemError, match=r"record_id: negative or repeated"):
        rewrite_cat048_positions(paths, out, np.r_[ids, ids[:1]], [1e3] * 4, [0.0] * 4)
    with pytest.raises(ProblemError, match=r"is an existing directory"):
        rewrite_cat048_positions(paths, tmp_path, ids, [1e3] * 3, [0.0] * 3)
    assert not out.exists()
