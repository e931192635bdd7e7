r"""The plane of maneuver along a track (paper 000): sliding windows, plane-change
detection, resolved/unresolved steps and the detector's power, one record per step.

:func:`track` re-estimates the ML plane (1.2)-(1.3) after every measurement from the
points of a window -- growing (no window, as :func:`identify_sequence`), the last
``window_seconds`` seconds or the last ``window_points`` points
(:func:`~optmodels.plane.windows.window_spec`; a bare ``window=40`` is refused as
ambiguous) -- and runs the
plane-change detector of :mod:`optmodels.plane.detector` on the stream. After an alarm
the detector restarts: the windows forget every point before the estimated change
(the split of the alarming test), so that the next plane is estimated from the new
motion only.

* Proportional covariances (1.4), :math:`D_i = \alpha_i^2 D` (``cov`` (3, 3), or a stack
  detected as proportional): the closed form (1.5)-(1.7) of every window from running
  weighted sums with removal (:mod:`optmodels.plane.windows`), the re-check of
  :func:`optmodels.plane.closed_form` on every step, all steps at once.
* General :math:`D_i` (e.g. one radar): :func:`optmodels.plane.general.fit_general` on
  each window, warm-started from the previous step's normal (re-solved cold when the warm
  run does not converge), with its own line test and re-check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import FloatArray, timed
from optmodels.plane.statistics import _planarity_arrays
from optmodels.plane.track_setup import _Setup, _validate
from optmodels.plane.track_steps import _detect, _fits_general, _fits_proportional, _lows
from optmodels.plane.windows import window_label

__all__ = ["PlaneTrack", "track"]

_ARRAYS = (
    "times",
    "n_points",
    "window_start",
    "normals",
    "offsets",
    "statistic",
    "dof",
    "threshold",
    "p_value",
    "resolved",
    "planar",
    "line_statistic",
    "line_threshold",
    "line_direction",
    "numerical_error",
    "change",
    "detector",
    "detector_threshold",
    "change_time",
    "detectable_tilt",
    "detectable_tilt_any",
)


@dataclass
class PlaneTrack:
    """The plane along a track, one record per step (K steps: the measurements from
    ``start`` on). Arrays over steps; angles in rad, lengths in m, times in s.

    Attributes
    ----------
    times : (K,) time of the step (its newest measurement).
    n_points : (K,) points in the step's window; window_start : (K,) time of its oldest.
    normals : (K, 3), offsets : (K,)
        The ML plane ⟨n, x⟩ = a of the window (offset ≥ 0); NaN where not ``resolved``.
    statistic : (K,) Λ_min (1.16), the minimum of (1.2) on the window (χ²(n − 3) if
        planar); dof : (K,) n − 3; threshold : (K,) ``chi2.ppf(level, dof)``;
        p_value : (K,) NaN where not resolved.
    resolved : (K,) bool
        The window determines the plane: its points are not on a line at ``level``
        (``line_statistic > line_threshold``, Λ₁ + Λ₂ vs χ²(2n − 4)) and the normal passes
        its numerical re-check (``numerical_error`` ≤ 1e-3 rad). Where False: NaN normal
        and offset, ``planar`` False, ``line_direction`` the line the data determine.
    planar : (K,) bool, resolved and ``statistic <= threshold``.
    line_statistic, line_threshold : (K,); line_direction : (K, 3) NaN where resolved.
    numerical_error : (K,) estimated error (rad) of the normal (re-check).
    change : (K,) bool
        The detector fires at this step (``detector > detector_threshold``); it then
        restarts from the estimated change.
    detector : (K,) the largest Chow statistic U over the test scales (χ²(3) if the plane
        did not change; NaN where no test was possible: no resolved reference window).
    detector_threshold : (K,) its threshold c (constant along the track).
    change_time : (K,) at an alarm, the estimated time of the change (the last point of
        the reference window of the alarming test); NaN elsewhere.
    detectable_tilt : (K,) rad
        The power figure: the tilt of the plane about the velocity at the split (a bank
        change -- the plane of a continuous maneuver always contains the velocity) that
        this step's test detects with probability ``power``, best over the scales; NaN
        where no test, inf where no tilt is. "With these covariances and this window the
        detector cannot reliably see a bank change below this."
    detectable_tilt_any : (K,) rad
        The same for the least informed direction of rotation (≥ ``detectable_tilt``).
    level, false_alarm_rate_per_h, power : the settings (false alarms per hour).
    window : None, float (s) or int (points), as :func:`window_spec` returns it
        (:func:`window_label` gives its text, ``"40s"``); scales : the test-segment
        lengths (s, or points with a points window).
    method : "closed_form" (1.4) or "general" (:func:`fit_general`).
    test_level : the level p of each test (``false_alarm_rate · dt / len(scales)``).
    solve_time : float, s for the whole track.
    """

    times: FloatArray
    n_points: FloatArray
    window_start: FloatArray
    normals: FloatArray
    offsets: FloatArray
    statistic: FloatArray
    dof: FloatArray
    threshold: FloatArray
    p_value: FloatArray
    resolved: np.ndarray
    planar: np.ndarray
    line_statistic: FloatArray
    line_threshold: FloatArray
    line_direction: FloatArray
    numerical_error: FloatArray
    change: np.ndarray
    detector: FloatArray
    detector_threshold: FloatArray
    change_time: FloatArray
    detectable_tilt: FloatArray
    detectable_tilt_any: FloatArray
    level: float = 0.997
    false_alarm_rate_per_h: float = 1.0
    power: float = 0.9
    window: float | int | None = None
    scales: tuple[float, ...] = ()
    method: str = "closed_form"
    test_level: float = float("nan")
    solve_time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def false_alarm_rate(self) -> float:
        """The bound in false alarms per SECOND (``false_alarm_rate_per_h / 3600``)."""
        return self.false_alarm_rate_per_h / 3600.0

    @property
    def n_steps(self) -> int:
        return len(self.times)

    @property
    def change_times(self) -> FloatArray:
        """Times (s) of the steps at which the detector fired."""
        return self.times[self.change]

    def to_rows(self) -> list[dict[str, Any]]:
        """One plain dict per step (floats, bools; NaN kept) for a CSV writer: ``time,
        nx, ny, nz, offset, statistic, threshold, resolved, planar, change, detector,
        detector_threshold, change_time, detectable_tilt, detectable_tilt_any, n_points,
        window_start,
        line_x, line_y, line_z, numerical_error, p_value``."""
        rows = []
        for k in range(self.n_steps):
            n = self.normals[k]
            ld = self.line_direction[k]
            rows.append(
                {
                    "time": float(self.times[k]),
                    "nx": float(n[0]),
                    "ny": float(n[1]),
                    "nz": float(n[2]),
                    "offset": float(self.offsets[k]),
                    "statistic": float(self.statistic[k]),
                    "threshold": float(self.threshold[k]),
                    "resolved": bool(self.resolved[k]),
                    "planar": bool(self.planar[k]),
                    "change": bool(self.change[k]),
                    "detector": float(self.detector[k]),
                    "detector_threshold": float(self.detector_threshold[k]),
                    "change_time": float(self.change_time[k]),
                    "detectable_tilt": float(self.detectable_tilt[k]),
                    "detectable_tilt_any": float(self.detectable_tilt_any[k]),
                    "n_points": int(self.n_points[k]),
                    "window_start": float(self.window_start[k]),
                    "line_x": float(ld[0]),
                    "line_y": float(ld[1]),
                    "line_z": float(ld[2]),
                    "numerical_error": float(self.numerical_error[k]),
                    "p_value": float(self.p_value[k]),
                }
            )
        return rows

    def to_dict(self) -> dict[str, Any]:
        """Plain lists for JSON: every array over steps, NaN and ±inf as ``None``, plus
        the settings."""

        def clean(a: np.ndarray) -> Any:
            if a.dtype == bool:
                return a.tolist()
            obj = a.astype(object)
            obj[~np.isfinite(a)] = None
            return obj.tolist()

        out: dict[str, Any] = {k: clean(np.asarray(getattr(self, k))) for k in _ARRAYS}
        out.update(
            level=self.level,
            false_alarm_rate_per_h=self.false_alarm_rate_per_h,
            power=self.power,
            window=window_label(self.window),
            scales=list(self.scales),
            method=self.method,
            test_level=self.test_level,
            solve_time=self.solve_time,
            n_steps=self.n_steps,
            change_times=self.change_times.tolist(),
        )
        return out


# =========================================================================== entry
def track(
    times: ArrayLike,
    points: ArrayLike,
    cov: ArrayLike,
    *,
    window: str | None = None,
    window_points: int | None = None,
    window_seconds: float | None = None,
    level: float = 0.997,
    false_alarm_rate_per_h: float = 1.0,
    alpha2: ArrayLike | None = None,
    start: float | None = None,
    scales: Any = None,
    power: float = 0.9,
    min_reference: int = 8,
    max_reference_sd: float = 0.1,
    false_alarm_rate: Any = None,
) -> PlaneTrack:
    r"""The plane of maneuver along a track, with plane-change detection.

    Parameters
    ----------
    times : (N,) strictly increasing measurement times (s).
    points : (N, 3) measured positions (m), any Cartesian frame.
    cov : (3, 3) or (N, 3, 3)
        Error covariances D_i (m², same frame): a (3, 3) ``D`` with ``alpha2`` for (1.4),
        or one per point (proportional stacks are detected; others use
        :func:`optmodels.plane.general.fit_general`).
    window_seconds : float, optional
        The last ``window_seconds`` seconds (points with t > t_k − window_seconds).
    window_points : int, optional
        The last ``window_points`` measurements (≥ 4).
    window : str, optional
        The same as text with its unit: ``"40s"``, ``"100pts"`` or ``"growing"``. At most
        one of the three; none: a growing window (all points since the start or the last
        change). A bare number (``window=40``) is refused: points or seconds? (issue 26;
        :func:`window_spec`).
    level : float
        Level of the χ²(n − 3) planarity test and of the line test behind ``resolved``,
        in (0, 1) (default 0.997 as in the paper).
    false_alarm_rate_per_h : float
        Bound on the detector's false alarms per HOUR of planar track (default 1), for
        every kind of window. Each of the ``len(scales)`` tests of a step has level
        ``rate · dt / len(scales)`` (the rate per second, ``dt`` the median sampling
        interval); their union bounds the rate (see :mod:`optmodels.plane.detector`).
        Alarms may come in clusters after a restart (the bound is on their mean rate).
    alpha2 : (N,), optional
        The factors α_i² of (1.4) with a (3, 3) ``cov``.
    start : float, optional
        First time (s) reported (default: the 4th measurement).
    scales : sequence, optional
        Test-segment lengths of the detector: seconds (float or ``None`` window) or points
        (int window). Default: 1/8, 1/4, 1/2 of the window; (5, 10, 20) s for a growing
        window.
    power : float
        Detection probability behind ``detectable_tilt``, in (0, 1).
    min_reference : int
        Fewest points (≥ 4) in a reference window for a test.
    max_reference_sd : float
        A test is made only when the reference plane is firm: the largest standard
        deviation of its tilts (rad; errors in variables: the noise of the reference's
        in-plane coordinates counted, :func:`~optmodels.plane.detector.reference_information`)
        is at most this (default 0.1 rad ≈ 6°). A barely resolved reference (nearly
        straight, just after a restart, or a short window of many points: ``"100pts"`` at
        10 Hz is 10 s of track) fits its rotation about the line to the noise, and U is
        then not χ²(3); such steps have no test (``detector`` NaN).
    false_alarm_rate : removed
        Was per SECOND; refused with a message: write ``false_alarm_rate_per_h``.

    Returns
    -------
    PlaneTrack
        One record per step; ``to_rows()`` / ``to_dict()`` for CSV / JSON.

    Raises
    ------
    ProblemError
        Naming the argument (``"plane.track <argument>"``; the points and covariances are
        checked by :class:`PlaneData`).
    """
    setup = _validate(
        times,
        points,
        cov,
        window=window,
        window_points=window_points,
        window_seconds=window_seconds,
        level=level,
        false_alarm_rate_per_h=false_alarm_rate_per_h,
        alpha2=alpha2,
        start=start,
        scales=scales,
        power=power,
        min_reference=min_reference,
        max_reference_sd=max_reference_sd,
        false_alarm_rate=false_alarm_rate,
    )
    rec = _records(setup.n - setup.first)
    with timed() as tm:
        restarts = _run(setup, rec)
    return _package(setup, rec, restarts, tm.elapsed)


def _records(k: int) -> dict[str, Any]:
    """The per-step arrays of :func:`track`, NaN/empty for the ``k`` reported steps."""
    return {
        "normal": np.full((k, 3), np.nan),
        "offset": np.full(k, np.nan),
        "stat": np.full(k, np.nan),
        "count": np.zeros(k),
        "wstart": np.full(k, np.nan),
        "line_stat": np.full(k, np.nan),
        "line_dir": np.full((k, 3), np.nan),
        "err": np.full(k, np.inf),
        "resolved": np.zeros(k, dtype=bool),
        "det": np.full(k, np.nan),
        "change": np.zeros(k, dtype=bool),
        "ctime": np.full(k, np.nan),
        "tilt": np.full(k, np.nan),
        "tilt_any": np.full(k, np.nan),
    }


def _run(st: _Setup, rec: dict[str, Any]) -> list[int]:
    """The steps, chunk by chunk, into ``rec``; returns the restart indices. Steps are
    evaluated in chunks, so that a restart costs O(chunk), not O(N): a chunk needs the fits
    of its steps and of the reference windows of its splits."""
    data, t, win, splits, first, n = st.data, st.t, st.win, st.splits, st.first, st.n
    restarts: list[int] = []
    lo0 = _lows(t, win, 0)
    reach = max(int(np.max(np.arange(n) - sp_idx)) for sp_idx in splits)
    w_max = 0 if win is None else int(np.max(np.arange(n) - lo0)) + 1
    # (general D_i: a fit per step, so a smaller chunk wastes less after an alarm)
    chunk0 = max(64, 2 * (reach + w_max)) if st.general else max(512, 4 * (reach + w_max))
    origin = 0
    report = first
    warm: FloatArray | None = None
    while report < n:
        lo = np.maximum(lo0, origin)
        size = chunk0 if win is not None else max(chunk0, report - origin)
        end = min(n, report + size)
        base = max(origin, min(int(sp_idx[report]) for sp_idx in splits))
        base = min(base, report)
        fits = (
            _fits_general(data, lo, base, end, st.lv, warm)
            if st.general
            else _fits_proportional(data, lo, base, end, st.spread, st.lv)
        )
        det, arg_s, tilt, tilt_any = _detect(
            data,
            t,
            fits,
            origin,
            report,
            end,
            splits,
            st.min_ref,
            st.spread,
            st.lam_star,
            st.general,
            st.max_sd,
        )
        alarms = np.flatnonzero(det > st.thr)
        stop = end if alarms.size == 0 else report + int(alarms[0]) + 1
        rows = np.arange(report, stop)
        r_fit = rows - base
        r_out = rows - first
        for key, src in (
            ("normal", fits.normal),
            ("offset", fits.offset),
            ("stat", fits.stat),
            ("count", fits.count),
            ("line_stat", fits.line_stat),
            ("line_dir", fits.line_dir),
            ("err", fits.err),
            ("resolved", fits.resolved),
        ):
            rec[key][r_out] = src[r_fit]
        rec["wstart"][r_out] = t[lo[rows]]
        rec["det"][r_out] = det[: stop - report]
        rec["tilt"][r_out] = tilt[: stop - report]
        rec["tilt_any"][r_out] = tilt_any[: stop - report]
        warm = fits.warm
        if alarms.size == 0:
            report = end
            continue
        j = stop - 1
        s_hat = int(arg_s[stop - 1 - report])
        rec["change"][j - first] = True
        rec["ctime"][j - first] = t[s_hat]
        restarts.append(s_hat + 1)
        origin = s_hat + 1
        report = j + 1
    return restarts


def _package(st: _Setup, rec: dict[str, Any], restarts: list[int], elapsed: float) -> PlaneTrack:
    """The :class:`PlaneTrack` of the steps: the planarity and line tests per step, the
    estimates blanked where not resolved."""
    resolved = rec["resolved"]
    count = rec["count"]
    with np.errstate(invalid="ignore"):
        arr = _planarity_arrays(
            np.nan_to_num(rec["stat"], nan=0.0),
            np.maximum(count, 4.0),
            st.lv,
            np.nan_to_num(rec["line_stat"], nan=0.0),
            resolved,
        )
    normal = np.where(resolved[:, None], rec["normal"], np.nan)
    offset = np.where(resolved, rec["offset"], np.nan)
    line_dir = np.where(resolved[:, None], np.nan, rec["line_dir"])
    k = len(count)
    return PlaneTrack(
        times=st.t[st.first :],
        n_points=count,
        window_start=rec["wstart"],
        normals=normal,
        offsets=offset,
        statistic=rec["stat"],
        dof=count - 3.0,
        threshold=np.asarray(arr["threshold"], dtype=float),
        p_value=arr["p_value"],
        resolved=resolved,
        planar=arr["planar"] & np.isfinite(rec["stat"]),
        line_statistic=rec["line_stat"],
        line_threshold=np.asarray(arr["line_threshold"], dtype=float),
        line_direction=line_dir,
        numerical_error=rec["err"],
        change=rec["change"],
        detector=rec["det"],
        detector_threshold=np.full(k, st.thr),
        change_time=rec["ctime"],
        detectable_tilt=rec["tilt"],
        detectable_tilt_any=rec["tilt_any"],
        level=st.lv,
        false_alarm_rate_per_h=st.far_h,
        power=st.pw,
        window=st.win,
        scales=st.sc,
        method="general" if st.general else "closed_form",
        test_level=st.p_test,
        solve_time=elapsed,
        info={"restarts": restarts, "noncentrality": st.lam_star, "dt": st.dt},
    )
