r"""The steps of :func:`optmodels.plane.track`: the window fits of a chunk of steps and the
plane-change detector on them (paper 000 (1.2)-(1.8); :mod:`optmodels.plane.detector`).

* :func:`_lows` / :func:`_splits`: the first index of each step's window and the split
  (last point of the reference) of each step for one test-segment length;
* :class:`_Fits`: the fits of the windows ``base..end-1`` of a chunk;
  :func:`_fits_proportional` (the closed form (1.5)-(1.7) of every window from running
  sums, under (1.4)) and :func:`_fits_general` (:func:`~optmodels.plane.general.fit_general`
  per window, warm-started);
* :func:`_detect`: the linearised Chow statistic U (max over the scales), its split and
  the detectable tilts of the chunk's steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optmodels.core import REJECT_TOL, FloatArray, ProblemError
from optmodels.plane.closedform import _closed_form_from_sums
from optmodels.plane.data import PlaneData
from optmodels.plane.detector import (
    change_statistic,
    detectable_tilt,
    noise_info_moments,
    noise_info_points,
    reference_information,
    reference_tilt_sd,
    score_info_moments,
    score_info_points,
    velocity_direction,
)
from optmodels.plane.statistics import _planarity_arrays
from optmodels.plane.verify import _tangent_basis
from optmodels.plane.windows import Moments, range_moments

__all__: list[str] = []


def _lows(t: FloatArray, window: float | int | None, origin: int) -> np.ndarray:
    """First index of each step's window (all N steps), clipped at ``origin``."""
    n = len(t)
    if window is None:
        lo = np.zeros(n, dtype=np.int64)
    elif isinstance(window, int):
        lo = np.arange(n, dtype=np.int64) - window + 1
    else:
        lo = np.searchsorted(t, t - window, side="right").astype(np.int64)
    return np.maximum(lo, origin)


def _splits(t: FloatArray, scale: float, window: float | int | None) -> np.ndarray:
    """Split index s_j (last point of the reference) of every step j for one scale."""
    n = len(t)
    if isinstance(window, int):
        return np.arange(n, dtype=np.int64) - int(scale)
    return (np.searchsorted(t, t - scale, side="right") - 1).astype(np.int64)


@dataclass
class _Fits:
    """Window fits of the indices ``base..end-1`` (row r ↔ index base + r)."""

    normal: FloatArray
    offset: FloatArray
    stat: FloatArray
    count: FloatArray
    line_stat: FloatArray
    line_dir: FloatArray
    err: FloatArray
    resolved: np.ndarray
    base: int = 0
    moments: Moments | None = None
    info_cold: int = 0
    warm: FloatArray | None = None


def _fits_proportional(
    data: PlaneData, lo: np.ndarray, base: int, end: int, spread: float, lv: float
) -> _Fits:
    """Closed form of the windows ``[lo_i, i]``, ``base <= i < end``."""
    assert data.base_cov is not None and data.alpha2 is not None
    hi = np.arange(base, end)
    lo = lo[base:end]
    w = 1.0 / data.alpha2
    mom = range_moments(data.points, w, lo, hi, origin=int(lo.min()), spread=spread)
    count = mom.count
    eig = _closed_form_from_sums(
        mom.s0, np.zeros_like(mom.mean), mom.q, mom.qabs, count, data.base_cov / spread**2
    )
    normal = eig.normal
    offset = np.sum(normal * mom.mean, axis=1)  # (1.7) about the window's weighted mean
    lead = np.take_along_axis(normal, np.argmax(normal != 0, axis=-1)[:, None], -1)[:, 0]
    flip = (offset < 0) | ((offset == 0) & (lead < 0))
    normal = np.where(flip[:, None], -normal, normal)
    offset = np.abs(offset)
    stat = eig.check.rho
    line_stat = eig.lam[:, 0] + eig.lam[:, 1]
    err = eig.check.step
    small = count < 4
    with np.errstate(invalid="ignore", divide="ignore"):
        arr = _planarity_arrays(
            stat, np.maximum(count, 4.0), lv, line_stat, (err <= REJECT_TOL) & ~small
        )
    return _Fits(
        normal=normal,
        offset=offset,
        stat=np.where(small, np.nan, stat),
        count=count,
        line_stat=line_stat,
        line_dir=eig.line,
        err=err,
        resolved=arr["resolved"],
        base=base,
        moments=mom,
    )


def _fits_general(
    data: PlaneData, lo: np.ndarray, base: int, end: int, lv: float, warm: FloatArray | None
) -> _Fits:
    """fit_general on every window ``[lo_i, i]``, ``base <= i < end``, warm-started from
    the previous window's normal (cold again where the warm run is not OK)."""
    from optmodels.plane.general import fit_general

    m = end - base
    out = _Fits(
        normal=np.full((m, 3), np.nan),
        offset=np.full(m, np.nan),
        stat=np.full(m, np.nan),
        count=np.zeros(m),
        line_stat=np.full(m, np.nan),
        line_dir=np.full((m, 3), np.nan),
        err=np.full(m, np.inf),
        resolved=np.zeros(m, dtype=bool),
        base=base,
    )
    for r in range(m):
        i = base + r
        a = int(lo[i])
        out.count[r] = i - a + 1
        if out.count[r] < 4:
            continue
        x = data.points[a : i + 1]
        c = data.covs[a : i + 1]
        try:
            fit = fit_general(x, c, normal0=warm, level=lv)
            cold = warm is None
            if warm is not None and not fit.ok:
                fit = fit_general(x, c, level=lv)
                cold = True
        except ProblemError:  # collinear (or identical) to round-off: no plane
            y = x - x.mean(axis=0)
            d = np.linalg.svd(y, full_matrices=False)[2][0]
            out.line_dir[r] = d if d[np.argmax(np.abs(d))] > 0 else -d
            out.stat[r] = 0.0
            out.line_stat[r] = 0.0
            warm = None
            continue
        out.normal[r] = fit.normal
        out.offset[r] = fit.offset
        out.stat[r] = fit.objective
        out.line_stat[r] = fit.line_statistic
        out.line_dir[r] = fit.line_direction
        out.err[r] = fit.numerical_error
        out.resolved[r] = bool(fit.resolved and fit.ok)
        if fit.ok:
            warm = fit.normal
        out.info_cold += int(cold)
    out.warm = warm
    return out


def _detect(
    data: PlaneData,
    t: FloatArray,
    fits: _Fits,
    origin: int,
    report: int,
    end: int,
    splits: list[np.ndarray],
    min_ref: int,
    spread: float,
    lam_star: float,
    general: bool,
    max_sd: float,
) -> tuple[FloatArray, np.ndarray, FloatArray, FloatArray]:
    """Detector statistic (max over scales), its split index and the detectable tilts for
    the steps ``report..end-1`` (the fits hold the windows ``fits.base..end-1``)."""
    steps = np.arange(report, end)
    best = np.full(len(steps), -np.inf)
    arg = np.full(len(steps), -1, dtype=np.int64)
    tilt = np.full(len(steps), np.inf)
    tilt_any = np.full(len(steps), np.inf)
    any_test = np.zeros(len(steps), dtype=bool)
    for sp_idx in splits:
        s = sp_idx[steps]
        ok = (s >= origin) & (steps - s >= 3)
        rows = np.where(ok, s - fits.base, 0)
        ok &= fits.resolved[rows] & (fits.count[rows] >= min_ref)
        if not np.any(ok):
            continue
        jj = steps[ok]
        ss = s[ok]
        ra = ss - fits.base
        na = fits.normal[ra]
        aa = fits.offset[ra]
        junction = data.points[ss]
        if general:
            ja = np.empty((len(jj), 3, 3))
            ba = np.empty((len(jj), 3))
            jb = np.empty_like(ja)
            bb = np.empty_like(ba)
            ell = np.empty(len(jj))
            na_noise = np.empty_like(ja)
            nb_noise = np.empty_like(ja)
            frames = _tangent_basis(na)
            for q, (j, s_, nrm, off) in enumerate(zip(jj, ss, na, aa, strict=True)):
                a0 = int(s_ - fits.count[s_ - fits.base] + 1)
                xa = data.points[a0 : s_ + 1]
                ell[q] = max(
                    float(np.sqrt(np.mean(np.sum((xa - xa.mean(0)) ** 2, 1)))) / spread, 1e-300
                )
                ca = data.covs[a0 : s_ + 1]
                ja[q], ba[q] = score_info_points(
                    nrm, off, junction[q], xa, ca, spread, ell[q], frames[q]
                )
                na_noise[q] = noise_info_points(nrm, ca, spread, ell[q], frames[q])
                cb = data.covs[s_ + 1 : j + 1]
                jb[q], bb[q] = score_info_points(
                    nrm,
                    off,
                    junction[q],
                    data.points[s_ + 1 : j + 1],
                    cb,
                    spread,
                    ell[q],
                    frames[q],
                )
                nb_noise[q] = noise_info_points(nrm, cb, spread, ell[q], frames[q])
        else:
            assert fits.moments is not None and data.base_cov is not None
            assert data.alpha2 is not None
            ma = fits.moments
            mom_a = Moments(
                s0=ma.s0[ra],
                mean=ma.mean[ra],
                q=ma.q[ra],
                qabs=ma.qabs[ra],
                count=ma.count[ra],
                spread=spread,
                recomputed=ma.recomputed[ra],
            )
            mom_b = range_moments(
                data.points, 1.0 / data.alpha2, ss + 1, jj, origin=int(ss.min()) + 1, spread=spread
            )
            ell = np.sqrt(np.maximum(np.trace(mom_a.q, axis1=1, axis2=2) / mom_a.s0, 1e-300))
            ja, ba = score_info_moments(na, aa, junction, mom_a, data.base_cov, ell)
            jb, bb = score_info_moments(na, aa, junction, mom_b, data.base_cov, ell)
            na_noise = noise_info_moments(na, mom_a.count, data.base_cov, ell, spread)
            nb_noise = noise_info_moments(na, mom_b.count, data.base_cov, ell, spread)
        # errors in variables (the noise of the in-plane coordinates): the reference's
        # information K_A (J_A overstates it on short, densely sampled arcs) and S_B, which
        # carries the reference's error into B's score (detector module docstring)
        ka, valid = reference_information(ja, na_noise)
        firm = valid & (reference_tilt_sd(ka, ell) <= max_sd)
        ja = np.where(firm[:, None, None], ja, np.eye(3))  # (placeholders where not firm)
        ka = np.where(firm[:, None, None], ka, np.eye(3))
        sb = jb - nb_noise
        beta_a: FloatArray = np.linalg.solve(ja, ba[..., None])[..., 0].astype(float)
        u = np.where(firm, change_statistic(ka, beta_a, jb, bb, sb), -np.inf)
        back = np.minimum(5, fits.count[ra].astype(np.int64) - 1)
        vel = velocity_direction(na, _tangent_basis(na), data.points, ss, back)
        th = np.where(firm, detectable_tilt(ka, jb, ell, lam_star, vel, sb), np.inf)
        th_any = np.where(firm, detectable_tilt(ka, jb, ell, lam_star, sb=sb), np.inf)
        pos = np.flatnonzero(ok)
        better = u > best[pos]
        best[pos[better]] = u[better]
        arg[pos[better]] = ss[better]
        tilt[pos] = np.minimum(tilt[pos], th)
        tilt_any[pos] = np.minimum(tilt_any[pos], th_any)
        any_test[pos] |= firm
    best = np.where(any_test, best, np.nan)
    tilt = np.where(any_test, tilt, np.nan)
    tilt_any = np.where(any_test, tilt_any, np.nan)
    return best, arg, tilt, tilt_any
