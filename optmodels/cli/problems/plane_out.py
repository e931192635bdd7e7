"""The outputs of ``optmodels plane fit``: the plane's orientation for a person (tilt and
its azimuth), the normal's sign convention (the one the library applies), and the readable
text of a fit."""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.cli.contract import _OK_STATUSES

#: The sign convention of every normal the library returns (``plane.closed_form``,
#: ``plane.solve``, ``identify_sequence``, ``track``; :class:`optmodels.plane.PlaneSolution`):
#: the data fix (n, a) only up to a common sign, the library reports ``offset >= 0``.
SIGN_CONVENTION = (
    "offset >= 0: the normal points from the origin (0, 0, 0) of the file's frame towards "
    "the plane ((-n, -offset) is the same plane: the data do not fix the sign); for a plane "
    "through the origin, the first non-zero component of the normal is > 0"
)


def orientation(normal: Any) -> dict[str, float]:
    """The plane's orientation in degrees, for a person (the file's frame read as local
    ENU: x east, y north, z up): ``tilt_deg``, the angle between the plane and the
    horizontal (0: a level turn, 90: a vertical plane), and ``tilt_azimuth_deg``, the
    direction in which the plane rises most steeply, clockwise from north (NaN for a
    level plane)."""
    n = np.asarray(normal, dtype=float)
    if not np.all(np.isfinite(n)):
        return {"tilt_deg": float("nan"), "tilt_azimuth_deg": float("nan")}
    tilt = float(np.degrees(np.arccos(min(1.0, abs(float(n[2]))))))
    # the plane rises along the horizontal part of -n·sign(nz) (up-slope direction)
    up = -np.sign(n[2]) * n[:2] if n[2] != 0 else n[:2]
    az = float(np.degrees(np.arctan2(up[0], up[1])) % 360.0) if tilt > 1e-9 else float("nan")
    return {"tilt_deg": tilt, "tilt_azimuth_deg": az}


def print_plane_fit(res: dict[str, Any]) -> None:
    n = res["normal"]
    span = res.get("time_span")
    when = f", t = {span[0]:g} ... {span[1]:g} s" if span else ""
    print(f"{res['file']}: N = {res['n_points']}{when}, {res['method']} -> {res['status']}")
    if res["status"] not in _OK_STATUSES:
        print(f"  {res['message']}")
        if res.get("line_direction"):
            d = res["line_direction"]
            print(f"  line direction = ({d[0]:.9f}, {d[1]:.9f}, {d[2]:.9f})")
        return
    print(f"  normal  = ({n[0]:.9f}, {n[1]:.9f}, {n[2]:.9f})")
    print(f"  offset  = {res['offset']:.6f} m")
    print(
        "  sign    : offset ≥ 0, the normal points from the file's origin (0, 0, 0) towards "
        "the plane (the data fix it only up to sign: −normal, −offset is the same plane)"
    )
    az = res["tilt_azimuth_deg"]
    # 359.96° is printed as 0.0°, not 360.0°
    az_text = f"{float(f'{az:.1f}') % 360.0:.1f}" if az == az else ""
    print(
        f"  tilt    = {res['tilt_deg']:.3f}° from the horizontal"
        + (
            f", rising towards azimuth {az_text}° (clockwise from north)"
            if az == az
            else " (a level plane)"
        )
    )
    print(
        f"  objective (1.2) = {res['objective']:.6g}; max residual (1.3) = "
        f"{max(res['residuals'].values(), default=0.0):.1e}"
    )
    t = res.get("planarity_test")
    if t:
        verdict = "planar" if t["planar"] else "NOT planar"
        print(
            f"  χ² test: Λ = {t['statistic']:.6g}, dof = {t['dof']}, threshold "
            f"{t['threshold']:.6g} at level {t['level']} -> {verdict} (p = {t['p_value']:.3g})"
        )
        print(
            f"  line test: {t['line_statistic']:.6g} > {t['line_threshold']:.6g} "
            f"(χ²({t['line_dof']})) -> the plane is resolved"
        )
        pv = "planar" if t["paper_planar"] else "NOT planar"
        print(
            f"  paper (1.17): √(2Λ) = {t['paper_statistic']:.4f} vs √(2N)+2 = "
            f"{t['paper_threshold']:.4f} -> {pv}"
        )
