r"""The arguments of :func:`optmodels.plane.tracking.track` checked (paper 000 along a
track): :func:`_validate` turns them into a :class:`_Setup` -- the data (:class:`PlaneData`,
detection of (1.4)), the times, the window (:func:`~optmodels.plane.windows.window_spec`),
the levels, the test scales (:func:`_scales_arg`), the first reported step, and what
follows from them alone: the detector's threshold and per-test level
(:func:`~optmodels.plane.detector.detector_threshold`), the noncentrality behind the power
figure and the splits of every scale. Every refusal is one ``ProblemError`` naming the
argument (``"plane.track <argument>"``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_count,
    as_finite_array,
    as_number,
    as_positive,
    as_probability,
)
from optmodels.plane.data import PlaneData
from optmodels.plane.detector import detector_threshold, noncentrality_for_power
from optmodels.plane.track_steps import _splits
from optmodels.plane.windows import track_spread, window_spec

_W = "plane.track"
#: Default test-segment lengths as fractions of the window (time or count).
_SCALE_FRACTIONS = (0.125, 0.25, 0.5)
#: Default scales (s) for a growing window.
_GROWING_SCALES = (5.0, 10.0, 20.0)


def _scales_arg(scales: Any, window: float | int | None) -> tuple[float, ...]:
    """The detector's test-segment lengths, sorted and distinct: ``scales`` checked
    (seconds, or counts ≥ 3 with a points window; at most half the window), or the
    defaults (1/8, 1/4, 1/2 of the window; 5, 10, 20 s for a growing window)."""
    if scales is None:
        if window is None:
            return _GROWING_SCALES
        if isinstance(window, int):
            return tuple(sorted({max(3, round(f * window)) for f in _SCALE_FRACTIONS}))
        return tuple(f * window for f in _SCALE_FRACTIONS)
    try:
        items = list(scales)
    except TypeError:
        raise ProblemError(f"{_W} scales: expected a sequence of lengths, got {scales!r}") from None
    if not items:
        raise ProblemError(f"{_W} scales: at least one test-segment length is needed")
    if isinstance(window, int):
        out = tuple(float(as_count(f"{_W} scales[{i}]", s, minimum=3)) for i, s in enumerate(items))
    else:
        out = tuple(as_positive(f"{_W} scales[{i}]", s) for i, s in enumerate(items))
    if window is not None and max(out) > 0.5 * window:
        # the reference is the window's part before the test segment: a segment longer than
        # half the window leaves a reference too short to be firm (false alarms, found by review)
        raise ProblemError(
            f"{_W} scales: test segments of at most half the window "
            f"({0.5 * window:g} {'points' if isinstance(window, int) else 's'})"
            f" are allowed, got {max(out):g}"
        )
    return tuple(sorted(set(out)))


@dataclass(frozen=True)
class _Setup:
    """The checked arguments of :func:`~optmodels.plane.tracking.track` and what follows
    from them alone."""

    data: PlaneData
    t: FloatArray
    win: float | int | None
    lv: float
    far_h: float
    pw: float
    min_ref: int
    max_sd: float
    sc: tuple[float, ...]
    first: int
    dt: float
    thr: float
    p_test: float
    lam_star: float
    general: bool
    spread: float
    splits: list[np.ndarray]

    @property
    def n(self) -> int:
        return self.data.n_points


def _validate(
    times: ArrayLike,
    points: ArrayLike,
    cov: ArrayLike,
    *,
    window: str | None,
    window_points: int | None,
    window_seconds: float | None,
    level: float,
    false_alarm_rate_per_h: float,
    alpha2: ArrayLike | None,
    start: float | None,
    scales: Any,
    power: float,
    min_reference: int,
    max_reference_sd: float,
    false_alarm_rate: Any,
) -> _Setup:
    """Every argument of :func:`~optmodels.plane.tracking.track` checked (one
    ``ProblemError`` naming it), and the detector's threshold, the scales and the splits."""
    try:
        data = PlaneData(points, cov, alpha2)  # type: ignore[arg-type]  # (checked there)
    except ProblemError as exc:
        raise ProblemError(f"{_W}: {exc}") from None
    n = data.n_points
    t = as_finite_array(f"{_W} times", times, shape=(n,), max_abs=1e100)
    if np.any(np.diff(t) <= 0):
        raise ProblemError(f"{_W} times: must be strictly increasing")
    win = window_spec(window, window_points=window_points, window_seconds=window_seconds)
    lv = as_probability(f"{_W} level", level, low_open=True, high_open=True)
    if false_alarm_rate is not None:
        raise ProblemError(
            f"{_W} false_alarm_rate: renamed false_alarm_rate_per_h, false "
            "alarms per HOUR (it was per second); write false_alarm_rate_per_h"
            f"={3600.0 * float(false_alarm_rate):g} for the same bound"
            if isinstance(false_alarm_rate, int | float)
            else f"{_W} false_alarm_rate: renamed false_alarm_rate_per_h (per hour)"
        )
    far_h = as_positive(f"{_W} false_alarm_rate_per_h", false_alarm_rate_per_h)
    pw = as_probability(f"{_W} power", power, low_open=True, high_open=True)
    min_ref = as_count(f"{_W} min_reference", min_reference, minimum=4)
    max_sd = as_positive(f"{_W} max_reference_sd", max_reference_sd, allow_inf=True)
    sc = _scales_arg(scales, win)
    if isinstance(win, float) and n > 1:
        dt = float(np.median(np.diff(t)))
        if win < 3.0 * dt:  # a plane needs 4 points: found by review (n_points = 1 per step)
            raise ProblemError(
                f"{_W} window_seconds: {win:g} s holds fewer than 4 measurements at "
                f"the median sampling interval {dt:g} s; give at least "
                f"{3.0 * dt:g} s"
            )
    if start is None:
        first = 3
        if first >= n:  # issue 28: the message named "t = None"
            raise ProblemError(f"{_W} times: {n} measurements; a step needs at least 4")
    else:
        t0 = as_number(f"{_W} start", start)
        first = max(int(np.searchsorted(t, t0, side="left")), 3)
        if first >= n:
            raise ProblemError(
                f"{_W} start: no step with at least 4 measurements at or after t = {t0:g} s"
            )
    dt = float(np.median(np.diff(t)))
    thr, p_test = detector_threshold(far_h / 3600.0, dt, len(sc))
    if not p_test < 0.5:
        raise ProblemError(
            f"{_W} false_alarm_rate_per_h: {far_h:g} per hour with a sampling "
            f"interval of {dt:g} s and {len(sc)} scales gives a per-test "
            f"level {p_test:.3g}; must be < 0.5"
        )
    return _Setup(
        data=data,
        t=t,
        win=win,
        lv=lv,
        far_h=far_h,
        pw=pw,
        min_ref=min_ref,
        max_sd=max_sd,
        sc=sc,
        first=first,
        dt=dt,
        thr=thr,
        p_test=p_test,
        lam_star=noncentrality_for_power(thr, pw),
        general=not data.proportional,
        spread=track_spread(data.points),
        splits=[_splits(t, s, win) for s in sc],
    )
