"""Scenario generators: truth lies on the stated plane; radar covariances are right."""

import numpy as np
import pytest

from optmodels import scenarios


def spherical_to_cartesian(r: float, az: float, el: float) -> np.ndarray:
    return r * np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])


def test_radar_covariance_is_jacobian_sandwich() -> None:
    # Central finite differences of the spherical→Cartesian map (step 1e-6 relative:
    # truncation ~1e-12, round-off ~1e-10 relative), then J diag(σ²) Jᵀ.
    r, az, el = 30e3, 0.7, 0.2
    x = spherical_to_cartesian(r, az, el)
    steps = np.array([1e-6 * r, 1e-6, 1e-6])
    jac = np.empty((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = steps[k]
        p = np.array([r, az, el])
        jac[:, k] = (spherical_to_cartesian(*(p + e)) - spherical_to_cartesian(*(p - e))) / (
            2 * steps[k]
        )
    want = jac @ np.diag([10.0**2, 2e-3**2, 3e-3**2]) @ jac.T
    got = scenarios.radar_covariances(x[None, :], np.zeros(3), 10.0, 2e-3, 3e-3)[0]
    np.testing.assert_allclose(got, want, rtol=1e-6)
    # the range direction has the range variance: uᵀ D u = σ_r²
    u = x / r
    assert u @ got @ u == pytest.approx(100.0, rel=1e-9)


@pytest.mark.parametrize("geometry", ["broadside", "edge-on"])
def test_radar_plane_truth_on_plane(geometry: str) -> None:
    sc = scenarios.radar_plane(200, 3, geometry=geometry)
    assert np.max(np.abs(sc.truth @ sc.normal - sc.offset)) <= 1e-8 * sc.offset + 1e-8
    assert sc.offset >= 0 and sc.cov.shape == (200, 3, 3)


def test_paper_example_geometry() -> None:
    sc = scenarios.paper_plane_example(0)
    assert sc.points.shape == (1000, 3) and sc.times[-1] == pytest.approx(10.0)
    assert np.max(np.abs(sc.truth[:, 1])) == 0.0  # the plane OXZ: n = (0,1,0), a = 0
    speed = np.linalg.norm(np.diff(sc.truth, axis=0), axis=1) / 0.01
    # chord speed of a 1130 m circle at 500 m/s over 0.01 s: 500·(1 - O((v dt / r)²/24))
    np.testing.assert_allclose(speed, 500.0, rtol=1e-5)
    centre = np.array([5000 * np.cos(np.pi / 4), 0, 5000 * np.sin(np.pi / 4)])
    np.testing.assert_allclose(
        np.linalg.norm(sc.truth - centre, axis=1), scenarios.PAPER_RADIUS, rtol=1e-12
    )
