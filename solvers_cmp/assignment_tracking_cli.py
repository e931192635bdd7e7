"""The command line of the track-level study :mod:`solvers_cmp.assignment_tracking`
(issue 18's crossing / parallel study, issue 29's traffic study and per-scan benchmark);
``python -m solvers_cmp.assignment_tracking`` runs :func:`main`.

Usage::

    .venv/bin/python -m solvers_cmp.assignment_tracking [--runs 20] [--q 2]
        [--kind crossing] [--ratios 0.25 0.5 0.75 1.5 2 3]
    .venv/bin/python -m solvers_cmp.assignment_tracking --traffic --runs 12 [--seed 2029]
    .venv/bin/python -m solvers_cmp.assignment_tracking --bench 3
"""

from __future__ import annotations

import argparse
import json
import time

from optmodels.scenarios.encounters import TRAFFIC_KINDS
from solvers_cmp import assignment_tracking
from solvers_cmp.assignment_tracking import (
    METHODS,
    RATIOS,
    benchmark,
    done_when,
    done_when_traffic,
    study,
    summarise,
    summarise_traffic,
    traffic_encounters,
    traffic_study,
)


def main(argv: list[str] | None = None) -> None:
    """Run the study ``argv`` asks for (module docstring) and print its table and verdict,
    or with ``--json`` one JSON document."""
    ap = argparse.ArgumentParser(description=(assignment_tracking.__doc__ or "").split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--q", type=int, default=2)
    ap.add_argument("--kind", default="crossing", choices=("crossing", "parallel"))
    ap.add_argument(
        "--seed",
        type=int,
        default=None,
        help="default 2026 (crossing study), 2029 (--traffic, --bench)",
    )
    ap.add_argument("--ratios", type=float, nargs="*", default=list(RATIOS))
    ap.add_argument("--scans", type=int, default=24)
    ap.add_argument("--half-angle", type=float, default=5.0, help="crossing half-angle, deg")
    ap.add_argument(
        "--no-resolution",
        action="store_true",
        help="MAP+merges with the constant ρ even if a sensor model exists",
    )
    ap.add_argument(
        "--no-cell",
        action="store_true",
        help="MAP+merges without the one-cell constraint on merged members",
    )
    ap.add_argument("--methods", nargs="*", default=list(METHODS), choices=METHODS)
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--traffic",
        action="store_true",
        help="issue 29: the traffic encounters (--runs per kind), five methods",
    )
    ap.add_argument("--kinds", nargs="*", default=list(TRAFFIC_KINDS), choices=TRAFFIC_KINDS)
    ap.add_argument(
        "--bench",
        type=int,
        default=0,
        metavar="RUNS",
        help="issue 29: per-scan cost soft vs JPDA on RUNS encounters per kind",
    )
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.seed is None:
        a.seed = 2029 if (a.traffic or a.bench) else 2026
    if a.bench:
        print(json.dumps(benchmark(traffic_encounters(tuple(a.kinds), a.bench, a.seed)), indent=1))
        return
    if a.traffic:
        trows = summarise_traffic(traffic_study(kinds=tuple(a.kinds), runs=a.runs, seed=a.seed))
        if a.json:
            print(
                json.dumps(
                    {
                        "rows": trows,
                        "done_when": done_when_traffic(trows),
                        "wall_s": time.perf_counter() - t0,
                    },
                    indent=1,
                )
            )
            return
        print(
            f"{'kind':>13} {'method':>10} {'GOSPA':>7} {'se':>5} {'merged':>7} "
            f"{'swaps':>5} {'breaks':>6}"
        )
        for r in trows:
            print(
                f"{r['kind']:>13} {r['method']:>10} {r['gospa']:7.1f} {r['gospa_se']:5.1f} "
                f"{r['gospa_merged']:7.1f} {r['swaps']:5d} {r['breaks']:6d}"
            )
        print(json.dumps(done_when_traffic(trows)))
        return
    res = study(
        ratios=tuple(a.ratios),
        runs=a.runs,
        q=a.q,
        kind=a.kind,
        seed=a.seed,
        use_resolution=not a.no_resolution,
        scans=a.scans,
        half_angle_deg=a.half_angle,
        cell_information=not a.no_cell,
        methods=tuple(a.methods),
    )
    rows = summarise(res)
    verdict = done_when(rows)
    if a.json:
        print(
            json.dumps(
                {"rows": rows, "done_when": verdict, "wall_s": time.perf_counter() - t0}, indent=1
            )
        )
        return
    print(
        f"{'ratio':>6} {'method':>11} {'GOSPA':>8} {'se':>6} {'swaps':>5} {'breaks':>6} "
        f"{'merged':>6} {'s/run':>6}"
    )
    for r in rows:
        print(
            f"{r['ratio']:6.2f} {r['method']:>11} {r['gospa']:8.1f} {r['gospa_se']:6.1f} "
            f"{r['swaps']:5d} {r['breaks']:6d} {r['merged_scans']:6.1f} "
            f"{r['s_per_run']:6.2f}"
        )
    print(json.dumps(verdict))
    print(f"wall {time.perf_counter() - t0:.0f} s")
