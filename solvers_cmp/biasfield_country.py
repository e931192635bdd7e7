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
from solvers_cmp.biasfield_scale import RssTrace, peak_rss_mb, run_in_child, traffic, trim_heap

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


def read_hours(folder: str, progress: bool) -> PlotTable:
    """Read the recording hour by hour (the ``hour*.npz`` files of ``folder``) and join
    the hours into one plot table, column by column (each column's hourly pieces freed
    once joined: the peak is the table and one column's pieces, not two tables)."""
    import os

    names = sorted(n for n in os.listdir(folder) if n.startswith("hour") and n.endswith(".npz"))
    keys = ("time", "radar", "range", "azimuth", "object")
    parts: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for name in _bar(names, progress, "reading hours"):
        with np.load(os.path.join(folder, name)) as z:
            for k in keys:
                parts[k].append(z[k])
    cols = {}
    for k in keys:
        cols[k] = np.concatenate(parts.pop(k))
    return PlotTable(cols["time"], cols["radar"], cols["range"], cols["azimuth"], cols["object"])


def _chain(
    read: Any,
    radars: RadarSet,
    cells: int,
    scheduler: Any,
    progress: bool,
    seed: int,
    trace: RssTrace,
    prefix: str = "",
) -> tuple[Any, PlotTable, Any, Any, dict[str, Any]]:
    """Read (``read(prefix, sec)``: the table; its seconds in ``sec["read_s"]``), FieldData
    (the pipeline, union coverage), closed form (11), corrected plots; seconds per step
    (``trace`` marks each step's end, its name after ``prefix``). Returns the
    FieldData, the plots it used (after cleaning), the solution, the corrected plots and
    the figures. The pipeline's diagnostics (the track fits, ~70 B a plot: 2.2 GB at
    3.2·10⁷ plots) are dropped once FieldData is built: nothing downstream reads them."""
    from optmodels.biasfield import closed_form, correct_plots, field_data_from_plots

    sec: dict[str, Any] = {}
    t = time.perf_counter()
    # the table goes straight into the pipeline: no reference to the table as read is kept
    # here, so that a cleaning that drops plots leaves only the cleaned table alive
    build = field_data_from_plots(
        read(prefix, sec),
        radars,
        cells=cells,
        coverage="union",
        clean=True,
        scheduler=scheduler,
        progress=progress,
        seed=seed,
    )
    sec["field_data_s"] = time.perf_counter() - t - sec["read_s"]
    sec.update({f"field_data.{k}_s": round(v, 2) for k, v in build.timings.items()})
    sec.update(
        {f"field_data.build.{k}_s": round(v, 2) for k, v in build.diagnostics.timings.items()}
    )
    sec["dropped_plots"] = dict(build.dropped)
    sec["rss_max_per_field_data_stage_mb"] = _field_data_stages(trace, build)
    fd, plots = build.data, build.plots
    del build  # the fits (freed in millions of small arrays: their heap given back)
    trim_heap()
    trace.mark(f"{prefix}field_data")
    t = time.perf_counter()
    sol = closed_form(fd)
    sec["solve_s"] = time.perf_counter() - t
    trace.mark(f"{prefix}solve")
    t = time.perf_counter()
    cor = correct_plots(plots, radars, sol.map()) if sol.status.ok else None
    sec["correct_s"] = time.perf_counter() - t
    trace.mark(f"{prefix}correct")
    return fd, plots, sol, cor, sec


def _field_data_stages(trace: RssTrace, build: Any) -> dict[str, float]:
    """The largest sampled RSS (MB) of this process in each stage of the pipeline (from
    its seconds, the stages following the read's mark): cleaning, positions, track fits,
    samples, centres, averaging (and the FieldData's assembly, ``rest``)."""
    start = trace.marks[-1][1]
    ends: dict[str, float] = {}
    clock = start
    for key in ("locate", "clean", "positions"):
        clock += build.timings.get(key, 0.0)
        ends[key] = clock
    for key, sec in build.diagnostics.timings.items():
        clock += sec
        ends[key] = clock
    ends["rest"] = trace.now()
    return trace.per_stage(ends, start=start)


def _check(plots: PlotTable, cor: Any, radars: RadarSet) -> dict[str, Any]:
    """The figures of the corrected plots: the share of the plots seen by two radars or
    more that were corrected, the reasons, the registration error (on a tenth of the
    aircraft) before and after."""
    from optmodels.biasfield import RadarSet, registration_error, seen_by_others
    from optmodels.biasfield.usage import REASONS

    res: dict[str, Any] = {}
    res["corrected_share_of_multi_radar_plots"] = float(cor.covered[seen_by_others(plots)].mean())
    res["reasons"] = {r: int(np.count_nonzero(cor.reason == r)) for r in REASONS}
    t = time.perf_counter()
    sub = plots.object % 10 == 0  # registration on a tenth of the aircraft
    wide = RadarSet(
        radars.sites,
        radars.sigma_range,
        radars.sigma_azimuth,
        radars.max_range + 5e3,
        radars.names,
    )
    before = registration_error(plots.subset(sub), wide)
    after = registration_error(cor.plots.subset(sub), wide)
    res["registration_m"] = {"before": before.overall, "after": after.overall, "noise": after.noise}
    res["registration_s"] = time.perf_counter() - t
    return res


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
    processes (the recording read again from its hourly files), with the largest
    difference of the two fields (they must be equal).

    Memory (sampled every 0.1 s): ``rss_max_per_stage_mb`` is this process's largest
    resident set per stage, ``rss_tree_max_per_stage_mb`` with its descendants (the
    traffic generator, the fit workers, the Dask cluster), ``rss_children_max_mb`` the
    descendants' largest sum, ``rss_max_per_field_data_stage_mb`` this process's per
    stage of the pipeline."""
    import tempfile

    cfg = dict(COUNTRY_SMALL if small else COUNTRY_FULL)
    for key, val in (("aircraft", aircraft), ("hours", hours), ("cells", cells)):
        if val is not None:
            cfg[key] = val
    res: dict[str, Any] = {"config": cfg, "workers": workers}
    m = int(cfg["radars"])
    radars, _ = country_network(seed, m)
    with tempfile.TemporaryDirectory() as folder:
        # the recording, one file per hour, simulated in a spawned child (its memory stays
        # out of this process's peak); read hour by hour by each pass of the chain
        trace = RssTrace()
        t0 = time.perf_counter()
        run_in_child(_generate_hours, (folder, seed, m, int(cfg["aircraft"]), float(cfg["hours"])))
        res["simulate_s"] = time.perf_counter() - t0
        trace.mark("simulate")
        t0 = time.perf_counter()

        def read(prefix: str, sec: dict[str, Any]) -> PlotTable:
            t = time.perf_counter()
            plots = read_hours(folder, progress)
            sec["read_s"] = time.perf_counter() - t
            sec["plots"] = len(plots)
            trace.mark(f"{prefix}read")
            return plots

        fd, plots, sol, cor, sec = _chain(
            read, radars, int(cfg["cells"]), "processes", progress, seed, trace
        )
        res.update(sec)
        res["cells"] = fd.k
        res["radars_per_cell"] = {
            str(c): int(v) for c, v in enumerate(np.bincount(fd.subsets.sum(axis=1))) if v
        }
        res["status"] = sol.status.value
        res["components"] = sol.info.get("components")
        if cor is not None:
            res.update(_check(plots, cor, radars))
            trace.mark("registration")
        res["total_local_s"] = time.perf_counter() - t0
        # the children's largest sampled resident set (getrusage's figure for the children
        # is no measure here: a child forked late inherits this process's peak at the fork)
        res["peak_rss_mb"] = peak_rss_mb()[0]
        res["rss_children_max_mb"] = trace.children_max()
        res["rss_max_per_stage_mb"] = trace.stages()
        res["rss_tree_max_per_stage_mb"] = trace.stages(tree=True)
        # the local figures before the Dask pass (a long run stopped there keeps them)
        print(f"local: {json.dumps(res)}", file=sys.stderr, flush=True)
        if dask:
            xi, field, k = fd.xi, sol.field, fd.k
            del fd, plots, sol, cor  # the Dask pass reads the recording again
            trim_heap()
            res.update(_dask_pass(read, radars, cfg, workers, progress, seed, trace, xi, field, k))
            res["rss_max_per_stage_mb"] = trace.stages()
            res["rss_tree_max_per_stage_mb"] = trace.stages(tree=True)
            res["rss_children_max_mb"] = trace.children_max()
        res["rss_trace_peak"] = trace.stop()
    return res


def _dask_pass(
    read: Any,
    radars: RadarSet,
    cfg: dict[str, Any],
    workers: int,
    progress: bool,
    seed: int,
    trace: RssTrace,
    xi: np.ndarray,
    field: np.ndarray,
    k: int,
) -> dict[str, Any]:
    """The chain again on a ``distributed.LocalCluster``; its seconds and the largest
    differences from the local pass's ``xi`` and ``field`` (``k`` cells)."""
    from distributed import Client, LocalCluster

    res: dict[str, Any] = {}
    t = time.perf_counter()
    with (
        LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        res["dask_start_s"] = time.perf_counter() - t
        trace.mark("dask.start")
        fd2, _, s2, _, sec2 = _chain(
            read, radars, int(cfg["cells"]), client, progress, seed, trace, "dask."
        )
    res["dask"] = sec2
    res["dask_total_s"] = time.perf_counter() - t
    res["dask_equal"] = {
        "cells": fd2.k == k,
        "max_abs_xi_diff_m": float(np.max(np.abs(fd2.xi - xi))),
        "max_abs_field_diff": [
            float(np.max(np.abs(s2.field[..., c] - field[..., c]))) for c in (0, 1)
        ],
    }
    return res
