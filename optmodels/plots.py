"""Matplotlib figures, written to files (Agg back-end, no screen needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from optmodels.core import FloatArray


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
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


def plane_statistic(path: Path, times: FloatArray, stat: FloatArray, paper_thr: FloatArray,
                    chi2_thr: FloatArray, level: float) -> Path:
    """Paper 000, fig. 2: √(2Λ) against the paper's threshold and the χ²(N-3) one."""
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(times, stat, label=r"$\sqrt{2\Lambda_{\min}}$")
    ax.plot(times, paper_thr, "r--", label=r"paper (1.17): $\sqrt{2N}+2$")
    ax.plot(times, np.sqrt(2 * chi2_thr), "k-.",
            label=rf"$\sqrt{{2\,\chi^2_{{N-3}}({level})}}$ (corrected)")
    ax.set_xlabel("time, s")
    ax.set_ylabel("Y")
    ax.legend()
    ax.grid(alpha=0.3)
    ax.set_title("Fig. 2: planarity statistic and thresholds")
    return _save(fig, path)


def plane_error(path: Path, times: FloatArray, err: FloatArray, bound: FloatArray, *,
                ylabel: str, title: str, mc_rms: FloatArray | None = None) -> Path:
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


def radius_bound(path: Path, radii: FloatArray, angle: FloatArray, offset: FloatArray,
                 chosen: float) -> Path:
    """CRB at 10 s against the (unpublished) radius of the paper's turn."""
    fig, ax1 = plt.subplots(figsize=(7, 4))
    ax1.plot(radii, angle * 1e3, "b-", label="angle RMS bound, mrad")
    ax1.axhline(1.4 / np.sqrt(np.pi / 4), color="b", ls=":",
                label="RMS matching the paper's 1.4 mrad mean error")
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
