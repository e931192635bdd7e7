"""``optmodels assignment solve CASE.json`` with per-measurement covariances and a sensor
block (issue 18 item 6), through the installed console script in a subprocess: the
answer equals the in-process brute force on the same model, and every schema error is
exit 2 with one line naming the key."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from optmodels import assignment as asg
from optmodels.assignment.polar import polar_measurement_covs
from optmodels.assignment.sensor import Resolution
from tests.test_cli import assert_error, run_many


def _scene() -> dict:
    """Three objects ~9 km from a radar at the origin, two within one cell (150 m ×
    1.5°), two measurements with their own polar covariances (σ_r 30 m, σ_az 0.3°)."""
    rng = np.random.default_rng(18)
    means = np.array([[9000.0, 0.0], [9080.0, 60.0], [9400.0, -200.0]])
    meas = np.array([means[:2].mean(axis=0), means[2]]) + rng.normal(0, 20, (2, 2))
    r = polar_measurement_covs(meas, [0.0, 0.0], 30.0, math.radians(0.3))
    return {
        "means": means.tolist(),
        "covs": [(np.eye(2) * 900.0).tolist()] * 3,
        "measurements": meas.tolist(),
        "meas_cov": r.tolist(),
        "volume": 600.0**2,
        "pd": 0.9,
    }


def test_sensor_and_per_measurement_covs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    case = _scene()
    polar = {
        **case,
        "sensor": {
            "range": 150.0,
            "azimuth_deg": 1.5,
            "site": [0.0, 0.0],
            "weights": [1.0, 2.0, 1.0],
        },
    }
    ellipse = {**case, "sensor": {"ellipse": [[150.0**2, 0.0], [0.0, 150.0**2]]}}
    paths = {}
    for name, doc in [
        ("polar", polar),
        ("ellipse", ellipse),
        ("both", {**polar, "rho": 0.3}),
        ("neither", case),
        ("badkey", {**case, "sensor": {"range": 150.0, "azimuth": 0.02}}),
        ("badrange", {**case, "sensor": {"range": -1.0, "azimuth_deg": 1.5}}),
        ("badcov", {**case, "rho": 0.3, "meas_cov": case["meas_cov"][:1]}),
        ("notobj", {**case, "sensor": [150.0, 1.5]}),
    ]:
        paths[name] = tmp_path / f"{name}.json"
        paths[name].write_text(json.dumps(doc))
    runs = run_many(
        [
            ["assignment", "solve", paths["polar"], "--k", "3", "--json"],
            ["assignment", "solve", paths["ellipse"], "--method", "brute-force", "--json"],
            ["assignment", "solve", paths["badkey"], "--json"],
        ],
        expect=None,
    )
    r_polar, r_ell, r_key = runs
    # the polar cell with amplitude weights: = brute force in process on the same model
    sens = Resolution(
        range=150.0, azimuth=math.radians(1.5), site=[0.0, 0.0], weights=[1.0, 2.0, 1.0]
    )
    data = asg.AssignmentData(**{k: np.asarray(v) for k, v in case.items()}, sensor=sens)
    ref = asg.brute_force(data)
    assert r_polar.code == 0, r_polar.err
    res = r_polar.json()
    assert res["status"] == "optimal"
    assert [tuple(b) for b in res["partition"]] == ref.partition
    assert res["assignment"] == list(ref.assignment)
    assert res["log_score"] == pytest.approx(ref.log_score, abs=1e-9)
    assert any(len(b) == 2 for b in res["partition"])  # the merged pair is the MAP
    np.testing.assert_allclose(res["pair_unresolved"], data.pair_unresolved(), rtol=1e-12)
    assert len(res["k_best"]) == 3 and res["k_best"][0]["log_score"] == pytest.approx(
        ref.log_score, abs=1e-9
    )
    # the ellipse block, by enumeration
    d_ell = asg.AssignmentData(
        **{k: np.asarray(v) for k, v in case.items()},
        sensor=Resolution(ellipse=np.eye(2) * 150.0**2),
    )
    assert r_ell.code == 0, r_ell.err
    assert r_ell.json()["log_score"] == pytest.approx(asg.brute_force(d_ell).log_score, abs=1e-9)
    # schema errors: exit 2, one line naming the key (one through the script, the rest in
    # process: each subprocess costs seconds of imports)
    assert_error(r_key, 2, "sensor: unknown keys ['azimuth']")
    for name, fragment in [
        ("both", "rho: give rho"),
        ("neither", "missing fields ['rho']"),
        ("badrange", "Resolution range (m)"),
        ("badcov", "meas_cov"),
        ("notobj", "sensor: expected a JSON object"),
    ]:
        code, err = _in_process(["assignment", "solve", str(paths[name])], capsys)
        assert code == 2, (name, err)
        lines = [x for x in err.splitlines() if x.strip()]
        assert len(lines) == 1 and fragment in lines[0], (name, lines)


def _in_process(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``optmodels.cli.main(argv)``: its exit status and stderr."""
    from optmodels.cli import main

    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return int(code or 0), capsys.readouterr().err
