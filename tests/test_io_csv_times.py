"""ISO 8601 times in a CSV time column (issue 26 item 2): read as seconds since UTC
midnight of the earliest time, as from_frame takes a DataFrame's timestamps; checked against
datetime arithmetic, and through the bias-field plots reader against the same file in
seconds."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import csv_numbers, csv_times, read_csv_rows


def _iso(rng: np.random.Generator, n: int) -> tuple[list[str], np.ndarray]:
    """ISO cells in several spellings and their seconds since 2026-03-01T00:00Z."""
    base = dt.datetime(2026, 3, 1, tzinfo=dt.UTC)
    secs = np.sort(rng.uniform(30.0, 2 * 86400.0, n))
    secs = np.round(secs * 1000) / 1000  # ms, exact in ISO text
    cells = []
    for k, s in enumerate(secs):
        t = base + dt.timedelta(seconds=float(s))
        style = k % 4
        if style == 0:
            cells.append(t.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3])  # naive = UTC
        elif style == 1:
            cells.append(t.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "Z")
        elif style == 2:  # +02:00 offset
            cells.append(
                (t + dt.timedelta(hours=2)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "+02:00"
            )
        else:
            cells.append(t.isoformat())
    return cells, secs


def test_iso_times_are_seconds_since_midnight_of_the_first_day(tmp_path) -> None:
    rng = np.random.default_rng(2602)
    cells, secs = _iso(rng, 200)
    got, epoch = csv_times("x.csv", "time", cells)
    assert epoch == np.datetime64("2026-03-01T00:00:00", "ns")
    assert np.max(np.abs(got - secs)) < 1e-6
    # through a CSV file and csv_numbers (the readers' path), and with an epoch given
    p = tmp_path / "t.csv"
    p.write_text("time,value\n" + "".join(f"{c},{k}\n" for k, c in enumerate(cells)))
    rows = read_csv_rows(p)
    col = [r[0] for r in rows.rows]
    np.testing.assert_allclose(csv_numbers(p, "time", col, rows.lines), secs, atol=1e-6)
    later, _ = csv_times(p, "time", col, epoch="2026-03-02")
    np.testing.assert_allclose(later, secs - 86400.0, atol=1e-6)
    # numbers stay numbers (no epoch); datetime64 cells (a Parquet column) are converted
    num, e = csv_times(p, "time", [f"{s:.3f}" for s in secs])
    assert e is None and np.max(np.abs(num - secs)) < 1e-9
    stamps = np.datetime64("2026-03-01", "ns") + (secs * 1e9).astype("timedelta64[ns]")
    np.testing.assert_allclose(csv_numbers(p, "time", stamps), secs, atol=1e-6)


def test_bad_iso_columns_are_refused_with_the_line(tmp_path) -> None:
    cells = ["2026-03-01T00:00:01", "2026-03-01T00:00:02", "17.5"]
    with pytest.raises(
        ProblemError,
        match=r"x\.csv: line 4, column 'time': '17\.5' is not an "
        r"ISO 8601",
    ):
        csv_times("x.csv", "time", cells, [2, 3, 4])
    with pytest.raises(ProblemError, match=r"line 3, column 'time'.*2026-13-01"):
        csv_times("x.csv", "time", ["2026-03-01T00:00:01", "2026-13-01T00:00:00"], [2, 3])
    # not a time column: a date is still not a number
    with pytest.raises(ProblemError, match=r"column 'range': '2026-03-01' is not a number"):
        csv_numbers("x.csv", "range", ["2026-03-01"])


def test_plots_csv_with_iso_times_equals_the_seconds_file(tmp_path) -> None:
    import optmodels.biasfield as bf

    (tmp_path / "radars.csv").write_text(
        "name,x,y,sigma_range,sigma_azimuth,max_range\n"
        "R1,0,0,30,0.05,200000\nR2,50000,0,30,0.05,200000\n"
    )
    radars, _ = bf.read_radars(tmp_path / "radars.csv")
    rng = np.random.default_rng(2603)
    cells, secs = _iso(rng, 60)
    body = [
        f"{r},{rg:.1f},{az:.4f},{o}"
        for r, rg, az, o in zip(
            rng.choice(["R1", "R2"], 60),
            rng.uniform(1e3, 1e5, 60),
            rng.uniform(0, 359, 60),
            rng.integers(0, 5, 60),
            strict=True,
        )
    ]
    iso, sec = tmp_path / "iso.csv", tmp_path / "sec.csv"
    iso.write_text(
        "time,radar,range,azimuth,object\n"
        + "".join(f"{c},{b}\n" for c, b in zip(cells, body, strict=True))
    )
    sec.write_text(
        "time,radar,range,azimuth,object\n"
        + "".join(f"{s:.3f},{b}\n" for s, b in zip(secs, body, strict=True))
    )
    a, _ = bf.read_plots(iso, radars)
    b, _ = bf.read_plots(sec, radars)
    np.testing.assert_allclose(a.time, b.time, atol=1e-6)
    np.testing.assert_array_equal(a.radar, b.radar)
    np.testing.assert_array_equal(a.range, b.range)
