"""National-network scale of the bias-field chain (issue 16, item 4): 20 radars, 5000
aircraft, one day → FieldData with K ≈ 10⁴ cells, timed stage by stage with the peak
memory (``resource.getrusage``: the peak resident set of this process and, separately,
of its finished children, the fit workers).

The traffic is generated here, vectorised (the package's simulator loops per aircraft and
radar in Python): straight legs across the region at 150-250 m/s, one plot per scan of
each radar (period 8-12 s, a random phase per radar and aircraft), the true polar
position plus a smooth bias field plus Gaussian noise (σ_r 50 m, σ_az 0.08°). Every
radar must see a cell for the averaging (6)-(7) of paper 001, so the 20 sites lie within
±150 km and the long-range radars reach 460 km (250 NM); the traffic flies within
±200 km. This is the 2-D chain; :func:`plot_cost_3d` measures what the exact 3-D
conversion adds per plot.

``python -m solvers_cmp.biasfield_scale [--small] [--scheduler serial|processes]
[--workers N] [--aircraft N] [--hours H]`` prints the figures (JSON on the last line).

Issue 24's country-scale network, ``--country [--small] [--dask] [--workers 2] [--json]``,
is :func:`solvers_cmp.biasfield_country.run_country` (40 radars over ~1000 × 1000 km,
the recording read hour by hour, FieldData over the union of coverage, solve, correct).
"""

from __future__ import annotations

import argparse
import gc
import json
import resource
import sys
import time
import warnings
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from optmodels.biasfield import (
    BiasField,
    PlotTable,
    RadarSet,
    build_field_data,
    clean_plots,
    fit_tracks,
    to_polar,
    wrap_angle,
)

#: The full benchmark and its quick variant (``--small``).
FULL = {"radars": 20, "aircraft": 5000, "hours": 24.0, "cells": 10_000}
SMALL = {"radars": 20, "aircraft": 200, "hours": 1.0, "cells": 400}

SITE_HALF = 150e3
REGION = 200e3
MAX_RANGE = 460e3


def peak_rss_mb() -> tuple[float, float]:
    """Peak resident set (MB) of this process and of its finished children (Linux KiB)."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return own, kids


class RssTrace:
    """The resident set sampled every ``period`` s in a thread (``/proc``): this process
    and (``tree``) this process plus its descendants (fit workers, a Dask cluster's
    processes; a sum of resident sets, shared library pages counted in each). :meth:`stop`
    says when the peak was reached (seconds since the start), :meth:`mark` ends a stage
    and :meth:`stages` gives each marked stage's largest sample."""

    def __init__(self, period: float = 0.1) -> None:
        import os
        import threading

        self.samples: list[tuple[float, float]] = []
        self.tree: list[float] = []
        self.marks: list[tuple[str, float]] = []
        self._page = os.sysconf("SC_PAGE_SIZE") / 2**20
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._t0 = time.perf_counter()
        self._thread = threading.Thread(target=self._loop, args=(period,), daemon=True)
        self._thread.start()

    def _loop(self, period: float) -> None:
        while not self._stop.wait(period):
            if not self._sample():  # not Linux: no trace
                return

    def _sample(self) -> bool:
        import os

        try:
            with open("/proc/self/statm") as fh:
                rss = int(fh.read().split()[1]) * self._page
        except OSError:
            return False
        with self._lock:
            self.samples.append((time.perf_counter() - self._t0, rss))
            self.tree.append(rss + _descendants_pages(os.getpid()) * self._page)
        return True

    def now(self) -> float:
        """Seconds since the start of the trace."""
        return time.perf_counter() - self._t0

    def mark(self, stage: str) -> None:
        """``stage`` ends now (it began at the previous mark, or at the start); one
        sample is taken here, so that a stage shorter than the period has its own."""
        self._sample()
        self.marks.append((stage, time.perf_counter() - self._t0))

    def stages(self, tree: bool = False) -> dict[str, float]:
        """The largest sampled RSS (MB) of each marked stage: this process, or with
        ``tree`` the sum over it and its descendants."""
        with self._lock:
            values = list(self.tree) if tree else [mb for _, mb in self.samples]
            times = [t for t, _ in self.samples]
        out: dict[str, float] = {}
        lo = 0.0
        for key, hi in self.marks:
            seg = [mb for t, mb in zip(times, values, strict=True) if lo <= t <= hi]
            if seg:
                out[key] = round(max(seg), 1)
            lo = hi
        return out

    def per_stage(self, ends: dict[str, float], start: float = 0.0) -> dict[str, float]:
        """The largest sampled RSS (MB) in each stage; ``ends`` stage → its end (s since
        the start of the trace, in order), the first stage beginning at ``start``."""
        out: dict[str, float] = {}
        lo = start
        with self._lock:
            samples = list(self.samples)
        for key, hi in ends.items():
            seg = [mb for t, mb in samples if lo <= t < hi]
            if seg:
                out[key] = round(max(seg), 1)
            lo = hi
        return out

    def children_max(self) -> float:
        """The largest sampled sum of the descendants' resident sets (MB)."""
        with self._lock:
            return round(
                max(
                    (t - s for t, (_, s) in zip(self.tree, self.samples, strict=True)), default=0.0
                ),
                1,
            )

    def stop(self) -> dict[str, float]:
        self._stop.set()
        self._thread.join()
        if not self.samples:
            return {}
        t, mb = max(self.samples, key=lambda s: s[1])
        return {"peak_mb": round(mb, 1), "at_s": round(t, 1)}


def trim_heap() -> None:
    """Give the freed heap back to the OS (glibc's ``malloc_trim``; nothing elsewhere).
    Millions of small arrays freed at once (the track fits) leave their pages in the
    heap, reused only by small allocations: the large arrays of the next stage (mapped
    apart) would add to them in the resident set."""
    import ctypes

    try:  # the symbols already loaded (no find_library: it forks ldconfig)
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _descendants_pages(root: int) -> int:
    """Resident pages of the processes descending from ``root`` (a scan of ``/proc``)."""
    import os

    parent: dict[int, int] = {}
    pages: dict[int, int] = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as fh:
                stat = fh.read()
        except OSError:  # the process ended meanwhile
            continue
        rest = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
        parent[int(name)], pages[int(name)] = int(rest[1]), int(rest[21])
    total = 0
    for pid, rss in pages.items():
        p = parent.get(pid, 0)
        while p > 1 and p != root:
            p = parent.get(p, 0)
        if p == root and pid != root:
            total += rss
    return total


def network(seed: int, m: int) -> tuple[RadarSet, list[BiasField]]:
    """``m`` radars within ±150 km (none closer than 40 km to another), smooth fields."""
    rng = np.random.default_rng([seed, 0])
    sites: list[np.ndarray] = []
    while len(sites) < m:
        c = rng.uniform(-SITE_HALF, SITE_HALF, 2)
        if all(np.hypot(*(c - s)) > 40e3 for s in sites):
            sites.append(c)
    radars = RadarSet(np.array(sites), 50.0, np.deg2rad(0.08), MAX_RANGE)
    fields = [
        BiasField.smooth(
            rng,
            center=np.zeros(2),
            scale=REGION,
            range_amplitude=150.0,
            azimuth_amplitude=np.deg2rad(0.3),
        )
        for _ in range(m)
    ]
    return radars, fields


def traffic(
    seed: int,
    radars: RadarSet,
    fields: list[BiasField],
    aircraft: int,
    hours: float,
    region: float = REGION,
) -> PlotTable:
    """Straight legs across the ±``region`` (m) square, entering uniformly over ``hours``;
    the plots of every radar, vectorised per radar (module docstring)."""
    REGION = region  # the module default, overridden for the country network
    rng = np.random.default_rng([seed, 1])
    day = hours * 3600.0
    # entry on the boundary of the ±REGION square, heading towards a random interior point
    side = rng.integers(0, 4, aircraft)
    u = rng.uniform(-REGION, REGION, aircraft)
    p0 = np.where(
        side[:, None] == 0,
        np.column_stack([u, np.full(aircraft, -REGION)]),
        np.where(
            side[:, None] == 1,
            np.column_stack([u, np.full(aircraft, REGION)]),
            np.where(
                side[:, None] == 2,
                np.column_stack([np.full(aircraft, -REGION), u]),
                np.column_stack([np.full(aircraft, REGION), u]),
            ),
        ),
    )
    aim = rng.uniform(-0.5 * REGION, 0.5 * REGION, (aircraft, 2))
    speed = rng.uniform(150.0, 250.0, aircraft)
    d = aim - p0
    vel = speed[:, None] * d / np.linalg.norm(d, axis=1)[:, None]
    # time to leave the square
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(vel > 0, (REGION - p0) / vel, np.where(vel < 0, (-REGION - p0) / vel, np.inf))
    t_in = np.nanmin(np.where(tx > 1.0, tx, np.inf), axis=1)
    t0 = rng.uniform(0.0, day, aircraft)
    t1 = t0 + t_in
    cols: list[list[np.ndarray]] = [[] for _ in range(5)]
    for i in range(radars.m):
        period = rng.uniform(8.0, 12.0)
        phase = rng.uniform(0.0, period, aircraft)
        first = np.ceil((t0 - phase) / period)
        count = np.floor((t1 - phase) / period) - first + 1
        count = np.maximum(count, 0).astype(np.int64)
        obj = np.repeat(np.arange(aircraft), count)
        k = np.arange(obj.size) - np.repeat(np.cumsum(count) - count, count)
        t = phase[obj] + (first[obj] + k) * period
        x = p0[obj] + vel[obj] * (t - t0[obj])[:, None]
        pol = to_polar(x, radars.sites[i])
        meas = (
            pol
            + fields[i](x)
            + rng.normal(size=pol.shape) * [radars.sigma_range[i], radars.sigma_azimuth[i]]
        )
        seen = (meas[:, 0] <= radars.max_range[i]) & (pol[:, 0] > 1e3)
        for c, v in zip(
            cols,
            (t, np.full(t.size, i), np.abs(meas[:, 0]), wrap_angle(meas[:, 1]), obj),
            strict=True,
        ):
            c.append(v[seen])
    out = []
    for c in cols:  # column by column, each one's pieces freed once joined
        out.append(np.concatenate(c))
        c.clear()
    # radar by radar (the pipeline sorts what it needs): no second copy for a time sort
    return PlotTable(out[0], out[1].astype(np.int64), out[2], out[3], out[4].astype(np.int64))


def _generate(path: str, seed: int, m: int, aircraft: int, hours: float) -> None:
    """Child process: the network's plots to an .npz (the generator's memory then stays
    out of the pipeline's peak)."""
    radars, fields = network(seed, m)
    p = traffic(seed, radars, fields, aircraft, hours)
    np.savez(path, time=p.time, radar=p.radar, range=p.range, azimuth=p.azimuth, object=p.object)


def run_in_child(target: Any, args: tuple[Any, ...]) -> None:
    """``target(*args)`` in a spawned child process (its memory stays out of this process's
    peak), killed with this process on an interrupt; a non-zero exit is a RuntimeError."""
    import multiprocessing as mp

    proc = mp.get_context("spawn").Process(target=target, args=args)
    proc.start()
    try:
        proc.join()
    except BaseException:
        proc.kill()
        proc.join()
        raise
    if proc.exitcode != 0:
        raise RuntimeError(f"the traffic generator failed (exit {proc.exitcode})")


def simulate_in_child(seed: int, m: int, aircraft: int, hours: float) -> PlotTable:
    """:func:`traffic` in a spawned child process; the plots come back through a file."""
    import os
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "plots.npz")
        run_in_child(_generate, (path, seed, m, aircraft, hours))
        with np.load(path) as z:
            return PlotTable(z["time"], z["radar"], z["range"], z["azimuth"], z["object"])


def kmeans_tree(points: np.ndarray, count: int, seed: int, iters: int = 20) -> np.ndarray:
    """Lloyd's k-means with a k-d tree for the nearest centre (O(N log K) per iteration
    instead of the O(N K) of scipy's ``vq``), random points as the start; :func:`run`
    uses it on up to 2·10⁶ plot positions (the traffic density) unless told otherwise."""
    rng = np.random.default_rng(seed)
    scale = points.std(axis=0)
    p = points / scale
    cent = p[rng.choice(p.shape[0], count, replace=False)]
    for _ in range(iters):
        lab = cKDTree(cent).query(p)[1]
        sums = np.column_stack(
            [np.bincount(lab, p[:, j], minlength=count) for j in range(p.shape[1])]
        )
        n = np.bincount(lab, minlength=count)
        moved = n > 0
        cent[moved] = sums[moved] / n[moved, None]
    return cent * scale


def plot_cost_3d(n: int = 20_000, seed: int = 0) -> dict[str, float]:
    """Seconds per 10⁶ plots of the exact 3-D placement (slant range, own-north azimuth,
    height → plane) and covariance, on a 3-D network sample (median of 3)."""
    from optmodels.scenarios.radar_network import radar_network

    sc = radar_network(seed, n_aircraft=40, duration=1800.0, geometry="3d")
    plots = sc.plots.subset(np.arange(min(n, len(sc.plots))))
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        z = plots.cartesian(sc.radars)
        for i in range(sc.radars.m):
            sel = plots.radar == i
            sc.radars.cartesian_cov(i, z[sel], height=plots.height[sel])  # type: ignore
        times.append(time.perf_counter() - t0)
    return {"plots": len(plots), "s_per_1e6_plots_3d": float(np.median(times)) / len(plots) * 1e6}


def _stage(res: dict[str, Any], key: str, t0: float) -> None:
    """Record a stage's seconds and say so on stderr (a long run shows its progress)."""
    res[key] = time.perf_counter() - t0
    print(
        f"{key}: {res[key]:.1f} (peak RSS {peak_rss_mb()[0]:.0f} MB)", file=sys.stderr, flush=True
    )


def run(
    *,
    small: bool = False,
    scheduler: str = "serial",
    workers: int | None = None,
    aircraft: int | None = None,
    hours: float | None = None,
    cells: int | None = None,
    seed: int = 0,
    fast_centers: bool = False,
    clean: bool = True,
    separate_fit: bool = False,
    child_generator: bool = True,
) -> dict[str, Any]:
    """The chain, stage by stage: simulate (in a child process unless
    ``child_generator=False``, so that ``peak_rss_mb`` is the pipeline's own), clean,
    FieldData (its own fits with ``scheduler``; centres by
    :func:`~optmodels.biasfield.cells.place_centers` on the sampled positions, or with
    ``fast_centers`` by this module's :func:`kmeans_tree` on up to 2·10⁶ plot positions,
    the previous benchmark's choice; averaging; its stage seconds from
    ``Diagnostics.timings``). ``separate_fit`` adds a separate pass of the fits (to time
    the scheduler alone); with it or ``fast_centers`` the plots' positions are computed
    once here and passed on (``positions=``; otherwise build_field_data's fits compute
    them and free them after the fits: −16 B per plot at the peak). Returns the figures
    (seconds, MB, sizes, the RSS trace per stage)."""
    cfg = dict(SMALL if small else FULL)
    for key, val in (("aircraft", aircraft), ("hours", hours), ("cells", cells)):
        if val is not None:
            cfg[key] = val
    res: dict[str, Any] = {"config": cfg, "scheduler": scheduler, "workers": workers}
    trace = RssTrace()
    t_all = time.perf_counter()
    t = time.perf_counter()
    radars, fields = network(seed, int(cfg["radars"]))
    if child_generator:
        plots = simulate_in_child(
            seed, int(cfg["radars"]), int(cfg["aircraft"]), float(cfg["hours"])
        )
    else:
        plots = traffic(seed, radars, fields, int(cfg["aircraft"]), float(cfg["hours"]))
    res["plots"] = len(plots)
    _stage(res, "t_simulate_s", t)
    if clean:
        t = time.perf_counter()
        plots, rep = clean_plots(plots, radars)
        _stage(res, "t_clean_s", t)
        res["cleaning_dropped"] = rep.counts
    z = None  # the plots' positions, computed here only if this benchmark needs them too
    if separate_fit or fast_centers:
        t = time.perf_counter()
        z = plots.cartesian(radars)
        _stage(res, "t_positions_s", t)
    if separate_fit:
        t = time.perf_counter()
        fits, dropped = fit_tracks(plots, radars, scheduler=scheduler, workers=workers, positions=z)
        _stage(res, "t_fit_s", t)
        res["fits"] = len(fits)
        res["fit_dropped"] = dropped.counts
        del fits
        gc.collect()
    centres: Any = int(cfg["cells"])
    if fast_centers:
        t = time.perf_counter()
        sample = np.random.default_rng(seed).choice(len(z), min(len(z), 2_000_000), replace=False)
        centres = kmeans_tree(z[sample], int(cfg["cells"]), seed)  # type: ignore[index]
        del sample
        _stage(res, "t_centres_tree_s", t)
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fd, diag = build_field_data(plots, radars, cells=centres, scheduler=scheduler, positions=z)
    _stage(res, "t_field_data_s", t)  # includes its own track fits
    res["field_data_stages_s"] = {k: round(v, 2) for k, v in diag.timings.items()}
    res["fits_in_field_data"] = len(diag.fits)
    res["cells"] = fd.k
    res["dropped_cells"] = diag.dropped_cells
    res["t_total_s"] = time.perf_counter() - t_all
    res["peak_rss_mb"], res["peak_rss_children_mb"] = peak_rss_mb()
    res["rss_trace_peak"] = trace.stop()  # when (s since the start) the peak was reached
    ends: dict[str, float] = {}
    clock = 0.0
    for key in ("t_simulate_s", "t_clean_s", "t_positions_s", "t_fit_s", "t_centres_tree_s"):
        if key in res:
            clock += res[key]
            ends[key] = clock
    for key, sec in diag.timings.items():
        clock += sec
        ends[f"field_data.{key}"] = clock
    ends["field_data.rest"] = res["t_total_s"] + 1.0
    res["rss_max_per_stage_mb"] = trace.per_stage(ends)
    return res


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="20 radars, 200 aircraft, 1 h")
    ap.add_argument("--scheduler", choices=("serial", "processes"), default="serial")
    ap.add_argument("--workers", type=int)
    ap.add_argument("--aircraft", type=int)
    ap.add_argument("--hours", type=float)
    ap.add_argument("--cells", type=int)
    ap.add_argument(
        "--tree-centres",
        action="store_true",
        help="centres by this module's kmeans_tree on 2·10⁶ plot positions "
        "(default: build_field_data's place_centers on its samples)",
    )
    ap.add_argument("--no-clean", action="store_true")
    ap.add_argument(
        "--generate-here",
        action="store_true",
        help="simulate in this process (its memory then counts in the peak)",
    )
    ap.add_argument(
        "--separate-fit",
        action="store_true",
        help="a separate pass of the fits, to time the scheduler alone",
    )
    ap.add_argument(
        "--country",
        action="store_true",
        help="issue 24: 40 radars over 1000 × 1000 km, ranges 200-250 km, the "
        "field over the union of coverage, solve and correct (with "
        "--small: 600 aircraft, 2 h)",
    )
    ap.add_argument(
        "--dask",
        action="store_true",
        help="with --country: the same chain again on a Dask LocalCluster",
    )
    ap.add_argument(
        "--json", action="store_true", help="only the JSON document on stdout (no progress bars)"
    )
    a = ap.parse_args(argv)
    if a.country:
        from solvers_cmp.biasfield_country import run_country

        res = run_country(
            small=a.small,
            aircraft=a.aircraft,
            hours=a.hours,
            cells=a.cells,
            workers=a.workers or 2,
            dask=a.dask,
            progress=not a.json,
        )
        if not a.json:
            for k, v in res.items():
                print(f"{k}: {v}", file=sys.stderr)
        print(json.dumps(res))
        return res
    res = run(
        small=a.small,
        scheduler=a.scheduler,
        workers=a.workers,
        aircraft=a.aircraft,
        hours=a.hours,
        cells=a.cells,
        fast_centers=a.tree_centres,
        clean=not a.no_clean,
        separate_fit=a.separate_fit,
        child_generator=not a.generate_here,
    )
    for k, v in res.items():
        print(f"{k}: {v}", file=sys.stderr)
    print(json.dumps(res))
    return res


if __name__ == "__main__":
    main()
