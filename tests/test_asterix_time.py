"""One continuous time axis across files and radars (issue 28 item 1): the times read back
equal the true times (s from midnight of the first day) to the I140 LSB, for a day in
hourly files, a day boundary, radar-by-radar files; what cannot be placed is refused
naming the file."""

from __future__ import annotations

import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax

LSB = 1 / 128  # I048/140 (s)
DAY = 86400.0


def _plots(t: np.ndarray, sic: int, rng: np.random.Generator) -> bytes:
    """CAT048 of one radar (SAC 1) at true times ``t`` (any day: encoded modulo 86 400)."""
    return ax.encode_cat048(
        t, 1, sic, rng.uniform(1e3, 4e5, t.size), rng.uniform(0, 2 * np.pi, t.size), per_block=17
    )


def _scan(t0: float, t1: float, rng: np.random.Generator) -> np.ndarray:
    """Report times of one radar from t0 to t1: a 4 s scan with jitter."""
    t = np.arange(t0, t1, 4.0)
    return np.sort(t + rng.uniform(0, 0.5, t.size))


def _check(d: ax.AsterixData, want: dict[int, np.ndarray]) -> None:
    c = d.cat048
    for sic, t in want.items():
        got = c.time[c.sic == sic]
        assert got.shape == t.shape
        assert np.max(np.abs(got - t)) <= LSB / 2 + 1e-9, np.max(np.abs(got - t))


def test_day_in_hourly_files(tmp_path) -> None:
    """24 hourly files, three radars interleaved by datablock: a file at 13:00 starts at
    +46 800 s (not −39 600 s), every file on day 0."""
    rng = np.random.default_rng(2801)
    files, want = [], {s: [] for s in (1, 2, 3)}
    for h in range(24):
        blocks = []
        for s in (1, 2, 3):
            t = _scan(3600.0 * h + s, 3600.0 * (h + 1), rng)
            want[s].append(t)
            blocks.append(_plots(t, s, rng))
        p = tmp_path / f"h{h:02d}.ast"
        p.write_bytes(b"".join(blocks))
        files.append(p)
    d = ax.read_asterix(files, date="2026-05-04")
    _check(d, {s: np.concatenate(v) for s, v in want.items()})
    first13 = d.cat048.time[d.cat048.file == 13].min()
    assert 46800.0 <= first13 < 46800.0 + 4.0
    assert np.all(d.cat048.time < DAY)


def test_day_boundary_in_files(tmp_path) -> None:
    """23:00 → 01:00 in two files, and a radar that first appears after midnight: all past
    midnight lands on day 1."""
    rng = np.random.default_rng(2802)
    a1, a2 = _scan(82800.0, 86400.0, rng), _scan(86400.0, 90000.0, rng)
    b2 = _scan(88200.0, 90000.0, rng)  # radar 2 starts at 00:30
    p1, p2 = tmp_path / "2300.ast", tmp_path / "0000.ast"
    p1.write_bytes(_plots(a1, 1, rng))
    p2.write_bytes(_plots(b2, 2, rng) + _plots(a2, 1, rng))
    d = ax.read_asterix([p1, p2])
    _check(d, {1: np.concatenate([a1, a2]), 2: b2})


def test_radar_by_radar_in_one_file_and_in_files(tmp_path) -> None:
    """Three radars of 14 h each written one after the other (in one file, then one file
    each): every radar on the same day, not radar k on day k."""
    rng = np.random.default_rng(2803)
    want = {s: _scan(21600.0 + 60 * s, 21600.0 + 14 * 3600.0, rng) for s in (1, 2, 3)}
    one = tmp_path / "all.ast"
    one.write_bytes(b"".join(_plots(t, s, rng) for s, t in want.items()))
    _check(ax.read_asterix(one), want)
    per = []
    for s, t in want.items():
        p = tmp_path / f"r{s}.ast"
        p.write_bytes(_plots(t, s, rng))
        per.append(p)
    _check(ax.read_asterix(per), want)
    # the same three radars (ending at 20:00) continuing in a file of the next day
    nxt = {s: _scan(DAY + 10.0 * s, DAY + 3600.0, rng) for s in want}
    p = tmp_path / "next.ast"
    p.write_bytes(b"".join(_plots(t, s, rng) for s, t in nxt.items()))
    _check(ax.read_asterix([*per, p]), {s: np.concatenate([want[s], nxt[s]]) for s in want})


def test_what_cannot_be_placed_is_refused_naming_the_file(tmp_path) -> None:
    rng = np.random.default_rng(2804)
    p1, p2 = tmp_path / "h12.ast", tmp_path / "h11.ast"
    p1.write_bytes(_plots(_scan(43200.0, 46800.0, rng), 1, rng))
    p2.write_bytes(_plots(_scan(39600.0, 43200.0, rng), 1, rng))
    with pytest.raises(
        ProblemError,
        match=r"h11\.ast: cannot place.*SAC/SIC 1/1.*time "
        r"order",
    ):
        ax.read_asterix([p1, p2])  # hourly files out of order
    # radar 1 stops at 01:00, radar 2 runs to 23:00; a file at 23:30 with both
    q1 = tmp_path / "day.ast"
    q1.write_bytes(
        _plots(_scan(0.0, 3600.0, rng), 1, rng) + _plots(_scan(0.0, 82800.0, rng), 2, rng)
    )
    q2 = tmp_path / "late.ast"
    q2.write_bytes(
        _plots(_scan(84600.0, 86000.0, rng), 2, rng) + _plots(_scan(84600.0, 86000.0, rng), 1, rng)
    )
    with pytest.raises(ProblemError, match=r"late\.ast: cannot place.*SAC/SIC 1/1"):
        ax.read_asterix([q1, q2])
