"""Peak memory and time of :func:`optmodels.assignment.solve` on dense scenes (issue 14).

Each run is a fresh child interpreter (so peak memory is the run's own: ``ru_maxrss`` of
the child, read by the child itself at the end) under an address-space cap
(``RLIMIT_AS``, default 8 GiB) so that a model that asks for too much fails with
MemoryError instead of taking the machine down; the figure it asked for is reported.
Times are the medians of ``--repeats`` children (each child solves once, cold).

Scenes: Q objects uniform in a square of side ``side_factor``·√Q (3: the comparison's
default density; 2 and 1.5: dense), covariances 0.1-0.5 I, measurement noise 0.25 I,
N = Q + Q//8 + 1 measurements (the first min(N, Q) on objects, the rest clutter), P_D
0.9, ρ 0.05, a Mahalanobis gate of 3 or none; ``prune=False`` is the model
:func:`~optmodels.assignment.k_best` solves (every measurement-group pair kept).

Usage::

    .venv/bin/python -m solvers_cmp.bench_assignment_memory [--repeats 3] [--cap-gib 8]
        [--pythonpath DIR]   # benchmark another checkout of optmodels (e.g. the old one)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from typing import Any

import numpy as np

#: (label, Q, side factor, gate, max_group_size, prune)
CASES: tuple[tuple[str, int, float, float | None, int | None, bool], ...] = (
    ("Q=100 side 3√Q gate 3", 100, 3.0, 3.0, None, True),
    ("Q=100 side 2√Q gate 3", 100, 2.0, 3.0, None, True),
    ("Q=100 side 2√Q gate 3, prune=False", 100, 2.0, 3.0, None, False),
    ("Q=100 side 1.5√Q gate 3", 100, 1.5, 3.0, None, True),
    ("Q=100 side 1.5√Q gate 3, prune=False", 100, 1.5, 3.0, None, False),
    ("Q=100 side 0.7√Q gate 3 (5.7e5 cliques)", 100, 0.7, 3.0, None, True),
    ("Q=200 no gate, no merges", 200, 3.0, None, 1, True),
    ("Q=200 no gate, no merges, prune=False", 200, 3.0, None, 1, False),
    ("Q=200 no gate, merges ≤ 2", 200, 3.0, None, 2, True),
    ("Q=200 no gate, all merges", 200, 3.0, None, None, True),
)

CHILD = r"""
import json, resource, sys, time
import numpy as np
cap = int(sys.argv[2])
if cap > 0:
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
q, side_factor, gate, mgs, prune = json.loads(sys.argv[1])
from optmodels import assignment as asg
from solvers_cmp.assignment import instance
data = instance(q, q + q // 8 + 1, 0, gate, side_factor=side_factor, max_group_size=mgs)
out = {}
t0 = time.perf_counter()
try:
    sol = asg.solve(data, prune=prune)
    out.update(outcome=sol.status.value, log_score=sol.log_score,
               groups=sol.info.get("candidate_groups"),
               pairs=sol.info.get("assignment_variables"))
except MemoryError as exc:
    out.update(outcome="MemoryError", message=str(exc)[:200])
except Exception as exc:  # a ProblemError (size guard) is an expected outcome
    out.update(outcome=type(exc).__name__, message=str(exc)[:200])
out["wall_s"] = time.perf_counter() - t0
out["maxrss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print("@@" + json.dumps(out))
"""


def run_case(
    q: int,
    side_factor: float,
    gate: float | None,
    mgs: int | None,
    prune: bool,
    *,
    cap_bytes: int,
    pythonpath: str | None,
    timeout: float,
) -> dict[str, Any]:
    """One child run; its JSON report (or a timeout / crash record)."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    args = [
        sys.executable,
        "-c",
        CHILD,
        json.dumps([q, side_factor, gate, mgs, prune]),
        str(cap_bytes),
    ]
    try:
        # cwd: with -c the current directory comes first on sys.path
        proc = subprocess.run(
            args, capture_output=True, text=True, timeout=timeout, env=env, cwd=pythonpath
        )
    except subprocess.TimeoutExpired:
        return {"outcome": f"timeout > {timeout:g} s"}
    for line in proc.stdout.splitlines():
        if line.startswith("@@"):
            return dict(json.loads(line[2:]))
    return {"outcome": f"crashed (exit {proc.returncode})", "message": proc.stderr[-200:]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cap-gib", type=float, default=8.0)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--pythonpath", default=None)
    ap.add_argument("--only", default=None, help="substring of the case labels to run")
    args = ap.parse_args(argv)
    cap = int(args.cap_gib * 2**30)
    print("| case | outcome | groups | pairs | peak RSS, MiB | wall, s (median) |")
    print("|---|---|---|---|---|---|")
    for label, q, sf, gate, mgs, prune in CASES:
        if args.only and args.only not in label:
            continue
        runs = [
            run_case(
                q,
                sf,
                gate,
                mgs,
                prune,
                cap_bytes=cap,
                pythonpath=args.pythonpath,
                timeout=args.timeout,
            )
            for _ in range(args.repeats)
        ]
        last = runs[-1]
        rss = np.median([r.get("maxrss_mib", np.nan) for r in runs])
        wall = np.median([r.get("wall_s", np.nan) for r in runs])
        outcome = last["outcome"] + (f": {last['message']}" if "message" in last else "")
        print(
            f"| {label} | {outcome} | {last.get('groups', '')} | {last.get('pairs', '')} "
            f"| {rss:.0f} | {wall:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
