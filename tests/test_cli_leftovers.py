"""The new-user review's leftovers, run as the user ran them -- the installed console script
in a subprocess -- and checked against independent computations:

1. ``trajectories fit --family custom``: θ and its standard deviations, one labelled line
   per entry (quantity, objects, unit), not a flat list;
2. ``biasfield simulate --spacing 150`` (km meant) and ``--max-range 250``: refused (exit 2,
   one line naming the flag, in METRES) instead of a network of one site or no plot;
3. ``plane fit``: the normal's sign convention (offset ≥ 0: the normal points from the
   frame's origin towards the plane) stated in the text, the help and ``--json``, and the
   one the library applies in every solver.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tests.test_cli import assert_error, run_many

# ------------------------------------------------------------------ 1. θ labelled
#: (start, velocity) per object: a and b share the start, b and c the velocity.
LINES = {"a": (1.0, 1.0), "b": (1.0, -0.5), "c": (3.0, -0.5)}
TIMES = np.arange(8.0)
SIGMA = 0.1


def _trajectory_csv(path: Path, dim: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The objects of :data:`LINES` (coordinate k offset by k) with N(0, σ²) noise; writes
    ``object,t,y`` (dim 1) or ``object,t,x,y`` (dim 2) and returns the values written."""
    header = "object,t,y" if dim == 1 else "object,t,x,y"
    rows, values = [], {}
    for obj, (y0, v) in LINES.items():
        vals = np.column_stack(
            [y0 + k + v * TIMES + rng.normal(scale=SIGMA, size=TIMES.size) for k in range(dim)]
        )
        values[obj] = vals
        rows += [
            f"{obj},{t!r}," + ",".join(repr(float(x)) for x in row) + "\n"
            for t, row in zip(TIMES.tolist(), vals, strict=True)
        ]
    path.write_text(header + "\n" + "".join(rows), encoding="utf-8")
    return values


def _independent_fit(values: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """θ (starts of {a, b}, {c}; velocities of {a}, {b, c}) by ordinary least squares on
    the design matrix written out here, and its standard deviation σ·sqrt(diag (AᵀA)⁻¹)."""
    start_col = {"a": 0, "b": 0, "c": 1}
    vel_col = {"a": 2, "b": 3, "c": 3}
    a_rows, y_rows = [], []
    for obj, vals in values.items():
        for t, y in zip(TIMES, vals, strict=True):
            row = np.zeros(4)
            row[start_col[obj]], row[vel_col[obj]] = 1.0, t
            a_rows.append(row)
            y_rows.append(y)
    a, y = np.array(a_rows), np.array(y_rows)
    theta = np.linalg.lstsq(a, y, rcond=None)[0]
    std = SIGMA * np.sqrt(np.diag(np.linalg.inv(a.T @ a)))
    return theta, std


def test_custom_family_theta_is_labelled(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    one = _trajectory_csv(tmp_path / "one.csv", 1, rng)
    two = _trajectory_csv(tmp_path / "two.csv", 2, rng)
    fam = ["--family", "custom", "--shared-start", "a,b", "--shared-velocity", "b,c"]
    sig = ["--sigma2", repr(SIGMA**2)]
    text1, doc1, text2 = run_many(
        [
            ["trajectories", "fit", tmp_path / "one.csv", *fam, *sig],
            ["trajectories", "fit", tmp_path / "one.csv", *fam, *sig, "--json"],
            ["trajectories", "fit", tmp_path / "two.csv", *fam, *sig],
        ]
    )
    names = ["start of a, b", "start of c", "velocity of a", "velocity of b, c"]
    units = ["unit of y", "unit of y", "unit of y per s", "unit of y per s"]
    theta, std = _independent_fit(one)
    assert "θ std = [" not in text1.out  # the former unlabelled flat list
    for name, unit, v, e in zip(names, units, theta[:, 0], std, strict=True):
        m = re.search(rf"^    {name} = (\S+) ± (\S+) \({unit}\)$", text1.out, re.MULTILINE)
        assert m, (name, text1.out)
        assert float(m.group(1)) == pytest.approx(v, abs=1e-6)  # printed to 6 decimals
        assert float(m.group(2)) == pytest.approx(e, rel=1e-5)  # 6 significant digits
    doc = doc1.json()
    assert [
        f"{lab['quantity']} of {', '.join(lab['objects'])}" for lab in doc["theta_labels"]
    ] == names
    assert [lab["unit"] for lab in doc["theta_labels"]] == units
    np.testing.assert_allclose(np.ravel(doc["theta"]), theta[:, 0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.ravel(doc["theta_std"]), std, rtol=1e-9)
    # two coordinates: one line per entry, each coordinate named, the unit said once
    theta2, std2 = _independent_fit(two)
    for name, unit, v, e in zip(names, units, theta2, std2, strict=True):
        unit2 = unit.replace("unit of y", "unit of x, y")
        m = re.search(
            rf"^    {name}: x = (\S+) ± (\S+), y = (\S+) ± (\S+) \({unit2}\)$",
            text2.out,
            re.MULTILINE,
        )
        assert m, (name, text2.out)
        got = np.array([float(g) for g in m.groups()])
        np.testing.assert_allclose(got[[0, 2]], v, atol=1e-6)
        np.testing.assert_allclose(got[[1, 3]], [e, e], rtol=1e-5)


# -------------------------------------------------------- 2. simulate in metres
#: The simulator's figures the refusals rest on (its defaults, written out here):
#: azimuth noise 0.08°, traffic entering a square of half-side 150 km, aircraft 3-12 km
#: up, sites up to 610 m above the ellipsoid, a 40° cone of silence.
MIN_SEPARATION = 5 * np.deg2rad(0.08) * 150e3  # 1047 m
MIN_RANGE = np.floor((3000.0 - 610.0) / np.sin(np.deg2rad(40.0)) / 100) * 100  # 3700 m


def test_simulate_refuses_km_for_metres(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    base = ["biasfield", "simulate", "--aircraft", "3", "--duration", "120", "--out"]
    spacing, max_range, apart, pair, helped = run_many(
        [
            [*base, out, "--spacing", "150"],
            [*base, out, "--max-range", "250", "--json"],
            [*base, out, "--spacing", "400000"],
            # two radars 1200 m apart (> 1047 m): a network, simulated
            [*base, tmp_path / "pair", "--n-radars", "2", "--spacing", "600", "--json"],
            ["biasfield", "simulate", "--help"],
        ],
        expect=None,
    )
    line = assert_error(spacing, 2, "--spacing 150", "METRES", "--spacing 150000")
    gap = 2 * 150 * np.sin(np.pi / 4)
    assert f"are {gap:.0f} m apart, closer than {MIN_SEPARATION:.0f} m" in line
    assert f"give at least {np.ceil(MIN_SEPARATION / (2 * np.sin(np.pi / 4))):.0f}" in line
    line = assert_error(max_range, 2, "--max-range 250", "METRES", "--max-range 250000")
    assert f"below {MIN_RANGE:.0f} m no radar ever sees an aircraft" in line
    line = assert_error(apart, 2, "--spacing 400000", "--max-range 250000", "two radars")
    assert f"{2 * 400e3 * np.sin(np.pi / 4):.0f} m apart" in line
    assert not (out / "recording.ast").exists() and not (out / "sites.csv").exists()
    assert pair.code == 0, pair.err
    doc = pair.json()
    assert doc["cat048"] > 0 and Path(doc["sites"]).is_file()
    text = " ".join(helped.out.split())
    assert "--spacing METRES radius of the ring of sites, in metres" in text
    assert "--max-range METRES each radar's maximum slant range, in metres" in text


def test_simulate_limits_in_process() -> None:
    """The rule's edges (no subprocess, no simulation): 4 radars on a ring of radius R are
    R·√2 apart; refused below 1047 m apart, a range below 3700 m, or neighbours more than
    2·(range + 610 m) apart; the figures agree with the simulator's own parameters."""
    from optmodels.cli.problems.biasfield_out import _check_network, _network_limits
    from optmodels.core import ProblemError

    lim = _network_limits()
    assert lim["min_separation"] == pytest.approx(MIN_SEPARATION, rel=1e-12)
    assert lim["min_range"] == MIN_RANGE
    r_min = MIN_SEPARATION / np.sqrt(2)
    _check_network(4, np.ceil(r_min), 250e3)
    with pytest.raises(ProblemError, match=r"^--spacing"):
        _check_network(4, np.floor(r_min), 250e3)
    _check_network(4, 1000.0, MIN_RANGE)
    with pytest.raises(ProblemError, match=r"^--max-range"):
        _check_network(4, 1000.0, MIN_RANGE - 1)
    r_max = 2 * (250e3 + 610.0) / np.sqrt(2)
    _check_network(4, np.floor(r_max), 250e3)
    with pytest.raises(ProblemError, match=r"^--spacing .* with --max-range"):
        _check_network(4, np.ceil(r_max), 250e3)
    with pytest.raises(ProblemError, match=r"0\.9 earth radii"):
        _check_network(4, 6e6, 1e8)


# ------------------------------------------------------------ 3. the normal's sign
def _tilted_circle(path: Path, shift: float) -> np.ndarray:
    """A circle of 5 km tilted 0.5 rad about x (rising to the north), its centre at
    z = ``shift``, 5 m isotropic noise; written as t,x,y,z. Returns the points."""
    rng = np.random.default_rng(5)
    t = np.arange(200) / 2.0
    w = 2 * np.pi / 60
    c = np.column_stack([5e3 * np.cos(w * t), 5e3 * np.sin(w * t), np.zeros_like(t)])
    rot = np.array([[1, 0, 0], [0, np.cos(0.5), -np.sin(0.5)], [0, np.sin(0.5), np.cos(0.5)]])
    x = c @ rot.T + np.array([0.0, 0.0, shift]) + rng.normal(scale=5.0, size=c.shape)
    path.write_text(
        "t,x,y,z\n"
        + "".join(
            f"{float(a)!r},{float(p)!r},{float(q)!r},{float(r)!r}\n"
            for a, (p, q, r) in zip(t, x, strict=True)
        ),
        encoding="utf-8",
    )
    return x


def _tls_plane(x: np.ndarray) -> tuple[np.ndarray, float]:
    """The ML plane under equal isotropic covariances, by total least squares (the
    smallest right-singular vector of the centred points), signed so that offset ≥ 0."""
    centre = x.mean(axis=0)
    n = np.linalg.svd(x - centre)[2][-1]
    a = float(n @ centre)
    return (n, a) if a >= 0 else (-n, -a)


def test_plane_fit_states_the_sign_of_its_normal(tmp_path: Path) -> None:
    below = _tilted_circle(tmp_path / "below.csv", -3000.0)  # the plane passes below 0
    above = _tilted_circle(tmp_path / "above.csv", 3000.0)
    fit = ["plane", "fit", "--sigma2", "25"]
    text, doc_ipopt, doc_cf, doc_above, helped = run_many(
        [
            [*fit[:2], tmp_path / "below.csv", *fit[2:]],
            [*fit[:2], tmp_path / "below.csv", *fit[2:], "--json"],
            [*fit[:2], tmp_path / "below.csv", *fit[2:], "--method", "closed-form", "--json"],
            [*fit[:2], tmp_path / "above.csv", *fit[2:], "--json"],
            ["plane", "fit", "--help"],
        ]
    )
    n_ref, a_ref = _tls_plane(below)
    assert n_ref[2] < -0.8  # the review's case: the normal points down
    for run in (doc_ipopt, doc_cf):
        doc = run.json()
        np.testing.assert_allclose(doc["normal"], n_ref, atol=1e-6)
        assert doc["offset"] == pytest.approx(a_ref, rel=1e-6)
        assert doc["sign_convention"].startswith("offset >= 0: the normal points from the origin")
    # the same plane with the origin on its other side: the normal flips, offset ≥ 0 still
    n_up, _ = _tls_plane(above)
    doc = doc_above.json()
    assert n_up[2] > 0.8 and doc["offset"] > 0
    np.testing.assert_allclose(doc["normal"], n_up, atol=1e-6)
    lines = text.out.splitlines()
    k = next(i for i, x in enumerate(lines) if x.startswith("  normal  = ("))
    printed = [float(v) for v in lines[k].split("(")[1].rstrip(")").split(",")]
    np.testing.assert_allclose(printed, doc_ipopt.json()["normal"], atol=1e-9)
    assert lines[k + 2].startswith("  sign    : offset ≥ 0, the normal points from the file's")
    az = doc_ipopt.json()["tilt_azimuth_deg"]
    shown = f"{az:.1f}" if f"{az:.1f}" != "360.0" else "0.0"
    assert f"rising towards azimuth {shown}° (clockwise from north)" in text.out
    assert "azimuth 360.0°" not in text.out
    assert "The normal's sign: offset ≥ 0" in " ".join(helped.out.split())


def test_every_plane_solver_applies_the_same_sign() -> None:
    """closed_form, solve (full and reduced) and fit_general on data whose plane passes
    below the origin: one normal, pointing down (offset ≥ 0), to 1e-6."""
    from optmodels import plane

    rng = np.random.default_rng(9)
    uv = rng.uniform(-5e3, 5e3, (60, 2))
    n_true = np.array([0.0, np.sin(0.5), -np.cos(0.5)])
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(n_true, e1)
    x = 2000.0 * n_true + uv[:, :1] * e1 + uv[:, 1:] * e2 + rng.normal(scale=5.0, size=(60, 3))
    data = plane.PlaneData(x, 25.0 * np.eye(3))
    n_ref, a_ref = _tls_plane(x)
    sols = [
        plane.closed_form(data),
        plane.solve(data, "full"),
        plane.solve(data, "reduced"),
        plane.fit_general(x, 25.0 * np.eye(3)),
    ]
    for sol in sols:
        assert sol.offset >= 0
        np.testing.assert_allclose(sol.normal, n_ref, atol=1e-6)
        assert sol.offset == pytest.approx(a_ref, rel=1e-6)
    assert n_ref[2] < 0
