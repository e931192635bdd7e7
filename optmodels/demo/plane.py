"""Paper 000 demo: the plane of maneuver example (figures 1-4, Monte Carlo vs CRB)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from optmodels import plane, plots, scenarios
from optmodels.io import markdown_table, write_json

__all__ = ["run_plane_demo"]


def _crb(sc: scenarios.ManeuverScenario, n: int | None = None) -> tuple[float, float]:
    """CRB (angle RMS, offset std) from the first ``n`` true positions (default all)."""
    c = plane.cramer_rao_bound(plane.PlaneData(sc.truth[:n], sc.cov), sc.normal, sc.offset)
    return c.angle_rms, c.offset_std


def run_plane_demo(out: Path, *, runs: int = 200, seed: int = 0,
                   progress: bool = False) -> dict[str, Any]:
    """Paper 000's example end to end: figures 1-4, Monte Carlo against the CRB.

    Writes ``out/fig1_trajectory.png`` ... ``out/fig4_offset_error.png``,
    ``out/radius_bound.png``, ``out/report.md`` and ``out/summary.json``; returns the
    summary. ``runs`` Monte Carlo runs of the whole 10 s sequence (seeded from ``seed``).
    """
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sc = scenarios.paper_plane_example(rng)
    seq = plane.identify_sequence(sc.times, sc.points, sc.cov, start=2.0, resolve_every=100)
    ang1, off1 = plane.plane_errors(seq.normal, seq.offset, sc.normal, sc.offset)
    crb_ang, crb_off = np.array([_crb(sc, int(n)) for n in seq.n_points]).T

    # Monte Carlo over whole sequences
    ang = np.empty((runs, len(seq.times)))
    off = np.empty_like(ang)
    paper_alarm = np.zeros(runs, dtype=bool)
    chi2_alarm = np.zeros(runs, dtype=bool)
    seq_time = np.empty(runs)
    for k in tqdm(range(runs), desc="plane Monte Carlo", disable=not progress):
        s = scenarios.paper_plane_example(rng)
        q = plane.identify_sequence(s.times, s.points, s.cov, start=2.0)
        ang[k], off[k] = plane.plane_errors(q.normal, q.offset, s.normal, s.offset)
        paper_alarm[k] = not np.all(q.paper_planar)
        chi2_alarm[k] = not np.all(q.planar)
        seq_time[k] = q.solve_time
    rms_ang = np.sqrt(np.mean(ang**2, axis=0))
    rms_off = np.sqrt(np.mean(off**2, axis=0))

    # the full NLP and the closed form on the first run at 10 s
    data = plane.PlaneData(sc.points, sc.cov)
    cf = plane.closed_form(data)
    full = plane.solve(data, "full")
    red = plane.solve(data, "reduced")
    test = plane.planarity_test(data, cf)

    # CRB at 10 s against the radius the paper does not give
    radii = np.linspace(500, 5000, 46)
    rb = np.array([_crb(scenarios.paper_plane_example(0, radius=r)) for r in radii])

    figs = {
        "fig1": plots.plane_trajectory(out / "fig1_trajectory.png", sc.truth, sc.points),
        "fig2": plots.plane_statistic(out / "fig2_statistic.png", seq.times,
                                      seq.paper_statistic, seq.paper_threshold,
                                      seq.threshold, seq.level),
        "fig3": plots.plane_error(out / "fig3_angle_error.png", seq.times, ang1 * 1e3,
                                  crb_ang * 1e3, mc_rms=rms_ang * 1e3,
                                  ylabel="normal angle error, mrad",
                                  title="Fig. 3: error of the normal's direction"),
        "fig4": plots.plane_error(out / "fig4_offset_error.png", seq.times, np.abs(off1),
                                  crb_off, mc_rms=rms_off, ylabel="|error of a|, m",
                                  title="Fig. 4: error of the offset a"),
        "radius": plots.radius_bound(out / "radius_bound.png", radii, rb[:, 0], rb[:, 1],
                                     scenarios.PAPER_RADIUS),
    }
    mc_rows = [
        {"quantity": "normal angle error, mrad",
         "MC RMS": rms_ang[-1] * 1e3, "MC mean": float(np.mean(ang[:, -1])) * 1e3,
         "MC RMS std. error": rms_ang[-1] * 1e3 / np.sqrt(2 * runs),
         "CRB (RMS)": crb_ang[-1] * 1e3, "paper": 1.4},
        {"quantity": "offset error, m",
         "MC RMS": rms_off[-1], "MC mean": float(np.mean(np.abs(off[:, -1]))),
         "MC RMS std. error": rms_off[-1] / np.sqrt(2 * runs),
         "CRB (RMS)": crb_off[-1], "paper": 2.0},
    ]
    solver_rows = [
        {"method": s.method, "status": s.status.value, "objective (1.2)": s.objective,
         "angle to closed form, rad": float(plane.angle_error(s.normal, cf.normal)),
         "max residual (1.3)": s.max_residual, "build, s": s.build_time,
         "solve, s": s.solve_time, "iterations": s.iterations}
        for s in (cf, red, full)
    ]
    gen = seq.generic or {}
    gen_err = float(np.nanmax(plane.angle_error(gen["normal"], seq.normal[gen["index"]])))
    summary = {
        "runs": runs, "seed": seed, "radius": scenarios.PAPER_RADIUS,
        "monte_carlo": mc_rows, "solvers": solver_rows,
        "planarity_at_10s": test.to_dict(),
        "false_alarm_paper_rule": float(np.mean(paper_alarm)),
        "false_alarm_chi2": float(np.mean(chi2_alarm)),
        "sequence_closed_form_time_median_s": float(np.median(seq_time)),
        "sequence_generic_vs_closed_form_max_angle_rad": gen_err,
        "figures": {k: str(v.name) for k, v in figs.items()},
    }
    write_json(out / "summary.json", summary)
    fmt = {"MC RMS": ".3f", "MC mean": ".3f", "MC RMS std. error": ".3f",
           "CRB (RMS)": ".3f", "paper": ".1f"}
    report = f"""# Plane of maneuver (paper 000): the paper's example

Circle at 500 m/s in the vertical plane OXZ, centre 5000 m away at 45° elevation,
σ² = 625 m² per axis, 100 Hz for 10 s, identification from 2 s on. Radius (not given in
the paper): {scenarios.PAPER_RADIUS:.0f} m, the radius that minimises the Cramér–Rao bound
on the normal after 10 s (see `radius_bound.png`).

![fig1](fig1_trajectory.png)

## Fig. 2: planarity statistic

![fig2](fig2_statistic.png)

The statistic Λ_min is χ² with N − 3 degrees of freedom. The paper's rule (1.17)
√(2Λ) > √(2N) + 2 has a false-alarm probability of about 2 %, not 0.3 %; the corrected
threshold is χ²_(N−3)(0.997). Over the {runs} runs, the paper's rule raised an alarm at
some step of the 8 s sequence in {100 * np.mean(paper_alarm):.1f} % of the runs, the
corrected one in {100 * np.mean(chi2_alarm):.1f} % (each step is a test, so a sequence
alarm is more frequent than the per-step level).

## Figs. 3 and 4: errors of the plane

![fig3](fig3_angle_error.png)
![fig4](fig4_offset_error.png)

Monte Carlo ({runs} runs) at 10 s, next to the Cramér–Rao bound and the paper's numbers:

{markdown_table(mc_rows, list(mc_rows[0]), fmt)}
The ML estimate attains the bound. The paper's 1.4 mrad is the *mean* angle error
(mean/RMS = √(π/4) = 0.886 for two equal tilts); its 2 m offset error is below the
bound for every radius (≥ 3.3 m, `radius_bound.png`): a single run's reading.

## Closed form vs generic solves (first run, N = 1000)

{markdown_table(solver_rows, list(solver_rows[0]))}
The sequential closed form takes {1e3 * np.median(seq_time):.2f} ms for all 801 steps
(median of {runs} runs); the warm-started generic re-solves every 100 steps agree with it
to {gen_err:.1e} rad.
"""
    (out / "report.md").write_text(report)
    return summary
