r"""Per-scan cost of the exact MAP joint assignment (paper 004, issue 25 item 5) at
air-picture scale, against what a performance-minded user writes and Stone Soup's
associators, on the same scans.

Scene (:func:`scan`): Q aircraft uniform in area over a 20-200 km annulus around the radar,
Q/20 of them with a close partner (range offset U(−300, 300) m, azimuth offset
U(−1.5°, 1.5°): below to above the cell), predicted covariances K_j with axes U(50, 200) m
in a random orientation, true positions drawn from N(m_j, K_j); the radar's resolution
cell 150 m × 1° (a pair whose true difference lies in it gives one return at the
centroid), P_D 0.9, clutter 0.1 Q returns uniform over the annulus, each return with its
own Cartesian covariance from σ_r = 30 m, σ_az = 0.15° (:func:`optmodels.assignment.
polar_measurement_covs`). How it differs from real traffic: aircraft are placed
independently (real traffic concentrates on airways and near airports, with more and
larger close groups, formations, and holding stacks), the close pairs are planted, the
clutter is uniform (real clutter clusters on terrain, weather and the sea), the predicted
covariances are drawn, not from a tracker, and every scan is a snapshot (no scan-to-scan
correlation). See ``docs/guide/assignment.md``.

Contenders on each scan (time per scan, median of rounds, interleaved, and the ratio of
the fastest rounds and of the median CPU times (``time.process_time``), less sensitive to
a loaded machine, where a millisecond call is often preempted; peak Python memory (NumPy's
arrays included, not HiGHS' own) by ``tracemalloc`` in a separate pass):

* ``MAP``: ``optmodels.assignment.solve`` with the package defaults and the sensor's
  ``Resolution`` (exact MAP with merges; decomposed, direct HiGHS);
* ``GNN``: a vectorised numpy + scipy GNN: Mahalanobis d² with S_ij = K_j + R_i (chunked
  over measurements), 5σ gate, :func:`scipy.optimize.linear_sum_assignment`;
* ``SS-GNN`` / ``SS-JPDA``: Stone Soup ``GNNWith2DAssignment`` (``DistanceHypothesiser``,
  Mahalanobis, missed distance 5) and ``JPDAwithEHM2`` (``PDAHypothesiser``), up to
  ``--stonesoup-max`` aircraft (their hypothesisers visit every track × detection pair in
  Python).

Q = 3000 (and any Q ≥ ``--limit-from``) runs in a child process under an 8 GiB
address-space limit (``resource.setrlimit(RLIMIT_AS)``).

Usage::

    .venv/bin/python -m solvers_cmp.assignment_scale [--q 10 100 1000 3000] [--rounds 5]
        [--stonesoup-max 100] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
import tracemalloc
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

SITE = np.zeros(2)
CELL_RANGE, CELL_AZ = 150.0, math.radians(1.0)
SIGMA_R, SIGMA_AZ = 30.0, math.radians(0.15)
R_IN, R_OUT = 20e3, 200e3
PD = 0.9
LIMIT_BYTES = 8 * 2**30


def scan(q: int, seed: int = 0) -> dict[str, Any]:
    """One scan of the scene (module docstring): ``means`` (Q, 2), ``covs`` (Q, 2, 2),
    ``measurements`` (N, 2), ``meas_cov`` (N, 2, 2), ``volume`` (m²), ``pd``, the true
    ``origin`` of each return (tuple of aircraft, () for clutter)."""
    from optmodels.assignment import polar_measurement_covs

    rng = np.random.default_rng(seed)
    n_pairs = q // 20
    n_free = q - n_pairs
    r = np.sqrt(rng.uniform(R_IN**2, R_OUT**2, n_free))
    az = rng.uniform(-math.pi, math.pi, n_free)
    host = rng.choice(n_free, n_pairs, replace=False)
    r2 = np.clip(r[host] + rng.uniform(-300, 300, n_pairs), R_IN, R_OUT)
    az2 = az[host] + rng.uniform(-1.5, 1.5, n_pairs) * math.pi / 180
    pol = np.column_stack([np.concatenate([r, r2]), np.concatenate([az, az2])])
    truth = pol[:, :1] * np.column_stack([np.cos(pol[:, 1]), np.sin(pol[:, 1])])
    ang = rng.uniform(0, math.pi, q)
    axes = rng.uniform(50.0, 200.0, (q, 2)) ** 2
    rot = np.stack(
        [np.column_stack([np.cos(ang), np.sin(ang)]), np.column_stack([-np.sin(ang), np.cos(ang)])],
        axis=2,
    )  # (Q, 2, 2)
    covs = np.einsum("qij,qj,qkj->qik", rot, axes, rot)
    chol = np.linalg.cholesky(covs)
    means = truth + np.einsum("qij,qj->qi", chol, rng.standard_normal((q, 2)))
    # unresolved pairs of true positions merge (the cell on the true polar difference)
    true_pol = np.column_stack(
        [np.hypot(truth[:, 0], truth[:, 1]), np.arctan2(truth[:, 1], truth[:, 0])]
    )
    from scipy.spatial import cKDTree

    near = cKDTree(truth).query_pairs(CELL_RANGE + R_OUT * CELL_AZ, output_type="ndarray")
    parent = list(range(q))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in near:
        dr = abs(true_pol[a, 0] - true_pol[b, 0])
        da = abs((true_pol[a, 1] - true_pol[b, 1] + math.pi) % (2 * math.pi) - math.pi)
        if dr < CELL_RANGE and da < CELL_AZ:
            parent[find(a)] = find(b)
    blocks: dict[int, list[int]] = {}
    for j in range(q):
        blocks.setdefault(find(j), []).append(j)
    returns, origin = [], []
    for members in blocks.values():
        if rng.uniform() < PD:
            returns.append(truth[members].mean(axis=0))
            origin.append(tuple(members))
    n_clutter = round(0.1 * q)
    rc = np.sqrt(rng.uniform(R_IN**2, R_OUT**2, n_clutter))
    ac = rng.uniform(-math.pi, math.pi, n_clutter)
    clutter = rc[:, None] * np.column_stack([np.cos(ac), np.sin(ac)])
    exact = np.vstack([np.array(returns).reshape(-1, 2), clutter])
    origin += [()] * n_clutter
    pr = np.column_stack([np.hypot(exact[:, 0], exact[:, 1]), np.arctan2(exact[:, 1], exact[:, 0])])
    pr += rng.standard_normal(pr.shape) * np.array([SIGMA_R, SIGMA_AZ])
    meas = pr[:, :1] * np.column_stack([np.cos(pr[:, 1]), np.sin(pr[:, 1])])
    order = rng.permutation(len(meas))
    meas = meas[order]
    area = math.pi * (R_OUT**2 - R_IN**2)
    return {
        "means": means,
        "covs": covs,
        "measurements": meas,
        "meas_cov": polar_measurement_covs(meas, SITE, SIGMA_R, SIGMA_AZ),
        "volume": area / max(n_clutter, 1),
        "pd": PD,
        "origin": [origin[k] for k in order],
    }


def resolution() -> Any:
    from optmodels.assignment import Resolution

    return Resolution(range=CELL_RANGE, azimuth=CELL_AZ, site=SITE)


def run_map(sc: dict[str, Any]) -> Any:
    """The exact MAP with the resolution model and the package's defaults."""
    from optmodels import assignment as asg

    data = asg.AssignmentData(
        sc["means"],
        sc["covs"],
        sc["measurements"],
        sc["meas_cov"],
        volume=sc["volume"],
        pd=sc["pd"],
        sensor=resolution(),
    )
    return asg.solve(data)


def run_gnn(sc: dict[str, Any], chunk: int = 256) -> np.ndarray:
    """Vectorised GNN: (N,) track index or −1 (module docstring)."""
    m, k, z, r = sc["means"], sc["covs"], sc["measurements"], sc["meas_cov"]
    n, q = len(z), len(m)
    cost = np.empty((n, q))
    for a in range(0, n, chunk):
        s = k[None, :] + r[a : a + chunk, None]  # (c, Q, 2, 2)
        det = s[..., 0, 0] * s[..., 1, 1] - s[..., 0, 1] ** 2
        dx = z[a : a + chunk, None, :] - m[None]
        d2 = (
            s[..., 1, 1] * dx[..., 0] ** 2
            - 2 * s[..., 0, 1] * dx[..., 0] * dx[..., 1]
            + s[..., 0, 0] * dx[..., 1] ** 2
        ) / det
        cost[a : a + chunk] = np.where(d2 <= 25.0, d2, 1e9)
    rows, cols = linear_sum_assignment(cost)
    out = np.full(n, -1)
    ok = cost[rows, cols] <= 25.0
    out[rows[ok]] = cols[ok]
    return out


def _stonesoup_scene(sc: dict[str, Any]) -> tuple[list[Any], list[Any], Any, Any]:
    """Tracks (position-only Gaussian states, zero-time prediction) and detections with
    their own measurement models, the predictor, the updater."""
    from datetime import datetime

    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        RandomWalk,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    t0 = datetime(2026, 1, 1)
    trans = CombinedLinearGaussianTransitionModel([RandomWalk(1e-6), RandomWalk(1e-6)])
    base = LinearGaussian(ndim_state=2, mapping=(0, 1), noise_covar=np.eye(2))
    tracks = [
        Track([GaussianState(m.reshape(2, 1), c, timestamp=t0)])
        for m, c in zip(sc["means"], sc["covs"], strict=True)
    ]
    dets = [
        Detection(
            z.reshape(2, 1),
            timestamp=t0,
            measurement_model=LinearGaussian(ndim_state=2, mapping=(0, 1), noise_covar=r),
        )
        for z, r in zip(sc["measurements"], sc["meas_cov"], strict=True)
    ]
    return tracks, dets, KalmanPredictor(trans), KalmanUpdater(base)


def run_stonesoup(sc: dict[str, Any], kind: str) -> Any:
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDAwithEHM2
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.measures import Mahalanobis

    tracks, dets, pred, upd = _stonesoup_scene(sc)
    t = tracks[0].timestamp
    if kind == "SS-GNN":
        assoc = GNNWith2DAssignment(
            DistanceHypothesiser(pred, upd, Mahalanobis(), missed_distance=5.0)
        )
    else:
        assoc = JPDAwithEHM2(
            PDAHypothesiser(
                pred,
                upd,
                clutter_spatial_density=1.0 / sc["volume"],
                prob_detect=sc["pd"],
                prob_gate=0.99999,
            )
        )
    return assoc.associate(set(tracks), set(dets), t)


def _timed(fn: Any, *args: Any) -> tuple[float, float]:
    """Wall-clock and CPU seconds (``time.process_time``: what the call consumed, robust to
    the preemption a loaded machine adds to millisecond calls)."""
    t, c = time.perf_counter(), time.process_time()
    fn(*args)
    return time.perf_counter() - t, time.process_time() - c


def _peak(fn: Any, *args: Any) -> float:
    tracemalloc.start()
    try:
        fn(*args)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def measure(
    q: int, rounds: int, stonesoup_max: int, seed: int = 0, ss_rounds: int = 3
) -> dict[str, Any]:
    """Medians over interleaved rounds of each contender on one scan: ``rounds`` rounds
    (at least 51 below Q = 300, where a call takes milliseconds), Stone Soup's in the
    first ``ss_rounds`` of them (seconds per call)."""
    rounds = max(rounds, 51) if q < 300 else rounds
    sc = scan(q, seed)
    names = ["MAP", "GNN"] + (["SS-GNN", "SS-JPDA"] if q <= stonesoup_max else [])
    calls = {
        "MAP": lambda: run_map(sc),
        "GNN": lambda: run_gnn(sc),
        "SS-GNN": lambda: run_stonesoup(sc, "SS-GNN"),
        "SS-JPDA": lambda: run_stonesoup(sc, "SS-JPDA"),
    }
    sol = run_map(sc)  # warm-up and the answer's check
    run_gnn(sc)
    times: dict[str, list[float]] = {k: [] for k in names}
    cpu: dict[str, list[float]] = {k: [] for k in names}
    for r in range(rounds):
        for k in names if r % 2 == 0 else names[::-1]:
            if k.startswith("SS-") and r >= ss_rounds:
                continue
            wall, used = _timed(calls[k])
            times[k].append(wall)
            cpu[k].append(used)
    med = {k: statistics.median(v) for k, v in times.items()}
    low = {k: min(v) for k, v in times.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    peak = {k: _peak(calls[k]) for k in names}
    return {
        "q": q,
        "n": len(sc["measurements"]),
        "status": sol.status.value,
        "components": sol.info.get("components"),
        "contended": sol.info.get("contended_components"),
        "largest": sol.info.get("largest_component"),
        "merged_blocks": sum(1 for b in sol.partition if len(b) > 1),
        "time": med,
        "peak_mib": peak,
        "ratio_map_gnn": med["MAP"] / med["GNN"],
        "time_min": low,
        "ratio_min": low["MAP"] / low["GNN"],
        "cpu": med_cpu,
        "ratio_cpu": med_cpu["MAP"] / max(med_cpu["GNN"], 1e-9),
        "rounds": {k: len(v) for k, v in times.items()},
        "load": os.getloadavg(),
    }


def measure_limited(q: int, rounds: int, stonesoup_max: int) -> dict[str, Any]:
    """:func:`measure` in a child process under an 8 GiB address-space limit."""
    code = (
        "import json, resource, sys\n"
        f"resource.setrlimit(resource.RLIMIT_AS, ({LIMIT_BYTES}, {LIMIT_BYTES}))\n"
        "from solvers_cmp.assignment_scale import measure\n"
        f"print(json.dumps(measure({q}, {rounds}, {stonesoup_max})))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    if out.returncode != 0:
        return {"q": q, "error": out.stderr.strip().splitlines()[-1:] or ["failed"]}
    res = json.loads(out.stdout.strip().splitlines()[-1])
    res["address_space_limit_gib"] = LIMIT_BYTES / 2**30
    return res


def table(rows: list[dict[str, Any]]) -> str:
    head = (
        "| Q | N | MAP s | GNN s | MAP/GNN | min-round ratio | CPU ratio | SS-GNN s | "
        "SS-JPDA s | MAP MiB | GNN MiB | components (contended, largest) | merged | load |"
    )
    lines = [head, "|" + "---|" * 14]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['q']} | failed: {r['error']} |")
            continue
        t, p = r["time"], r["peak_mib"]

        def f(k: str, t: dict[str, float] = t) -> str:
            return f"{t[k]:.4g}" if k in t else "—"

        lim = " (8 GiB AS)" if "address_space_limit_gib" in r else ""
        lines.append(
            f"| {r['q']}{lim} | {r['n']} | {f('MAP')} | {f('GNN')} | "
            f"{r['ratio_map_gnn']:.2f} | {r['ratio_min']:.2f} | "
            f"{r['ratio_cpu']:.2f} | {f('SS-GNN')} | "
            f"{f('SS-JPDA')} | "
            f"{p['MAP']:.1f} | {p['GNN']:.1f} | {r['components']} "
            f"({r['contended']}, {r['largest']}) | {r['merged_blocks']} | "
            f"{r['load'][0]:.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--q", type=int, nargs="+", default=[10, 30, 100, 300, 1000, 3000])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--stonesoup-max", type=int, default=100)
    ap.add_argument("--limit-from", type=int, default=3000)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rows = []
    for q in a.q:
        rows.append(
            measure_limited(q, a.rounds, a.stonesoup_max)
            if q >= a.limit_from
            else measure(q, a.rounds, a.stonesoup_max)
        )
        print(table(rows[-1:]).splitlines()[-1], flush=True)
    print(table(rows))
    if a.json:
        from optmodels.io import atomic_write

        with atomic_write(a.json, name="--json") as fh:
            fh.write(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
