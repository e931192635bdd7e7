"""Paper 004 demo: closely spaced space objects tracked over observation sessions with the
MAP joint assignment (merged groups and clutter allowed, one MILP per session) against a
resolved-only association (linear assignment, what a GNN tracker does), with a Kalman
update; correct-association rate and position error against object separation."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import assignment as asg
from optmodels import plots
from optmodels.io import markdown_table, write_json
from optmodels.scenarios.space_objects import SpaceScenario, space_objects

__all__ = ["run_assignment_demo", "track"]

SEPARATIONS = (40.0, 80.0, 120.0, 200.0, 400.0)


def _cv(dt: float, accel: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity transition and process noise (white acceleration ``accel``)."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    g = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
    return f, accel**2 * g @ g.T


def track(sc: SpaceScenario, *, merges: bool, rng: np.random.Generator, rho: float = 0.3,
          gate: float = 5.0, accel: float = 0.01) -> dict[str, Any]:
    """Run the tracker over the sessions. ``merges=False`` is the resolved-only baseline.

    Update of a block S that received measurement z: the members' stacked states with the
    measurement model z = mean_{j∈S} H x_j + w (H picks the position); the members'
    covariances are kept block-diagonal afterwards (cross terms dropped)."""
    q = sc.x0.shape[0]
    sp, sv = 50.0, 0.5
    p0 = np.diag([sp**2, sp**2, sv**2, sv**2])
    x = sc.x0 + rng.multivariate_normal(np.zeros(4), p0, size=q)
    p = np.repeat(p0[None], q, axis=0)
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    correct = total = 0
    t_prev = sc.sessions[0].time
    for s in sc.sessions:
        f, qn = _cv(s.time - t_prev, accel)
        t_prev = s.time
        x = x @ f.T
        p = f @ p @ f.T + qn
        data = asg.AssignmentData(x[:, :2], p[:, :2, :2], s.measurements, sc.meas_cov,
                                  sc.volume, sc.pd, rho, max_group_size=None if merges else 1,
                                  group_gate=gate if merges else None)
        sol = asg.solve(data).require_ok() if merges else asg.linear_assignment(data)
        for i, a in enumerate(sol.assignment):
            est = sol.partition[a] if a >= 0 else ()
            correct += int(est == tuple(sorted(s.truth[i])))
            total += 1
            if a < 0:
                continue
            members = list(sol.partition[a])
            k = len(members)
            hs = np.hstack([h / k] * k)
            ps = np.zeros((4 * k, 4 * k))
            for b, j in enumerate(members):
                ps[4 * b:4 * b + 4, 4 * b:4 * b + 4] = p[j]
            xs = np.concatenate([x[j] for j in members])
            sm = hs @ ps @ hs.T + sc.meas_cov
            gain = ps @ hs.T @ np.linalg.inv(sm)
            xs = xs + gain @ (s.measurements[i] - hs @ xs)
            ps = (np.eye(4 * k) - gain @ hs) @ ps
            for b, j in enumerate(members):
                x[j] = xs[4 * b:4 * b + 4]
                p[j] = 0.5 * (ps[4 * b:4 * b + 4, 4 * b:4 * b + 4]
                              + ps[4 * b:4 * b + 4, 4 * b:4 * b + 4].T)
    err = x[:, :2] - sc.sessions[-1].positions
    return {"correct": correct, "total": total,
            "rms_position": float(np.sqrt(np.mean(np.sum(err**2, axis=1))))}


def run_assignment_demo(out: Path, *, runs: int = 8, seed: int = 0, q: int = 4,
                        progress: bool = False) -> dict[str, Any]:
    """Writes ``out/association.png``, ``out/report.md`` and ``out/summary.json``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for sep in tqdm(SEPARATIONS, desc="assignment demo", disable=not progress):
        acc: dict[str, list[float]] = {"MAP": [], "GNN": [], "MAP rms": [], "GNN rms": []}
        for r in range(runs):
            sc = space_objects(np.random.default_rng([seed, int(sep), r]), q=q, separation=sep)
            for name, merges in (("MAP", True), ("GNN", False)):
                res = track(sc, merges=merges, rng=np.random.default_rng([seed, int(sep), r, 9]))
                acc[name].append(res["correct"] / res["total"])
                acc[f"{name} rms"].append(res["rms_position"])
        rows.append({"separation, m": sep,
                     "MAP correct": float(np.mean(acc["MAP"])),
                     "MAP se": float(np.std(acc["MAP"], ddof=1) / np.sqrt(runs)),
                     "GNN correct": float(np.mean(acc["GNN"])),
                     "GNN se": float(np.std(acc["GNN"], ddof=1) / np.sqrt(runs)),
                     "MAP RMS pos, m": float(np.sqrt(np.mean(np.square(acc["MAP rms"])))),
                     "GNN RMS pos, m": float(np.sqrt(np.mean(np.square(acc["GNN rms"]))))})
    fig = plots.association_rates(out / "association.png", rows)
    example = space_objects(np.random.default_rng([seed, 1]), q=3, separation=60.0)
    s0 = example.sessions[0]
    counts = [{"Q": qq, "N": nn, "variants": sum(v[0] for v in
                                                  asg.count_per_variant(qq, nn).values()),
               "hypotheses (14)": asg.count_hypotheses(qq, nn)}
              for qq, nn in ((2, 3), (3, 3), (4, 5), (7, 8), (10, 12), (12, 14))]
    summary = {"runs": runs, "seed": seed, "q": q, "rows": rows, "counts": counts}
    write_json(out / "summary.json", summary)
    fmt = {"MAP correct": ".3f", "MAP se": ".3f", "GNN correct": ".3f", "GNN se": ".3f",
           "MAP RMS pos, m": ".1f", "GNN RMS pos, m": ".1f", "hypotheses (14)": ",d"}
    report = f"""# Joint assignment with unresolved groups (paper 004)

{q} space objects in a line, {len(example.sessions)} sessions 60 s apart, measurement noise
{np.sqrt(example.meas_cov[0, 0]):.0f} m per axis, sensor resolution
{example.resolution:.0f} m (closer objects give one merged measurement at their mean),
P_D = {example.pd}, Poisson clutter (mean 2 per session), merge prior ρ = 0.3. Per
session the tracker predicts
the catalogue (constant velocity), solves the MAP hypothesis — every unresolved variant and
every assignment, as one MILP on HiGHS (exact, zero MIP gap) — and updates each detected
block with the measurement model z = mean of its members. The baseline associates with
merges disallowed (a linear assignment with missed-detection and clutter options, as GNN
trackers do). {runs} runs per separation; "correct": the share of measurements assigned to
exactly the block (or clutter) that produced them.

{markdown_table(rows, list(rows[0]), fmt)}
![association]({fig.name})

Below the resolution the resolved-only association must give a merged measurement to one
object and call the others missed (their tracks coast and drift); the MAP hypothesis
recognises the merge and updates every member with the mean. Far apart, both coincide.
When objects stay merged only their mean is observed, so individual positions remain
poorly determined whatever the association (the RMS errors of hundreds of metres).
With a small merge prior (ρ = 0.05 < 1 − P_D) the MAP rarely merges and behaves like the
baseline: the prior matters, and the paper leaves it open. An example session at 60 m
spacing: {len(s0.measurements)} measurements,
true sources {[list(t) for t in s0.truth]}.

How many hypotheses the paper's rule (14) scores (all unresolved variants, every
assignment; `optmodels assignment count Q N`):

{markdown_table(counts, list(counts[0]), fmt)}
At Q = 12, N = 14 the MILP with exact dominance pruning takes about 0.5 s
(`solvers_cmp`); the enumeration would score 1.8·10¹⁴ hypotheses.
"""
    (out / "report.md").write_text(report)
    return summary
