r"""The radar's polar coordinates in the joint assignment of paper 004: range (m, over all
coordinates) and azimuth atan2(y − y_s, x − x_s) (rad, counter-clockwise from the x axis)
around a site, their Jacobian, and the Cartesian covariances of polar measurements
(:func:`polar_measurement_covs`, first order).

Holds :func:`cartesian_to_polar`, :func:`polar_to_cartesian`,
:func:`polar_measurement_covs` and the model's unchecked :func:`_cartesian_to_polar`,
:func:`_polar_jacobian` (used by :class:`~optmodels.assignment.sensor.Resolution`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_choice, as_finite_array, as_positive


def cartesian_to_polar(points: FloatArray, site: FloatArray) -> FloatArray:
    """(N, d ≥ 2) Cartesian points (m) → (N, 2) range (m, over all coordinates) and
    azimuth atan2(y − y_s, x − x_s) (rad, counter-clockwise from the x axis).

    Raises
    ------
    ProblemError
        Naming the argument: ``points`` not (N, d ≥ 2) finite, ``site`` not (d,) finite.
    """
    pts = as_finite_array("assignment.cartesian_to_polar points", points, ndim=2)
    if pts.shape[1] < 2:
        raise ProblemError(
            f"assignment.cartesian_to_polar points: expected (N, d ≥ 2), got {pts.shape}"
        )
    s = as_finite_array("assignment.cartesian_to_polar site", site, shape=(pts.shape[1],))
    return _cartesian_to_polar(pts, s)


def _cartesian_to_polar(points: FloatArray, site: FloatArray) -> FloatArray:
    """:func:`cartesian_to_polar` without the checks (the model's own calls)."""
    dp = np.asarray(points, dtype=float) - site
    return np.column_stack([np.linalg.norm(dp, axis=1), np.arctan2(dp[:, 1], dp[:, 0])])


def polar_to_cartesian(polar: FloatArray, site: FloatArray) -> FloatArray:
    """(N, 2) range (m) and azimuth (rad, counter-clockwise from the x axis) → (N, 2)
    Cartesian points (m) around the 2-D ``site``."""
    w = "assignment.polar_to_cartesian"
    pol = as_finite_array(f"{w} polar", polar, ndim=2)
    s = as_finite_array(f"{w} site", site, shape=(2,))
    if pol.shape[1] != 2:
        raise ProblemError(f"{w} polar: expected (N, 2) range, azimuth; got {pol.shape}")
    return s + pol[:, :1] * np.column_stack([np.cos(pol[:, 1]), np.sin(pol[:, 1])])


def _polar_jacobian(points: FloatArray, site: FloatArray) -> FloatArray:
    """∂(r, az)/∂p (N, 2, d) at Cartesian points (N, d)."""
    dp = points - site
    r = np.linalg.norm(dp, axis=1)
    rho2 = dp[:, 0] ** 2 + dp[:, 1] ** 2
    jac = np.zeros((len(dp), 2, dp.shape[1]))
    jac[:, 0, :] = dp / r[:, None]
    jac[:, 1, 0] = -dp[:, 1] / rho2
    jac[:, 1, 1] = dp[:, 0] / rho2
    return jac


def polar_measurement_covs(
    measurements: Any,
    site: Any,
    sigma_range: Any,
    sigma_azimuth: Any,
    *,
    coordinates: str = "cartesian",
) -> FloatArray:
    """Cartesian covariances R_i (N, 2, 2) of 2-D polar measurements, each converted with
    its own Jacobian: R_i = G_i diag(σ_r², σ_az²) G_iᵀ, G_i = ∂(x, y)/∂(r, az) =
    [[cos az, −r sin az], [sin az, r cos az]] at the measurement (first-order; the
    neglected bias is O(σ_az²) relative).

    Parameters
    ----------
    measurements : (N, 2)
        Cartesian points (m) or, with ``coordinates="polar"``, range (m) and azimuth (rad,
        counter-clockwise from the x axis).
    site : (2,)
        The sensor's position, m, in the measurements' Cartesian frame.
    sigma_range : float
        Range standard deviation, m (> 0).
    sigma_azimuth : float
        Azimuth standard deviation, rad (> 0).
    coordinates : {"cartesian", "polar"}
    """
    w = "assignment.polar_measurement_covs"
    kind = as_choice(f"{w} coordinates", coordinates, ("cartesian", "polar"))
    meas = as_finite_array(f"{w} measurements", measurements, ndim=2)
    if meas.shape[1] != 2:
        raise ProblemError(f"{w} measurements: expected (N, 2), got {meas.shape}")
    s = as_finite_array(f"{w} site", site, shape=(2,))
    sr = as_positive(f"{w} sigma_range (m)", sigma_range)
    sa = as_positive(f"{w} sigma_azimuth (rad)", sigma_azimuth)
    if sa > 0.5:  # ~29°: no radar's angle noise; found by review (10 "rad" accepted)
        raise ProblemError(
            f"{w} sigma_azimuth (rad): {sa:g} rad is {np.rad2deg(sa):.3g}°, "
            "not an angle noise (degrees given as radians?)"
        )
    if kind == "cartesian":
        pol = _cartesian_to_polar(meas, s)
    else:
        pol = meas
        if np.any(pol[:, 0] < 0):
            raise ProblemError(f"{w} measurements: a negative range")
    if np.any(pol[:, 0] <= 0):
        raise ProblemError(
            f"{w} measurements: a measurement at the sensor's site (range 0: no azimuth)"
        )
    r, az = pol[:, 0], pol[:, 1]
    g = np.empty((len(r), 2, 2))
    g[:, 0, 0], g[:, 0, 1] = np.cos(az), -r * np.sin(az)
    g[:, 1, 0], g[:, 1, 1] = np.sin(az), r * np.cos(az)
    d = np.array([sr**2, sa**2])
    out = np.einsum("nij,j,nkj->nik", g, d, g)
    return 0.5 * (out + out.transpose(0, 2, 1))
