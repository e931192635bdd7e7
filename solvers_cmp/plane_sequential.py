"""Per-step cost of the general-covariance plane estimator in sliding windows (issue 19).

:func:`benchmark` slides a window of ``window`` points one measurement at a time along
:func:`optmodels.scenarios.maneuver.climb_turn_track` (radar covariances: non-proportional
:math:`D_i`) and times :func:`optmodels.plane.general.fit_general` per step, cold (no
start) and warm (started from the previous step's normal), against the warm-started
reduced NLP :func:`optmodels.plane.solve` (CasADi + IPOPT, one start, on a subset of the
steps), with the largest angle between the two per step. Median over steps and runs.
Run: ``.venv/bin/python -m solvers_cmp.plane_sequential``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from optmodels import plane
from optmodels.core import as_count
from optmodels.plane.general import fit_general
from optmodels.scenarios.maneuver import climb_turn_track


def _windows(window: int, rate_hz: float, seed: int) -> tuple[np.ndarray, np.ndarray, int]:
    dur = max(150.0, 1.5 * window / rate_hz)
    tr = climb_turn_track(seed, rate_hz=rate_hz, durations=(dur * 0.4, dur * 0.2, dur * 0.4))
    return tr.points, tr.cov, len(tr.points) - window + 1


def benchmark(
    window: int = 100,
    runs: int = 3,
    seed: int = 0,
    *,
    rate_hz: float = 2.0,
    nlp_steps: int = 20,
    progress: bool = False,
) -> dict[str, Any]:
    """Per-step wall times (ms) of :func:`fit_general` in sliding windows of ``window``
    points, cold and warm, and of the warm reduced NLP on ``nlp_steps`` of the steps.

    Returns a dict: ``window``, ``steps`` (per run), ``runs``; ``warm_ms``, ``cold_ms``,
    ``nlp_ms``: median wall time per step (and ``*_p90``); ``warm_cpu_ms``: median CPU
    time of the warm steps (insensitive to other processes on a shared machine);
    ``warm_iterations``: median Newton
    iterations per warm step; ``max_angle_vs_nlp``: the largest angle (rad) between the
    warm fit and the reduced NLP (tight tolerances) over the compared steps;
    ``all_ok``: every warm step's status OK.
    """
    window = as_count(
        "solvers_cmp.plane_sequential.benchmark window", window, minimum=10, maximum=100_000
    )
    runs = as_count("solvers_cmp.plane_sequential.benchmark runs", runs, minimum=1)
    seed = as_count("solvers_cmp.plane_sequential.benchmark seed", seed)
    nlp_steps = as_count("solvers_cmp.plane_sequential.benchmark nlp_steps", nlp_steps)
    warm_t: list[float] = []
    warm_cpu: list[float] = []
    cold_t: list[float] = []
    nlp_t: list[float] = []
    iters: list[int] = []
    worst = 0.0
    all_ok = True
    steps = 0
    opts = {"tol": 1e-14, "constr_viol_tol": 1e-14}
    for run in range(runs):
        pts, cov, steps = _windows(window, rate_hz, seed + run)
        prev = None
        check = set(np.linspace(0, steps - 1, min(nlp_steps, steps)).astype(int).tolist())
        for k in range(steps):
            sl = slice(k, k + window)
            c0, t0 = time.process_time(), time.perf_counter()
            fit = fit_general(pts[sl], cov[sl], normal0=prev)
            t1, c1 = time.perf_counter(), time.process_time()
            if prev is not None:
                warm_t.append(t1 - t0)
                warm_cpu.append(c1 - c0)
                iters.append(fit.iterations)
            all_ok &= fit.ok
            prev = fit.normal
            t0 = time.perf_counter()
            fit_general(pts[sl], cov[sl])
            cold_t.append(time.perf_counter() - t0)
            if k in check:
                data = plane.PlaneData(pts[sl], cov[sl])
                t0 = time.perf_counter()
                sol = plane.solve(
                    data, "reduced", starts=1, initial_normal=prev, ipopt_options=opts
                )
                nlp_t.append(time.perf_counter() - t0)
                if sol.ok:
                    worst = max(worst, float(plane.angle_error(fit.normal, sol.normal)))
        if progress:
            print(f"run {run + 1}/{runs}: {steps} steps", flush=True)
    ms = 1e3

    def q(v: list[float], p: float) -> float:
        return float(np.percentile(v, p)) * ms if v else float("nan")

    return {
        "window": window,
        "steps": steps,
        "runs": runs,
        "rate_hz": rate_hz,
        "warm_ms": q(warm_t, 50),
        "warm_p90_ms": q(warm_t, 90),
        "warm_cpu_ms": q(warm_cpu, 50),
        "cold_ms": q(cold_t, 50),
        "cold_p90_ms": q(cold_t, 90),
        "nlp_ms": q(nlp_t, 50),
        "nlp_p90_ms": q(nlp_t, 90),
        "warm_iterations": float(np.median(iters)) if iters else float("nan"),
        "max_angle_vs_nlp": worst,
        "all_ok": bool(all_ok),
    }


def main() -> None:
    for window in (40, 100, 400):
        res = benchmark(window)
        print(
            f"window {window:4d}: warm {res['warm_ms']:.3f} ms (p90 {res['warm_p90_ms']:.3f},"
            f" CPU {res['warm_cpu_ms']:.3f}),"
            f" cold {res['cold_ms']:.3f} ms, reduced NLP warm {res['nlp_ms']:.2f} ms; "
            f"{res['warm_iterations']:.0f} Newton it./step; max angle vs NLP "
            f"{res['max_angle_vs_nlp']:.1e} rad; all OK {res['all_ok']}"
        )


if __name__ == "__main__":
    main()
