"""The vectorised ASTERIX encoders (issue 26 item 6, issue 28 item 4): byte for byte what
libasterix writes (the reference encoders of optmodels.io.asterix.libencode, one
libasterix record object per report) on random values, values on the rounding midpoints,
absent items and the angle wrap; values outside a field refused naming the argument (the
reference wraps them: FL 5000 reads back as FL 904)."""

from __future__ import annotations

import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax
from optmodels.io.asterix import libencode as ref

NM, FT = 1852.0, 0.3048


def _cat048_args(rng: np.random.Generator, n: int) -> tuple[tuple, dict]:
    tod = rng.uniform(-1000, 2 * 86400, n)  # wrapped into the day by both
    rho = rng.uniform(0, 255.9 * NM, n)
    # a quarter of the ranges exactly on a rounding midpoint (half to even)
    k = rng.integers(0, 65000, n // 4)
    rho[: n // 4] = (k + 0.5) / 256 * NM
    az = rng.uniform(-8, 8, n)
    fl = rng.uniform(-2048, 2047.75, n)
    fl[rng.random(n) < 0.3] = np.nan
    fl[: n // 8] = rng.integers(-8000, 8000, n // 8) / 4 + 0.125  # midpoints
    addr = np.where(rng.random(n) < 0.3, -1, rng.integers(0, 2**24, n))
    m3 = np.where(rng.random(n) < 0.3, -1, rng.integers(0, 4096, n))
    return (tod, int(rng.integers(0, 256)), rng.integers(0, 256, n), rho, az), {
        "flight_level": fl,
        "address": addr,
        "mode3a": m3,
    }


@pytest.mark.parametrize("per_block", [1, 13, 500])
def test_cat048_bytes_equal_libasterix(per_block: int) -> None:
    rng = np.random.default_rng(2606 + per_block)
    args, kw = _cat048_args(rng, 1500)
    assert ax.encode_cat048(*args, **kw, per_block=per_block) == ref.encode_cat048(
        *args, **kw, per_block=per_block
    )
    # no optional item at all, and an other edition
    assert ax.encode_cat048(*args, per_block=per_block) == ref.encode_cat048(
        *args, per_block=per_block
    )
    # edition 1.31 (its I090 FL unsigned in libasterix's specification: FL ≥ 0)
    kw31 = {**kw, "flight_level": np.abs(kw["flight_level"])}
    assert ax.encode_cat048(*args, **kw31, edition=(1, 31)) == ref.encode_cat048(
        *args, **kw31, edition=(1, 31)
    )
    with pytest.raises(ProblemError, match=r"encode_cat048 flight_level: need 0 to"):
        ax.encode_cat048(*args, **kw, edition=(1, 31))


@pytest.mark.parametrize("high_resolution", [True, False])
def test_cat021_bytes_equal_libasterix(high_resolution: bool) -> None:
    rng = np.random.default_rng(2607)
    n = 1500
    lat, lon = rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)
    lat[:4], lon[:4] = [90, -90, 0, 1], [180, -180, 0, 180]  # the edges
    h = rng.uniform(-1000, 60000, n)
    h[rng.random(n) < 0.3] = np.nan
    fl = rng.uniform(-1000, 8000, n)
    fl[rng.random(n) < 0.3] = np.nan
    addr = np.where(rng.random(n) < 0.3, -1, rng.integers(0, 2**24, n))
    args = (rng.uniform(0, 86400, n), 3, 4, lat, lon)
    kw = {"height": h, "flight_level": fl, "address": addr, "high_resolution": high_resolution}
    for per_block in (1, 7, 300):
        assert ax.encode_cat021(*args, **kw, per_block=per_block) == ref.encode_cat021(
            *args, **kw, per_block=per_block
        )


def test_read_back_within_half_an_lsb_and_angle_wrap(tmp_path) -> None:
    rng = np.random.default_rng(2608)
    args, kw = _cat048_args(rng, 800)
    az = args[4]
    az[:3] = [2 * np.pi - 1e-7, -1e-7, 4 * np.pi]  # round to THETA 0
    p = tmp_path / "x.ast"
    p.write_bytes(ax.encode_cat048(*args, **kw))
    c = ax.read_asterix(p).cat048
    assert np.max(np.abs(c.range - args[3])) <= NM / 256 / 2 + 1e-6
    d = (c.azimuth - az + np.pi) % (2 * np.pi) - np.pi
    assert np.max(np.abs(d)) <= np.pi / 2**16 + 1e-12
    assert np.all(c.azimuth[:3] == 0.0)
    fl = kw["flight_level"]
    ok = np.isfinite(fl)
    assert np.array_equal(np.isfinite(c.pressure_altitude), ok)
    assert np.max(np.abs(c.pressure_altitude[ok] - fl[ok] * 100 * FT)) <= 25 * FT / 2 + 1e-6


def test_out_of_range_values_are_refused_naming_the_argument() -> None:
    one = ([1.0], 1, 2, [1000.0], [0.0])
    # the reference wraps FL 5000 (14-bit signed field) into FL 904
    wrapped = ref.encode_cat048(*one, flight_level=[5000.0])
    assert int.from_bytes(wrapped[-2:], "big") & 0x3FFF == 904 * 4
    with pytest.raises(
        ProblemError,
        match=r"encode_cat048 flight_level: need -2048 to "
        r"2047\.75 FL .*got 5000",
    ):
        ax.encode_cat048(*one, flight_level=[5000.0])
    cases48 = [
        ({"range": [65535.7 / 256 * NM]}, "range"),
        ({"range": [-1.0]}, "range"),
        ({"sac": 256}, "sac"),
        ({"sic": -1}, "sic"),
        ({"sic": 1.5}, "sic"),
        ({"address": [2**24]}, "address"),
        ({"mode3a": [4096]}, "mode3a"),
        ({"flight_level": [-2048.2]}, "flight_level"),
    ]
    base = dict(time_of_day=[1.0], sac=1, sic=2, range=[1000.0], azimuth=[0.0])
    for change, name in cases48:
        args = {**base, **change}
        extra = {k: args.pop(k) for k in ("flight_level", "address", "mode3a") if k in args}
        with pytest.raises(ProblemError, match=rf"asterix\.encode_cat048 {name}: need"):
            ax.encode_cat048(*args.values(), **extra)
    with pytest.raises(ProblemError, match=r"encode_cat021 height: need .* m"):
        ax.encode_cat021([1.0], 1, 2, [45.0], [15.0], height=[70_000.0])
    with pytest.raises(ProblemError, match=r"encode_cat021 flight_level: need"):
        ax.encode_cat021([1.0], 1, 2, [45.0], [15.0], flight_level=[9000.0])
    # a 77 kB datablock: LEN holds 65 535 bytes
    n = 6000
    with pytest.raises(
        ProblemError,
        match=r"encode_cat048 per_block: a datablock of \d+ "
        r"bytes exceeds the 65 535",
    ):
        ax.encode_cat048(
            np.arange(n, dtype=float),
            1,
            2,
            np.full(n, 1e4),
            np.zeros(n),
            address=np.arange(n),
            per_block=n,
        )
