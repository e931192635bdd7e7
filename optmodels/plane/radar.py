r"""Error covariances :math:`D_i` of a radar's positions, for the plane of maneuver (paper 000).

A radar measures range ``r`` (m), azimuth ``β`` (rad, clockwise from north) and elevation
``ε`` (rad, up from the horizontal) with independent errors of standard deviations
``σ_r``, ``σ_β``, ``σ_ε``. Converted to Cartesian positions the errors are correlated and
anisotropic -- precise along the line of sight, ``r σ_β cos ε`` and ``r σ_ε`` across it --
so the :math:`D_i` of (1.2) are not proportional (1.4) and the plane is fitted by
:func:`optmodels.plane.solve` or :func:`optmodels.plane.general.fit_general`.

Frame: the radar's local East-North-Up (ENU), flat: ``site`` and the points in the same
Cartesian frame, metres, its axes E, N, U; the radar's azimuth zero is that frame's +N
and its horizontal is the E-N plane (no earth curvature, no refraction: for points
geodetic, convert them to the radar's ENU first, e.g. ``pymap3d.geodetic2enu``).

:func:`to_polar` / :func:`from_polar` convert between the two (checked wrappers of
:mod:`optmodels.geometry`, the package's one polar convention);
:func:`radar_covariances` gives :math:`D_i = J_i\,\mathrm{diag}(\sigma_r^2, \sigma_\beta^2,
\sigma_\varepsilon^2)\,J_i^T`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from optmodels import geometry
from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_finite_array,
    as_positive,
)

__all__ = ["from_polar", "radar_covariances", "to_polar"]


def _site_offsets(where: str, points: ArrayLike, site: ArrayLike) -> tuple[FloatArray, FloatArray]:
    pts = as_finite_array(f"{where} points", points, shape=(None, 3), max_abs=MAX_MAGNITUDE)
    st = as_finite_array(f"{where} site", site, shape=(3,), max_abs=MAX_MAGNITUDE)
    d = pts - st
    r = np.linalg.norm(d, axis=1)
    if np.any(r == 0):
        raise ProblemError(
            f"{where} points: {int(np.sum(r == 0))} coincide with the site "
            "(azimuth and elevation undefined)"
        )
    return d, r


def to_polar(points: ArrayLike, site: ArrayLike) -> FloatArray:
    """``(N, 3)`` columns range (m), azimuth (rad, clockwise from north, in (−π, π]),
    elevation (rad, up) of ENU ``points`` (m) seen from ``site`` (m)."""
    d, _ = _site_offsets("plane.to_polar", points, site)
    return geometry.to_polar3d(d)


def from_polar(polar: ArrayLike, site: ArrayLike) -> FloatArray:
    """ENU positions (m) of ``(N, 3)`` range (m), azimuth (rad, clockwise from north),
    elevation (rad) measured from ``site``: ``E = r cos ε sin β``, ``N = r cos ε cos β``,
    ``U = r sin ε`` (plus the site)."""
    p = as_finite_array("plane.from_polar polar", polar, shape=(None, 3), max_abs=MAX_MAGNITUDE)
    st = as_finite_array("plane.from_polar site", site, shape=(3,), max_abs=MAX_MAGNITUDE)
    return st + geometry.from_polar3d(p)


def radar_covariances(
    points: ArrayLike,
    site: ArrayLike,
    sigma_range: float,
    sigma_azimuth: float,
    sigma_elevation: float,
) -> FloatArray:
    r"""Cartesian (ENU) error covariances :math:`D_i` (N, 3, 3) of a radar's positions.

    :math:`D_i = J_i\,\mathrm{diag}(\sigma_r^2, \sigma_\beta^2, \sigma_\varepsilon^2)\,J_i^T`
    with :math:`J_i` the exact Jacobian of :func:`from_polar` at the point's (r, β, ε):

    .. math::
        J = \begin{pmatrix} \cos\varepsilon\sin\beta & r\cos\varepsilon\cos\beta &
        -r\sin\varepsilon\sin\beta\\ \cos\varepsilon\cos\beta & -r\cos\varepsilon\sin\beta
        & -r\sin\varepsilon\cos\beta\\ \sin\varepsilon & 0 & r\cos\varepsilon\end{pmatrix}.

    Parameters
    ----------
    points : array_like (N, 3)
        Positions (m) in the radar's local flat ENU frame (module docstring); the true
        positions when known, else the measured ones (the difference is second order).
    site : array_like (3,)
        The radar's position (m) in the same frame.
    sigma_range : float
        Standard deviation of range, m.
    sigma_azimuth, sigma_elevation : float
        Standard deviations of azimuth and elevation, **rad**.

    Returns
    -------
    ndarray (N, 3, 3)
        SPD. Along the line of sight exactly :math:`u^T D u = \sigma_r^2` (``u`` the unit
        site-to-point vector).

    Raises
    ------
    ProblemError
        Naming the argument: shapes, non-finite values, a standard deviation ≤ 0, a
        point at the site or straight above/below it (azimuth undefined, ``D`` singular).

    Notes
    -----
    First order (the linearisation of the polar-to-Cartesian map): the covariance of the
    converted noise differs from this by terms of relative order
    :math:`\sigma_\beta^2 + \sigma_\varepsilon^2 + \sigma_r^2/r^2` (1e-5 at σ = 2 mrad,
    30 km), and the converted positions have a mean bias of :math:`-\tfrac12
    (\sigma_\varepsilon^2 d + \sigma_\beta^2 d_h)` (``d`` the site-to-point vector,
    ``d_h`` its horizontal part: :math:`E\cos(\varepsilon + e) = \cos\varepsilon\,
    e^{-\sigma^2/2}`; 0.12 m at 30 km and 2 mrad, small against the 60 m across the beam),
    neither of which (1.2) models. Exact for the range term.
    Checked against a Monte Carlo of converted polar noise in
    ``tests/test_plane_general.py``.
    """
    w = "plane.radar_covariances"
    d, r = _site_offsets(w, points, site)
    s_r = as_positive(f"{w} sigma_range (m)", sigma_range)
    s_az = as_positive(f"{w} sigma_azimuth (rad)", sigma_azimuth)
    s_el = as_positive(f"{w} sigma_elevation (rad)", sigma_elevation)
    horiz = np.hypot(d[:, 0], d[:, 1])
    if np.any(horiz <= 1e-12 * r):
        raise ProblemError(
            f"{w} points: {int(np.sum(horiz <= 1e-12 * r))} are straight above "
            "or below the site (azimuth undefined, the covariance singular)"
        )
    # sin/cos of azimuth and elevation straight from the offsets (no atan2 round trip)
    saz, caz = d[:, 0] / horiz, d[:, 1] / horiz
    ce, se = horiz / r, d[:, 2] / r
    jac = np.empty((len(r), 3, 3))
    jac[:, :, 0] = np.column_stack([ce * saz, ce * caz, se])
    jac[:, :, 1] = np.column_stack([r * ce * caz, -r * ce * saz, np.zeros_like(r)])
    jac[:, :, 2] = np.column_stack([-r * se * saz, -r * se * caz, r * ce])
    s = np.array([s_r, s_az, s_el]) ** 2
    cov = np.einsum("nij,j,nkj->nik", jac, s, jac)
    return 0.5 * (cov + cov.transpose(0, 2, 1))
