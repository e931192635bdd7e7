"""Matplotlib figures, written to files (Agg back-end, no screen needed)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from optmodels.core import FloatArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def _save(fig: Figure, path: Path, *, bbox: str | None = None) -> Path:
    from optmodels.io import atomic_write

    fig.tight_layout()
    with atomic_write(path, binary=True) as fh:  # a kill keeps the previous figure
        fig.savefig(fh, dpi=110, bbox_inches=bbox, format=Path(path).suffix[1:] or "png")
    plt.close(fig)
    return path


def plane_trajectory(path: Path, truth: FloatArray, points: FloatArray) -> Path:
    """Paper 000, fig. 1: the true trajectory and the measurements."""
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=1, c="0.6", label="measurements")
    ax.plot(truth[:, 0], truth[:, 1], truth[:, 2], "b-", lw=2, label="true trajectory")
    ax.set_xlabel("x, m")
    ax.set_ylabel("y, m")
    ax.set_zlabel("z, m")
    ax.legend(loc="upper left")
    ax.set_title("Fig. 1: true motion in the plane OXZ")
    return _save(fig, path)


def plane_statistic(
    path: Path,
    times: FloatArray,
    stat: FloatArray,
    paper_thr: FloatArray,
    chi2_thr: FloatArray,
    level: float,
) -> Path:
    """Paper 000, fig. 2: √(2Λ) against the paper's threshold and the χ²(N-3) one."""
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(times, stat, label=r"$\sqrt{2\Lambda_{\min}}$")
    ax.plot(times, paper_thr, "r--", label=r"paper (1.17): $\sqrt{2N}+2$")
    ax.plot(
        times,
        np.sqrt(2 * chi2_thr),
        "k-.",
        label=rf"$\sqrt{{2\,\chi^2_{{N-3}}({level})}}$ (corrected)",
    )
    ax.set_xlabel("time, s")
    ax.set_ylabel("Y")
    ax.legend()
    ax.grid(alpha=0.3)
    ax.set_title("Fig. 2: planarity statistic and thresholds")
    return _save(fig, path)


def plane_error(
    path: Path,
    times: FloatArray,
    err: FloatArray,
    bound: FloatArray,
    *,
    ylabel: str,
    title: str,
    mc_rms: FloatArray | None = None,
) -> Path:
    """Paper 000, figs. 3-4: an error over time, with the Cramér–Rao bound."""
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(times, err, label="one run (as in the paper)")
    if mc_rms is not None:
        ax.plot(times, mc_rms, "g-", lw=2, label="RMS over Monte Carlo runs")
    ax.plot(times, bound, "k--", label="Cramér–Rao bound (RMS)")
    ax.set_xlabel("time, s")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return _save(fig, path)


def radius_bound(
    path: Path, radii: FloatArray, angle: FloatArray, offset: FloatArray, chosen: float
) -> Path:
    """CRB at 10 s against the (unpublished) radius of the paper's turn."""
    fig, ax1 = plt.subplots(figsize=(7, 4))
    ax1.plot(radii, angle * 1e3, "b-", label="angle RMS bound, mrad")
    ax1.axhline(
        1.4 / np.sqrt(np.pi / 4),
        color="b",
        ls=":",
        label="RMS matching the paper's 1.4 mrad mean error",
    )
    ax1.set_xlabel("radius of the turn, m")
    ax1.set_ylabel("mrad", color="b")
    ax2 = ax1.twinx()
    ax2.plot(radii, offset, "r-", label="offset bound, m")
    ax2.axhline(2.0, color="r", ls=":", label="paper: 2 m")
    ax2.set_ylabel("m", color="r")
    ax1.axvline(chosen, color="k", ls="--", lw=1)
    h1, l1 = ax1.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax1.legend(h1 + h2, l1 + l2, fontsize=8)
    ax1.set_title("Cramér–Rao bounds at 10 s vs radius (dashed: chosen)")
    return _save(fig, path)


def _line_std(cov: FloatArray, i0: int, i1: int, t: FloatArray) -> FloatArray:
    """Standard deviation of start + velocity·t from Ψ entries (i0: start, i1: velocity)."""
    return np.sqrt(cov[i0, i0] + 2 * t * cov[i0, i1] + t * t * cov[i1, i1])


def trajectory_fits(
    path: Path,
    times: list[FloatArray],
    values: list[FloatArray],
    dep: dict[str, Any],
    ind: dict[str, Any],
    truth: tuple[FloatArray, FloatArray],
    title: str,
) -> Path:
    """Paper 002: data and fitted lines (top); error of the fitted lines against the truth
    with ±3σ bands from Ψ, dependent family (solid) vs independent lines (dashed).

    ``dep``/``ind``: ``start``, ``velocity`` (Q,), ``covariance`` (R, R), ``start_index``,
    ``velocity_index`` (Q,)."""
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7.5), sharex=True)
    tmax = max(float(np.max(t)) for t in times)
    tt = np.linspace(0.0, tmax, 300)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, (t, y) in enumerate(zip(times, values, strict=True)):
        c = colors[j % len(colors)]
        ax1.plot(t, y / 1e3, ".", ms=2, color=c)
        ax1.plot(
            tt,
            (dep["start"][j] + dep["velocity"][j] * tt) / 1e3,
            "-",
            color=c,
            lw=1,
            label=f"object {j + 1}",
        )
        for fit, ls, lab in ((dep, "-", "family"), (ind, "--", "independent")):
            err = fit["start"][j] + fit["velocity"][j] * tt - (truth[0][j] + truth[1][j] * tt)
            sd = _line_std(fit["covariance"], fit["start_index"][j], fit["velocity_index"][j], tt)
            ax2.plot(tt, err, ls, color=c, lw=1, label=f"{lab}, object {j + 1}" if j == 0 else None)
            if ls == "-":
                ax2.fill_between(tt, -3 * sd, 3 * sd, color=c, alpha=0.12)
            else:
                ax2.plot(tt, 3 * sd, ":", color=c, lw=0.8)
                ax2.plot(tt, -3 * sd, ":", color=c, lw=0.8)
    ax1.set_ylabel("along-track position, km")
    ax1.legend(fontsize=8, ncol=2)
    ax1.grid(alpha=0.3)
    ax1.set_title(title)
    ax2.set_xlabel("time since release, s")
    ax2.set_ylabel("fit − truth, m")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8, title="shaded/dotted: ±3σ from Ψ (14)", title_fontsize=8)
    return _save(fig, path)


def eta_curves(path: Path, rows: list[dict[str, Any]]) -> Path:
    """η(N) for Q objects: formula, Ψ ratio and Monte Carlo, with the paper's two-object
    curve and its asymptote 0.625."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for q in sorted({r["Q"] for r in rows}):
        sub = [r for r in rows if r["Q"] == q]
        n = np.array([r["N"] for r in sub])
        (line,) = ax.plot(n, [r["eta formula"] for r in sub], "-", label=f"η(N, Q={q}) formula")
        ax.errorbar(
            n,
            [r["eta MC"] for r in sub],
            yerr=[2 * r["eta MC avg se"] for r in sub],
            fmt="o",
            ms=4,
            capsize=3,
            color=line.get_color(),
            label=f"Monte Carlo, Q={q} (±2 se)",
        )
    ax.axhline(0.625, color="k", ls=":", lw=1, label="paper: 0.625 (N → ∞, Q = 2)")
    ax.set_xscale("log")
    ax.set_xlabel("measurements per object N")
    ax.set_ylabel("Var(dependent) / Var(independent)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("η for the unique parameters (equal times t_i = (i−1)ΔT)")
    return _save(fig, path)


def _sites(ax: Axes, sites: FloatArray) -> None:
    ax.plot(sites[:, 0] / 1e3, sites[:, 1] / 1e3, "k^", ms=8, label="sites A, B")


def fusion_maps(path: Path, maps: dict[str, Any], sites: FloatArray, *, n: int) -> Path:
    """Paper 003: first-order maps of the two-site system (CRB RMS, fusion (1) / CRB,
    relative standard deviation of Ŵ from (10))."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4), sharey=True)
    x, y = maps["x"] / 1e3, maps["y"] / 1e3
    panels = [
        (maps["crb"], "CRB RMS error, m (joint ML, first order)", "viridis", True),
        (maps["fused_ratio"], "fusion (1) with true W: RMS / CRB", "magma", False),
        (maps["rel_w"], f"rel. std of Ŵ by (10), n = {n}", "cividis", True),
    ]
    for ax, (val, title, cmap, log) in zip(axes, panels, strict=True):
        from matplotlib.colors import LogNorm

        norm = LogNorm(vmin=float(np.nanmin(val)), vmax=float(np.nanmax(val))) if log else None
        im = ax.pcolormesh(x, y, val, cmap=cmap, norm=norm, shading="auto")
        fig.colorbar(im, ax=ax)
        _sites(ax, sites)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("East, km")
        ax.set_aspect("equal")
    axes[0].set_ylabel("North, km")
    return _save(fig, path)


def fusion_positions(
    path: Path, positions: FloatArray, ratios: dict[str, FloatArray], sites: FloatArray
) -> Path:
    """Paper 003: Monte Carlo RMS / joint-ML RMS at the sampled positions, one panel per
    method."""
    k = len(ratios)
    fig, axes = plt.subplots(1, k, figsize=(5 * k, 4.2), sharey=True, squeeze=False)
    vmax = max(float(np.max(v)) for v in ratios.values())
    for ax, (name, val) in zip(axes[0], ratios.items(), strict=True):
        sc = ax.scatter(
            positions[:, 0] / 1e3,
            positions[:, 1] / 1e3,
            c=val,
            cmap="magma_r",
            vmin=1.0,
            vmax=vmax,
            s=40,
            edgecolors="k",
            linewidths=0.3,
        )
        _sites(ax, sites)
        ax.set_title(f"{name}: RMS / joint ML", fontsize=10)
        ax.set_xlabel("East, km")
        ax.set_aspect("equal")
        fig.colorbar(sc, ax=ax)
    axes[0, 0].set_ylabel("North, km")
    return _save(fig, path)


def fusion_vs_n(
    path: Path,
    ns: tuple[int, ...] | list[int],
    snapshot: list[FloatArray],
    reference: dict[str, FloatArray],
) -> Path:
    """Paper 003: RMS / joint ML of fusion (1) with Ŵ from n snapshots against n (median and
    90th percentile over positions), with reference methods as horizontal lines."""
    fig, ax = plt.subplots(figsize=(7, 4.2))
    med = [float(np.median(v)) for v in snapshot]
    p90 = [float(np.quantile(v, 0.9)) for v in snapshot]
    ax.plot(ns, med, "o-", label="fusion (1), Ŵ from n snapshots: median")
    ax.plot(ns, p90, "s--", label="… 90th percentile over positions")
    for (name, val), style in zip(reference.items(), (":", "-.", "--"), strict=False):
        ax.axhline(float(np.median(val)), ls=style, color="0.3", lw=1, label=f"{name}: median")
    ax.set_xscale("log")
    ax.set_xlabel("snapshots n")
    ax.set_ylabel("RMS error / joint-ML RMS (same draws)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def bias_maps(
    path: Path,
    centers: FloatArray,
    panels: dict[str, FloatArray],
    sites: FloatArray,
    *,
    component: int,
    truth_grid: tuple[Any, ...] | None = None,
    names: tuple[str, ...] = (),
) -> Path:
    """Paper 001, fig. 4: one bias component per radar (columns) for each estimate (rows):
    cells as dots coloured by value, radar sites as crosses with their names; ``truth_grid``
    = (gx, gy, values (ny, nx, m)) adds a first row with the true field as a filled map.
    ``component`` 0: range bias (m); 1: azimuth bias (shown in degrees). Each column is
    titled by its radar's name once (``names``, default "radar 1", ...), each row by its
    estimate at the left (wrapped), so that no title runs into its neighbour."""
    import textwrap

    m = sites.shape[0]
    names = tuple(names) if names else tuple(f"radar {i + 1}" for i in range(m))
    scale, unit = (1.0, "m") if component == 0 else (180 / np.pi, "deg")
    rows = (1 if truth_grid is not None else 0) + len(panels)
    vals = [v[..., component] * scale for v in panels.values()]
    if truth_grid is not None:
        vals.append(truth_grid[2][..., :m] * scale)
    lim = max(float(np.nanmax(np.abs(v))) for v in vals)
    fig, axes = plt.subplots(
        rows,
        m,
        figsize=(3.4 * m + 1.2, 3.1 * rows),
        squeeze=False,
        sharex=True,
        sharey=True,
        layout="constrained",
    )
    r0 = 0
    km = 1e-3
    row_titles = []
    if truth_grid is not None:
        gx, gy, gv = truth_grid
        for i in range(m):
            im = axes[0, i].pcolormesh(
                gx * km,
                gy * km,
                gv[..., i] * scale,
                cmap="RdBu_r",
                vmin=-lim,
                vmax=lim,
                shading="auto",
            )
        row_titles.append("true field")
        r0 = 1
    for r, (title, val) in enumerate(panels.items(), start=r0):
        for i in range(m):
            im = axes[r, i].scatter(
                centers[:, 0] * km,
                centers[:, 1] * km,
                c=val[:, i, component] * scale,
                cmap="RdBu_r",
                vmin=-lim,
                vmax=lim,
                s=14,
                edgecolors="k",
                linewidths=0.2,
            )
        row_titles.append(title)
    for i in range(m):
        axes[0, i].set_title(names[i], fontsize=10, fontweight="bold")
    for ax in axes.ravel():
        ax.plot(sites[:, 0] * km, sites[:, 1] * km, "kx", ms=7, mew=2)
        for j in range(m):
            ax.annotate(
                names[j],
                (sites[j, 0] * km, sites[j, 1] * km),
                fontsize=6,
                xytext=(3, 3),
                textcoords="offset points",
            )
        ax.set_aspect("equal")
    for ax in axes[-1]:
        ax.set_xlabel("East, km")
    for r, ax in enumerate(axes[:, 0]):
        ax.set_ylabel("\n".join(textwrap.wrap(row_titles[r], 24)) + "\n\nNorth, km", fontsize=8)
    what = "range bias" if component == 0 else "azimuth bias"
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label=f"{what}, {unit}")
    from optmodels.io import atomic_write

    with atomic_write(path, binary=True) as fh:  # a kill keeps the previous figure
        fig.savefig(fh, dpi=100, format=Path(path).suffix[1:] or "png")
    plt.close(fig)
    return path


def association_rates(path: Path, rows: list[dict[str, Any]]) -> Path:
    """Paper 004: correct-association rate vs separation, MAP (merges) vs GNN."""
    sep = [r["separation, m"] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, label, style in (
        ("MAP", "MAP joint assignment (merges, MILP)", "o-"),
        ("GNN", "resolved only (linear assignment)", "s--"),
        ("SS-GNN", "Stone Soup GNNWith2DAssignment", "^:"),
        ("SS-JPDA", "Stone Soup JPDA (most probable)", "v:"),
    ):
        if f"{key} correct" not in rows[0]:
            continue
        ax.errorbar(
            sep,
            [r[f"{key} correct"] for r in rows],
            yerr=[2 * r[f"{key} se"] for r in rows],
            fmt=style,
            capsize=3,
            label=label,
        )
    ax.set_xscale("log")
    ax.set_xlabel("object separation, m")
    ax.set_ylabel("correct associations (±2 se)")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path)


def scaling(
    path: Path, rows: list[dict[str, Any]], *, title: str, size_label: str, time_limit: float
) -> Path:
    """Log-log total time (build + solve) vs size, one panel per instance, one line per
    (formulation, solver) with its fitted log-log slope where it has three sizes or more
    (markers only otherwise: two points make no slope); failed runs drawn as × at the
    time limit; the closed form (the floor) as a thick black line."""
    instances = sorted({r["instance"] for r in rows})
    fig, axes = plt.subplots(
        1, len(instances), figsize=(5.2 * len(instances), 4.2), squeeze=False, sharey=True
    )
    series = sorted(
        {(r["formulation"], r["solver"]) for r in rows}, key=lambda fs: (fs[0] != "closed_form", fs)
    )
    cmap = plt.get_cmap("tab20")
    colors = {fs: cmap(k % 20) for k, fs in enumerate(s for s in series if s[0] != "closed_form")}
    for ax, inst in zip(axes[0], instances, strict=True):
        for fs in series:
            rs = sorted(
                (
                    r
                    for r in rows
                    if r["instance"] == inst and (r["formulation"], r["solver"]) == fs
                ),
                key=lambda r: r["size"],
            )
            if not rs:
                continue
            ok = [r for r in rs if r["success"]]
            bad = [r for r in rs if not r["success"]]
            floor = fs[0] == "closed_form"
            style = (
                {"color": "k", "lw": 2.5, "ls": "--", "marker": "s", "ms": 4}
                if floor
                else {"color": colors[fs], "lw": 1.2, "marker": "o", "ms": 3}
            )
            label = "closed form" if floor else f"{fs[1]} ({fs[0]})"
            if ok:
                xs = np.array([r["size"] for r in ok], float)
                ys = np.array([max(r["build_time"] + r["solve_time"], 1e-6) for r in ok])
                sizes = np.unique(xs)
                if len(sizes) >= 3:  # enough sizes for a slope: line and fitted exponent
                    slope = float(np.polyfit(np.log(xs), np.log(ys), 1)[0])
                    label += f", slope {slope:.2f}"
                else:  # two sizes make no slope: markers only, no line
                    style = {**style, "ls": "none"}
                ax.plot(xs, ys, label=label, **style)
            if bad:
                ax.plot(
                    [r["size"] for r in bad],
                    [time_limit] * len(bad),
                    "x",
                    color=style["color"],
                    ms=7,
                    label=None if ok else label + " (failed)",
                )
        ax.axhline(time_limit, color="0.6", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(size_label)
        ax.set_title(f"{title}: {inst}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("build + solve time, s (× = failed, at the time limit)")
    handles, labels = axes[0][-1].get_legend_handles_labels()
    for ax in axes[0][:-1]:
        h, lab = ax.get_legend_handles_labels()
        for hh, ll in zip(h, lab, strict=True):
            if ll not in labels:
                handles.append(hh)
                labels.append(ll)
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7)
    return _save(fig, path, bbox="tight")  # the legend sits right of the panels
