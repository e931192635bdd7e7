"""Using the field from the command line (issue 17): build → solve → correct → registration,
the installed console script in subprocesses, on simulated 3-D traffic encoded as ASTERIX
(CAT048 plots + CAT021 ADS-B). The numbers are checked against the library on the same
files (read_recording, FieldMap, correct_plots, registration_error, absolute_error)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from tests.test_cli import assert_error, run_cli, run_many
from tests.test_cli_biasfield_build import encode_scene, write_sites

ORG = (55.0, 83.0, 150.0)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 3-D network (smooth bias field, 30 aircraft, 25 min) as a sites CSV keyed by
    SAC/SIC and one ASTERIX file (CAT048 of every radar + CAT021 of every aircraft)."""
    from optmodels.scenarios.radar_network import radar_network

    tmp = tmp_path_factory.mktemp("use")
    sc = radar_network(4, n_aircraft=30, duration=1500.0, geometry="3d", origin=ORG)
    r = sc.radars
    sites = write_sites(tmp / "sites.csv", r)
    cat048, cat021, _ = encode_scene(sc, 30000.0, 0x3C0000 + np.arange(30))
    rec = tmp / "recording.ast"
    rec.write_bytes(cat048 + cat021)
    (tmp / "adsb_only.ast").write_bytes(cat021)
    fd, out = tmp / "fd.npz", tmp / "solved"
    run_cli("biasfield", "build", rec, "--radars", sites, "--cells", "60", "--out", fd)
    run_cli("biasfield", "solve", fd, "--solver", "closed-form", "--out", out)
    return {
        "tmp": tmp,
        "sites": sites,
        "recording": rec,
        "fd": fd,
        "field": out / "field.npz",
        "adsb_only": tmp / "adsb_only.ast",
    }


def test_round_trip_build_solve_correct_registration(recording: dict[str, Path]) -> None:
    """``correct`` writes one row per plot read, equal to the library's correct_plots on the
    same recording; ``registration`` of the corrected plots is ≤ 20 % of the original's
    (on the field's area), and the same figures as the library's; with CAT021 in the
    recording the absolute error against ADS-B is reported too."""
    from optmodels.biasfield.recording import read_recording
    from optmodels.biasfield.referee import absolute_error, adsb_reference
    from optmodels.biasfield.usage import FieldMap, correct_plots, registration_error

    tmp, sites, rec, field = (recording[k] for k in ("tmp", "sites", "recording", "field"))
    corrected = tmp / "corrected.csv"
    cor = run_cli(
        "biasfield",
        "correct",
        rec,
        "--radars",
        sites,
        "--field",
        field,
        "--out",
        corrected,
        "--json",
    )
    assert cor.code == 0, cor.err
    doc = cor.json()
    lib = read_recording([rec], sites)
    assert doc["plots"] == len(lib.plots) and doc["geometry"] == "3d"
    with corrected.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(lib.plots)
    assert list(rows[0]) == [
        "radar",
        "sac",
        "sic",
        "address",
        "time",
        "time_of_day",
        "utc",
        "range",
        "azimuth",
        "height",
        "height_source",
        "covered",
        "reason",
    ]
    fm = FieldMap.load(field)
    ok = lib.plots.locatable(lib.radars)
    ref = correct_plots(lib.plots.subset(ok), lib.radars, fm)
    got_r = np.array([float(r["range"]) for r in rows])[ok]
    got_a = np.deg2rad(np.array([float(r["azimuth"]) for r in rows]))[ok]
    # printed as "%.3f" m and "%.9f" deg in [0, 360)
    np.testing.assert_allclose(got_r, ref.plots.range, rtol=0, atol=5e-4 + 1e-9)
    d = np.angle(np.exp(1j * (got_a - ref.plots.azimuth)))
    assert np.max(np.abs(d)) <= np.deg2rad(5e-10) + 1e-12
    covered = np.array([int(r["covered"]) for r in rows])[ok].astype(bool)
    np.testing.assert_array_equal(covered, ref.covered)
    # the field exists where all four radars see the traffic: about a third of the plots
    assert doc["corrected"] == int(ref.covered.sum()) > 0.2 * len(rows)

    before, after = run_many(
        [
            ["biasfield", "registration", rec, "--radars", sites, "--field", field, "--json"],
            [
                "biasfield",
                "registration",
                corrected,
                "--radars",
                sites,
                "--field",
                field,
                "--json",
                "--drop-out-of-range",
            ],  # a corrected range may pass max_range
        ]
    )
    b, a = before.json(), after.json()
    assert b["registration"]["overall_m"] > 100.0
    assert a["registration"]["overall_m"] <= 0.2 * b["registration"]["overall_m"]
    for pair, v in b["registration"]["pairs"].items():
        assert a["registration"]["pairs"][pair]["rms_m"] <= 0.2 * v["rms_m"], pair
    # the library on the same plots (cleaned as the CLI does) gives the same figures
    from optmodels.biasfield.cleaning import clean_plots

    kept, _ = clean_plots(lib.plots.subset(ok), lib.radars)
    reg = registration_error(kept, lib.radars, within=fm)
    assert b["registration"]["overall_m"] == pytest.approx(reg.overall, rel=1e-9, abs=1e-9)
    assert b["absolute"] is not None and a["absolute"] is None  # CAT021 only in the recording
    ab = absolute_error(
        kept, lib.radars, adsb_reference(kept, lib.adsb, lib.radars.origin), within=fm
    )
    assert b["absolute"]["overall_m"] == pytest.approx(ab.overall, rel=1e-9, abs=1e-9)


def test_correct_and_registration_refuse_what_does_not_fit(recording: dict[str, Path]) -> None:
    """A field of other radars, a missing field file, bad flags, a recording without
    CAT048, sites whose SAC/SIC no plot carries, 2-D asked of ASTERIX: exit 2, one line."""
    tmp, sites, rec, field = (recording[k] for k in ("tmp", "sites", "recording", "field"))
    moved = tmp / "moved.csv"
    lines = sites.read_text().splitlines()
    head, first = lines[0], lines[1].split(",")
    first[3] = repr(float(first[3]) + 0.05)  # radar R1 5.5 km further north
    moved.write_text("\n".join([head, ",".join(first), *lines[2:]]) + "\n")
    wrong = tmp / "wrong_ids.csv"
    first = lines[1].split(",")
    first[2] = "99"  # R1's SIC: no plot of the recording carries it
    wrong.write_text("\n".join([head, ",".join(first), *lines[2:]]) + "\n")
    no_plots, silent, flat = run_many(
        [
            [
                "biasfield",
                "correct",
                recording["adsb_only"],
                "--radars",
                sites,
                "--field",
                field,
                "--out",
                tmp / "z.csv",
                "--json",
            ],
            ["biasfield", "build", rec, "--radars", wrong, "--out", tmp / "w.npz"],
            [
                "biasfield",
                "build",
                rec,
                "--radars",
                sites,
                "--geometry",
                "2d",
                "--out",
                tmp / "v.npz",
            ],
        ],
        expect=None,
    )
    assert_error(no_plots, 2, "no CAT048 plot")
    assert_error(silent, 2, "R1", "99", "[25, 10]")
    assert_error(flat, 2, "--geometry 2d", "ASTERIX")
    other, missing, area = run_many(
        [
            [
                "biasfield",
                "correct",
                rec,
                "--radars",
                moved,
                "--field",
                field,
                "--out",
                tmp / "x.csv",
                "--json",
            ],
            [
                "biasfield",
                "correct",
                rec,
                "--radars",
                sites,
                "--field",
                tmp / "none.npz",
                "--out",
                tmp / "y.csv",
            ],
            ["biasfield", "registration", rec, "--radars", sites, "--area", "-5"],
        ],
        expect=None,
    )
    assert_error(other, 2, "--field", "differs")  # the moved site moves the mean origin too
    assert_error(missing, 2, "none.npz")
    assert_error(area, 2, "--area")
