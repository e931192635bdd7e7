r"""Track-level evaluation of the MAP joint assignment with unresolved groups (paper 004,
issue 18 item 5): full tracking runs on crossing / parallel encounters
(:mod:`optmodels.scenarios.encounters`) with four associators in the same Stone Soup
Kalman tracker (constant velocity, the same initial tracks, per-measurement noise):

* ``MAP+merges``: :class:`optmodels.assignment.stonesoup.MergedMeasurementAssociator`
  (the sensor's resolution model when optmodels has one, else the constant ρ);
* ``resolved``: the same MAP with merges disallowed (``merges=False``);
* ``GNN``: Stone Soup ``GNNWith2DAssignment`` (Mahalanobis ``DistanceHypothesiser``);
* ``JPDA``: Stone Soup ``JPDA`` (``PDAHypothesiser``; posterior = Gaussian-mixture
  reduction);
* ``JPDA5``: the same JPDA with GNN's 5σ gate (prob_gate = P(χ²_2 ≤ 25)), to separate
  the gate's effect from the merged hypotheses';
* ``soft`` (issue 29, :func:`traffic_study` and on request): :class:`optmodels.assignment.
  stonesoup_soft.SoftMergedAssociator` (JPDA over the joint hypotheses with merges, the
  sensor's resolution model, GNN's 5σ gate: prob_gate = P(χ²_2 ≤ 25)).

Issue 29's encounters that look like real traffic (:func:`optmodels.scenarios.encounters.
traffic_encounter`: fast crossings with 1-3 merged scans, slow formations, long merges;
49 scans) are run by :func:`traffic_study`, reported per kind and together
(:func:`summarise_traffic`, the done-when :func:`done_when_traffic`); the per-scan cost of
the soft associator against Stone Soup's JPDA on the same scans is :func:`benchmark`.

The metrics of a run (GOSPA, track swaps and breaks) are :mod:`solvers_cmp.tracking_metrics`'s;
the command line below is :mod:`solvers_cmp.assignment_tracking_cli`'s.

Usage::

    .venv/bin/python -m solvers_cmp.assignment_tracking [--runs 20] [--q 2]
        [--kind crossing] [--ratios 0.25 0.5 0.75 1.5 2 3]
    .venv/bin/python -m solvers_cmp.assignment_tracking --traffic --runs 12 [--seed 2029]
    .venv/bin/python -m solvers_cmp.assignment_tracking --bench 3
"""

from __future__ import annotations

import dataclasses
import time
from datetime import timedelta
from typing import Any

import numpy as np

from optmodels.scenarios.encounters import (
    TRAFFIC_KINDS,
    Encounter,
    RadarCell,
    encounter,
    traffic_encounter,
)
from solvers_cmp.tracking_metrics import T0, gospa_per_scan, swaps_and_breaks

METHODS = ("MAP+merges", "resolved", "GNN", "JPDA")
#: Every method, the soft associator of issue 29 included.
ALL_METHODS = (*METHODS, "JPDA5", "soft")
#: The soft mixture methods (the tracker reduces a MultipleHypothesis per track).
MIXTURE = ("JPDA", "JPDA5", "soft")
RATIOS = (0.25, 0.5, 0.75, 1.5, 2.0, 3.0)


def resolution_model(sensor: RadarCell) -> Any:
    """The optmodels sensor model of ``sensor`` (``optmodels.assignment.sensor.Resolution``
    with the polar cell), or None when this optmodels has none (then ρ is used)."""
    try:
        from optmodels.assignment.sensor import Resolution  # type: ignore[import-not-found]
    except ImportError:
        return None
    return Resolution(
        range=sensor.range_res,
        azimuth=sensor.azimuth_res,
        site=np.asarray(sensor.site, dtype=float),
    )


def _components(accel: float) -> dict[str, Any]:
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.updater.kalman import KalmanUpdater

    trans = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(accel), ConstantVelocity(accel)]
    )
    default = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.eye(2) * 100.0)
    return {
        "predictor": KalmanPredictor(trans),
        "updater": KalmanUpdater(default),
        "LinearGaussian": LinearGaussian,
    }


def associator(
    method: str,
    enc: Encounter,
    comps: dict[str, Any],
    *,
    gate: float = 5.0,
    rho: float = 0.3,
    use_resolution: bool = True,
    cell_information: bool = True,
) -> Any:
    """The Stone Soup associator of ``method`` for the encounter's sensor."""
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.measures import Mahalanobis

    from optmodels.assignment.stonesoup import MergedMeasurementAssociator

    pred, upd = comps["predictor"], comps["updater"]
    lam, pd = enc.sensor.clutter_density, enc.sensor.pd
    if method == "GNN":
        return GNNWith2DAssignment(
            DistanceHypothesiser(pred, upd, measure=Mahalanobis(), missed_distance=gate)
        )
    pda = PDAHypothesiser(pred, upd, clutter_spatial_density=lam, prob_detect=pd)
    if method == "JPDA":
        return JPDA(pda)
    if method == "JPDA5":  # Stone Soup's JPDA with GNN's 5σ gate (the soft one's)
        from scipy.stats import chi2

        return JPDA(
            PDAHypothesiser(
                pred,
                upd,
                clutter_spatial_density=lam,
                prob_detect=pd,
                prob_gate=float(chi2.cdf(gate**2, 2)),
            )
        )
    if method == "soft":
        from scipy.stats import chi2

        from optmodels.assignment.stonesoup_soft import SoftMergedAssociator

        wide = PDAHypothesiser(
            pred,
            upd,
            clutter_spatial_density=lam,
            prob_detect=pd,
            prob_gate=float(chi2.cdf(gate**2, 2)),
        )
        res = resolution_model(enc.sensor) if use_resolution else None
        return SoftMergedAssociator(
            wide, resolution=res, rho=rho, cell_information=cell_information
        )
    if method in ("MAP+merges", "resolved"):
        res = resolution_model(enc.sensor) if use_resolution else None
        return MergedMeasurementAssociator(
            pda,
            merges=method == "MAP+merges",
            resolution=res if method == "MAP+merges" else None,
            rho=rho,
            cell_information=cell_information,
        )
    raise ValueError(f"method: expected one of {ALL_METHODS}, got {method!r}")


def run_tracking(
    enc: Encounter,
    method: str,
    *,
    accel: float = 1.0,
    gate: float = 5.0,
    rho: float = 0.3,
    use_resolution: bool = True,
    cell_information: bool = True,
    log: list[Any] | None = None,
) -> list[Any]:
    """One tracking run: Stone Soup tracks (one per object, started at ``enc.initial``)
    updated scan by scan with ``method``'s associator. The loop is Stone Soup's
    ``MultiTargetTracker`` step without initiation/deletion (the number of objects is
    known), plus the mixture reduction for JPDA. ``log`` (not JPDA) receives per scan the
    tracks (object indices) each measurement updated, in ``scan.measurements`` order."""
    from stonesoup.functions import gm_reduce_single
    from stonesoup.types.array import StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate

    comps = _components(accel)
    upd, lg = comps["updater"], comps["LinearGaussian"]
    assoc = associator(
        method,
        enc,
        comps,
        gate=gate,
        rho=rho,
        use_resolution=use_resolution,
        cell_information=cell_information,
    )
    tracks = [
        Track(
            [
                GaussianState(
                    enc.initial[j].reshape(-1, 1),
                    enc.initial_covar,
                    timestamp=T0 + timedelta(seconds=float(enc.times[0])),
                )
            ]
        )
        for j in range(enc.q)
    ]
    for s in enc.scans:
        when = T0 + timedelta(seconds=s.time)
        dets = [
            Detection(
                z.reshape(-1, 1),
                timestamp=when,
                measurement_model=lg(ndim_state=4, mapping=(0, 2), noise_covar=r),
            )
            for z, r in zip(s.measurements, s.covs, strict=True)
        ]
        hyps = assoc.associate(set(tracks), set(dets), when)
        if log is not None and method not in MIXTURE:
            index = {id(d): i for i, d in enumerate(dets)}
            claimed: dict[int, list[int]] = {}
            for j, tr in enumerate(tracks):
                if hyps[tr]:
                    src = getattr(hyps[tr].measurement, "merged_from", hyps[tr].measurement)
                    claimed.setdefault(index[id(src)], []).append(j)
            log.append([tuple(sorted(claimed.get(i, ()))) for i in range(len(dets))])
        for tr in tracks:
            h = hyps[tr]
            if method not in MIXTURE:
                tr.append(upd.update(h) if h else h.prediction)
                continue
            states = [upd.update(hh) if hh else hh.prediction for hh in h]
            weights = np.array([float(hh.probability) for hh in h])
            mean, cov = gm_reduce_single(
                StateVectors([st.state_vector for st in states]),
                np.stack([st.covar for st in states], axis=2),
                weights,
            )
            tr.append(GaussianStateUpdate(mean, cov, h, when))
    return tracks


def mean_gospa(enc: Encounter, tracks: list[Any], *, c: float = 500.0, p: float = 2.0) -> float:
    """Mean over the scans of Stone Soup's GOSPA distance (positions, m)."""
    return float(np.mean(gospa_per_scan(enc, tracks, c=c, p=p)))


@dataclasses.dataclass
class RunResult:
    method: str
    ratio: float
    seed: int
    gospa: float
    swaps: int
    breaks: int
    merged_scans: int
    seconds: float


def study(
    *,
    ratios: tuple[float, ...] = RATIOS,
    runs: int = 20,
    q: int = 2,
    kind: str = "crossing",
    seed: int = 2026,
    methods: tuple[str, ...] = METHODS,
    sensor: RadarCell | None = None,
    c: float = 500.0,
    use_resolution: bool = True,
    scans: int = 24,
    half_angle_deg: float = 5.0,
    cell_information: bool = True,
) -> list[RunResult]:
    """Every method on the same seeded encounters: ``runs`` per ratio separation/range_res,
    encounter r of ratio x from ``default_rng([seed, round(1000 x), r])`` (``scans``
    scans 5 s apart, crossing half-angle ``half_angle_deg``; the rest
    :func:`optmodels.scenarios.encounters.encounter`'s defaults)."""
    sensor = RadarCell() if sensor is None else sensor
    out: list[RunResult] = []
    for x in ratios:
        for r in range(runs):
            enc = encounter(
                np.random.default_rng([seed, round(1000 * x), r]),
                kind=kind,
                q=q,
                separation=x * sensor.range_res,
                sensor=sensor,
                scans=scans,
                half_angle_deg=half_angle_deg,
            )
            for m in methods:
                t0 = time.perf_counter()
                tracks = run_tracking(
                    enc, m, use_resolution=use_resolution, cell_information=cell_information
                )
                sw, br = swaps_and_breaks(enc, tracks, c=c)
                out.append(
                    RunResult(
                        m,
                        x,
                        r,
                        mean_gospa(enc, tracks, c=c),
                        sw,
                        br,
                        enc.merged_scans,
                        time.perf_counter() - t0,
                    )
                )
    return out


def summarise(results: list[RunResult]) -> list[dict[str, Any]]:
    """One row per (ratio, method): mean GOSPA ± its standard error, swaps, breaks (sums
    and per run), merged scans per run, seconds per run."""
    rows = []
    for x in sorted({r.ratio for r in results}):
        for m in dict.fromkeys(r.method for r in results):
            sel = [r for r in results if r.ratio == x and r.method == m]
            g = np.array([r.gospa for r in sel])
            rows.append(
                {
                    "ratio": x,
                    "method": m,
                    "runs": len(sel),
                    "gospa": float(g.mean()),
                    "gospa_se": float(g.std(ddof=1) / np.sqrt(len(g)))
                    if len(g) > 1
                    else float("nan"),
                    "swaps": int(sum(r.swaps for r in sel)),
                    "breaks": int(sum(r.breaks for r in sel)),
                    "merged_scans": float(np.mean([r.merged_scans for r in sel])),
                    "s_per_run": float(np.median([r.seconds for r in sel])),
                }
            )
    return rows


def done_when(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Issue 18's done-when on ``rows``: below the resolution (ratio < 1) MAP+merges has
    the lowest mean GOSPA of the four and no more swaps than any; at ratio ≥ 2 its mean
    GOSPA is within 2 % of GNN's."""
    by = {(r["ratio"], r["method"]): r for r in rows}
    below, above = [], []
    for x in sorted({r["ratio"] for r in rows}):
        mp = by.get((x, "MAP+merges"))
        if mp is None:
            continue
        others = [by[(x, m)] for m in METHODS[1:] if (x, m) in by]
        if x < 1:
            below.append(
                {
                    "ratio": x,
                    "lowest_gospa": all(mp["gospa"] < o["gospa"] for o in others),
                    "no_more_swaps": all(mp["swaps"] <= o["swaps"] for o in others),
                }
            )
        if x >= 2 and (x, "GNN") in by:
            g = by[(x, "GNN")]["gospa"]
            above.append({"ratio": x, "rel_diff_vs_gnn": (mp["gospa"] - g) / g})
    return {"below": below, "above": above}


# ----------------------------------------------------------------------------- issue 29
@dataclasses.dataclass
class TrafficResult:
    method: str
    kind: str
    seed: int
    gospa: float
    gospa_merged: float
    swaps: int
    breaks: int
    merged_scans: int
    seconds: float


def traffic_encounters(
    kinds: tuple[str, ...] = TRAFFIC_KINDS, runs: int = 8, seed: int = 2029
) -> list[Encounter]:
    """The encounter set: ``runs`` per kind, encounter r of kind k from
    ``default_rng([seed, k, r])`` (:func:`~optmodels.scenarios.encounters.
    traffic_encounter`, 49 scans 5 s apart)."""
    return [
        traffic_encounter(np.random.default_rng([seed, TRAFFIC_KINDS.index(k), r]), k)
        for k in kinds
        for r in range(runs)
    ]


def traffic_study(
    *,
    kinds: tuple[str, ...] = TRAFFIC_KINDS,
    runs: int = 8,
    seed: int = 2029,
    methods: tuple[str, ...] = ("MAP+merges", "GNN", "JPDA", "JPDA5", "soft"),
    c: float = 500.0,
) -> list[TrafficResult]:
    """Every method on the same traffic encounters (:func:`traffic_encounters`): mean
    GOSPA over all scans and over the scans with a merged return, swaps, breaks."""
    out = []
    for idx, enc in enumerate(traffic_encounters(kinds, runs, seed)):
        merged = [t for t, s in enumerate(enc.scans) if any(len(g) > 1 for g in s.groups)]
        for m in methods:
            t0 = time.perf_counter()
            tracks = run_tracking(enc, m)
            per = gospa_per_scan(enc, tracks, c=c)
            sw, br = swaps_and_breaks(enc, tracks, c=c)
            out.append(
                TrafficResult(
                    m,
                    enc.kind,
                    idx % runs,
                    float(np.mean(per)),
                    float(np.mean([per[t] for t in merged])) if merged else float("nan"),
                    sw,
                    br,
                    enc.merged_scans,
                    time.perf_counter() - t0,
                )
            )
    return out


def summarise_traffic(results: list[TrafficResult]) -> list[dict[str, Any]]:
    """One row per (kind, method) and per ("all", method): mean GOSPA ± standard error,
    mean GOSPA on the merged scans, swaps and breaks (sums), merged scans per run."""
    rows = []
    for kind in [*dict.fromkeys(r.kind for r in results), "all"]:
        for m in dict.fromkeys(r.method for r in results):
            sel = [r for r in results if r.method == m and kind in (r.kind, "all")]
            g = np.array([r.gospa for r in sel])
            gm = np.array([r.gospa_merged for r in sel if np.isfinite(r.gospa_merged)])
            rows.append(
                {
                    "kind": kind,
                    "method": m,
                    "runs": len(sel),
                    "gospa": float(g.mean()),
                    "gospa_se": float(g.std(ddof=1) / np.sqrt(len(g)))
                    if len(g) > 1
                    else float("nan"),
                    "gospa_merged": float(gm.mean()) if len(gm) else float("nan"),
                    "swaps": int(sum(r.swaps for r in sel)),
                    "breaks": int(sum(r.breaks for r in sel)),
                    "merged_scans": float(np.mean([r.merged_scans for r in sel])),
                    "s_per_run": float(np.median([r.seconds for r in sel])),
                }
            )
    return rows


def done_when_traffic(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Issue 29's done-when: on the fast crossings the soft associator's mean GOSPA
    ≤ 0.95 × JPDA's with no more swaps; on the long merges within 5 % of the MAP's."""
    by = {(r["kind"], r["method"]): r for r in rows}
    out: dict[str, Any] = {}
    if ("fast_crossing", "soft") in by and ("fast_crossing", "JPDA") in by:
        s, j = by[("fast_crossing", "soft")], by[("fast_crossing", "JPDA")]
        out["fast_crossing"] = {
            "ratio_vs_jpda": s["gospa"] / j["gospa"],
            "target": 0.95,
            "ok": s["gospa"] <= 0.95 * j["gospa"] and s["swaps"] <= j["swaps"],
            "swaps": (s["swaps"], j["swaps"]),
        }
    if ("long_merge", "soft") in by and ("long_merge", "MAP+merges") in by:
        s, mp = by[("long_merge", "soft")], by[("long_merge", "MAP+merges")]
        out["long_merge"] = {
            "ratio_vs_map": s["gospa"] / mp["gospa"],
            "target": 1.05,
            "ok": s["gospa"] <= 1.05 * mp["gospa"],
        }
    return out


def benchmark(encs: list[Encounter], *, rounds: int = 3) -> dict[str, Any]:
    """Per-scan cost of the soft associator against Stone Soup's JPDA on the same scans:
    the soft tracker's run, and at every scan both associators called on the same tracks
    and detections, ``rounds`` times, interleaved (the order alternating); medians over
    the rounds, then over the scans. Returns the median seconds per scan of each and the
    median and 90th percentile of the per-scan ratio soft/JPDA."""
    from stonesoup.functions import gm_reduce_single
    from stonesoup.types.array import StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate

    t_soft, t_jpda = [], []
    for enc in encs:
        comps = _components(1.0)
        upd, lg = comps["updater"], comps["LinearGaussian"]
        soft, jpda = associator("soft", enc, comps), associator("JPDA", enc, comps)
        tracks = [
            Track([GaussianState(enc.initial[j].reshape(-1, 1), enc.initial_covar, timestamp=T0)])
            for j in range(enc.q)
        ]
        for s in enc.scans:
            when = T0 + timedelta(seconds=s.time)
            dets = {
                Detection(
                    z.reshape(-1, 1),
                    timestamp=when,
                    measurement_model=lg(ndim_state=4, mapping=(0, 2), noise_covar=r),
                )
                for z, r in zip(s.measurements, s.covs, strict=True)
            }
            a, b = [], []
            hyps = None
            for k in range(rounds):
                for which in (0, 1) if k % 2 == 0 else (1, 0):
                    t0 = time.perf_counter()
                    if which == 0:
                        hyps = soft.associate(set(tracks), dets, when)
                        a.append(time.perf_counter() - t0)
                    else:
                        jpda.associate(set(tracks), dets, when)
                        b.append(time.perf_counter() - t0)
            t_soft.append(float(np.median(a)))
            t_jpda.append(float(np.median(b)))
            assert hyps is not None
            for tr in tracks:
                h = hyps[tr]
                states = [upd.update(hh) if hh else hh.prediction for hh in h]
                w = np.array([float(hh.probability) for hh in h])
                mean, cov = gm_reduce_single(
                    StateVectors([x.state_vector for x in states]),
                    np.stack([x.covar for x in states], axis=2),
                    w,
                )
                tr.append(GaussianStateUpdate(mean, cov, h, when))
    ratio = np.array(t_soft) / np.array(t_jpda)
    return {
        "scans": len(t_soft),
        "soft_s": float(np.median(t_soft)),
        "jpda_s": float(np.median(t_jpda)),
        "ratio_of_medians": float(np.median(t_soft) / np.median(t_jpda)),
        "median_ratio": float(np.median(ratio)),
        "p90_ratio": float(np.percentile(ratio, 90)),
        "rounds": rounds,
    }


if __name__ == "__main__":  # the study's command line (module docstring, "Usage")
    from solvers_cmp.assignment_tracking_cli import main

    main()
