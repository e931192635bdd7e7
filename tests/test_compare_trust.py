"""Issue 27: a solver comparison a user can trust -- compile-once models equal fresh ones,
instances that exercise their problem (assignment merges, a binding box), rankings with
intervals and ties that repeat, and a resume that recomputes rows whose key differs
(through the installed CLI)."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from optmodels import assignment as asg
from optmodels import trajectories as tr
from optmodels.trajectories import generic
from solvers_cmp import cases as cs
from solvers_cmp import harness
from solvers_cmp.harness.metrics import headline, rank_rows, sgm_interval, summarise
from tests.test_cli import OPTMODELS

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


# ------------------------------------------------------------ compile once (DPP)
@pytest.mark.parametrize("family", ["diverging", "parallel"])
@pytest.mark.parametrize("formulation", ["constrained", "reduced"])
def test_dpp_solve_equals_the_non_parametric_one(family: str, formulation: str) -> None:
    """Two data sets on the same design (times, weights): the second solve reuses the
    compiled model, and both equal a fresh non-parametric solve and the closed form."""
    rng = np.random.default_rng(7)
    times = [np.sort(rng.uniform(0, 100, 30)) for _ in range(4)]
    generic._MODELS.clear()
    for trial in range(2):
        vals = [50.0 + rng.uniform(-2, 2) * t + rng.normal(0, 1, 30) for t in times]
        data = tr.TrajectoryData(times, vals, 1.0)
        dpp = tr.solve(data, family, formulation=formulation)
        fresh = tr.solve(data, family, formulation=formulation, reuse_model=False)
        cf = tr.closed_form(data, family)
        assert dpp.status.ok and fresh.status.ok
        assert ("compiled model reused" in dpp.method) == (trial == 1)
        scale = np.max(np.abs(cf.theta))
        assert np.max(np.abs(dpp.theta - fresh.theta)) / scale < 1e-8
        assert np.max(np.abs(dpp.theta - cf.theta)) / scale < 1e-8
    assert len(generic._MODELS) == 1


# ------------------------------------------------------------ instances
@pytest.mark.parametrize("q", [4, 8, 25])
def test_assignment_merges_instance_has_merges_in_its_map(q: int) -> None:
    from solvers_cmp.assignment import merge_gain

    ad = cs.adapter("assignment")
    for seed in (0, 1, 2):
        data = ad.make("merges", q, seed)
        sol = asg.solve(data)
        merged = [g for g in sol.partition if len(g) > 1]
        assert merged, (q, seed)
        assert merge_gain(data, sol) > 0.5
        if q == 4:  # the enumeration (14) agrees: the MAP merges
            bf = asg.brute_force(data)
            assert sorted(map(sorted, bf.partition)) == sorted(map(sorted, sol.partition))
    res = asg.solve(ad.make("resolved", q, 0))
    assert all(len(g) == 1 for g in res.partition)


def test_biasfield_box_instance_binds() -> None:
    """The box of the ``box`` instance is active: the reference field touches it, and the
    unconstrained closed form violates it."""
    from optmodels import biasfield as bf

    ad = cs.adapter("biasfield")
    inst = ad.make("box", 100, 0)
    box = np.asarray(inst["box"])
    ref = ad.reference("box", inst)
    assert ref.ok
    field = np.abs(np.asarray(ref.x)).max(axis=(0, 1))
    assert np.all(field <= box * (1 + 1e-6))
    assert np.any(field >= box * (1 - 1e-6))
    free = np.abs(bf.closed_form(inst["data"]).field).max(axis=(0, 1))
    assert np.any(free > box * (1 + 1e-4))


# ------------------------------------------------------------ rankings
def _rows(rng: np.random.Generator, truth: dict[str, float], cases: int) -> list[dict]:
    out = []
    for c in range(cases):
        base = rng.lognormal(0, 0.5)  # instance difficulty, shared by the solvers
        for solver, t in truth.items():
            out.append(
                {
                    "problem": "toy",
                    "instance": "i",
                    "size": c,
                    "seed": 0,
                    "formulation": "original form",
                    "solver": solver,
                    "success": True,
                    "solve_time": t * base * rng.lognormal(0, 0.15),
                    "build_time": 0.0,
                    "solution_error": 0.0,
                    "max_violation": 0.0,
                    "status": "optimal",
                }
            )
    return out


def test_two_noisy_runs_give_the_same_headline_with_ties() -> None:
    """Same true order (A ≈ B ≪ C), two seeded noisy timing sets: the headline (rank 1
    with its ties) is the same, A and B tied, C ranked after them."""
    truth = {"A": 0.010, "B": 0.0105, "C": 0.2}
    heads = []
    for seed in (1, 2):
        summ = summarise(_rows(np.random.default_rng(seed), truth, 12), 5.0)
        heads.append(headline(summ))
        by = {s["solver"]: s for s in summ}
        assert by["A"]["tied"] and by["B"]["tied"] and by["A"]["rank"] == by["B"]["rank"] == 1
        assert by["C"]["rank"] == 3 and not by["C"]["tied"]
        for s in summ:  # the interval holds the estimate
            assert s["sgm_total_lo"] <= s["sgm_total_time"] <= s["sgm_total_hi"]
    assert heads[0] == heads[1] == {"toy: original form": ("A", "B")}


def test_overlapping_intervals_are_ties_and_disjoint_ones_are_not() -> None:
    def row(name: str, t: float, lo: float, hi: float) -> dict:
        return {
            "solver": name,
            "success_rate": 1.0,
            "sgm_total_time": t,
            "sgm_total_lo": lo,
            "sgm_total_hi": hi,
        }

    ranked = rank_rows(
        [row("slow", 3.0, 2.9, 3.1), row("b", 1.1, 1.0, 1.3), row("a", 1.0, 0.8, 1.05)]
    )
    got = {r["solver"]: (r["rank"], r["tied"]) for r in ranked}
    assert got == {"a": (1, True), "b": (1, True), "slow": (3, False)}
    lo, hi = sgm_interval([0.001, 0.002, 0.004, 0.003])
    assert lo < hi and lo >= 0.001 and hi <= 0.004


# ------------------------------------------------------------ timing columns
def test_repetitions_build_and_closed_form_build_are_measured(tmp_path: Path) -> None:
    rows = harness.run_sweep(
        ["trajectories"],
        tmp_path,
        sizes=[10],
        solvers=["CLARABEL"],
        instances=["diverging"],
        isolate=False,
        repeats=3,
    )
    by = {r["formulation"]: r for r in rows}
    cf, gen = by["closed_form"], by["constrained"]
    assert cf["success"] and gen["success"]
    assert 1e-7 < cf["build_time"] < 1.0  # measured, not 0 / 3.5e-18
    assert gen["repeats_done"] == 3
    # the compiled model is reused: the later builds are below the first one
    assert gen["build_again"] < gen["build_time"]


# ------------------------------------------------------------ resume cannot lie
def _cli(*args: str) -> dict:
    out = subprocess.run(
        [str(OPTMODELS), *args],
        capture_output=True,
        text=True,
        env=_env(),
        timeout=300,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def test_cli_rerun_with_another_time_limit_recomputes(tmp_path: Path) -> None:
    base = [
        "compare",
        "--problems",
        "fusion",
        "--instances",
        "independent",
        "--sizes",
        "3",
        "--solvers",
        "CLARABEL",
        "--out",
        str(tmp_path),
        "--json",
    ]
    first = _cli(*base, "--time-limit", "5")
    path = tmp_path / "results.csv"
    rows1 = list(csv.DictReader(path.open()))
    assert first["runs"] == len(rows1) == 2
    for c in ("time_limit", "options", "solver_version", "repeats"):
        assert c in rows1[0] and rows1[0][c] not in ("", "None")
    assert {float(r["time_limit"]) for r in rows1} == {5.0}
    _cli(*base, "--time-limit", "5")  # the same key: reused, nothing appended
    assert len(list(csv.DictReader(path.open()))) == 2
    third = _cli(*base, "--time-limit", "7")  # another key: recomputed
    rows3 = list(csv.DictReader(path.open()))
    assert len(rows3) == 4 and third["runs"] == 2 and third["time_limit_s"] == 7.0
    assert sorted(float(r["time_limit"]) for r in rows3) == [5.0, 5.0, 7.0, 7.0]


def test_compare_default_out_differs_from_the_demos() -> None:
    out = subprocess.run(
        [str(OPTMODELS), "compare", "--help"],
        capture_output=True,
        text=True,
        env=_env(),
        timeout=120,
        check=True,
    ).stdout
    assert "report/compare-full" in " ".join(out.split())


# ------------------------------------------------------------ paired ranking
def _sized_rows(rng: np.random.Generator, truth: dict[str, float], sizes: list[int]) -> list[dict]:
    """Cases whose times span 100× with their size (t ∝ size), each solver a fixed factor
    of the others plus 10 % timing noise: the spread of case sizes is what an unpaired
    interval sees."""
    out = []
    for size in sizes:
        for solver, f in truth.items():
            out.append(
                {
                    "problem": "toy",
                    "instance": "i",
                    "size": size,
                    "seed": 0,
                    "formulation": "original form",
                    "solver": solver,
                    "success": True,
                    "solve_time": f * 1e-3 * size * rng.lognormal(0, 0.1),
                    "build_time": 0.0,
                    "solution_error": 0.0,
                    "max_violation": 0.0,
                    "status": "optimal",
                }
            )
    return out


def test_paired_ranking_separates_a_consistent_factor_that_sizes_hide() -> None:
    """B is 4× slower than A on every case, C within 5 % of A. The unpaired intervals of
    all three overlap (the case sizes span 100×), the paired ratios do not: A and C are
    tied at rank 1, B ranked 3 with its ratio interval around the shifted ratio (3.4:
    the 10 ms shift damps the small cases), above the tie margin; the same in two
    seeded runs."""
    from solvers_cmp.harness.metrics import TIE_MARGIN

    truth = {"A": 1.0, "B": 4.0, "C": 1.05}
    sizes = [10, 20, 50, 100, 200, 500, 1000]
    heads = []
    for seed in (3, 4):
        summ = summarise(_sized_rows(np.random.default_rng(seed), truth, sizes), 5.0)
        by = {s["solver"]: s for s in summ}
        assert by["B"]["sgm_total_lo"] < by["A"]["sgm_total_hi"]  # unpaired: overlap
        assert by["A"]["rank"] == by["C"]["rank"] == 1 and by["A"]["tied"]
        assert by["B"]["rank"] == 3 and not by["B"]["tied"]
        # the shifted ratio without noise: exp(mean log((2t + shift)/(t + shift)))
        t = 1e-3 * np.array(sizes)
        want = float(np.exp(np.mean(np.log((4 * t + 0.01) / (t + 0.01)))))
        assert TIE_MARGIN < by["B"]["ratio_lo"] < want < by["B"]["ratio_hi"] < 4.0
        assert by[summ[0]["solver"]]["ratio_to_best"] == pytest.approx(1.0)
        heads.append(headline(summ))
    assert heads[0] == heads[1] == {"toy: original form": ("A", "C")}


def test_a_skipped_run_counts_as_a_failure_of_its_solver() -> None:
    """A solver left out of the larger cases as too slow is not ranked on its easy
    cases only: its success rate drops and it ranks after the solvers that ran them."""
    rows = _sized_rows(np.random.default_rng(5), {"A": 1.0, "Q": 0.5}, [10, 100, 1000])
    rows = [r for r in rows if not (r["solver"] == "Q" and r["size"] == 1000)]
    skipped = [
        {
            "problem": "toy",
            "instance": "i",
            "size": 1000,
            "seed": 0,
            "formulation": "original form",
            "solver": "Q",
            "why": "too slow",
        }
    ]
    by = {s["solver"]: s for s in summarise(rows, 5.0, skipped=skipped)}
    assert by["Q"]["runs"] == 3 and by["Q"]["skipped"] == 1
    assert by["Q"]["success_rate"] == pytest.approx(2 / 3)
    assert by["A"]["rank"] == 1 and by["Q"]["rank"] == 2


def test_linear_assignment_is_a_reduction_row_only(tmp_path: Path) -> None:
    """Both assignment instances at Q = 4: the linear assignment (merges disallowed) is a
    reduction row without a rank, the enumeration the floor; the headline ranks the
    joint MILP alone, and the report's headline names no linear assignment solver."""
    from solvers_cmp import report

    rows = harness.run_sweep(["assignment"], tmp_path, sizes=[4], isolate=False, repeats=1)
    assert {r["formulation"] for r in rows} == {
        "joint MILP",
        "linear assignment",
        "enumeration (14)",
    }
    summ = summarise(rows, 5.0)
    kinds = {s["formulation"]: s["kind"] for s in summ}
    assert kinds == {
        "joint MILP": "original",
        "linear assignment": "reduction",
        "enumeration (14)": "reference",
    }
    assert all("rank" not in s for s in summ if s["kind"] != "original")
    head = headline(summ)
    assert list(head) == ["assignment: joint MILP"]
    assert "scipy" not in head["assignment: joint MILP"]
    md = report.write_harness_report(
        tmp_path, rows, profile="default", time_limit=5.0, error_tol=1e-5, violation_tol=1e-6
    )
    table = md.split("## Headline")[1].split("\n## ")[0]
    line = next(x for x in table.splitlines() if x.startswith("| assignment"))
    best_generic = line.split("|")[3]
    assert "scipy" not in best_generic and "linear assignment" not in best_generic
    assert "scipy (linear assignment)" in line  # in the reduction column


def test_a_results_file_of_the_previous_columns_is_set_aside_and_rerun(tmp_path: Path) -> None:
    """A results.csv written before the efficiency columns: its rows cannot be reused
    (no estimate error), so they move to results.csv.skipped and the runs are redone."""
    from solvers_cmp.harness.results import COLUMNS

    old_cols = COLUMNS[: COLUMNS.index("estimate_sq_error")]
    path = tmp_path / "results.csv"
    path.write_text(",".join(old_cols) + "\n" + ",".join("1" for _ in old_cols) + "\n")
    rows = harness.run_sweep(
        ["trajectories"],
        tmp_path,
        sizes=[10],
        solvers=["CLARABEL"],
        instances=["diverging"],
        isolate=False,
        repeats=1,
    )
    assert len(rows) == 3 and all(np.isfinite(r["crb"]) for r in rows if r["success"])
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS) and len(lines) == 4
    assert (tmp_path / "results.csv.skipped").read_text().count("\n") == 1
    cf = next(r for r in rows if r["formulation"] == "closed_form")
    assert cf["estimate_sq_error"] > 0 and cf["crb"] > 0


def test_the_quick_sweep_leaves_out_too_slow_runs_and_says_so(tmp_path: Path) -> None:
    """qpOASES on the m = 20 minimum-trace QP is marked too slow
    (:data:`solvers_cmp.harness.profiles.TOO_SLOW`): the quick sweep does not run it,
    lists it with its reason in the report and ranks it as a failure."""
    import csv as _csv

    from optmodels.cli.compare import _run_harness
    from solvers_cmp.harness.profiles import TOO_SLOW

    res = _run_harness(
        tmp_path,
        ["fusion"],
        sizes=[20],
        solvers=["CASADI_QPOASES", "CLARABEL"],
        profile="default",
        seed=0,
        time_limit=5.0,
        quick=True,
        progress=False,
        instances=["correlated"],
        scheduler="serial",
        repeats=1,
    )
    why = TOO_SLOW[("fusion", "CASADI_QPOASES", "min-trace W", None)][1]
    assert [(k["solver"], k["size"], k["why"]) for k in res["skipped"]] == [
        ("CASADI_QPOASES", 20, why)
    ]
    ran = {r["solver"] for r in _csv.DictReader((tmp_path / "results.csv").open())}
    assert ran == {"numpy", "CLARABEL"}
    md = (tmp_path / "report.md").read_text()
    left = md.split("## Left out of this quick sweep")[1].split("\n## ")[0]
    assert "**CASADI_QPOASES**" in left and why in left
    summ = {r["solver"]: r for r in _csv.DictReader((tmp_path / "summary.csv").open())}
    assert float(summ["CASADI_QPOASES"]["success_rate"]) == 0.0
    assert summ["CASADI_QPOASES"]["skipped"] == "1"
    assert summ["CLARABEL"]["rank"] == "1"
