"""solvers_cmp harness: rows, resume, isolation (time-outs and crashes), metrics, report,
CLI; the CasADi conic bridge and NLP plugins it compares."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cvxpy as cp
import numpy as np
import pytest

from optmodels import plane, scenarios
from optmodels import trajectories as tr
from optmodels.backends.casadi_backend import nlp_plugins
from optmodels.backends.casadi_qp import CasadiConic, casadi_qp_plugins
from optmodels.backends.common import probe_in_child
from optmodels.cli import main
from optmodels.core import ProblemError
from optmodels.execution import LineLog
from solvers_cmp import cases as cs
from solvers_cmp import harness, report
from solvers_cmp.harness.profiles import _judge
from solvers_cmp.harness.results import _parse_line
from tests.harness_adapters import children, interrupt, wait_gone

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def trouble() -> None:
    cs.register("trouble", "tests.harness_adapters:Trouble")
    yield
    cs.REGISTRY.pop("trouble", None)


def _csv_rows(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(path.open()))


def test_sweep_rows_resume_and_errors(tmp_path: Path) -> None:
    rows = harness.run_sweep(
        ["trajectories"], tmp_path, sizes=[10], solvers=["CLARABEL", "OSQP"], isolate=False
    )
    # closed form + 2 formulations × 2 solvers, for both families
    assert len(rows) == 2 * 5
    assert all(r["success"] for r in rows), [r["reason"] for r in rows]
    file_rows = _csv_rows(tmp_path / "results.csv")
    assert list(file_rows[0]) == list(harness.COLUMNS)
    # the recorded error is the real one: re-solve one row independently
    data = cs.adapter("trajectories").make("parallel", 10, 0)
    ref = tr.closed_form(data, "parallel")
    sol = tr.solve(data, "parallel", formulation="reduced", solver="CLARABEL")
    err = np.max(np.abs(sol.theta - ref.theta)) / np.max(np.abs(ref.theta))
    row = next(
        r
        for r in rows
        if r["instance"] == "parallel"
        and r["formulation"] == "reduced"
        and r["solver"] == "CLARABEL"
    )
    # same deterministic solver on the same data: identical up to round-off (1e-12 of θ)
    assert row["solution_error"] == pytest.approx(err, abs=1e-12)
    # rerun: nothing new is run or written
    again = harness.run_sweep(
        ["trajectories"], tmp_path, sizes=[10], solvers=["CLARABEL", "OSQP"], isolate=False
    )
    assert len(again) == 10 and len(_csv_rows(tmp_path / "results.csv")) == 10
    # drop one finished row: only that one is run again
    lines = (tmp_path / "results.csv").read_text().splitlines()
    (tmp_path / "results.csv").write_text("\n".join(lines[:-1]) + "\n")
    harness.run_sweep(
        ["trajectories"], tmp_path, sizes=[10], solvers=["CLARABEL", "OSQP"], isolate=False
    )
    assert len(_csv_rows(tmp_path / "results.csv")) == 10


def test_time_limit_crash_and_exception_are_rows(tmp_path: Path, trouble: None) -> None:
    rows = harness.run_sweep(["trouble"], tmp_path, time_limit=3.0)
    by = {r["solver"]: r for r in rows}
    assert by["numpy"]["success"] and by["ok"]["success"]
    assert by["crash"]["status"] == "crashed" and not by["crash"]["success"]
    assert "exit code" in by["crash"]["message"]
    assert by["sleep"]["status"] == "time_limit" and "3 s time limit" in by["sleep"]["message"]
    assert by["raise"]["status"] == "error" and "exploded" in by["raise"]["message"]
    # 'sloppy' solves, but 1e-3 off the reference: a failure by the error tolerance
    assert by["sloppy"]["status"] == "optimal" and not by["sloppy"]["success"]
    assert by["sloppy"]["solution_error"] == pytest.approx(1e-3 / 2)
    assert "solution error" in by["sloppy"]["reason"]
    # the runs after the crash and the time-out still ran (the sweep went on)
    assert [r["solver"] for r in rows] == ["numpy", "crash", "ok", "sleep", "raise", "sloppy"]
    md = report.write_harness_report(
        tmp_path, rows, profile="default", time_limit=3.0, error_tol=1e-5, violation_tol=1e-6
    )
    for solver in ("crash", "sleep", "raise", "sloppy"):  # every failure is explained
        assert f"**{solver}**" in md
    assert (tmp_path / "trouble_scaling.png").stat().st_size > 0


def test_shifted_geometric_mean_and_summary() -> None:
    # exp(mean(log(t + 0.01))) − 0.01 for t = 0.01, 0.03: √(0.02·0.04) − 0.01
    assert harness.shifted_geometric_mean([0.01, 0.03]) == pytest.approx(
        np.sqrt(0.02 * 0.04) - 0.01, rel=1e-12
    )
    base = {
        "problem": "p",
        "formulation": "f",
        "build_time": 0.0,
        "solution_error": 0.0,
        "max_violation": 0.0,
    }
    rows = [
        {**base, "solver": "a", "success": True, "solve_time": 0.01},
        {**base, "solver": "a", "success": False, "solve_time": 0.001},
        {**base, "solver": "b", "success": True, "solve_time": 0.03},
    ]
    summ = {s["solver"]: s for s in harness.summarise(rows, time_limit=10.0)}
    assert summ["a"]["success_rate"] == 0.5
    # the failure is charged the time limit, not its own (short) time
    assert summ["a"]["sgm_solve_time"] == pytest.approx(np.sqrt(0.02 * 10.01) - 0.01)
    assert summ["b"]["rel_solve_time"] == pytest.approx(1.0)


def test_cli_compare_writes_everything(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "--problems",
                "fusion",
                "--instances",
                "independent",
                "--sizes",
                "3,6",
                "--solvers",
                "CLARABEL,CASADI_QRQP",
                "--out",
                str(out),
                "--json",
            ]
        )
        == 0
    )
    res = json.loads(capsys.readouterr().out)
    assert res["runs"] == 2 * 3 and res["successes"] == 6, res["failures"]
    for name in (
        "results.csv",
        "report.md",
        "summary.csv",
        "environment.json",
        "fusion_scaling.png",
    ):
        assert (out / name).stat().st_size > 0
    env = json.loads((out / "environment.json").read_text())
    assert env["packages"]["cvxpy"] and env["cpu"]
    rows = _csv_rows(out / "results.csv")
    assert {r["solver_version"].split()[0] for r in rows} == {"numpy", "clarabel", "casadi"}


def test_cli_compare_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "--problems", "nonsense", "--out", "/tmp/x"]) == 2
    assert "--problems" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["compare", "--profile", "extreme"])


def test_casadi_bridge_matches_clarabel_with_duals() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(8, 3)), rng.normal(size=8)
    x = cp.Variable(3)
    cons = [cp.sum(x) == 1, x <= 0.4]
    prob = cp.Problem(cp.Minimize(cp.sum_squares(a @ x - b)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    x_ref, d_eq, d_in = x.value.copy(), cons[0].dual_value, cons[1].dual_value.copy()
    assert np.max(d_in) > 1e-3  # the box is active: the inequality duals are tested
    for plugin in ("qrqp", "qpoases"):
        assert plugin in casadi_qp_plugins()
        prob.solve(solver=CasadiConic(plugin))
        # active-set / direct methods: the KKT solution to ~1e-9 (scale of x is 1)
        np.testing.assert_allclose(x.value, x_ref, atol=1e-7)
        np.testing.assert_allclose(cons[0].dual_value, d_eq, rtol=1e-6)
        np.testing.assert_allclose(cons[1].dual_value, d_in, atol=1e-6)


def test_trajectories_through_casadi_plugin() -> None:
    data = cs.adapter("trajectories").make("diverging", 20, 1)
    ref = tr.closed_form(data, "diverging")
    sol = tr.solve(data, "diverging", solver="CASADI_QRQP").require_ok()
    assert np.max(np.abs(sol.theta - ref.theta)) / np.max(np.abs(ref.theta)) < 1e-9


@pytest.mark.parametrize("plugin", ["sqpmethod", "fatrop"])
def test_plane_nlp_plugins_reach_the_closed_form(plugin: str) -> None:
    assert plugin in nlp_plugins()
    sc = scenarios.two_source_plane(40, np.random.default_rng(3))
    data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
    sol = plane.solve(data, "reduced", plugin=plugin).require_ok()
    # a KKT point to the plugin's tolerance (~1e-8) and the global one under (1.4)
    assert plane.angle_error(sol.normal, plane.closed_form(data).normal) < 1e-6


def test_unknown_plugin_is_a_clear_error() -> None:
    from optmodels.core import SolverNotAvailable

    sc = scenarios.two_source_plane(10, np.random.default_rng(3))
    data = plane.PlaneData(sc.points, sc.cov, sc.alpha2)
    with pytest.raises(SolverNotAvailable, match="plugin"):
        plane.solve(data, "reduced", plugin="no_such_solver")
    with pytest.raises(SolverNotAvailable, match="CASADI_HIGHS"):
        tr.solve(
            cs.adapter("trajectories").make("diverging", 10, 0), "diverging", solver="CASADI_HIGHS"
        )


def test_probe_survives_a_crashing_plugin() -> None:
    script = (
        "import os, signal, sys\n"
        "for name in sys.argv[1:]:\n"
        "    if name == 'bad':\n"
        "        os.kill(os.getpid(), signal.SIGSEGV)\n"
        "    print(name, 'ok', flush=True)\n"
    )
    res = probe_in_child(script, ["a", "bad", "c"])
    assert res["a"] == "ok" and res["c"] == "ok"
    assert res["bad"].startswith("crashed")


# ------------------------------------------------------------------------ faults
def _traj_sweep(out: Path) -> list[dict[str, object]]:
    return harness.run_sweep(
        ["trajectories"],
        out,
        sizes=[10],
        solvers=["CLARABEL"],
        instances=["parallel"],
        isolate=False,
    )


def test_cut_short_and_garbage_rows_are_rerun(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    first = _traj_sweep(tmp_path)
    assert len(first) == 3
    path = tmp_path / "results.csv"
    text = path.read_text()
    lines = text.splitlines()
    # a kill in the middle of the last row, after a garbage line
    path.write_text("\n".join(lines[:-1]) + "\nnot,a,row\n" + lines[-1][:25])
    with caplog.at_level("WARNING", logger="optmodels"):
        again = _traj_sweep(tmp_path)
    assert "skipped 1 unreadable line and a last line cut short (25 bytes)" in caplog.text
    assert (tmp_path / "results.csv.skipped").read_text().splitlines() == [
        "not,a,row",
        lines[-1][:25],
    ]
    rows = _csv_rows(path)
    assert len(rows) == 3 and list(rows[0]) == list(harness.COLUMNS)
    # the lost row was run again: same solver on the same data, round-off apart
    key = ("formulation", "solver")
    old = {tuple(r[k] for k in key): r for r in first}
    for r in again:
        assert r["success"]
        assert r["solution_error"] == pytest.approx(
            old[tuple(r[k] for k in key)]["solution_error"], abs=1e-12
        )
    assert harness.read_results(path) == [
        _parse_line(line.encode()) for line in path.read_text().splitlines()[1:]
    ]


def test_empty_results_file_and_foreign_csv(tmp_path: Path) -> None:
    (tmp_path / "results.csv").write_text("")  # a crash right after creating it
    assert len(_traj_sweep(tmp_path)) == 3 and len(_csv_rows(tmp_path / "results.csv")) == 3
    other = tmp_path / "other"
    other.mkdir()
    (other / "results.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ProblemError, match="other columns"):
        _traj_sweep(other)
    assert (other / "results.csv").read_text() == "a,b\n1,2\n"


def test_second_sweep_on_one_folder_is_refused(tmp_path: Path) -> None:
    with LineLog(tmp_path / "results.csv", "holder"):
        with pytest.raises(ProblemError, match="in use by another process"):
            _traj_sweep(tmp_path)
    assert len(_traj_sweep(tmp_path)) == 3  # released with its holder


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"solvers": ["NOSUCH"]}, "unknown solver.*NOSUCH"),
        ({"instances": ["bogus"]}, "unknown instance.*bogus"),
        ({"problems": ["nope"]}, "unknown problem"),
        ({"problems": []}, "at least one"),
        ({"time_limit": 0}, "time_limit"),
        ({"time_limit": -1.0}, "time_limit"),
        ({"time_limit": float("nan")}, "time_limit"),
        ({"time_limit": float("inf")}, "time_limit"),
        ({"sizes": [0]}, "sizes"),
        ({"sizes": [2.5]}, "sizes"),
        ({"seeds": [-1]}, "seeds"),
        ({"profile": "extreme"}, "profile"),
        ({"out": "FILE"}, "is a file"),
    ],
)
def test_bad_sweep_arguments(tmp_path: Path, kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {
        "problems": ["trajectories"],
        "out": tmp_path / "o",
        "sizes": [10],
        "isolate": False,
        **kwargs,
    }
    if args["out"] == "FILE":
        args["out"] = tmp_path / "f"
        (tmp_path / "f").write_text("x")
    with pytest.raises(ProblemError, match=match):
        harness.run_sweep(args.pop("problems"), args.pop("out"), **args)  # type: ignore[arg-type]
    assert not (tmp_path / "o" / "results.csv").exists()  # refused before any work


_TROUBLE = (
    "import sys\n"
    "from solvers_cmp import cases as cs, harness\n"
    "cs.register('trouble', 'tests.harness_adapters:Trouble')\n"
    "try:\n"
    "    harness.run_sweep(['trouble'], __import__('pathlib').Path({out!r}), "
    "time_limit=3.0)\n"
    "except KeyboardInterrupt as exc:  # what the CLI does: one line, exit 130\n"
    "    print(f'optmodels: {{exc}}', file=sys.stderr)\n"
    "    sys.exit(130)\n"
)


def _start_trouble(out: Path) -> subprocess.Popen[str]:
    """A sweep of 'trouble' in a child interpreter, stopped in the 60 s 'sleep' run (the
    fourth): returns once numpy, crash and ok are in results.csv."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _TROUBLE.format(out=str(out))],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        start_new_session=True,
        stderr=subprocess.PIPE,
        text=True,
    )
    path, deadline = out / "results.csv", time.monotonic() + 120
    while not (path.exists() and len(path.read_text().splitlines()) >= 4):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"the sweep did not reach its 4th run: {proc.communicate()[1]}")
        time.sleep(0.05)
    return proc


def test_harness_worker_dies_with_a_killed_parent(tmp_path: Path) -> None:
    proc = _start_trouble(tmp_path)
    kids = children(proc.pid)
    assert kids  # the worker, asleep in the 'sleep' run
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(30)
    assert wait_gone(kids, 10.0) == [], "the worker outlived its SIGKILLed parent"


def test_harness_ctrl_c_keeps_rows_and_resumes(tmp_path: Path, trouble: None) -> None:
    proc = _start_trouble(tmp_path / "a")
    kids = children(proc.pid)
    _, err, took = interrupt(proc)  # SIGINT to the whole group, as a terminal does
    assert proc.returncode == 130 and took < 2.0, (proc.returncode, took, err)
    assert len(err.splitlines()) == 1 and "compare: interrupted" in err, err
    assert wait_gone(kids, 5.0) == []
    kept = _csv_rows(tmp_path / "a" / "results.csv")
    assert [r["solver"] for r in kept] == ["numpy", "crash", "ok"]
    # the same time limit as the interrupted sweep: the resume key matches, the three kept
    # rows are reused (another limit would recompute them: tests/test_compare_trust.py)
    resumed = harness.run_sweep(["trouble"], tmp_path / "a", time_limit=3.0)
    fresh = harness.run_sweep(["trouble"], tmp_path / "b", time_limit=3.0)

    def outcome(r: dict[str, object]) -> tuple[object, ...]:
        # errors: 0 or 5e-4 exactly (x = data [+ 1e-3]), or NaN; the CSV keeps 10 digits
        return r["solver"], r["status"], r["success"], f"{r['solution_error']:.6g}"

    assert [outcome(r) for r in resumed] == [outcome(r) for r in fresh]
    assert len(_csv_rows(tmp_path / "a" / "results.csv")) == 6


# ------------------------------------------------------------------------ on Dask
@pytest.fixture(scope="module")
def dask_cluster() -> object:
    import distributed  # in the test extra (pyproject): must be here, never skipped

    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        yield cluster


def _outcome(r: dict[str, object]) -> tuple[object, ...]:
    # errors of 'trouble': 0 or 5e-4 exactly (x = data [+ 1e-3]), or NaN; messages of the
    # failures name the same time limit / exit code / exception on both engines
    return (
        r["solver"],
        r["status"],
        r["success"],
        r["reason"],
        f"{r['solution_error']:.6g}",
        r["message"] if not r["success"] else "",
    )


def test_sweep_on_a_dask_cluster_equals_the_local_one_and_resumes(
    tmp_path: Path, trouble: None, dask_cluster: object
) -> None:
    address = dask_cluster.scheduler_address  # type: ignore[attr-defined]
    local = harness.run_sweep(["trouble"], tmp_path / "a", time_limit=1.0)
    remote = harness.run_sweep(["trouble"], tmp_path / "b", time_limit=1.0, scheduler=address)
    assert [_outcome(r) for r in remote] == [_outcome(r) for r in local]
    by = {r["solver"]: r for r in remote}
    assert by["sleep"]["status"] == "time_limit" and by["crash"]["status"] == "crashed"
    assert by["sloppy"]["solution_error"] == pytest.approx(1e-3 / 2)
    assert {r["solver"] for r in _csv_rows(tmp_path / "b" / "results.csv")} == set(by)
    # resume on the cluster from the local run's file, cut after 3 rows: only the
    # 3 missing runs are run; the rows kept are not rewritten
    (tmp_path / "c").mkdir()
    lines = (tmp_path / "a" / "results.csv").read_text().splitlines()
    (tmp_path / "c" / "results.csv").write_text("\n".join(lines[:4]) + "\n")
    resumed = harness.run_sweep(["trouble"], tmp_path / "c", time_limit=1.0, scheduler=address)
    assert [_outcome(r) for r in resumed] == [_outcome(r) for r in local]
    text = (tmp_path / "c" / "results.csv").read_text().splitlines()
    assert text[:4] == lines[:4] and len(text) == 7
    assert sorted(r["solver"] for r in _csv_rows(tmp_path / "c" / "results.csv")) == sorted(by)
    # a finished sweep on the cluster runs nothing: the file is unchanged
    again = harness.run_sweep(["trouble"], tmp_path / "c", time_limit=1.0, scheduler=address)
    assert (tmp_path / "c" / "results.csv").read_text().splitlines() == text
    assert [_outcome(r) for r in again] == [_outcome(r) for r in local]


def test_cli_compare_on_a_dask_scheduler(
    tmp_path: Path, dask_cluster: object, capsys: pytest.CaptureFixture[str]
) -> None:
    address = dask_cluster.scheduler_address  # type: ignore[attr-defined]
    common = [
        "compare",
        "--problems",
        "trajectories",
        "--instances",
        "parallel",
        "--sizes",
        "10",
        "--solvers",
        "CLARABEL",
        "--json",
    ]
    assert main([*common, "--out", str(tmp_path / "l")]) == 0
    local = json.loads(capsys.readouterr().out)
    assert main([*common, "--out", str(tmp_path / "d"), "--scheduler", address]) == 0
    remote = json.loads(capsys.readouterr().out)  # exactly one JSON document on stdout
    assert remote["runs"] == local["runs"] == 3 and remote["successes"] == 3
    rows_l = _csv_rows(tmp_path / "l" / "results.csv")
    rows_d = _csv_rows(tmp_path / "d" / "results.csv")
    key = ("formulation", "solver")
    err = {tuple(r[k] for k in key): float(r["solution_error"]) for r in rows_l}
    assert sorted(err) == sorted(tuple(r[k] for k in key) for r in rows_d)
    # the error is the real one (see test_sweep_rows_resume_and_errors): recompute it
    data = cs.adapter("trajectories").make("parallel", 10, 0)
    ref = tr.closed_form(data, "parallel")
    sol = tr.solve(data, "parallel", formulation="reduced", solver="CLARABEL")
    exact = np.max(np.abs(sol.theta - ref.theta)) / np.max(np.abs(ref.theta))
    for r in rows_d:  # same deterministic solver on the same data: round-off apart
        assert r["status"] in ("optimal", "optimal_inaccurate") and r["success"] == "True"
        assert float(r["solution_error"]) == pytest.approx(err[tuple(r[k] for k in key)], abs=1e-12)
    row = next(r for r in rows_d if r["formulation"] == "reduced")
    assert float(row["solution_error"]) == pytest.approx(exact, abs=1e-12)


def test_bad_and_unreachable_schedulers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("localhost:8786", "tcp://", 3):
        with pytest.raises(ProblemError, match="compare scheduler"):
            harness.run_sweep(["trajectories"], tmp_path / "o", sizes=[10], scheduler=bad)
    assert not (tmp_path / "o" / "results.csv").exists()  # refused before any work
    t0 = time.monotonic()
    with pytest.raises(ProblemError, match="compare scheduler: cannot reach the Dask"):
        harness.run_sweep(
            ["trajectories"],
            tmp_path / "u",
            sizes=[10],
            scheduler="tcp://127.0.0.1:1",
            connect_timeout=1.0,
        )
    assert time.monotonic() - t0 < 8  # the connect timeout, not distributed's 30 s
    with pytest.raises(SystemExit) as info:  # the shared argparse type: usage error
        main(
            [
                "compare",
                "--problems",
                "trajectories",
                "--sizes",
                "10",
                "--out",
                str(tmp_path / "v"),
                "--scheduler",
                "localhost:8786",
                "--json",
            ]
        )
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tcp://host:8786" in err[0], err
    assert (
        main(["compare", "--details", "--scheduler", "tcp://h:1", "--out", str(tmp_path / "x")])
        == 2
    )
    assert "--scheduler" in capsys.readouterr().err


def test_ctrl_c_of_a_dask_sweep_keeps_rows_and_resumes(
    tmp_path: Path, trouble: None, dask_cluster: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    from optmodels.execution import Interrupted

    address = dask_cluster.scheduler_address  # type: ignore[attr-defined]
    judge = _judge

    def ctrl_c_at_sleep(row: dict[str, object], prof: harness.Profile) -> None:
        if row["solver"] == "sleep":  # Ctrl-C while the 4th result comes back
            raise KeyboardInterrupt
        judge(row, prof)

    monkeypatch.setattr(harness.sweep, "_judge", ctrl_c_at_sleep)  # read by _sweep
    with pytest.raises(Interrupted, match="compare: interrupted after 3 new run") as info:
        harness.run_sweep(["trouble"], tmp_path, time_limit=1.0, scheduler=address)
    assert [r["solver"] for r in info.value.partial] == ["numpy", "crash", "ok"]
    assert [r["solver"] for r in _csv_rows(tmp_path / "results.csv")] == ["numpy", "crash", "ok"]
    monkeypatch.setattr(harness.sweep, "_judge", judge)
    resumed = harness.run_sweep(["trouble"], tmp_path, time_limit=1.0, scheduler=address)
    local = harness.run_sweep(["trouble"], tmp_path / "local", time_limit=1.0)
    assert [_outcome(r) for r in resumed] == [_outcome(r) for r in local]
    assert len(_csv_rows(tmp_path / "results.csv")) == 6
