"""The base-layer radar geometry (``optmodels.geometry``) and seed helper
(``optmodels.seeds``) of issue 23 item 5."""

from __future__ import annotations

import numpy as np
import pytest

from optmodels import geometry, seeds
from optmodels.core import ProblemError


def test_azimuth_is_clockwise_from_north_and_round_trips() -> None:
    # north, east, south-west: azimuths 0, π/2, −3π/4 (clockwise from +y, in (−π, π])
    d = np.array([[0.0, 10.0, 0.0], [5.0, 0.0, 0.0], [-3.0, -3.0, 0.0]])
    p = geometry.to_polar3d(d)
    np.testing.assert_allclose(p[:, 0], [10.0, 5.0, np.hypot(3.0, 3.0)], rtol=1e-15)
    np.testing.assert_allclose(p[:, 1], [0.0, np.pi / 2, -3 * np.pi / 4], atol=1e-15)
    rng = np.random.default_rng(0)
    x = rng.normal(scale=1e4, size=(200, 3))
    np.testing.assert_allclose(geometry.from_polar3d(geometry.to_polar3d(x)), x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        geometry.from_polar2d(geometry.to_polar2d(x[:, :2])), x[:, :2], rtol=0, atol=1e-10
    )
    # elevation: asin(z / r) against the independent atan2 of the horizontal distance
    el = np.arctan2(x[:, 2], np.hypot(x[:, 0], x[:, 1]))
    np.testing.assert_allclose(geometry.to_polar3d(x)[:, 2], el, atol=1e-12)


def test_math_angle_is_the_counter_clockwise_convention() -> None:
    """θ = π/2 − β against the counter-clockwise-from-x angle atan2(y, x) computed
    directly (the convention of paper 004's sensor cells)."""
    rng = np.random.default_rng(1)
    xy = rng.normal(size=(500, 2))
    beta = geometry.to_polar2d(xy)[:, 1]
    theta = geometry.math_angle(beta)
    np.testing.assert_allclose(theta, np.arctan2(xy[:, 1], xy[:, 0]), atol=1e-12)
    np.testing.assert_allclose(geometry.azimuth_from_math_angle(theta), beta, atol=1e-12)
    assert np.all((theta > -np.pi) & (theta <= np.pi))


def test_seed_helper_one_meaning() -> None:
    a = seeds.as_generator("f seed", 7).normal(size=5)
    b = np.random.default_rng(7).normal(size=5)
    np.testing.assert_array_equal(a, b)  # the same stream as numpy's own seeding
    g = np.random.default_rng(3)
    assert seeds.as_generator("f seed", g) is g
    np.testing.assert_array_equal(
        seeds.as_generator("f seed", [1, 2]).integers(0, 10**9, 3),
        np.random.default_rng([1, 2]).integers(0, 10**9, 3),
    )
    for bad in (None, True, 1.5, "x", -1):
        with pytest.raises(ProblemError, match="f seed"):
            seeds.as_generator("f seed", bad)
    assert isinstance(seeds.as_generator("f seed", None, allow_none=True), np.random.Generator)
