"""The plane comparison runs end to end and its numbers are consistent."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from solvers_cmp import plane as cmp_plane
from solvers_cmp import report


def test_plane_comparison_small(tmp_path: Path) -> None:
    timing = cmp_plane.timing_rows([60], repeats=2)
    acc = cmp_plane.accuracy_rows([60], runs=30)
    md = report.write_plane(tmp_path, timing, acc)
    # every ML formulation solves and agrees with the reference to the plane tolerances
    for r in timing:
        assert r["status"] == "optimal"
        if r["formulation"] != "svd":
            assert r["solution_error"] <= 1e-7 and abs(r["objective_gap"]) <= 1e-8
        else:  # SVD is feasible but not optimal for (1.2): its gap is >= 0
            assert r["objective_gap"] >= -1e-12
    by = {r["setting"]: r for r in acc}
    # two sources with 10x different σ: ML beats the unweighted fit by a wide margin
    # (RMSE ratio ~0.19 at 200 runs; 30 runs give ±15%, so 0.5 is a safe bound).
    assert by["two-source"]["ratio_ml_over_svd"] < 0.5
    # edge-on radar: weights barely vary along the normal; ML ≈ SVD (ratio ~0.9-1.0)
    assert 0.7 < by["radar-edge-on"]["ratio_ml_over_svd"] < 1.15
    rows = list(csv.DictReader((tmp_path / "plane_timing.csv").open()))
    assert {
        "problem",
        "size",
        "formulation",
        "solver",
        "status",
        "objective_gap",
        "solution_error",
        "max_violation",
        "build_time",
        "solve_time",
        "iterations",
    } <= set(rows[0])
    assert "| two-source |" in md
    env = report.environment()
    assert env["packages"]["casadi"] and env["cores"]


def test_trajectories_comparison_small(tmp_path: Path) -> None:
    from solvers_cmp import trajectories as cmp_traj

    rows = cmp_traj.rows((2, 5), (10, 40), repeats=1)
    solvers = {r["solver"] for r in rows} - {"numpy"}
    assert {"CLARABEL", "OSQP"} <= solvers
    # 2 families × 4 sizes × (closed form + 2 formulations × solvers)
    assert len(rows) == 2 * 4 * (1 + 2 * len(solvers))
    for r in rows:
        assert r["status"] == "optimal", r
        # equality-constrained QP: every solver reaches the closed form to the 1e-9 bar
        assert r["solution_error"] < 1e-9 and abs(r["objective_gap"]) < 1e-9
        assert r["max_violation"] < 1e-8
    md = report.write_trajectories(tmp_path, rows)
    assert "| diverging | 5 | 40 | constrained | OSQP | optimal |" in md
    csv_rows = list(csv.DictReader((tmp_path / "trajectories_results.csv").open()))
    assert len(csv_rows) == len(rows)


def test_fusion_comparison_small(tmp_path: Path) -> None:
    from solvers_cmp import fusion as cmp_fusion

    rows = cmp_fusion.rows((2, 5), (1, 50), repeats=1)
    solvers = {r["solver"] for r in rows if r["case"] != "two-site joint ML"} - {"numpy"}
    assert {"CLARABEL", "OSQP"} <= solvers
    # 2 kinds × 2 sizes × (closed form + solvers) + 2 ML sizes × 2 methods
    assert len(rows) == 2 * 2 * (1 + len(solvers)) + 2 * 2
    for r in rows:
        assert r["status"] == "optimal", r
        # unconstrained least squares: SCS (first-order, eps 1e-9 on O(1) data) within
        # 1e-7 of the closed form, the others at round-off; the joint ML by IPOPT and
        # Gauss-Newton agree to 1e-6 CRB (both converged to ~1e-10 stationarity)
        assert r["solution_error"] < (1e-7 if r["solver"] == "SCS" else 1e-6), r
        assert r["max_violation"] < 1e-6
    md = report.write_fusion(tmp_path, rows)
    assert "| correlated | 5 | min-trace W | CLARABEL | optimal |" in md
    assert len(list(csv.DictReader((tmp_path / "fusion_results.csv").open()))) == len(rows)


def test_biasfield_comparison_small(tmp_path: Path) -> None:
    from solvers_cmp import biasfield as cmp_bf

    rows = cmp_bf.rows((60,), repeats=1, solvers=("CLARABEL", "SCS"))
    cases = {(r["case"], r["formulation"], r["solver"]): r for r in rows}
    assert cases[("no box", "closed_form", "numpy")]["status"] == "optimal"
    assert cases[("no box", "reduced", "SCS")]["status"] == "error"  # no constraint rows
    for r in rows:
        if r["status"] == "optimal":
            # no box: 1e-8 against the closed form; box: solvers agree to 1e-6
            assert r["solution_error"] < (1e-8 if r["case"] == "no box" else 1e-6), r
            assert r["max_violation"] < 1e-6
    assert any(r["active_bounds"] > 0 for r in rows if r["case"] != "no box")
    md = report.write_biasfield(tmp_path, rows)
    assert "| box (8) binding | 60 | reduced | CLARABEL | optimal |" in md


def test_assignment_comparison_small(tmp_path: Path) -> None:
    from solvers_cmp import assignment as cmp_as

    rows = cmp_as.rows(((3, 4, None), (5, 6, None), (20, 22, 3.0)), repeats=1)
    assert {r["formulation"] for r in rows} >= {
        "joint MILP",
        "enumeration (14)",
        "linear assignment",
    }
    for r in rows:
        assert r["status"] == "optimal" and r["solution_error"] == 0, r
        assert abs(r["objective_gap"]) < 1e-9
    md = report.write_assignment(tmp_path, rows)
    assert "| 5 | 6 | allowed | none | enumeration (14) | python | optimal |" in md


def _hold(mb: int, seconds: float) -> None:
    """Child process: ``mb`` MB resident for ``seconds``."""
    import time

    import numpy as np

    block = np.ones(mb * 2**17)  # touched: resident
    time.sleep(seconds)
    del block


def test_rss_trace_places_memory_in_its_stage_and_sees_children() -> None:
    """The country benchmark's memory figures: 300 MB held in stage "b" only shows there
    (this process), 200 MB held by a child shows in the children's sum and the tree."""
    import multiprocessing as mp
    import time

    import numpy as np

    from solvers_cmp.biasfield_scale import RssTrace

    trace = RssTrace(period=0.02)
    time.sleep(0.2)
    trace.mark("a")
    block = np.ones(300 * 2**17)
    time.sleep(0.2)
    trace.mark("b")
    del block
    time.sleep(0.1)
    trace.mark("c")
    child = mp.get_context("spawn").Process(target=_hold, args=(200, 3.0))
    child.start()
    child.join()
    trace.mark("d")
    trace.stop()
    own, tree = trace.stages(), trace.stages(tree=True)
    assert set(own) == set(tree) == {"a", "b", "c", "d"}
    assert own["b"] - own["a"] > 280
    assert own["d"] < own["a"] + 100  # the child's memory is not this process's
    assert tree["d"] - own["d"] > 180 and trace.children_max() > 180


def test_read_hours_joins_the_hourly_files_in_order(tmp_path: Path) -> None:
    import numpy as np

    from solvers_cmp.biasfield_country import read_hours

    rng = np.random.default_rng(3)
    cols = {"time": [], "radar": [], "range": [], "azimuth": [], "object": []}
    for h in (0, 1, 2):
        n = 5 + h
        part = {
            "time": 3600.0 * h + np.sort(rng.uniform(0, 3600, n)),
            "radar": rng.integers(0, 3, n),
            "range": rng.uniform(1e3, 2e5, n),
            "azimuth": rng.uniform(-3, 3, n),
            "object": rng.integers(0, 9, n),
        }
        np.savez(tmp_path / f"hour{h:03d}.npz", **part)
        for k, v in part.items():
            cols[k].append(v)
    (tmp_path / "notes.txt").write_text("not an hour")
    plots = read_hours(str(tmp_path), progress=False)
    for k, parts in cols.items():
        np.testing.assert_array_equal(getattr(plots, k), np.concatenate(parts))


@pytest.mark.slow
def test_country_chain_local_and_dask_agree_at_a_tiny_size() -> None:
    """Issue 24's country benchmark end to end at a tiny size: the figures it reports are
    consistent, every plot has one reason, and the Dask pass gives the same field."""
    from solvers_cmp.biasfield_country import run_country

    r = run_country(aircraft=150, hours=0.5, cells=150, dask=True, progress=False)
    assert r["status"] == "optimal" and r["cells"] > 100
    # every plot the pipeline kept (cleaning may drop some) has one reason
    kept = sum(r["reasons"].values())
    assert r["plots"] - sum(r["dropped_plots"].values()) <= kept <= r["plots"]
    assert r["registration_m"]["after"] < 0.2 * r["registration_m"]["before"]
    stages = {"simulate", "read", "field_data", "solve", "correct", "registration"}
    assert stages | {"dask.field_data", "dask.correct"} <= set(r["rss_max_per_stage_mb"])
    assert r["dask_equal"]["cells"]
    assert r["dask_equal"]["max_abs_xi_diff_m"] < 1e-9
    assert max(r["dask_equal"]["max_abs_field_diff"]) < 1e-9
