"""A radar engineer's first hour on the command line (issue 26): each trap a new user
fell into, run as they ran it -- the installed console script in a subprocess -- and
checked to be refused with the flag named (exit 2) or said in words in the output.

1. flag abbreviations (``--sigma 25`` taken as ``--sigma2 25``, a variance in m²);
2. a plots CSV in radians read as degrees; 3. ``--origin`` with latitude and longitude
swapped; 4. ``registration --area`` in km; 5. a registration figure clipped at the noise
floor; 6. ``(default: True)`` under ``--no-clean``; 7. numbers without units; 8. a binary
ASTERIX file named ``.csv``; 9. an unknown flag pointed at the root's help; 10. a flag
silently ignored, k best hypotheses not listed, ``optimal ()``, a 1000-digit count.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from optmodels import cli
from tests.test_cli import assert_error, run_cli, run_many

#: The sites of the CSV network (lat, lon, h): near Novosibirsk, as the user's.
ORG = (55.0, 83.0, 150.0)


# ------------------------------------------------------------------------ fixtures
def _write_network(tmp: Path, *, radians: bool = False) -> tuple[Path, Path]:
    """A 3-D network (4 radars, 8 aircraft, 10 min) as a geodetic sites CSV and a plots CSV
    with heights; azimuths in degrees, or in radians with ``radians``."""
    from optmodels.scenarios.radar_network import radar_network

    sc = radar_network(5, n_aircraft=8, duration=600.0, geometry="3d", origin=ORG)
    r, p = sc.radars, sc.plots
    assert r.geodetic is not None and p.height is not None
    sites = tmp / "sites.csv"
    sites.write_text(
        "name,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        + "".join(
            f"{r.names[i]},"
            + ",".join(
                repr(float(v))
                for v in (
                    *r.geodetic[i],
                    r.sigma_range[i],
                    np.rad2deg(r.sigma_azimuth[i]),
                    r.max_range[i],
                )
            )
            + "\n"
            for i in range(r.m)
        ),
        encoding="utf-8",
    )
    az = p.azimuth if radians else np.rad2deg(p.azimuth)
    plots = tmp / ("plots_rad.csv" if radians else "plots.csv")
    plots.write_text(
        "time,radar,range,azimuth,object,height\n"
        + "".join(
            f"{float(t)!r},{r.names[k]},{float(g)!r},{float(a)!r},A{o},{float(h)!r}\n"
            for t, k, g, a, o, h in zip(
                p.time, p.radar, p.range, az, p.object, p.height, strict=True
            )
        ),
        encoding="utf-8",
    )
    return sites, plots


@pytest.fixture(scope="module")
def network(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("network")
    sites, plots = _write_network(tmp)
    _, plots_rad = _write_network(tmp, radians=True)
    return {"tmp": tmp, "sites": sites, "plots": plots, "plots_rad": plots_rad}


@pytest.fixture(scope="module")
def chain(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The README's walk on a small simulated ASTERIX network: simulate -> build -> solve
    (closed form) -> correct (CSV)."""
    tmp = tmp_path_factory.mktemp("chain")
    sim = run_cli(
        "biasfield",
        "simulate",
        "--out",
        tmp / "sim",
        "--aircraft",
        "12",
        "--duration",
        "900",
        "--seed",
        "3",
        "--json",
    ).json()
    rec, sites = Path(sim["recording"]), Path(sim["sites"])
    run_cli("biasfield", "build", rec, "--radars", sites, "--cells", "40", "--out", tmp / "fd.npz")
    run_cli("biasfield", "solve", tmp / "fd.npz", "--method", "closed-form", "--out", tmp / "f")
    run_cli(
        "biasfield",
        "correct",
        rec,
        "--radars",
        sites,
        "--field",
        tmp / "f" / "field.npz",
        "--out",
        tmp / "corrected.csv",
    )
    return {"tmp": tmp, "rec": rec, "sites": sites, "field": tmp / "f" / "field.npz"}


def _leaves() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    out: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(p: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        out[path] = p
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, child in a.choices.items():
                    walk(child, (*path, name))

    walk(cli.build_parser(), ())
    return out


def _track_csv(path: Path) -> Path:
    """A level circle at 10 Hz, times written as 0.0, 0.1, ... (``0.3`` must come back as
    ``0.3``, not ``0.29999999999999999``); one plane throughout."""
    rng = np.random.default_rng(8)
    t = np.arange(300) / 10.0
    w = 2 * np.pi / 60.0
    xyz = np.column_stack([5e3 * np.cos(w * t), 5e3 * np.sin(w * t), np.full(t.size, 3e3)])
    xyz += rng.normal(scale=5.0, size=xyz.shape)
    path.write_text(
        "t,x,y,z\n"
        + "".join(
            f"{k / 10:.1f},{float(x)!r},{float(y)!r},{float(z)!r}\n"
            for k, (x, y, z) in enumerate(xyz)
        ),
        encoding="utf-8",
    )
    return path


# ------------------------------------------------------------- 1. no abbreviations
def test_no_parser_accepts_abbreviations() -> None:
    leaves = _leaves()
    assert len(leaves) > 15
    assert all(p.allow_abbrev is False for p in leaves.values()), [
        k for k, p in leaves.items() if p.allow_abbrev
    ]


def test_sigma_is_not_sigma2_and_the_former_rate_flag(tmp_path: Path) -> None:
    """``plane fit --sigma 25`` was ``--sigma2 25`` (exit 0, a variance of 25 m²): now a
    usage error naming the verb's help and the flag meant; ``--false-alarm-rate`` (the
    former name) is still ``--false-alarm-rate-per-h`` with a note, an abbreviation of it
    is not, and both names at once are refused."""
    pts = tmp_path / "pts.csv"
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1e3, 1e3, (20, 2))
    pts.write_text(
        "x,y,z\n"
        + "".join(f"{float(a)!r},{float(b)!r},{float(0.1 * a + rng.normal())!r}\n" for a, b in xy),
        encoding="utf-8",
    )
    trk = _track_csv(tmp_path / "trk.csv")
    base = ["plane", "track", trk, "--window", "10s", "--sigma2", "25", "--json"]
    sigma, fa_abbrev, former, both, unknown = run_many(
        [
            ["plane", "fit", pts, "--sigma", "25", "--json"],
            [*base, "--false-alarm", "2"],
            [*base, "--false-alarm-rate", "2"],
            [*base, "--false-alarm-rate", "2", "--false-alarm-rate-per-h", "3"],
            ["biasfield", "build", pts, "--radars", pts, "--bogus"],
        ],
        expect=None,
    )
    line = assert_error(sigma, 2, "--sigma", "did you mean --sigma2?", "optmodels plane fit --help")
    assert "unrecognized arguments" in line
    assert_error(fa_abbrev, 2, "--false-alarm", "--false-alarm-rate-per-h")
    assert former.code == 0, former.err
    assert former.json()["false_alarm_rate_per_h"] == 2.0
    assert "--false-alarm-rate is now --false-alarm-rate-per-h" in former.err
    assert_error(both, 2, "--false-alarm-rate", "give one of them")
    # 9. the verb's help, not the root's
    assert_error(unknown, 2, "--bogus", "see optmodels biasfield build --help")


# --------------------------------------------------------- 2. radians read as degrees
def test_radians_read_as_degrees_are_refused(network: dict[str, Path]) -> None:
    sites, rad, deg = network["sites"], network["plots_rad"], network["plots"]
    args = ["biasfield", "registration", "--radars", sites, "--json"]
    default, explicit_rad, explicit_deg, degrees = run_many(
        [
            [*args, rad],
            [*args, rad, "--azimuth-unit", "rad"],
            [*args, rad, "--azimuth-unit", "deg"],
            [*args, deg],
        ],
        expect=None,
    )
    n = sum(1 for _ in rad.open(encoding="utf-8")) - 1
    assert n >= 50
    assert_error(
        default, 2, "--azimuth-unit", f"all {n} azimuths", "±6.3", "radians?", "--azimuth-unit rad"
    )
    ok_rad, ok_deg = explicit_rad.json(), degrees.json()
    assert explicit_rad.code == degrees.code == 0, (explicit_rad.err, degrees.err)
    for key in ("overall_m", "raw_overall_m", "noise_m"):
        assert ok_rad["registration"][key] == pytest.approx(ok_deg["registration"][key])
    # an explicit deg is taken as given: read (and wrong), not refused for its unit
    assert "--azimuth-unit" not in explicit_deg.err


# --------------------------------------------------------------- 3. swapped origin
def test_origin_far_from_every_site_is_refused(network: dict[str, Path]) -> None:
    sites, plots = network["sites"], network["plots"]
    swapped, fine = run_many(
        [
            ["biasfield", "registration", plots, "--radars", sites, "--origin", "83,55,0"],
            [
                "biasfield",
                "registration",
                plots,
                "--radars",
                sites,
                "--origin",
                "55,83,0",
                "--json",
            ],
        ],
        expect=None,
    )
    line = assert_error(swapped, 2, "--origin 83,55,0", "km from the nearest site", "LAT,LON,H")
    assert "swapped" in line
    km = float(re.search(r"(\d+) km from", line).group(1))  # type: ignore[union-attr]
    assert 2000 < km < 4000
    assert fine.code == 0, fine.err
    assert fine.json()["registration"]["overall_m"] is not None


# ------------------------------------------------------ 4-5. registration in words
def test_registration_area_and_noise_floor(chain: dict[str, Path]) -> None:
    """``--area 25`` (km meant; the flag is a side in metres) is refused with the unit and
    the smallest value; an area that holds too little says why every figure is n/a; a
    figure clipped at 0 (after the correction) says it is at or below the noise floor."""
    rec, sites, tmp = chain["rec"], chain["sites"], chain["tmp"]
    reg = ["biasfield", "registration", "--radars", sites]
    km, small, after, after_json = run_many(
        [
            [*reg, rec, "--area", "25"],
            [*reg, rec, "--area", "1000"],
            [*reg, tmp / "corrected.csv", "--drop-out-of-range"],
            [*reg, tmp / "corrected.csv", "--drop-out-of-range", "--json"],
        ],
        expect=None,
    )
    assert_error(km, 2, "--area", "METRES", "1000")
    assert small.code == 1
    assert "no area of side 1000 m holds 20" in small.out and "n/a" in small.out
    assert "not OK: no area of side 1000 m" in small.err and "some part failed" not in small.err
    assert "nan" not in small.out
    doc = after_json.json()["registration"]
    zeros = [doc["overall_m"], *(v["rms_m"] for v in doc["pairs"].values())].count(0.0)
    assert zeros >= 1  # this network after its correction: systematic part ≤ noise
    assert after.out.count("(at or below the noise floor of") == zeros
    if doc["overall_m"] == 0.0:
        floor = f"{doc['noise_m']:.0f}"
        assert f"registration error 0.0 m (at or below the noise floor of {floor} m)" in after.out


def test_registration_text_in_process(capsys: pytest.CaptureFixture[str]) -> None:
    """The printer alone, on the user's figures (noise 51 m, raw 275 m, 0.0 m)."""
    from optmodels.cli.problems import biasfield_use

    res = {
        "plots": 1000,
        "registration": {
            "overall_m": 0.0,
            "raw_overall_m": 275.0,
            "noise_m": 51.0,
            "area_m": 25e3,
            "pairs": {
                "A-B": {
                    "rms_m": 0.0,
                    "raw_rms_m": 275.0,
                    "noise_m": 51.0,
                    "samples": 99,
                    "areas": 3,
                }
            },
        },
        "absolute": None,
    }
    biasfield_use._print_biasfield_registration(res)
    text = capsys.readouterr().out
    assert "registration error 0.0 m (at or below the noise floor of 51 m)" in text
    assert "raw 275.0 m" in text


# -------------------------------------------------------------------- 6. switches
def test_switches_show_no_true_or_false_default() -> None:
    for path, p in _leaves().items():
        text = " ".join(p.format_help().split())
        assert "(default: True)" not in text and "(default: False)" not in text, path
    for verb in ("build", "registration"):
        run = run_cli("biasfield", verb, "--help")
        assert "cleaning on unless --no-clean" in " ".join(run.out.split())


# ---------------------------------------------------------------------- 7. units
def test_montecarlo_text_says_its_units() -> None:
    text, doc = run_many(
        [
            ["montecarlo", "plane-angle", "--trials", "4", "--scheduler", "serial"],
            ["montecarlo", "plane-angle", "--trials", "4", "--scheduler", "serial", "--json"],
        ]
    )
    assert re.search(r"rmse_ml = \S+ rad\b", text.out), text.out
    assert re.search(r"crb2 = \S+ ± \S+ rad²", text.out), text.out
    assert doc.json()["units"]["rmse_ml"] == "rad"


def test_plane_track_text_and_csv(tmp_path: Path) -> None:
    trk = _track_csv(tmp_path / "trk.csv")
    args = ["plane", "track", trk, "--window", "10s", "--sigma2", "25"]
    summary, csv_out = run_many([[*args, "--out", tmp_path / "steps.csv"], args])
    assert "no plane change detected" in summary.out and "t = none" not in summary.out
    rows = csv_out.out.splitlines()
    times = [r.split(",")[0] for r in rows[1:]]
    assert "0.29999999999999999" not in csv_out.out
    assert all(t == repr(float(t)) for t in times)
    assert (tmp_path / "steps.csv").read_text(encoding="utf-8") == csv_out.out


def test_solve_lipschitz_has_its_unit(chain: dict[str, Path]) -> None:
    run = run_cli(
        "biasfield", "solve", chain["tmp"] / "fd.npz", "--lipschitz", "--out", chain["tmp"] / "l"
    )
    assert re.search(r"Lipschitz constant \S+ per m \(", run.out), run.out
    assert "()" not in run.out.splitlines()[0]


# ------------------------------------------------------- 8. a file named for its format
def test_correct_out_suffix_matches_the_format(chain: dict[str, Path], tmp_path: Path) -> None:
    rec, sites, field = chain["rec"], chain["sites"], chain["field"]
    base = ["biasfield", "correct", rec, "--radars", sites, "--field", field]
    ast_csv, csv_ast, default = run_many(
        [
            [*base, "--format", "asterix", "--out", tmp_path / "x.csv"],
            [*base, "--out", tmp_path / "x.ast"],
            [*base, "--format", "asterix", "--json"],
        ],
        expect=None,
        cwd=tmp_path,
    )
    assert_error(ast_csv, 2, "--out", "x.csv", "--format asterix", "x.ast")
    assert_error(csv_ast, 2, "--out", "x.ast", "--format csv")
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "x.ast").exists()
    assert default.code == 0, default.err
    assert default.json()["out"] == str((tmp_path / "corrected.ast").resolve())


# --------------------------------------------------------- 10. said, listed, readable
def test_trajectories_formulation_needs_a_solver(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    lines = [
        f"{o},{t},{1.0 + v * t + rng.normal(scale=0.1)!r}\n"
        for o, v in (("a", 1.0), ("b", -0.5))
        for t in range(8)
    ]
    path = tmp_path / "tr.csv"
    path.write_text("object,t,y\n" + "".join(lines), encoding="utf-8")
    ignored, solved = run_many(
        [
            ["trajectories", "fit", path, "--formulation", "reduced"],
            ["trajectories", "fit", path, "--formulation", "reduced", "--method", "CLARABEL"],
        ],
        expect=None,
    )
    assert_error(ignored, 2, "--formulation reduced", "--method")
    assert solved.code == 0, solved.err


def test_assignment_lists_the_k_best_and_counts_readably(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    means = rng.uniform(0, 3, (3, 2))
    case = {
        "means": means.tolist(),
        "covs": [np.eye(2).tolist()] * 3,
        "measurements": (means + rng.normal(0, 0.5, (3, 2))).tolist(),
        "meas_cov": (0.25 * np.eye(2)).tolist(),
        "volume": 9.0,
        "pd": 0.9,
        "rho": 0.3,
    }
    path = tmp_path / "case.json"
    path.write_text(json.dumps(case), encoding="utf-8")
    kbest, kjson, brute, count, count_json = run_many(
        [
            ["assignment", "solve", path, "--k", "3"],
            ["assignment", "solve", path, "--k", "3", "--json"],
            ["assignment", "solve", path, "--method", "brute-force"],
            ["assignment", "count", "500", "500"],
            ["assignment", "count", "500", "500", "--json"],
        ]
    )
    hyps = kjson.json()["k_best"]
    assert len(hyps) == 3
    for r, h in enumerate(hyps, start=1):
        line = next(x for x in kbest.out.splitlines() if x.strip().startswith(f"{r}. "))
        assert f"{h['log_score']:.6f}" in line
        assert line.count(" → ") == len(h["assignment"])
    assert "()" not in brute.out
    total = count_json.json()["total"]
    assert isinstance(total, int) and len(str(total)) > 1000  # JSON: the exact integer
    assert not re.search(r"\d{100}", count.out)
    lg = math.log10(total)
    assert f"(log10 {lg:.4f})" in count.out.splitlines()[0]


def test_plane_fit_formulation_with_the_closed_form_is_refused(tmp_path: Path) -> None:
    """``--formulation reduced`` names the generic NLP's form: with ``--method closed-form``
    it would be silently ignored, so it is refused (exit 2, naming the flag)."""
    path = tmp_path / "p.csv"
    path.write_text("x,y,z\n0,0,0\n1,0,0\n0,1,0\n1,1,0.01\n2,1,0\n")
    (r,) = run_many(
        [
            [
                "plane",
                "fit",
                path,
                "--sigma2",
                "1",
                "--method",
                "closed-form",
                "--formulation",
                "reduced",
            ]
        ],
        expect=None,
    )
    assert_error(r, 2, "--formulation reduced")
