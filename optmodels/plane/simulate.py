r"""Simulated tracks for the plane-change detector (paper 000): piecewise-planar arcs.

:func:`plane_change_track`: a target flies an arc of radius ``radius1`` in a plane P1
(e.g. a pull-up in a vertical plane, "the climb"), then at ``change_time`` an arc of
radius ``radius2`` in the plane P2 obtained by rotating P1 by ``tilt_deg`` about the
velocity at the junction (a bank: "the climbing turn"). Position and velocity are
continuous at the junction, the speed is constant, and the angle between the normals of
P1 and P2 is exactly ``tilt_deg``. ``tilt_deg=0`` gives one planar track (the null
hypothesis of the detector). Errors: isotropic (σ, m) or those of a radar
(:func:`optmodels.plane.radar_covariances`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from optmodels.core import (
    FloatArray,
    ProblemError,
    as_choice,
    as_generator,
    as_number,
    as_positive,
)
from optmodels.plane.radar import radar_covariances

__all__ = ["PlaneChangeTrack", "plane_change_track"]

_W = "plane.plane_change_track"


@dataclass(frozen=True)
class PlaneChangeTrack:
    """A simulated track with one plane change.

    times (N,) s; truth (N, 3) m; points (N, 3) measurements; cov (3, 3) (isotropic) or
    (N, 3, 3) (radar) m²; change_time (s); normals (2, 3) and offsets (2,) of P1 and P2
    (offset ≥ 0); tilt (rad) the angle between them; segment (N,) 0 before the change,
    1 after.
    """

    times: FloatArray
    truth: FloatArray
    points: FloatArray
    cov: FloatArray
    change_time: float
    normals: FloatArray
    offsets: FloatArray
    tilt: float
    segment: np.ndarray


def _arc(
    p0: FloatArray,
    tangent: FloatArray,
    inward: FloatArray,
    radius: float,
    speed: float,
    tau: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Positions on a circle from p0 (velocity ``speed·tangent``, centre at
    ``p0 + radius·inward``) after times tau; also the tangent and inward at the end."""
    w = speed / radius
    ph = w * tau
    pos = p0 + radius * (np.sin(ph)[:, None] * tangent + (1 - np.cos(ph))[:, None] * inward)
    ph_end = w * tau[-1] if len(tau) else 0.0
    t_end = np.cos(ph_end) * tangent + np.sin(ph_end) * inward
    i_end = -np.sin(ph_end) * tangent + np.cos(ph_end) * inward
    return pos, t_end, i_end


def _plane(normal: FloatArray, point: FloatArray) -> tuple[FloatArray, float]:
    off = float(normal @ point)
    return (normal, off) if off >= 0 else (-normal, -off)


def plane_change_track(
    seed: int | np.random.Generator = 0,
    *,
    tilt_deg: float = 30.0,
    speed: float = 200.0,
    radius1: float = 7e3,
    radius2: float = 7e3,
    climb_deg: float = 0.0,
    roll1_deg: float = 90.0,
    before: float = 120.0,
    after: float = 60.0,
    rate_hz: float = 1.0,
    sigma: float = 50.0,
    errors: str = "isotropic",
    site: FloatArray | None = None,
    sigma_range: float = 10.0,
    sigma_angle: float = 2e-3,
    start: FloatArray | None = None,
) -> PlaneChangeTrack:
    """An arc of radius ``radius1`` m for ``before`` s, heading east with flight-path angle
    ``climb_deg``, its centre rotated by ``roll1_deg`` from "up" towards the left (90: a
    level left turn if ``climb_deg`` = 0; 0: a pull-up in the vertical plane, "the
    climb"), then an arc of radius ``radius2`` m in the plane tilted by ``tilt_deg`` about
    the velocity ("the climbing turn") for ``after`` s (ENU metres, seconds).

    Defaults: 200 m/s; a level turn of 7 km (the radius of a 30° bank at 200 m/s) into a
    climbing turn of 7 km; 1 Hz; σ = 50 m per axis. ``errors="radar"``: a radar at
    ``site`` (default 30 km west and 30 km south of the start, on the ground) with
    ``sigma_range`` (m) and ``sigma_angle`` (rad, azimuth and elevation).
    """
    tilt = np.deg2rad(as_number(f"{_W} tilt_deg", tilt_deg, low=-180.0, high=180.0))
    speed = as_positive(f"{_W} speed", speed)
    radius1 = as_positive(f"{_W} radius1", radius1)
    radius2 = as_positive(f"{_W} radius2", radius2)
    climb = np.deg2rad(as_number(f"{_W} climb_deg", climb_deg, low=-80.0, high=80.0))
    roll1 = np.deg2rad(as_number(f"{_W} roll1_deg", roll1_deg, low=-180.0, high=180.0))
    before = as_positive(f"{_W} before", before)
    after = as_number(f"{_W} after", after, low=0.0)
    rate_hz = as_positive(f"{_W} rate_hz", rate_hz)
    sigma = as_positive(f"{_W} sigma", sigma)
    errors = as_choice(f"{_W} errors", errors, ("isotropic", "radar"))
    n = round((before + after) * rate_hz)
    if n < 8 or n > 10**7:
        raise ProblemError(f"{_W} before, after, rate_hz: {n} samples; need 8 ... 1e7")
    rng = as_generator(_W, seed)
    p0 = np.array([0.0, 0.0, 3000.0]) if start is None else np.asarray(start, dtype=float)
    times = np.arange(n) / rate_hz
    tangent = np.array([np.cos(climb), 0.0, np.sin(climb)])  # heading east, climbing
    up = np.array([-np.sin(climb), 0.0, np.cos(climb)])  # pull-up: centre above
    inward = np.cos(roll1) * up + np.sin(roll1) * np.array([0.0, 1.0, 0.0])
    n1 = np.cross(tangent, inward)
    seg1 = times <= before
    tc = float(times[seg1][-1])
    pos1, t_c, i_c = _arc(p0, tangent, inward, radius1, speed, times[seg1])
    p_c = pos1[-1]
    nc = np.cross(t_c, i_c)  # = n1
    i2 = np.cos(tilt) * i_c + np.sin(tilt) * nc  # the inward direction rotated about t_c
    pos2, _, _ = _arc(p_c, t_c, i2, radius2, speed, times[~seg1] - tc)
    truth = np.vstack([pos1, pos2])
    n2 = np.cross(t_c, i2)
    (m1, a1), (m2, a2) = _plane(n1, p0), _plane(n2, p_c)
    if errors == "isotropic":
        cov = sigma**2 * np.eye(3)
        points = truth + sigma * rng.normal(size=truth.shape)
    else:
        st = np.array([-30e3, -30e3, 0.0]) if site is None else np.asarray(site, dtype=float)
        cov = radar_covariances(truth, st, sigma_range, sigma_angle, sigma_angle)
        chol = np.linalg.cholesky(cov)
        points = truth + (chol @ rng.normal(size=(n, 3, 1)))[..., 0]
    return PlaneChangeTrack(
        times=times,
        truth=truth,
        points=points,
        cov=cov,
        change_time=tc,
        normals=np.array([m1, m2]),
        offsets=np.array([a1, a2]),
        tilt=float(abs(tilt)),
        segment=(~seg1).astype(int),
    )


# =========================================================================== Monte Carlo
def false_alarm_runs(
    hours: float,
    seed: int = 0,
    *,
    window: str | None = "40s",
    false_alarm_rate_per_h: float = 1.0,
    sigma: float = 50.0,
    errors: str = "isotropic",
    run_hours: float = 1.0,
    **kw: Any,
) -> dict[str, float]:
    """False alarms of :func:`optmodels.plane.tracking.track` on planar tracks (a turn of
    ``radius1`` in one plane, ``tilt_deg=0``), ``hours`` of track in runs of ``run_hours``.

    Returns ``alarms``, ``hours``, ``rate`` (per hour), ``se`` (Poisson: √alarms / hours),
    ``stated`` (``false_alarm_rate_per_h``) and ``seconds`` (wall time). ``window``: as
    :func:`optmodels.plane.windows.window_spec` reads it (``"40s"``, ``"100pts"``).
    """
    import time

    from optmodels.plane.tracking import track

    rng = np.random.default_rng(seed)
    runs = max(1, round(hours / run_hours))
    alarms = 0
    total = 0.0
    t0 = time.perf_counter()
    for _ in range(runs):
        sc = plane_change_track(
            rng,
            tilt_deg=0.0,
            before=3600.0 * run_hours,
            after=0.0,
            sigma=sigma,
            errors=errors,
            **kw,
        )
        tr = track(
            sc.times,
            sc.points,
            sc.cov,
            window=window,
            false_alarm_rate_per_h=false_alarm_rate_per_h,
        )
        alarms += int(np.sum(tr.change))
        total += float(tr.times[-1] - tr.times[0]) / 3600.0
    return {
        "alarms": float(alarms),
        "hours": total,
        "rate": alarms / total,
        "se": float(np.sqrt(max(alarms, 1))) / total,
        "stated": float(false_alarm_rate_per_h),
        "seconds": time.perf_counter() - t0,
    }


def detection_runs(
    runs: int,
    seed: int = 0,
    *,
    tilt_deg: float = 30.0,
    window: str | None = "40s",
    sigma: float = 50.0,
    errors: str = "isotropic",
    false_alarm_rate_per_h: float = 1.0,
    **kw: Any,
) -> dict[str, Any]:
    """Detection delay of :func:`optmodels.plane.tracking.track` on
    :func:`plane_change_track` (``runs`` seeded runs). ``delay`` (runs,) s from the change
    to the first alarm at or after it (inf: none); ``early`` (runs,) alarms before it;
    summary ``detected`` (fraction), ``median``, ``p90`` (90th percentile of the delay,
    inf if fewer than 90 % detected), ``seconds`` (wall time)."""
    import time

    from optmodels.plane.tracking import track

    rng = np.random.default_rng(seed)
    delay = np.full(runs, np.inf)
    early = np.zeros(runs, dtype=int)
    tilt = np.full(runs, np.nan)
    t0 = time.perf_counter()
    for r in range(runs):
        sc = plane_change_track(rng, tilt_deg=tilt_deg, sigma=sigma, errors=errors, **kw)
        tr = track(
            sc.times,
            sc.points,
            sc.cov,
            window=window,
            false_alarm_rate_per_h=false_alarm_rate_per_h,
        )
        at = tr.change_times
        early[r] = int(np.sum(at < sc.change_time))
        late = at[at >= sc.change_time]
        if late.size:
            delay[r] = float(late[0] - sc.change_time)
        k = int(np.searchsorted(tr.times, sc.change_time))
        tilt[r] = float(tr.detectable_tilt[min(k, tr.n_steps - 1)])
    det = np.isfinite(delay)
    ordered = np.sort(delay)
    return {
        "delay": delay,
        "early": early,
        "detected": float(np.mean(det)),
        "median": float(ordered[(runs - 1) // 2]),
        "p90": float(ordered[int(np.ceil(0.9 * runs)) - 1]),
        "detectable_tilt_deg": float(np.degrees(np.nanmedian(tilt))),
        "seconds": time.perf_counter() - t0,
    }
