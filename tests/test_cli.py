"""CLI round trips: what a user types, checked against the library's own answers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from optmodels import cli, plane, scenarios
from optmodels.io import write_plane_csv


def run_json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict:
    assert cli.main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("formulation", ["full", "reduced", "closed-form"])
def test_plane_fit_round_trip(tmp_path: Path, capsys, formulation: str) -> None:
    sc = scenarios.paper_plane_example(1, duration=3.0)
    path = tmp_path / "track.csv"
    write_plane_csv(path, sc.points, t=sc.times)
    res = run_json(capsys, ["plane", "fit", str(path), "--sigma2", "625",
                            "--formulation", formulation])
    ref = plane.closed_form(plane.PlaneData(sc.points, 625 * np.eye(3)))
    assert res["status"] == "optimal"
    # CSV written with 17 significant digits: the file round trip is exact; the solvers
    # agree to the tolerances of test_plane (angle 1e-7 rad, objective rel. 1e-8).
    assert plane.angle_error(res["normal"], ref.normal) <= 1e-7
    assert res["objective"] == pytest.approx(ref.objective, rel=1e-8)
    assert res["planarity_test"]["dof"] == len(sc.points) - 3
    assert res["planarity_test"]["planar"] is True


def test_plane_fit_per_point_covariance_and_alpha2(tmp_path: Path, capsys) -> None:
    sc = scenarios.radar_plane(60, 4, geometry="broadside")
    c = sc.cov
    path = tmp_path / "radar.csv"
    write_plane_csv(path, sc.points, cxx=c[:, 0, 0], cxy=c[:, 0, 1], cxz=c[:, 0, 2],
                    cyy=c[:, 1, 1], cyz=c[:, 1, 2], czz=c[:, 2, 2])
    res = run_json(capsys, ["plane", "fit", str(path), "--formulation", "reduced"])
    ref = plane.solve(plane.PlaneData(sc.points, sc.cov), "reduced")
    assert plane.angle_error(res["normal"], ref.normal) <= 1e-7

    sc2 = scenarios.two_source_plane(80, 5)
    path2 = tmp_path / "two.csv"
    write_plane_csv(path2, sc2.points, alpha2=sc2.alpha2)
    res2 = run_json(capsys, ["plane", "fit", str(path2), "--cov", "100,0,0,100,0,100",
                             "--formulation", "closed-form"])
    ref2 = plane.closed_form(plane.PlaneData(sc2.points, 100 * np.eye(3), sc2.alpha2))
    assert plane.angle_error(res2["normal"], ref2.normal) <= 1e-12


def test_plane_fit_errors_are_reported(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    assert cli.main(["plane", "fit", str(bad), "--sigma2", "1"]) == 2
    assert "missing column(s) z" in capsys.readouterr().err
    ok = tmp_path / "ok.csv"
    write_plane_csv(ok, np.random.default_rng(0).normal(size=(10, 3)))
    assert cli.main(["plane", "fit", str(ok)]) == 2
    assert "--sigma2" in capsys.readouterr().err
    assert cli.main(["plane", "fit", str(tmp_path / "none.csv"), "--sigma2", "1"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_plane_fit_text_output(tmp_path: Path, capsys) -> None:
    sc = scenarios.paper_plane_example(2, duration=2.0)
    path = tmp_path / "t.csv"
    write_plane_csv(path, sc.points)
    assert cli.main(["plane", "fit", str(path), "--sigma2", "625"]) == 0
    out = capsys.readouterr().out
    assert "normal" in out and "χ² test" in out and "paper (1.17)" in out


def test_demo_plane_writes_report(tmp_path: Path, capsys) -> None:
    res = run_json(capsys, ["demo", "plane", "--out", str(tmp_path), "--runs", "20"])
    for f in ("fig1_trajectory.png", "fig2_statistic.png", "fig3_angle_error.png",
              "fig4_offset_error.png", "radius_bound.png", "report.md", "summary.json"):
        assert (tmp_path / "plane" / f).is_file()
    assert (tmp_path / "index.md").is_file()
    summ = res["problems"]["plane"]
    # every solver row reached the closed form's plane (angle within 1e-7 rad)
    assert all(r["angle to closed form, rad"] <= 1e-7 for r in summ["solvers"])
    assert summ["sequence_generic_vs_closed_form_max_angle_rad"] <= 1e-7
