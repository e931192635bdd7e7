"""The bias field's user-facing chain (issues 24.3, 24.4, 26.6, 28.2), as a user runs it:
``optmodels biasfield simulate`` → ``build`` → ``solve`` → ``correct`` → ``registration``
through the installed console script, the outputs checked against independent
computations (the recording read back by :func:`optmodels.io.read_asterix`, the library's
correct_plots, a least-squares line through field.csv), output paths refused before any
work, and the heights of a recording with ADS-B altitude spikes."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from tests.test_cli import assert_error, run_cli, run_many

DATE = "2026-12-02"


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The README's walk-through on a small simulated network (12 aircraft, 15 min)."""
    tmp = tmp_path_factory.mktemp("walk")
    sim = run_cli(
        "biasfield",
        "simulate",
        "--out",
        tmp / "sim",
        "--aircraft",
        "12",
        "--duration",
        "900",
        "--adsb-interval",
        "2",
        "--adsb-spikes",
        "2",
        "--seed",
        "3",
        "--json",
    )
    doc = sim.json()
    rec, sites = Path(doc["recording"]), Path(doc["sites"])
    build = run_cli(
        "biasfield",
        "build",
        rec,
        "--radars",
        sites,
        "--cells",
        "40",
        "--date",
        DATE,
        "--out",
        tmp / "fd.npz",
        "--json",
    ).json()
    solve = run_cli(
        "biasfield",
        "solve",
        tmp / "fd.npz",
        "--method",
        "closed-form",
        "--out",
        tmp / "solved",
        "--json",
    ).json()
    cor = run_cli(
        "biasfield",
        "correct",
        rec,
        "--radars",
        sites,
        "--field",
        tmp / "solved" / "field.npz",
        "--date",
        DATE,
        "--out",
        tmp / "corrected.csv",
        "--json",
    ).json()
    return {
        "tmp": tmp,
        "sim": doc,
        "rec": rec,
        "sites": sites,
        "build": build,
        "solve": solve,
        "correct": cor,
    }


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_simulate_writes_what_it_says(walk: dict) -> None:
    """The recording holds the CAT048 plots of every radar (SAC/SIC of the sites CSV) and
    the CAT021 reports the simulator reports, in time order."""
    from optmodels.io import read_asterix

    doc = walk["sim"]
    data = read_asterix([walk["rec"]], date=DATE)
    assert len(data.cat048) == doc["cat048"] > 1000
    assert len(data.cat021) == doc["cat021"]
    sites = _rows(walk["sites"])
    assert [(int(r["sac"]), int(r["sic"])) for r in sites] == [tuple(i) for i in doc["sac_sic"]]
    got = set(zip(data.cat048.sac.tolist(), data.cat048.sic.tolist(), strict=True))
    assert got == {tuple(i) for i in doc["sac_sic"]}
    assert walk["build"]["adsb"]["adsb_heights_rejected"] == doc["spikes"] == 2


def test_corrected_rows_join_back_to_the_recording(walk: dict) -> None:
    """Every row of corrected.csv is one CAT048 record of the recording, found by (SAC/SIC,
    ICAO address, time of day); its radar name is the site's; the UTC date-time is the
    date plus the time of day; azimuths in [0°, 360°); range and azimuth equal the
    library's correct_plots on the same recording (to the printed digits)."""
    from optmodels.biasfield.recording import read_recording
    from optmodels.biasfield.usage import FieldMap, correct_plots
    from optmodels.io import read_asterix

    rows = _rows(walk["tmp"] / "corrected.csv")
    cor = walk["correct"]
    assert len(rows) == cor["plots"] and list(rows[0]) == list(cor["columns"])
    c = read_asterix([walk["rec"]], date=DATE).cat048
    keys = {}
    for k in range(len(c)):
        key = (
            int(c.sac[k]),
            int(c.sic[k]),
            f"{int(c.address[k]):06x}",
            round(float(np.mod(c.time[k], 86400.0)) * 128),
        )
        keys[key] = keys.get(key, 0) + 1
    names = {(r["sac"], r["sic"]): r["name"] for r in _rows(walk["sites"])}
    matched = 0
    for r in rows:
        key = (int(r["sac"]), int(r["sic"]), r["address"], round(float(r["time_of_day"]) * 128))
        assert keys.get(key) == 1, r
        assert names[(r["sac"], r["sic"])] == r["radar"]
        utc = np.datetime64(r["utc"].rstrip("Z"))
        want = np.datetime64(DATE) + np.timedelta64(round(float(r["time_of_day"]) * 1e3), "ms")
        assert abs((utc - want) / np.timedelta64(1, "ms")) <= 1
        matched += 1
    assert matched == len(c) == len(rows)
    az = np.array([float(r["azimuth"]) for r in rows])
    assert np.all((az >= 0.0) & (az < 360.0))
    lib = read_recording([walk["rec"]], walk["sites"], date=DATE)
    fm = FieldMap.load(walk["tmp"] / "solved" / "field.npz")
    ok = lib.plots.locatable(lib.radars)
    assert ok.all()
    ref = correct_plots(lib.plots, lib.radars, fm)
    # rows are in the recording's (time) order, as read_recording's plots
    np.testing.assert_allclose(
        [float(r["range"]) for r in rows], ref.plots.range, rtol=0, atol=5e-4 + 1e-9
    )  # "%.3f" m
    d = np.deg2rad(az) - ref.plots.azimuth
    assert np.max(np.abs(np.angle(np.exp(1j * d)))) <= np.deg2rad(5e-10) + 1e-12  # "%.9f"°
    assert [r["address"] for r in rows] == [lib.icao24[o] for o in lib.plots.object]
    # each plot's own CAT048 record (for a rewrite of the recording): same address and time
    assert lib.record is not None and np.unique(lib.record).size == len(rows)
    np.testing.assert_array_equal(c.address[lib.record], lib.addresses[lib.plots.object])
    np.testing.assert_array_equal(c.time[lib.record], lib.plots.time)
    np.testing.assert_array_equal(c.offset[lib.record], lib.offset)
    assert cor["corrected"] == int(ref.covered.sum()) >= 0.9 * len(rows)
    assert sum(cor["reasons"].values()) == len(rows)


def test_field_csv_and_solve_summary(walk: dict) -> None:
    """field.csv: numbers as numbers, radar names; the per-radar baseline of ``solve
    --json`` equals a least-squares line (numpy.polyfit) through field.csv's range biases
    against the distance from the site, and the mean of its azimuth biases; the spread is
    their standard deviation. J is explained in the JSON and left out of the text."""
    from optmodels.io import read_npz

    tmp = walk["tmp"]
    rows = _rows(tmp / "solved" / "field.csv")
    names = [r["name"] for r in _rows(walk["sites"])]
    assert {r["radar"] for r in rows} == set(names)
    for r in rows:
        for key in ("x_m", "y_m", "range_bias_m", "azimuth_bias_deg"):
            float(r[key])  # a plain number (was np.float64(...))
    sites = read_npz(tmp / "solved" / "field.npz")["radars"]
    summary = {s["radar"]: s for s in walk["solve"]["radars"]}
    assert "smoothness" in walk["solve"]["objective_note"]
    for i, name in enumerate(names):
        mine = [r for r in rows if r["radar"] == name]
        xy = np.array([[float(r["x_m"]), float(r["y_m"])] for r in mine])
        rho = np.hypot(*(xy - sites[i]).T)
        fr = np.array([float(r["range_bias_m"]) for r in mine])
        fa = np.array([float(r["azimuth_bias_deg"]) for r in mine])
        gain, const = np.polyfit(rho, fr, 1)
        s = summary[name]
        assert s["cells"] == len(mine)
        # field.csv carries 10 significant digits: 1e-6 relative is far above that
        assert s["range_bias_m"] == pytest.approx(const, rel=1e-6, abs=1e-6)
        assert s["range_gain_ppm"] == pytest.approx(gain * 1e6, rel=1e-6, abs=1e-6)
        assert s["azimuth_bias_deg"] == pytest.approx(fa.mean(), rel=1e-6, abs=1e-9)
        assert s["range_spread_m"] == pytest.approx(np.std(fr), rel=1e-6, abs=1e-6)
        resid = fr - (const + gain * rho)
        want_se = np.sqrt(
            resid
            @ resid
            / (len(mine) - 2)
            * np.linalg.inv(
                np.column_stack([np.ones_like(rho), rho]).T
                @ np.column_stack([np.ones_like(rho), rho])
            )[0, 0]
        )
        assert s["range_bias_sigma_m"] == pytest.approx(want_se, rel=1e-5)
    text = run_cli(
        "biasfield",
        "solve",
        tmp / "fd.npz",
        "--method",
        "closed-form",
        "--out",
        tmp / "solved_text",
    )
    assert "J =" not in text.out and "range bias m" in text.out
    for name in names:
        assert f"  {name} " in text.out


def test_registration_after_the_walk_through(walk: dict) -> None:
    """corrected.csv reads back as plots (its address column labels the tracks) and its
    cross-radar registration error is ≤ 20 % of the recording's, on the field's area."""
    tmp = walk["tmp"]
    field = tmp / "solved" / "field.npz"
    before, after = run_many(
        [
            [
                "biasfield",
                "registration",
                walk["rec"],
                "--radars",
                walk["sites"],
                "--field",
                field,
                "--json",
            ],
            [
                "biasfield",
                "registration",
                tmp / "corrected.csv",
                "--radars",
                walk["sites"],
                "--field",
                field,
                "--drop-out-of-range",
                "--json",
            ],
        ]
    )
    b, a = before.json()["registration"], after.json()["registration"]
    assert b["overall_m"] > 100.0
    assert a["overall_m"] <= 0.2 * b["overall_m"]


def test_build_text_is_a_summary(walk: dict) -> None:
    """``build`` prints lines a person reads (no Python dict)."""
    tmp = walk["tmp"]
    run = run_cli(
        "biasfield",
        "build",
        walk["rec"],
        "--radars",
        walk["sites"],
        "--cells",
        "30",
        "--out",
        tmp / "fd_text.npz",
    )
    assert "{" not in run.out and "cells per radar" in run.out
    assert "height spikes rejected" in run.out


def test_output_paths_are_checked_before_any_work(walk: dict, tmp_path: Path) -> None:
    """An unwritable --out, an existing folder given as a FILE, a file given as the
    FOLDER: exit 2 naming --out, before the recording is even read (a missing recording
    is not what the message is about), and nothing written beside the folder."""
    folder = tmp_path / "existing"
    folder.mkdir()
    afile = tmp_path / "afile"
    afile.write_text("x")
    missing = tmp_path / "missing.ast"
    runs = run_many(
        [
            ["biasfield", "build", missing, "--radars", walk["sites"], "--out", "/proc/x.npz"],
            ["biasfield", "build", missing, "--radars", walk["sites"], "--out", folder],
            [
                "biasfield",
                "correct",
                missing,
                "--radars",
                walk["sites"],
                "--field",
                missing,
                "--out",
                "/proc/y.csv",
            ],
            [
                "biasfield",
                "correct",
                missing,
                "--radars",
                walk["sites"],
                "--field",
                missing,
                "--out",
                folder,
            ],
            ["biasfield", "solve", missing, "--out", afile],
            ["biasfield", "simulate", "--out", afile],
        ],
        expect=None,
    )
    for run in runs:
        assert_error(run, 2, "--out")
        assert "missing" not in run.err_lines[0]
    assert not (tmp_path / "existing.npz").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "existing"]


def _spike_recording(tmp_path: Path, spike: slice) -> tuple[Path, Path, dict]:
    """One aircraft level at 10 km (geometric), ADS-B every second, CAT048 plots of one
    radar every 4 s with the right flight level; the ADS-B heights in ``spike`` get
    +7.8 km."""
    import pymap3d

    from optmodels.io import encode_cat021, encode_cat048
    from optmodels.scenarios.recording import _flight_level

    site = (55.0, 83.0, 200.0)
    sites = tmp_path / "sites.csv"
    sites.write_text(
        "name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        f"R1,7,11,{site[0]},{site[1]},{site[2]},50,0.08,250000\n"
        "R2,7,12,56.0,84.0,300,50,0.08,250000\n"
    )  # (a set needs 2 radars)
    t = 40000.0 + np.arange(120.0)
    lat = 55.5 + 1e-4 * np.arange(120.0)
    lon = np.full(120, 83.2)
    h = np.full(120, 10_000.0)
    bad = h.copy()
    bad[spike] += 7800.0
    tp = 40000.0 + np.arange(2.5, 118.0, 4.0)
    la = np.interp(tp, t, lat)
    az, _el, sr = pymap3d.geodetic2aer(la, np.full(tp.size, 83.2), 10_000.0, *site)
    fl = _flight_level(np.full(tp.size, 10_000.0))
    rec = tmp_path / "spike.ast"
    rec.write_bytes(
        encode_cat021(t, 9, 1, lat, lon, height=bad, address=0xABC123)
        + encode_cat048(tp, 7, 11, sr, np.radians(az), flight_level=fl, address=0xABC123)
    )
    near = (tp >= t[spike][0] - 1.0) & (tp <= t[spike][-1] + 1.0)
    return rec, sites, {"near": near, "fl": fl}


def test_an_isolated_height_spike_is_cleaned(tmp_path: Path) -> None:
    """One +7.8 km CAT021 altitude spike: discarded before the interpolation, so the plots
    beside it get the ADS-B height of the clean neighbours (10 km to the 6.25 ft LSB),
    not the +3.9 km of the interpolation through the spike; without the cleaning, the
    flight-level check still rejects the spiked ADS-B heights for the flight level."""
    from optmodels.biasfield.heights import fl_to_height
    from optmodels.biasfield.recording import HEIGHT_SOURCES, read_recording

    rec, sites, f = _spike_recording(tmp_path, slice(50, 51))
    near = f["near"]
    assert near.sum() == 1  # the plot interpolated through the spike (t = 50.5 s)
    r = read_recording(rec, sites)
    assert r.report.adsb_heights_rejected == 1
    assert np.all(r.height_source == 1)
    assert np.max(np.abs(r.plots.height - 10_000.0)) <= 6.25 * 0.3048 / 2 + 1e-6
    raw = read_recording(rec, sites, clean_heights=False)
    assert raw.report.adsb_heights_rejected == 0
    src = np.asarray(HEIGHT_SOURCES)[raw.height_source]
    assert list(src[near]) == ["flight level, ADS-B rejected"]
    assert raw.report.heights[HEIGHT_SOURCES[3]] == 1
    fl_h = fl_to_height(np.round(f["fl"] * 4) / 4 * 100 * 0.3048)  # I090 LSB 1/4 FL
    np.testing.assert_allclose(raw.plots.height[near], fl_h[near], rtol=0, atol=1e-6)


def test_a_long_height_spike_gives_the_flight_level_height(tmp_path: Path) -> None:
    """Eight consecutive spiked CAT021 reports outvote the median of their neighbours, so
    the cleaning keeps some; the plots among them disagree with their own flight level
    by ~7.8 km (> 300 m + 8 % of 10 km) and get the flight-level height (within the FL
    LSB of the truth), counted per source; the other plots keep the ADS-B height."""
    from optmodels.biasfield.heights import fl_to_height
    from optmodels.biasfield.recording import HEIGHT_SOURCES, read_recording

    rec, sites, f = _spike_recording(tmp_path, slice(40, 48))
    near = f["near"]
    r = read_recording(rec, sites)
    src = np.asarray(HEIGHT_SOURCES)[r.height_source]
    inside = near & (r.plots.time > 40000.0 + 40.5) & (r.plots.time < 40000.0 + 46.5)
    assert inside.sum() >= 1
    assert set(src[inside]) == {"flight level, ADS-B rejected"}
    fl_h = fl_to_height(np.round(f["fl"] * 4) / 4 * 100 * 0.3048)
    np.testing.assert_allclose(r.plots.height[inside], fl_h[inside], rtol=0, atol=1e-6)
    assert np.max(np.abs(r.plots.height - 10_000.0)) <= 0.25 * 100 * 0.3048 / 2 + 15.0
    assert r.report.heights[HEIGHT_SOURCES[3]] == int(np.sum(r.height_source == 3))
    assert set(src[~near]) == {"adsb"}


def test_simulate_refuses_bad_arguments(tmp_path: Path) -> None:
    """One ProblemError naming the argument (API) and exit 2 with one line (CLI)."""
    from optmodels.core import ProblemError
    from optmodels.scenarios.recording import simulate_recording

    for kw, name in (
        ({"radars": 1}, "radars"),
        ({"start": 90000.0}, "start"),
        ({"biases": "wavy"}, "biases"),
        ({"aircraft": 0}, "aircraft"),
        ({"adsb_interval": 0.5}, "adsb_interval"),
    ):
        with pytest.raises(ProblemError, match=name):
            simulate_recording(tmp_path / "x", **kw)
    assert not (tmp_path / "x" / "recording.ast").exists()
    bad = run_cli("biasfield", "simulate", "--out", tmp_path / "y", "--start", "90000", expect=None)
    assert_error(bad, 2, "start")


def test_correct_format_asterix_replaces_only_i040(walk: dict) -> None:
    """``correct --format asterix``: the corrected recording reads back with the same
    records in the same order, every column but range/azimuth equal, the covered plots'
    range and azimuth equal to corrected.csv's within one I040 LSB (1/256 NM, 360°/2¹⁶)
    and the others unchanged (the bytes: tests/test_asterix_rewrite.py)."""
    from optmodels.io import read_asterix

    out = walk["tmp"] / "corrected.ast"
    res = run_cli(
        "biasfield",
        "correct",
        walk["rec"],
        "--radars",
        walk["sites"],
        "--field",
        walk["tmp"] / "solved" / "field.npz",
        "--date",
        DATE,
        "--format",
        "asterix",
        "--out",
        out,
        "--json",
    ).json()
    assert res["format"] == "asterix" and res["corrected"] == walk["correct"]["corrected"]
    a = read_asterix([walk["rec"]], date=DATE)
    b = read_asterix([out], date=DATE)
    assert len(b.cat048) == len(a.cat048) and len(b.cat021) == len(a.cat021)
    for name in ("time", "sac", "sic", "address", "pressure_altitude"):
        assert np.array_equal(getattr(a.cat048, name), getattr(b.cat048, name), equal_nan=True), (
            name
        )
    rows = _rows(walk["tmp"] / "corrected.csv")
    cov = np.array([r["covered"] == "1" for r in rows])
    assert cov.sum() > 0  # (all of them on this small network)
    # the CSV's rows are one per plot read, in the order the plots were read: match the
    # records by (SAC/SIC, address, time of day) as the join-back test does
    key_b = {
        (
            int(b.cat048.sac[k]),
            int(b.cat048.sic[k]),
            int(b.cat048.address[k]),
            round(float(np.mod(b.cat048.time[k], 86400.0)) * 128),
        ): k
        for k in range(len(b.cat048))
    }
    lsb_r, lsb_a = 1852.0 / 256.0, 360.0 / 2**16
    changed = 0
    for r, c in zip(rows, cov, strict=True):
        k = key_b[
            (
                int(r["sac"]),
                int(r["sic"]),
                int(r["address"], 16),
                round(float(r["time_of_day"]) * 128),
            )
        ]
        if c:
            assert abs(b.cat048.range[k] - float(r["range"])) <= lsb_r
            d = (np.rad2deg(b.cat048.azimuth[k]) - float(r["azimuth"]) + 180.0) % 360.0 - 180.0
            assert abs(d) <= lsb_a
            changed += int(abs(b.cat048.range[k] - a.cat048.range[k]) > lsb_r / 2)
        else:
            assert b.cat048.range[k] == a.cat048.range[k]
            assert b.cat048.azimuth[k] == a.cat048.azimuth[k]
    assert changed > 0.5 * cov.sum()  # the biases are tens of metres: most ranges move


def test_correct_format_asterix_refuses_a_csv_recording(tmp_path: Path) -> None:
    """A CSV/Parquet recording has no CAT048 records to rewrite: exit 2, one line."""
    plots = tmp_path / "plots.csv"
    plots.write_text("time,radar,range,azimuth\n0,0,1000,10\n", encoding="utf-8")
    sites = tmp_path / "sites.csv"
    sites.write_text("name,x,y\nR1,0,0\nR2,5000,0\n", encoding="utf-8")
    field = tmp_path / "field.npz"
    np.savez(field, x=np.zeros(1))
    r = run_cli(
        "biasfield",
        "correct",
        plots,
        "--radars",
        sites,
        "--field",
        field,
        "--format",
        "asterix",
        "--out",
        tmp_path / "c.ast",
        expect=2,
    )
    assert len(r.err.strip().splitlines()) == 1
    assert "--format asterix" in r.err and "not an ASTERIX recording" in r.err
