"""``optmodels plane track`` (issue 19 item 5): the installed console script in a
subprocess, its values against an independent call of :func:`optmodels.plane.tracking.track`
on the same data, the contract (one JSON document, exit statuses, one error line)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from optmodels import plane
from optmodels.core import ProblemError
from optmodels.io import read_plane_csv, write_plane_csv
from optmodels.plane.radar import radar_covariances
from optmodels.plane.tracking import track
from optmodels.scenarios.maneuver import climb_turn_track
from tests.test_cli import assert_error, run_cli, run_json, run_many

SIG_DEG = 0.05  # radar angle errors, degrees on the command line


def _track_file(tmp_path: Path, *, cov_columns: bool = False, seed: int = 0) -> Path:
    tr = climb_turn_track(
        seed,
        durations=(30.0, 30.0, 40.0),
        sigma_azimuth=np.deg2rad(SIG_DEG),
        sigma_elevation=np.deg2rad(SIG_DEG),
    )
    path = tmp_path / f"track{seed}{'_cov' if cov_columns else ''}.csv"
    extra = {}
    if cov_columns:
        c = tr.cov
        extra = {
            "cxx": c[:, 0, 0],
            "cxy": c[:, 0, 1],
            "cxz": c[:, 0, 2],
            "cyy": c[:, 1, 1],
            "cyz": c[:, 1, 2],
            "czz": c[:, 2, 2],
        }
    write_plane_csv(path, tr.points, t=tr.times, **extra)
    return path


def _read_steps(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _reference(path: Path, window: str | None, **cov_kw: float) -> plane.PlaneTrack:
    """The library's own answer on the file as read back (exact: 17 digits)."""
    cols = read_plane_csv(path)
    if cov_kw:
        cov = radar_covariances(
            cols["points"],
            np.zeros(3),
            cov_kw["sigma_range"],
            np.deg2rad(SIG_DEG),
            np.deg2rad(SIG_DEG),
        )
    else:
        cov = cols["cov"]
    return track(cols["t"], cols["points"], cov, window=window)


def test_track_json_matches_the_library_with_radar_flags(tmp_path: Path) -> None:
    path = _track_file(tmp_path)
    res = run_json(
        "plane",
        "track",
        path,
        "--window",
        "40s",
        "--site",
        "0,0,0",
        "--sigma-range",
        "30",
        "--sigma-azimuth",
        str(SIG_DEG),
        "--sigma-elevation",
        str(SIG_DEG),
    )
    ref = _reference(path, "40s", sigma_range=30.0)
    assert res["n_steps"] == ref.n_steps == len(res["steps"])
    assert res["method"] == "general" and res["covariance"] == "radar"
    assert res["window"] == "40s" and res["false_alarm_rate_per_h"] == 1.0
    assert res["units"]["detectable_tilt_deg"] == "deg"
    got_tilt = np.array(
        [
            np.nan if s["detectable_tilt_deg"] is None else s["detectable_tilt_deg"]
            for s in res["steps"]
        ],
        dtype=float,
    )
    fin = np.isfinite(ref.detectable_tilt)  # inf/NaN (no test possible) -> JSON null
    assert fin.any() and np.all(np.isnan(got_tilt[~fin]))
    np.testing.assert_allclose(got_tilt[fin], np.degrees(ref.detectable_tilt[fin]), rtol=1e-12)
    steps = res["steps"]
    got_t = np.array([s["time"] for s in steps])
    np.testing.assert_allclose(got_t, ref.times, rtol=0, atol=0)
    res_mask = np.array([s["resolved"] for s in steps])
    np.testing.assert_array_equal(res_mask, ref.resolved)
    assert res_mask.any() and (~res_mask).any()  # the straight climb is unresolved
    got_n = np.array([[s["nx"], s["ny"], s["nz"]] for s in steps if s["resolved"]], dtype=float)
    # same computation on the same numbers: the JSON carries repr-exact floats
    assert float(np.max(plane.angle_error(got_n, ref.normals[ref.resolved]))) <= 1e-12
    for key, arr in (("statistic", ref.statistic), ("threshold", ref.threshold)):
        got = np.array([np.nan if s[key] is None else s[key] for s in steps], dtype=float)
        np.testing.assert_allclose(got, arr, rtol=1e-12, equal_nan=True)
    np.testing.assert_array_equal([s["change"] for s in steps], ref.change)
    np.testing.assert_array_equal([s["planar"] for s in steps], ref.planar)
    # unresolved steps: no normal, the line direction instead
    for s in steps:
        if not s["resolved"]:
            assert s["nx"] is None and s["line_x"] is not None
            assert s["status"] in ("unresolved", "error")
    assert res["status_counts"]["error"] == 0 and res["status"] == "optimal"


def test_track_csv_out_and_file_covariances(tmp_path: Path) -> None:
    path = _track_file(tmp_path, cov_columns=True)
    out = tmp_path / "sub" / "steps.csv"
    run = run_cli("plane", "track", path, "--window", "100pts", "--out", out)
    assert "steps:" in run.out and f"wrote {out.resolve()}" in run.out
    rows = _read_steps(out)
    ref = _reference(path, "100pts")
    assert len(rows) == ref.n_steps
    assert list(rows[0])[:10] == [
        "time",
        "nx",
        "ny",
        "nz",
        "offset",
        "statistic",
        "threshold",
        "resolved",
        "planar",
        "change",
    ]
    assert "detectable_tilt_deg" in rows[0] and "status" in rows[0]
    assert "detectable_tilt" not in rows[0] and "numerical_error_rad" in rows[0]
    n = np.array([[float(r["nx"]), float(r["ny"]), float(r["nz"])] for r in rows])
    ok = ref.resolved
    assert float(np.max(plane.angle_error(n[ok], ref.normals[ok]))) <= 1e-12
    np.testing.assert_allclose(
        [float(r["offset"]) for r in rows], ref.offsets, rtol=1e-12, equal_nan=True
    )
    np.testing.assert_array_equal([r["resolved"] == "True" for r in rows], ref.resolved)
    np.testing.assert_allclose(
        [float(r["detectable_tilt_deg"]) for r in rows],
        np.degrees(ref.detectable_tilt),
        rtol=1e-12,
        equal_nan=True,
    )


def test_track_stdout_is_the_csv(tmp_path: Path) -> None:
    sc_t = np.arange(60) * 0.5
    rng = np.random.default_rng(3)
    ang = 0.05 * sc_t
    truth = np.column_stack([3000 * np.cos(ang), 3000 * np.sin(ang), np.full(60, 2000.0)])
    pts = truth + rng.normal(scale=10.0, size=truth.shape)
    path = tmp_path / "level.csv"
    write_plane_csv(path, pts, t=sc_t)
    run = run_cli("plane", "track", path, "--window", "growing", "--sigma2", "100")
    lines = run.out.splitlines()
    assert lines[0].startswith("time,nx,ny,nz,offset")
    ref = track(sc_t, pts, 100.0 * np.eye(3), window=None)
    assert len(lines) == ref.n_steps + 1
    last = dict(zip(lines[0].split(","), lines[-1].split(","), strict=True))
    assert (
        float(
            plane.angle_error(
                [float(last["nx"]), float(last["ny"]), float(last["nz"])], ref.normals[-1]
            )
        )
        <= 1e-12
    )
    # a level circle: the normal is vertical to within its noise
    assert abs(abs(float(last["nz"])) - 1.0) <= 1e-4


def test_track_bad_input_exits_2(tmp_path: Path) -> None:
    path = _track_file(tmp_path)
    no_t = tmp_path / "no_t.csv"
    write_plane_csv(no_t, np.random.default_rng(0).normal(size=(10, 3)))
    back = tmp_path / "back.csv"
    write_plane_csv(
        back,
        np.random.default_rng(0).normal(size=(10, 3)),
        t=np.array([0, 1, 2, 3, 2.5, 5, 6, 7, 8, 9.0]),
    )
    runs = run_many(
        [
            ["plane", "track", no_t, "--window", "5pts", "--sigma2", "1"],
            ["plane", "track", back, "--window", "5pts", "--sigma2", "1", "--json"],
            ["plane", "track", path, "--window", "40s"],
            ["plane", "track", path, "--window", "40s", "--site", "0,0,0", "--sigma-range", "30"],
            ["plane", "track", path, "--window", "40s", "--sigma2", "1", "--out", tmp_path],
        ],
        expect=None,
    )
    assert_error(runs[0], 2, "missing column t")
    assert_error(runs[1], 2, "line 6", "strictly increasing")
    assert_error(runs[2], 2, "covariance")
    assert_error(runs[3], 2, "--sigma-azimuth")
    assert_error(runs[4], 2, "--out")


def test_plane_fit_uses_the_time_column(tmp_path: Path) -> None:
    """``plane fit --start/--end``: the rows of a time range, against the closed form on
    those rows; the time span is reported."""
    t = np.arange(100) * 0.5
    rng = np.random.default_rng(9)
    ang = 0.04 * t
    truth = np.column_stack([2000 * np.cos(ang), 2000 * np.sin(ang), 100 + 0.1 * t])
    pts = truth + rng.normal(scale=5.0, size=truth.shape)
    path = tmp_path / "fit.csv"
    write_plane_csv(path, pts, t=t)
    res = run_json(
        "plane",
        "fit",
        path,
        "--sigma2",
        "25",
        "--formulation",
        "closed-form",
        "--start",
        "10",
        "--end",
        "30",
    )
    keep = (t >= 10) & (t <= 30)
    ref = plane.closed_form(plane.PlaneData(pts[keep], 25 * np.eye(3)))
    assert res["n_points"] == int(keep.sum())
    assert res["time_span"] == [10.0, 30.0]
    assert float(plane.angle_error(res["normal"], ref.normal)) <= 1e-12
    run = run_cli("plane", "fit", path, "--sigma2", "25", "--start", "60", expect=2)
    assert_error(run, 2, "--start/--end")


def test_track_exit_code_follows_the_step_statuses(tmp_path: Path) -> None:
    path = _track_file(tmp_path, cov_columns=True, seed=1)
    run = run_cli("plane", "track", path, "--window", "40s", "--json")
    doc = run.json()
    assert run.code == (0 if doc["status_counts"]["error"] == 0 else 1)
    assert sum(doc["status_counts"].values()) == doc["n_steps"]
    assert (
        [s["status"] for s in doc["steps"]].count("unresolved")
        == doc["status_counts"]["unresolved"]
        > 0
    )


def test_step_status_rules() -> None:
    """What makes a step not OK (exit 1): the line rejected but no plane passed the
    re-check. Resolved steps are optimal (error ≤ 1e-6 rad) or inaccurate (≤ 1e-3)."""
    from types import SimpleNamespace

    from optmodels.cli.problems.plane import _step_status

    trk = SimpleNamespace(
        n_steps=4,
        resolved=np.array([True, True, False, False]),
        numerical_error=np.array([1e-9, 1e-5, 1e-9, np.inf]),
        line_statistic=np.array([500.0, 500.0, 50.0, 500.0]),
        line_threshold=np.full(4, 100.0),
    )
    assert _step_status(trk) == ["optimal", "optimal_inaccurate", "unresolved", "error"]


def test_plane_fit_on_a_line_is_unresolved(tmp_path: Path) -> None:
    """The straight climb of climb_turn_track (its first 30 s) is a line: `plane fit` reports
    no plane (status unresolved, exit 1, normal null) and the line's direction, which is the
    climb's velocity direction to within the noise (independent: the true positions)."""
    tr = climb_turn_track(3, durations=(30.0, 30.0, 40.0))
    path = tmp_path / "line.csv"
    write_plane_csv(path, tr.points, t=tr.times)
    run = run_cli("plane", "fit", path, "--sigma2", "900", "--end", "29", "--json", expect=1)
    res = run.json()
    assert res["status"] == "unresolved" and res["normal"] == [None, None, None]
    assert res["planarity_test"]["resolved"] is False
    seg = tr.truth[tr.times <= 29.0]
    true_dir = (seg[-1] - seg[0]) / np.linalg.norm(seg[-1] - seg[0])
    assert abs(float(np.dot(res["line_direction"], true_dir))) > 1 - 1e-4
    assert "not OK: status unresolved" in run.err


def test_track_on_three_rows_names_the_times_not_none(tmp_path: Path) -> None:
    """Issue 28: three rows (a step needs four measurements) is one error naming the times
    and the count, not "t = None"; the library says the same."""
    path = tmp_path / "three.csv"
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    write_plane_csv(path, pts, t=np.array([0.0, 1.0, 2.0]))
    line = assert_error(
        run_cli("plane", "track", path, "--window", "growing", "--sigma2", "1", expect=None),
        2,
        "times",
        "3 measurements",
        "at least 4",
    )
    assert "None" not in line
    with pytest.raises(ProblemError, match="times: 3 measurements; a step needs at least 4"):
        track([0.0, 1.0, 2.0], pts, np.eye(3))


def test_track_out_is_written_whole_and_a_refused_run_keeps_the_old_file(tmp_path: Path) -> None:
    """``--out`` goes through ``io.atomic_write``: no temporary file is left beside it, and
    a run refused before the write (bad input) leaves the previous file as it was."""
    path = _track_file(tmp_path)
    out = tmp_path / "steps.csv"
    run_cli("plane", "track", path, "--window", "40s", "--sigma2", "25", "--out", out)
    before = out.read_bytes()
    rows = _read_steps(out)
    assert len(rows) == len(read_plane_csv(path, require_time=True)["t"]) - 3
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,y,z\n0,0,0,0\n")
    run_cli("plane", "track", bad, "--window", "40s", "--sigma2", "25", "--out", out, expect=2)
    assert out.read_bytes() == before
