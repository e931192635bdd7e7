"""Issue 24's country-scale network for the bias-field chain (:func:`run_country`): 40
radars over ~1000 × 1000 km with ranges 200-250 km (no area seen by more than a few),
10 000 aircraft over 24 h (``small``: 600 aircraft, 2 h), the recording read hour by hour,
FieldData over the union of coverage (``biasfield.pipeline``), the closed form (11),
``correct_plots``; with ``dask`` the chain is repeated on a ``distributed.LocalCluster``
and the largest difference of the two results reported.

The traffic is :mod:`solvers_cmp.biasfield_scale`'s (:func:`~solvers_cmp.biasfield_scale.
traffic`), and so are the memory figures (:func:`~solvers_cmp.biasfield_scale.peak_rss_mb`,
:class:`~solvers_cmp.biasfield_scale.RssTrace`). Run it as ``python -m
solvers_cmp.biasfield_scale --country [--small] [--dask] [--workers 2] [--json]`` (full
size: ``--country --dask --workers 2``).
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np

from optmodels.biasfield import BiasField, PlotTable, RadarSet
from solvers_cmp.biasfield_scale import RssTrace, peak_rss_mb, run_in_child, traffic

#: The country-scale network of issue 24: 40 radars over ~1000 × 1000 km, ranges 200-250 km
#: (no area is seen by more than a few), 10 000 aircraft over 24 h, read hour by hour.
COUNTRY_FULL = {"radars": 40, "aircraft": 10_000, "hours": 24.0, "cells": 8000}
COUNTRY_SMALL = {"radars": 40, "aircraft": 600, "hours": 2.0, "cells": 600}
COUNTRY_HALF = 500e3
COUNTRY_RANGE = (200e3, 250e3)


def country_network(seed: int, m: int) -> tuple[RadarSet, list[BiasField]]:
    """``m`` radars uniformly over ±500 km (none closer than 110 km to another), ranges
    uniform in 200-250 km, smooth fields (amplitude range 150 m, azimuth 0.3°, scale the
    radar's own coverage). Differs from a real network: flat plane (2-D chain), straight
    legs with uniform entry points (no airways), every scan detects."""
    rng = np.random.default_rng([seed, 2])
    sites: list[np.ndarray] = []
    while len(sites) < m:
        c = rng.uniform(-COUNTRY_HALF, COUNTRY_HALF, 2)
        if all(np.hypot(*(c - q)) > 110e3 for q in sites):
            sites.append(c)
    rngs = rng.uniform(*COUNTRY_RANGE, m)
    radars = RadarSet(
        np.array(sites), 50.0, np.deg2rad(0.08), rngs, names=tuple(f"R{i + 1}" for i in range(m))
    )
    fields = [
        BiasField.smooth(
            rng,
            center=np.array(sites[i]),
            scale=250e3,
            range_amplitude=150.0,
            azimuth_amplitude=np.deg2rad(0.3),
        )
        for i in range(m)
    ]
    return radars, fields


def _generate_hours(folder: str, seed: int, m: int, aircraft: int, hours: float) -> None:
    """Child process: the country network's plots, one .npz per hour of plot time (the
    recording as it arrives), so that the parent reads them hour by hour."""
    import os

    radars, fields = country_network(seed, m)
    p = traffic(seed, radars, fields, aircraft, hours, region=COUNTRY_HALF + 50e3)
    hour = np.floor(p.time / 3600.0).astype(np.int64)
    for h in np.unique(hour):
        sel = hour == h
        np.savez(
            os.path.join(folder, f"hour{int(h):03d}.npz"),
            time=p.time[sel],
            radar=p.radar[sel],
            range=p.range[sel],
            azimuth=p.azimuth[sel],
            object=p.object[sel],
        )


def _bar(items: Any, progress: bool, desc: str) -> Any:
    """tqdm on stderr, off without ``progress`` or when stderr is not a terminal."""
    from tqdm import tqdm

    return tqdm(
        items,
        desc=desc,
        file=sys.stderr,
        leave=False,
        disable=not (progress and sys.stderr.isatty()),
    )


def read_hours(seed: int, m: int, aircraft: int, hours: float, progress: bool) -> PlotTable:
    """Simulate in a spawned child (its memory stays out of the peak), then read the
    recording hour by hour and join the hours into one plot table."""
    import os
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        run_in_child(_generate_hours, (tmp, seed, m, aircraft, hours))
        parts: list[list[np.ndarray]] = [[] for _ in range(5)]
        for name in _bar(sorted(os.listdir(tmp)), progress, "reading hours"):
            with np.load(os.path.join(tmp, name)) as z:
                for c, key in zip(
                    parts, ("time", "radar", "range", "azimuth", "object"), strict=True
                ):
                    c.append(z[key])
    cols = [np.concatenate(c) for c in parts]
    return PlotTable(cols[0], cols[1].astype(np.int64), cols[2], cols[3], cols[4].astype(np.int64))


def _chain(
    plots: PlotTable, radars: RadarSet, cells: int, scheduler: Any, progress: bool, seed: int
) -> tuple[Any, Any, Any, dict[str, float]]:
    """FieldData (the pipeline, union coverage), closed form (11), corrected plots;
    seconds per step."""
    from optmodels.biasfield import closed_form, correct_plots, field_data_from_plots

    sec: dict[str, float] = {}
    t = time.perf_counter()
    build = field_data_from_plots(
        plots,
        radars,
        cells=cells,
        coverage="union",
        clean=True,
        scheduler=scheduler,
        progress=progress,
        seed=seed,
    )
    sec["field_data_s"] = time.perf_counter() - t
    sec.update({f"field_data.{k}_s": round(v, 2) for k, v in build.timings.items()})
    sec.update(
        {f"field_data.build.{k}_s": round(v, 2) for k, v in build.diagnostics.timings.items()}
    )
    t = time.perf_counter()
    sol = closed_form(build.data)
    sec["solve_s"] = time.perf_counter() - t
    t = time.perf_counter()
    cor = correct_plots(build.plots, radars, sol.map()) if sol.status.ok else None
    sec["correct_s"] = time.perf_counter() - t
    return build, sol, cor, sec


def run_country(
    *,
    small: bool = True,
    aircraft: int | None = None,
    hours: float | None = None,
    cells: int | None = None,
    seed: int = 0,
    workers: int = 2,
    dask: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Issue 24's country-scale chain: read hour by hour, FieldData over the union of
    coverage, solve, correct; locally (``processes`` scheduler, ``workers``) and, with
    ``dask``, again on a ``distributed.LocalCluster`` of ``workers`` single-threaded
    processes, with the largest difference of the two fields (they must be equal)."""
    from optmodels.biasfield import registration_error, seen_by_others

    cfg = dict(COUNTRY_SMALL if small else COUNTRY_FULL)
    for key, val in (("aircraft", aircraft), ("hours", hours), ("cells", cells)):
        if val is not None:
            cfg[key] = val
    res: dict[str, Any] = {"config": cfg, "workers": workers}
    trace = RssTrace()
    t0 = time.perf_counter()
    radars, _ = country_network(seed, int(cfg["radars"]))
    plots = read_hours(
        seed, int(cfg["radars"]), int(cfg["aircraft"]), float(cfg["hours"]), progress
    )
    res["plots"] = len(plots)
    res["read_s"] = time.perf_counter() - t0
    build, sol, cor, sec = _chain(plots, radars, int(cfg["cells"]), "processes", progress, seed)
    res.update(sec)
    fd = build.data
    seen = fd.subsets
    res["cells"] = fd.k
    res["radars_per_cell"] = {
        str(c): int(v) for c, v in enumerate(np.bincount(seen.sum(axis=1))) if v
    }
    res["status"] = sol.status.value
    res["components"] = sol.info.get("components")
    if cor is not None:
        two = seen_by_others(build.plots)
        res["corrected_share_of_multi_radar_plots"] = float(cor.covered[two].mean())
        res["reasons"] = {
            str(r): int(n) for r, n in zip(*np.unique(cor.reason, return_counts=True), strict=True)
        }
        t = time.perf_counter()
        sub = build.plots.object % 10 == 0  # registration on a tenth of the aircraft
        wide = RadarSet(
            radars.sites,
            radars.sigma_range,
            radars.sigma_azimuth,
            radars.max_range + 5e3,
            radars.names,
        )
        before = registration_error(build.plots.subset(sub), wide)
        after = registration_error(cor.plots.subset(sub), wide)
        res["registration_m"] = {
            "before": before.overall,
            "after": after.overall,
            "noise": after.noise,
        }
        res["registration_s"] = time.perf_counter() - t
    res["total_local_s"] = time.perf_counter() - t0
    res["peak_rss_mb"], res["peak_rss_children_mb"] = peak_rss_mb()
    res["rss_trace_peak"] = trace.stop()
    clock, ends = 0.0, {}
    for key in ("read_s", "field_data_s", "solve_s", "correct_s", "registration_s"):
        if key in res:
            clock += res[key]
            ends[key.removesuffix("_s")] = clock
    res["rss_max_per_stage_mb"] = trace.per_stage(ends)  # this process, sampled every 0.1 s
    # the local figures before the Dask pass (a long run stopped there keeps them)
    print(f"local: {json.dumps(res)}", file=sys.stderr, flush=True)
    if dask:
        from distributed import Client, LocalCluster

        t = time.perf_counter()
        with (
            LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            res["dask_start_s"] = time.perf_counter() - t
            b2, s2, _, sec2 = _chain(plots, radars, int(cfg["cells"]), client, progress, seed)
        res["dask"] = sec2
        res["dask_total_s"] = time.perf_counter() - t
        res["dask_equal"] = {
            "cells": b2.data.k == fd.k,
            "max_abs_xi_diff_m": float(np.max(np.abs(b2.data.xi - fd.xi))),
            "max_abs_field_diff": [
                float(np.max(np.abs(s2.field[..., c] - sol.field[..., c]))) for c in (0, 1)
            ],
        }
    return res
