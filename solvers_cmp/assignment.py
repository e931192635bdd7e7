"""Joint assignment with unresolved groups (paper 004): the joint MILP (HiGHS; SCIP where
installed) against the paper's brute-force enumeration (where it is feasible) and, with
merges disallowed, the linear assignment -- time vs Q and N, the same MAP required.

Rows follow DESIGN.md's columns; ``solution_error`` is 0 when the hypothesis equals the
reference (brute force where run, else the HiGHS MILP), 1 otherwise; ``objective_gap`` the
log-score difference to the reference.

This file is the problem's whole comparison face: the rows and benchmarks above,
:class:`Adapter` (the harness adapter, ``solvers_cmp.assignment:Adapter``, found by
:mod:`solvers_cmp.cases` by the problem's name; references: enumeration (14), the joint
MILP) and :func:`write_report` (the ``compare --details`` section, also
``solvers_cmp.report.write_assignment``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import assignment as asg
from optmodels.backends.cvxpy_backend import available_solvers
from optmodels.io import markdown_table
from solvers_cmp import cases, report
from solvers_cmp.cases import Outcome, Run, cvxpy_milp_solvers
from solvers_cmp.common import repeat

#: (Q, N, all groups or gate): small cases get every subset, large ones a Mahalanobis gate.
CASES = (
    (2, 3, None),
    (4, 5, None),
    (6, 7, None),
    (8, 9, None),
    (12, 14, None),
    (25, 28, 3.0),
    (50, 55, 3.0),
)
#: Enumerate only below this many hypotheses (brute force scores ~10⁵ per second).
BRUTE_LIMIT = 200_000


def instance(
    q: int,
    n: int,
    seed: int,
    gate: float | None,
    *,
    rho: float | None = None,
    merges: bool = True,
    side_factor: float = 3.0,
    max_group_size: int | None = None,
    merged_pairs: int | None = None,
) -> asg.AssignmentData:
    """Q objects in a square of side ``side_factor``·√Q (constant density, so some are
    closer than the measurement noise), the first measurements on objects, the rest
    uniform clutter. Groups up to ``max_group_size`` objects (no limit by default; 1
    without ``merges``).

    ``merges=True`` (the harness's ``merges`` instance): ``merged_pairs`` (default
    max(1, Q // 8)) pairs of objects 1 m apart (objects 2k, 2k + 1), each seen as ONE
    measurement at the pair's centroid (noise σ = 0.2 m), no clutter within 3 m of a
    pair, P_D = 0.99 and ρ = 0.2 (default): the MAP merges every such pair (a missed
    detection costs ln 0.01, a merge ln 0.2) -- tested, and the MAP's merge gain (its
    log score minus the best hypothesis without merges) is in the harness rows.
    Until issue 27 every measurement was on a single object and the MAP never merged
    (merge gain 0.0 on every size and seed). ``merges=False`` (``resolved``): the scene
    as before (σ = 0.5 m, P_D = 0.9, ρ = 0.05), groups of one.
    """
    rng = np.random.default_rng([seed, q, n])
    side = side_factor * np.sqrt(q)
    means = rng.uniform(0, side, (q, 2))
    covs = np.stack([np.eye(2) * rng.uniform(0.1, 0.5) for _ in range(q)])
    meas = rng.uniform(0, side, (n, 2))
    if not merges:
        k = min(n, q)
        meas[:k] = means[:k] + rng.normal(0, 0.5, (k, 2))
        return asg.AssignmentData(
            means,
            covs,
            meas,
            0.25 * np.eye(2),
            side**2,
            0.9,
            0.05 if rho is None else rho,
            max_group_size=1,
            group_gate=gate,
        )
    m = min(q // 2, max(1, q // 8) if merged_pairs is None else int(merged_pairs))
    ang = rng.uniform(0, 2 * np.pi, m)
    means[1 : 2 * m : 2] = means[0 : 2 * m : 2] + np.column_stack([np.cos(ang), np.sin(ang)])
    cen = (means[0 : 2 * m : 2] + means[1 : 2 * m : 2]) / 2
    seen = [j for j in range(q) if not (j < 2 * m and j % 2 == 1)]  # one per pair
    k = min(n, len(seen))
    for i in range(k, n):  # clutter away from the pairs
        while m and np.min(np.linalg.norm(cen - meas[i], axis=1)) < 3.0:
            meas[i] = rng.uniform(0, side, 2)
    for i, j in enumerate(seen[:k]):
        c = (means[j] + means[j + 1]) / 2 if j < 2 * m else means[j]
        meas[i] = c + rng.normal(0, 0.2, 2)
    return asg.AssignmentData(
        means,
        covs,
        meas,
        0.04 * np.eye(2),
        side**2,
        0.99,
        0.2 if rho is None else rho,
        max_group_size=max_group_size,
        group_gate=gate,
    )


def merge_gain(data: asg.AssignmentData, sol: Any) -> float:
    """The MAP's merge gain: its log score minus that of the best hypothesis without
    merges (the linear assignment on the same data); 0 when the MAP merges nothing."""
    import dataclasses

    lin = asg.linear_assignment(dataclasses.replace(data, max_group_size=1))
    return float(sol.log_score - lin.log_score)


def rows(
    cases: tuple[tuple[int, int, float | None], ...] = CASES,
    *,
    seed: int = 0,
    repeats: int = 3,
    progress: bool = False,
) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    milp_solvers = [s for s in ("HIGHS", "SCIP") if s in available_solvers()]
    for q, n, gate in tqdm(cases, desc="assignment comparison", disable=not progress):
        for merges in (True, False):
            data = instance(q, n, seed, gate, merges=merges)
            runs: list[tuple[str, str, Any, float]] = []
            for s in milp_solvers:
                rep = repeat(lambda d=data, s=s: asg.solve(d, solver=s), repeats)
                runs.append(("joint MILP", s, rep.last, rep.median))
            if not merges:
                rep = repeat(lambda d=data: asg.linear_assignment(d), repeats)
                runs.append(("linear assignment", "scipy", rep.last, rep.median))
            if merges and asg.count_hypotheses(q, n) <= BRUTE_LIMIT:
                rep = repeat(lambda d=data: asg.brute_force(d), 1)
                runs.append(("enumeration (14)", "python", rep.last, rep.median))
            ref = next((r[2] for r in runs if r[0] == "enumeration (14)"), runs[0][2])
            for form, solver, sol, wall in runs:
                same = (
                    sol.status.ok
                    and sol.partition == ref.partition
                    and list(sol.assignment) == list(ref.assignment)
                )
                out.append(
                    {
                        "problem": "assignment",
                        "size": q,
                        "measurements": n,
                        "merges": "allowed" if merges else "disallowed",
                        "gate": gate if gate is not None else "none",
                        "seed": seed,
                        "formulation": form,
                        "solver": solver,
                        "settings": "default",
                        "status": sol.status.value,
                        "objective": sol.log_score,
                        "objective_gap": sol.log_score - ref.log_score,
                        "solution_error": 0.0 if same else 1.0,
                        "max_violation": sol.max_residual,
                        "build_time": sol.build_time,
                        "solve_time": sol.solve_time,
                        "total_time": wall,
                        "iterations": sol.iterations,
                        "hypotheses": asg.count_hypotheses(q, n) if merges else None,
                    }
                )
    return out


def kbest_benchmark(
    q: int = 12,
    n: int = 14,
    k: tuple[int, ...] = (2, 10),
    *,
    repeats: int = 3,
    seed: int = 0,
    gate: float | None = None,
) -> list[dict[str, Any]]:
    """Wall time of :func:`optmodels.assignment.k_best` (median of ``repeats``) on the
    comparison's scene (:func:`instance`; Q = 12, N = 14, every group: issue 18's case),
    with the MAP (:func:`optmodels.assignment.solve`) for scale. One row per k (k = 1:
    the MAP): the k-th best score, the size of the reduced model the MILPs ran on, and
    whether the scores are non-increasing and the hypotheses distinct."""
    data = instance(q, n, seed, gate)
    out: list[dict[str, Any]] = []
    rep = repeat(lambda: asg.solve(data), repeats)
    out.append(
        {
            "q": q,
            "n": n,
            "k": 1,
            "method": "MAP (solve)",
            "median_s": rep.median,
            "walls_s": rep.walls,
            "kth_score": rep.last.log_score,
            "candidate_groups": rep.last.info.get("candidate_groups"),
            "assignment_variables": rep.last.info.get("assignment_variables"),
            "consistent": rep.last.ok,
        }
    )
    for kk in k:
        rep = repeat(lambda kk=kk: asg.k_best(data, kk), repeats)
        hyps = rep.last.hypotheses
        scores = [h.log_score for h in hyps]
        keys = {(tuple(h.partition), tuple(map(int, h.assignment))) for h in hyps}
        out.append(
            {
                "q": q,
                "n": n,
                "k": kk,
                "method": "k_best",
                "median_s": rep.median,
                "walls_s": rep.walls,
                "kth_score": scores[-1],
                "candidate_groups": hyps[-1].info.get("candidate_groups"),
                "assignment_variables": hyps[-1].info.get("assignment_variables"),
                "consistent": len(keys) == len(hyps) == kk
                and bool(np.all(np.diff(scores) <= 1e-9)),
            }
        )
    return out


# ------------------------------------------------------------ harness adapter
class Adapter(cases.Adapter):
    """Joint assignment with unresolved groups (paper 004); size = Q objects, N = Q + Q//8
    + 1 measurements (a clutter share), gate 3σ from Q = 20 on. ``merges``: the joint MILP
    vs the enumeration (14) where it has ≤ 2·10⁵ hypotheses (else the best known: HiGHS at
    zero gap); ``resolved``: merges disallowed, reference = the linear assignment (scipy).
    Error: 0 for the reference's MAP hypothesis, 1 otherwise."""

    name = "assignment"
    instances = ("merges", "resolved")
    sizes = (4, 8, 25)
    size_meaning = "objects Q"
    problem_class = "MILP"
    brute_limit = 200_000
    reference_formulations = ("enumeration (14)",)
    reductions = ("linear assignment",)

    def notes(self, instance: str, data: Any, ref: Outcome) -> dict[str, Any]:
        """The reference MAP's merged groups and its merge gain (log score over the best
        hypothesis without merges, :func:`merge_gain`)."""
        from optmodels import assignment as asg

        sol = asg.solve(data)
        return {
            "MAP merged groups": sum(len(g) > 1 for g in sol.partition),
            "merge gain (ln)": merge_gain(data, sol),
        }

    def make(self, instance: str, size: int, seed: int) -> Any:
        from solvers_cmp.assignment import instance as gen

        gate = 3.0 if size >= 20 else None
        return gen(size, size + size // 8 + 1, seed, gate, merges=instance == "merges")

    @staticmethod
    def _key(sol: Any) -> list[Any]:
        return [sorted(map(list, sol.partition)), list(map(int, sol.assignment))]

    def _out(self, sol: Any) -> Outcome:
        return cases._from_solution(sol, self._key(sol), objective=sol.log_score)

    def reference(self, instance: str, data: Any) -> Outcome:
        from optmodels import assignment as asg

        if instance == "resolved":
            return self._out(asg.linear_assignment(data))
        if asg.count_hypotheses(data.q, data.n) <= self.brute_limit:
            return self._out(asg.brute_force(data))
        return self._out(asg.solve(data, solver="HIGHS"))

    def runs(self, instance: str) -> list[Run]:
        from optmodels import assignment as asg  # noqa: F401

        out = [Run("joint MILP", s) for s in cvxpy_milp_solvers()]
        if instance == "resolved":
            out.insert(0, Run("linear assignment", "scipy"))
        else:
            out.insert(0, Run("enumeration (14)", "python"))
        return out

    def solve(self, instance: str, data: Any, run: Run, options: dict[str, Any]) -> Outcome:
        from optmodels import assignment as asg
        from optmodels.core import ProblemError

        if run.formulation == "linear assignment":
            return self._out(asg.linear_assignment(data))
        if run.formulation == "enumeration (14)":
            if asg.count_hypotheses(data.q, data.n) > self.brute_limit:
                raise ProblemError(
                    f"enumeration: {asg.count_hypotheses(data.q, data.n):.3g} "
                    f"hypotheses, above the limit {self.brute_limit:.0e}"
                )
            return self._out(asg.brute_force(data))
        return self._out(asg.solve(data, solver=run.solver, **options))

    def error(self, x: Any, ref: Any) -> float:
        return 0.0 if x == ref else 1.0


# ------------------------------------------------------ compare --details report
def write_report(out: Path, rows: list[dict[str, Any]]) -> str:
    """Write ``assignment_results.csv`` and return the Markdown section."""
    report._results_csv(out, "assignment", rows)
    cols = [
        "size",
        "measurements",
        "merges",
        "gate",
        "formulation",
        "solver",
        "status",
        "solution_error",
        "objective_gap",
        "build_time",
        "solve_time",
        "total_time",
        "hypotheses",
    ]
    fmt = {
        "objective_gap": ".1e",
        "build_time": ".4f",
        "solve_time": ".4f",
        "total_time": ".4f",
        "solution_error": ".0f",
        "hypotheses": ".3g",
    }
    md = (
        "## Joint assignment with unresolved groups (paper 004)\n\n"
        "size = Q objects. The joint MILP (exact pruning, zero MIP gap) against the paper's "
        "enumeration (14) where it has at most 2·10⁵ hypotheses, and, with merges "
        "disallowed, against the linear assignment (scipy). solution_error 0: the same "
        "MAP hypothesis as the reference; 'hypotheses': how many (14) would score.\n\n"
        + markdown_table(rows, cols, fmt)
    )
    return md + "\n"
