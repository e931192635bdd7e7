r"""Track fitting (paper 001, (3) and section 3): per radar and object, the biased motion
ξ_i^a(t) = x^a(t) + s_i(x^a(t)) as a polyline g(t)θ with knots at fixed times, fitted to
the radar's plots by generalised least squares with the plot covariances V_i.

A polyline with knots τ_0 < … < τ_K is Σ_k h_k(t)θ_k with hat functions h_k; θ_k ∈ R² is
the position at τ_k (:mod:`~optmodels.biasfield.polyline`: the basis, the knots, the normal
equations and their solve). With plots z_j at t_j and Cartesian covariances V_j (first order,
evaluated at the plot), the GLS estimate solves

.. math::
    \min_\theta \sum_j (z_j - g(t_j)\theta)^T V_j^{-1} (z_j - g(t_j)\theta),\qquad
    \operatorname{Cov}\hat\theta = \Big(\sum_j g(t_j)^T V_j^{-1} g(t_j)\Big)^{-1}.

Interior knots are the multiples of ``knot_spacing`` (absolute times, the same for every
radar observing an object, so that the interpolation error of a curved path is nearly
common to all radars -- and a common shift is invisible to the bias field anyway); the end
knots are the first and last plots, so a fit is never evaluated beyond its data. A track is split
where plots are more than ``max_gap`` apart; a piece with fewer plots than its polyline
has parameters (plus ``min_redundancy``) is dropped and reported.

Scale. N is block-tridiagonal (2×2 blocks): it is assembled as its band (bincount, O(n))
and solved by the block Cholesky recursion (O(K)); θ is then a Gauss-Markov chain, so the
band of Cov θ̂ (Cov θ_k and Cov(θ_k, θ_k+1)) determines every other block exactly and is
all a :class:`TrackFit` stores: O(K) memory instead of the (2K)² of the dense inverse
(a 90-min track at 20 s knots: 17 KB instead of 583 KB). The (radar, object) tracks are
independent: :func:`fit_tracks` runs them serially, on local processes or on Dask
(``scheduler=``, the engine of the Monte Carlo studies), with identical results.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.polyline import (
    inv2,
    locate,
    normal_band,
    polyline_knots,
    polyline_normal,
    solve_bands,
    split_at_gaps,
    whiten,
)
from optmodels.biasfield.tables import PlotTable, RadarSet, check_tables
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_positive,
)

# polyline_normal stays importable from here (tests/test_biasfield_clean.py)
__all__ = [
    "Dropped",
    "ResidualCheck",
    "TrackFit",
    "fit_tracks",
    "polyline_normal",
    "residual_check",
]


@dataclass
class TrackFit:
    """One radar's fitted polyline for one object over [knots[0], knots[-1]].

    ``theta`` (K, 2) positions at the knots. Its covariance is stored as its block band:
    ``cov_diag`` (K, 2, 2) = Cov(θ_k) and ``cov_next`` (K−1, 2, 2) = Cov(θ_k, θ_k+1); the
    normal matrix of a polyline is block-tridiagonal, so θ is a Gauss-Markov chain and
    every other block follows exactly, Cov(θ_j, θ_l) = A_j Cov(θ_j+1, θ_l) (j < l) with
    A_j = Cov(θ_j, θ_j+1) Cov(θ_j+1)⁻¹ (:attr:`cov` assembles the dense (2K, 2K) matrix
    of ``theta.ravel()`` = x0, y0, x1, y1, … on demand). ``rows`` the indices of the plots
    used; ``chi2`` the GLS residual sum Σ rᵀV⁻¹r with ``dof`` = 2n − 2K degrees of
    freedom; ``whitened`` (n, 2) residuals V^{-1/2}(z − ξ̂) (zero mean, unit covariance if
    the motion model and V are right). Memory: O(K + n), not O(K²).
    """

    radar: int
    object: int
    knots: FloatArray
    theta: FloatArray
    cov_diag: FloatArray
    cov_next: FloatArray
    rows: np.ndarray
    chi2: float
    dof: int
    whitened: FloatArray = field(repr=False)

    @property
    def span(self) -> tuple[float, float]:
        return float(self.knots[0]), float(self.knots[-1])

    @property
    def cov(self) -> FloatArray:
        """Dense covariance (2K, 2K) of ``theta.ravel()`` (O(K²) memory: for inspection;
        the pipeline uses the band)."""
        k = self.knots.size
        return self._block(0, k - 1)

    def _block(self, j0: int, j1: int) -> FloatArray:
        """Dense covariance of θ_j0..θ_j1, (2w, 2w) with w = j1 − j0 + 1."""
        w = j1 - j0 + 1
        out = np.zeros((w, w, 2, 2))
        for a in range(w):
            out[a, a] = self.cov_diag[j0 + a]
        if w > 1:
            gain = self.cov_next[j0:j1] @ inv2(self.cov_diag[j0 + 1 : j1 + 1])  # A_j
            for col in range(1, w):
                out[col - 1, col] = self.cov_next[j0 + col - 1]
                for row in range(col - 2, -1, -1):
                    out[row, col] = gain[row] @ out[row + 1, col]
            for col in range(1, w):
                for row in range(col):
                    out[col, row] = out[row, col].T
        return out.transpose(0, 2, 1, 3).reshape(2 * w, 2 * w)

    def at(self, t: ArrayLike) -> FloatArray:
        """ξ̂(t), (T, 2), for t inside the span."""
        tt = as_finite_array(
            "biasfield.TrackFit.at t", t, ndim=(0, 1), max_abs=MAX_MAGNITUDE
        ).reshape(-1)
        k, u = locate(tt, self.knots)
        return (1.0 - u)[:, None] * self.theta[k] + u[:, None] * self.theta[k + 1]

    def cov_at(self, t: ArrayLike) -> FloatArray:
        """Cov ξ̂(t), (T, 2, 2)."""
        tt = as_finite_array(
            "biasfield.TrackFit.cov_at t", t, ndim=(0, 1), max_abs=MAX_MAGNITUDE
        ).reshape(-1)
        k, u = locate(tt, self.knots)
        a, b = (1.0 - u)[:, None, None], u[:, None, None]
        nxt = self.cov_next[k]
        return (
            a * a * self.cov_diag[k]
            + b * b * self.cov_diag[k + 1]
            + a * b * (nxt + np.swapaxes(nxt, 1, 2))
        )

    def mean_over(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Average of ξ̂ over the instants t and its covariance (exact: a linear function
        h·θ of θ̂, only the knots j0..j1 around t enter).

        Cov(Σ h_j θ_j) = Σ_l h_l² C_ll + h_l (G_l C_ll + (G_l C_ll)ᵀ), G_j0 = 0,
        G_l+1 = (G_l + h_l I) A_l: the Markov recursion, O(j1 − j0) 2×2 products."""
        tt = np.asarray(t, dtype=float).reshape(-1)
        if tt.size == 0 or not np.all(np.isfinite(tt)):
            raise ProblemError("biasfield.TrackFit.mean_over t: expected ≥ 1 finite instants")
        k, u = locate(tt, self.knots)
        j0, j1 = int(k.min()), int(k.max()) + 1
        w = j1 - j0 + 1
        h = (
            np.bincount(k - j0, 1.0 - u, minlength=w) + np.bincount(k + 1 - j0, u, minlength=w)
        ) / tt.size
        mean = h @ self.theta[j0 : j1 + 1]
        diag = self.cov_diag[j0 : j1 + 1].reshape(w, 4).tolist()
        nxt = self.cov_next[j0:j1].reshape(w - 1, 4).tolist()
        hl = h.tolist()
        g00 = g01 = g10 = g11 = 0.0
        s00 = s01 = s11 = 0.0
        for m in range(w):
            c00, c01, _, c11 = diag[m]
            hm = hl[m]
            # G C (G: 2×2, C symmetric)
            q00, q01 = g00 * c00 + g01 * c01, g00 * c01 + g01 * c11
            q10, q11 = g10 * c00 + g11 * c01, g10 * c01 + g11 * c11
            s00 += hm * (hm * c00 + 2.0 * q00)
            s01 += hm * (hm * c01 + q01 + q10)
            s11 += hm * (hm * c11 + 2.0 * q11)
            if m == w - 1:
                break
            # A_m = Cov(θ_m, θ_m+1) Cov(θ_m+1)⁻¹
            n00, n01, n10, n11 = nxt[m]
            d00, d01, _, d11 = diag[m + 1]
            det = d00 * d11 - d01 * d01
            i00, i01, i11 = d11 / det, -d01 / det, d00 / det
            a00, a01 = n00 * i00 + n01 * i01, n00 * i01 + n01 * i11
            a10, a11 = n10 * i00 + n11 * i01, n10 * i01 + n11 * i11
            e00, e01, e10, e11 = g00 + hm, g01, g10, g11 + hm
            g00, g01 = e00 * a00 + e01 * a10, e00 * a01 + e01 * a11
            g10, g11 = e10 * a00 + e11 * a10, e10 * a01 + e11 * a11
        return mean, np.array([[s00, s01], [s01, s11]])

    def means_over(self, t: ArrayLike, group: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`mean_over` for many sets of instants at once: ``group`` (T,) labels
        0..G−1 of the instants ``t`` (T,); returns the G averages (G, 2) and their
        covariances (G, 2, 2), exactly as G calls of :meth:`mean_over` would (the Markov
        recursion runs over the knots of all groups together). A group without instants
        gets NaN."""
        tt = np.asarray(t, dtype=float).reshape(-1)
        grp = np.asarray(group).reshape(-1)
        if (
            grp.shape != tt.shape
            or not np.issubdtype(grp.dtype, np.integer)
            or (grp.size and grp.min() < 0)
            or not np.all(np.isfinite(tt))
        ):
            raise ProblemError(
                "biasfield.TrackFit.means_over: expected finite instants t "
                "(T,) and group labels ≥ 0 (T,)"
            )
        ng = int(grp.max()) + 1 if grp.size else 0
        k, u = locate(tt, self.knots)
        cnt = np.bincount(grp, minlength=ng).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (
                np.column_stack(
                    [
                        np.bincount(
                            grp,
                            (1.0 - u) * self.theta[k, c] + u * self.theta[k + 1, c],
                            minlength=ng,
                        )
                        for c in range(2)
                    ]
                )
                / cnt[:, None]
            )
        j0 = np.full(ng, np.iinfo(np.int64).max)
        j1 = np.full(ng, -1)
        np.minimum.at(j0, grp, k)
        np.maximum.at(j1, grp, k + 1)
        empty = cnt == 0
        j0[empty], j1[empty] = 0, 0
        w = j1 - j0 + 1
        wmax = int(w.max()) if ng else 0
        # h[g, m]: weight of knot j0_g + m in group g
        h = np.zeros((ng, max(wmax, 1)))
        np.add.at(h, (grp, k - j0[grp]), (1.0 - u))
        np.add.at(h, (grp, k + 1 - j0[grp]), u)
        h /= np.where(empty, 1.0, cnt)[:, None]
        kk = self.knots.size
        cov = np.zeros((ng, 2, 2))
        gmat = np.zeros((ng, 2, 2))
        eye = np.eye(2)
        for m in range(wmax):
            live = m < w
            j = np.minimum(j0 + m, kk - 1)
            c = self.cov_diag[j]
            hm = np.where(live, h[:, m], 0.0)[:, None, None]
            q = gmat @ c
            cov += hm * (hm * c + q + np.swapaxes(q, 1, 2))
            if m == wmax - 1:
                break
            jn = np.minimum(j, kk - 2)
            a = self.cov_next[jn] @ inv2(self.cov_diag[jn + 1])
            gmat = np.where(live[:, None, None], (gmat + hm * eye) @ a, 0.0)
        cov[empty] = np.nan
        return mean, cov


@dataclass
class Dropped:
    """Plots not used, with the reason: ``counts`` reason → number of plots."""

    counts: dict[str, int] = field(default_factory=dict)

    def add(self, reason: str, n: int) -> None:
        if n:
            self.counts[reason] = self.counts.get(reason, 0) + int(n)

    @property
    def total(self) -> int:
        return sum(self.counts.values())


#: Plots per task of the parallel fits (a task fits whole (radar, object) tracks).
CHUNK_PLOTS = 200_000


def _array(a: np.ndarray) -> np.ndarray:
    return a


class _Take:
    """``source[rows]``, taken only when the task runs or is pickled for a worker: the
    tasks of a national day then hold no copy of the plots' times, positions and heights
    (−32 B per plot in the caller while the fits run; 2-D, 0.7 GB at 2.3·10⁷ plots)."""

    __slots__ = ("rows", "source")

    def __init__(self, source: np.ndarray, rows: np.ndarray) -> None:
        self.source, self.rows = source, rows

    def __reduce__(self) -> tuple[Any, tuple[np.ndarray]]:
        return _array, (self.source[self.rows],)


def _taken(a: Any) -> Any:
    return a.source[a.rows] if isinstance(a, _Take) else a


def _fit_chunk(
    radars: RadarSet,
    radar: int,
    rows: np.ndarray,
    t: FloatArray,
    z: FloatArray,
    height: FloatArray | None,
    bounds: np.ndarray,
    objects: np.ndarray,
    spacing: float,
    gap: float,
    redundancy: int,
) -> tuple[list[TrackFit], int]:
    """Fit the tracks of one radar in one task: track g has the plots
    ``bounds[g]:bounds[g+1]`` (sorted by time) of object ``objects[g]``; ``rows`` their
    indices in the caller's table. Returns the fits and the number of plots of pieces too
    short for their polyline."""
    t, z, height = _taken(t), _taken(z), _taken(height)
    vinv = inv2(
        radars.cartesian_cov(radar, z)
        if height is None
        else radars.cartesian_cov(radar, z, height=height)
    )
    short = 0
    jobs: list[tuple[int, np.ndarray, FloatArray, tuple[FloatArray, ...]]] = []
    for g in range(objects.size):
        lo, hi = int(bounds[g]), int(bounds[g + 1])
        for piece in split_at_gaps(t[lo:hi], gap):
            sel = piece + lo
            knots = polyline_knots(t[sel], spacing)
            if 2 * sel.size < 2 * knots.size + redundancy:
                short += sel.size
                continue
            jobs.append(
                (int(objects[g]), sel, knots, normal_band(t[sel], knots, vinv[sel], z[sel]))
            )
    solved = solve_bands([j[3][:3] for j in jobs])
    fits: list[TrackFit] = []
    for (obj, sel, knots, (_, _, _, idx, u)), sol in zip(jobs, solved, strict=True):
        if sol is None:
            short += sel.size
            continue
        theta, cdiag, cnext = sol
        fitted = (1.0 - u)[:, None] * theta[idx] + u[:, None] * theta[idx + 1]
        white = whiten(vinv[sel], z[sel] - fitted)
        fits.append(
            TrackFit(
                radar,
                obj,
                knots,
                theta,
                cdiag,
                cnext,
                rows[sel],
                float(np.sum(white**2)),
                int(2 * sel.size - 2 * knots.size),
                white,
            )
        )
    return fits, short


def _tasks(
    plots: PlotTable, radars: RadarSet, z_all: FloatArray, chunk: int
) -> list[tuple[Any, ...]]:
    """The (radar, object) tracks in tasks of about ``chunk`` plots, in a fixed order
    (radar, then object, then time): the same fits whatever runs them."""
    heights = plots.height if getattr(radars, "is_3d", False) else None
    known = np.flatnonzero(plots.object >= 0)
    order = known[np.lexsort((plots.time[known], plots.object[known], plots.radar[known]))]
    rad, obj = plots.radar[order], plots.object[order]
    new = np.flatnonzero(np.concatenate([[True], (rad[1:] != rad[:-1]) | (obj[1:] != obj[:-1])]))
    starts = np.append(new, order.size)
    tasks: list[tuple[Any, ...]] = []
    g = 0
    while g < new.size:
        i = int(rad[new[g]])
        g1 = g + 1
        # whole tracks of one radar, up to ``chunk`` plots (at least one track)
        while g1 < new.size and int(rad[new[g1]]) == i and starts[g1 + 1] - starts[g] <= chunk:
            g1 += 1
        lo, hi = int(starts[g]), int(starts[g1])
        rows = order[lo:hi]
        tasks.append(
            (
                radars,
                i,
                rows,
                _Take(plots.time, rows),
                _Take(z_all, rows),
                None if heights is None else _Take(heights, rows),
                starts[g : g1 + 1] - lo,
                obj[new[g:g1]],
            )
        )
        g = g1
    return tasks


def _as_scheduler(fn: str, scheduler: Any) -> Any:
    """The scheduler in the one vocabulary (:func:`optmodels.execution.as_scheduler`;
    ``None`` is ``"serial"``)."""
    from optmodels.execution import as_scheduler

    return as_scheduler(f"{fn} scheduler", scheduler, default="serial")


def fit_tracks(
    plots: PlotTable,
    radars: RadarSet,
    *,
    knot_spacing: float = 20.0,
    max_gap: float | None = None,
    min_redundancy: int = 2,
    scheduler: Any = None,
    workers: int | None = None,
    chunk: int = CHUNK_PLOTS,
    positions: ArrayLike | None = None,
) -> tuple[list[TrackFit], Dropped]:
    """GLS polyline fits (3) of every (radar, object) track of ``plots``.

    Plots with ``object == -1`` cannot be assigned to a track and are dropped (counted).
    ``max_gap`` (s, default ``knot_spacing``) splits tracks at longer silences; each piece
    gets knots at the multiples of ``knot_spacing`` (s) that bracket it, and knots whose
    support holds no plot are removed (the polyline then spans the gap linearly). A 3-D
    radar set uses each plot's height for its covariance.

    The tracks are independent: ``scheduler`` runs them here (``None`` or ``"serial"``),
    on ``workers`` local processes (``"processes"``: a spawn pool whose workers exit with
    the parent and leave Ctrl-C to it, :func:`optmodels.execution.execute`), or on Dask
    (a ``distributed.Client``, or its address ``tcp://host:8786``), in tasks of whole
    tracks of about ``chunk`` plots. The fits are the same whatever runs them (same
    tasks, same order: radar, object, time).
    ``positions`` (n, 2): the plots' positions on the common plane if already computed
    (``plots.cartesian(radars)``; the exact 3-D placement costs ~11 s per 10⁶ plots).

    Returns
    -------
    tuple
        The fits (ordered by radar, object, time) and the dropped-plot counts.
    """
    from optmodels.execution import MAX_WORKERS, execute

    fn = "biasfield.fit_tracks"
    knot_spacing = as_positive(f"{fn} knot_spacing (s)", knot_spacing)
    gap = knot_spacing if max_gap is None else as_positive(f"{fn} max_gap (s)", max_gap)
    min_redundancy = as_count(f"{fn} min_redundancy", min_redundancy)
    chunk = as_count(f"{fn} chunk (plots)", chunk, minimum=1)
    if workers is not None:
        workers = as_count(f"{fn} workers", workers, minimum=1, maximum=MAX_WORKERS)
    engine = _as_scheduler(fn, scheduler)
    check_tables(fn, plots, radars)
    plots.check(radars)
    z_all = (
        plots.cartesian(radars)
        if positions is None
        else as_finite_array(
            f"{fn} positions (m)", positions, shape=(len(plots), 2), max_abs=MAX_MAGNITUDE
        )
    )
    dropped = Dropped()
    dropped.add("no object id", int(np.sum(plots.object < 0)))
    if not np.any(plots.object >= 0):
        raise ProblemError(
            f"{fn} plots: no plot with an object id is left ({len(plots)} "
            "plots; were they all dropped by the reader or the cleaning?)"
        )
    tasks = [
        (*task, knot_spacing, gap, min_redundancy) for task in _tasks(plots, radars, z_all, chunk)
    ]
    results: list[tuple[list[TrackFit], int] | None] = [None] * len(tasks)

    trim = _heap_trimmer() if engine != "serial" else None

    def keep(k: int, res: tuple[list[TrackFit], int]) -> None:
        results[k] = res
        if trim is not None:
            trim(0)  # the unpickling buffers of each result, back to the OS

    execute(_fit_chunk, tasks, on_result=keep, scheduler=engine, workers=workers, what=fn)
    fits: list[TrackFit] = []
    for res in results:
        assert res is not None  # execute raises rather than lose a task
        fits.extend(res[0])
        dropped.add("too few plots for the polyline", res[1])
    return fits, dropped


def _heap_trimmer() -> Any:
    """glibc's ``malloc_trim`` (None elsewhere). Results received from workers are
    unpickled between freed receive buffers; without trimming, the freed heap stays in
    the process (measured: +40 % of the fits' own size in resident memory)."""
    import ctypes
    import ctypes.util

    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return None


@dataclass(frozen=True)
class ResidualCheck:
    """Per radar: whitened-residual ``mean`` (m, 2) and covariance ``cov`` (m, 2, 2),
    ``chi2``, ``dof`` and the upper-tail ``p_value`` of Σχ² (the paper's check that the
    track model (3) fits: mean ≈ 0 and covariance ≈ V_i, i.e. ≈ (1 − p/n)I whitened)."""

    mean: FloatArray
    cov: FloatArray
    chi2: FloatArray
    dof: np.ndarray
    p_value: FloatArray


def residual_check(fits: list[TrackFit], m: int) -> ResidualCheck:
    """Pool the whitened residuals of ``fits`` per radar (0..m−1)."""
    from scipy import stats

    m = as_count("biasfield.residual_check m", m, minimum=1)
    if not isinstance(fits, list | tuple) or not all(isinstance(f, TrackFit) for f in fits):
        raise ProblemError(
            "biasfield.residual_check fits: expected a list of TrackFit (e.g. "
            f"Diagnostics.fits), got {type(fits).__name__}"
        )

    mean = np.full((m, 2), np.nan)
    cov = np.full((m, 2, 2), np.nan)
    chi2 = np.zeros(m)
    dof = np.zeros(m, dtype=int)
    for i in range(m):
        mine = [f for f in fits if f.radar == i]
        if not mine:
            continue
        w = np.concatenate([f.whitened for f in mine])
        mean[i], cov[i] = w.mean(axis=0), np.cov(w.T)
        chi2[i] = sum(f.chi2 for f in mine)
        dof[i] = sum(f.dof for f in mine)
    with np.errstate(invalid="ignore"):
        p = np.where(dof > 0, stats.chi2.sf(chi2, np.maximum(dof, 1)), np.nan)
    return ResidualCheck(mean, cov, chi2, dof, p)
