"""pandas in and out (optmodels.biasfield.frames): round trips of ADS-B reports and radar plots
with the ADS-B tools' column names (timestamp, icao24, latitude, longitude, altitude)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from optmodels.biasfield.frames import default_epoch, from_frame, to_frame
from optmodels.biasfield.recording import AdsbReports
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import ProblemError

TOL_T = 1e-6  # s: datetimes are ns; seconds of day ~1e5 carry ~1e-11 s of float error


def _adsb(rng: np.random.Generator, n: int = 50) -> AdsbReports:
    addr = rng.choice([0x3C6444, 0x4CA123, 0x000001], n)
    _, obj = np.unique(addr, return_inverse=True)
    t = np.sort(rng.uniform(86000.0, 87000.0, n))  # across midnight
    order = np.lexsort((t, obj))
    h = rng.uniform(-50, 12000, n)
    h[3] = np.nan
    return AdsbReports(
        t[order],
        obj[order],
        addr[order],
        rng.uniform(-90, 90, n)[order],
        rng.uniform(-180, 180, n)[order],
        h[order],
        rng.uniform(0, 13000, n)[order],
    )


def test_adsb_round_trip_with_datetimes() -> None:
    rep = _adsb(np.random.default_rng(1))
    df = to_frame(rep, epoch="2026-03-01")
    assert list(df.columns) == [
        "timestamp",
        "icao24",
        "latitude",
        "longitude",
        "altitude",
        "baroaltitude",
    ]
    assert str(df["timestamp"].dt.tz) == "UTC"
    assert set(df["icao24"]) == {"3c6444", "4ca123", "000001"}
    # 86 400 s after the epoch is the next midnight
    k = int(np.argmin(np.abs(rep.time - 86500.0)))
    want = pd.Timestamp("2026-03-02", tz="UTC") + pd.Timedelta(seconds=rep.time[k] - 86400)
    assert abs((df["timestamp"].iloc[k] - want).total_seconds()) <= TOL_T
    back = from_frame(df, epoch="2026-03-01")
    assert isinstance(back, AdsbReports)
    np.testing.assert_allclose(back.time, rep.time, rtol=0, atol=TOL_T)
    for name in ("object", "address"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rep, name))
    for name in ("latitude", "longitude", "height", "pressure_altitude"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rep, name))
    # without an epoch: the UTC midnight of the earliest timestamp
    assert default_epoch(df) == pd.Timestamp("2026-03-01", tz="UTC")
    np.testing.assert_allclose(from_frame(df).time, rep.time, rtol=0, atol=TOL_T)


def test_adsb_float_and_tz_aware_timestamps() -> None:
    rep = _adsb(np.random.default_rng(2))
    df = to_frame(rep)  # float seconds
    assert df["timestamp"].dtype == float and default_epoch(df) is None
    np.testing.assert_array_equal(from_frame(df).time, rep.time)
    # a tz-aware column in Paris time (UTC+1 in March) is converted to UTC
    paris = to_frame(rep, epoch="2026-03-01")
    paris["timestamp"] = paris["timestamp"].dt.tz_convert("Europe/Paris")
    back = from_frame(paris, epoch=pd.Timestamp("2026-03-01", tz="UTC"))
    np.testing.assert_allclose(back.time, rep.time, rtol=0, atol=TOL_T)
    # an unsorted frame with upper-case addresses: sorted by (object, time) on the way in
    shuffled = df.sample(frac=1.0, random_state=3)
    shuffled["icao24"] = shuffled["icao24"].str.upper()
    back = from_frame(shuffled)
    np.testing.assert_array_equal(back.time, rep.time)
    np.testing.assert_array_equal(back.address, rep.address)


def test_plots_round_trip_names_icao24_heights() -> None:
    rng = np.random.default_rng(4)
    radars = RadarSet(
        None,
        [30.0, 40.0],
        [1e-3, 1e-3],
        [2.5e5, 2.5e5],
        ("North", "East"),
        geodetic=np.array([[45.0, 15.5, 300.0], [45.6, 16.4, 150.0]]),
        ids=((7, 11), (7, 12)),
    )
    n = 40
    az = rng.uniform(-np.pi, np.pi, n)
    az[0] = np.pi / 2
    plots = PlotTable(
        np.sort(rng.uniform(0, 600, n)),
        rng.integers(0, 2, n),
        rng.uniform(1e3, 2e5, n),
        az,
        rng.integers(0, 3, n),
        rng.uniform(3000, 12000, n),
    )
    addresses = np.array([0x000AAA, 0x3C6444, 0xFFFFFF])
    df = to_frame(plots, radars=radars, addresses=addresses)
    assert df["azimuth"].iloc[0] == pytest.approx(90.0, abs=1e-12)
    assert set(df["radar"]) <= {"North", "East"}
    assert df["icao24"].iloc[0] == f"{addresses[plots.object[0]]:06x}"
    back = from_frame(df, radars=radars)
    for name in ("time", "radar", "range", "object", "height"):
        np.testing.assert_array_equal(getattr(back, name), getattr(plots, name))
    np.testing.assert_allclose(back.azimuth, plots.azimuth, rtol=0, atol=1e-14)
    # objects from icao24 alone: numbered in sorted address order (= the given ones here)
    back2 = from_frame(df.drop(columns="object"), radars=radars)
    np.testing.assert_array_equal(back2.object, plots.object)
    # radar indices instead of names
    back3 = from_frame(to_frame(plots))
    np.testing.assert_array_equal(back3.radar, plots.radar)


def test_recording_to_frame(tmp_path) -> None:
    import pymap3d

    from optmodels.biasfield.recording import read_recording
    from optmodels.io import asterix as ax

    sites = tmp_path / "s.csv"
    sites.write_text(
        "name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        "A,1,1,45,15,100,30,0.05,250000\nB,1,2,45.5,15.8,100,30,0.05,250000\n"
    )
    t = 3600.0 + np.arange(5.0)
    az, _el, sr = pymap3d.geodetic2aer(45.2, 15.4, 8000.0, 45.0, 15.0, 100.0)
    p = tmp_path / "r.ast"
    p.write_bytes(
        ax.encode_cat021(
            t, 9, 9, np.full(5, 45.2), np.full(5, 15.4), height=np.full(5, 8000.0), address=0x4CA123
        )
        + ax.encode_cat048(t, 1, 1, np.full(5, sr), np.full(5, np.radians(az)), address=0x4CA123)
    )
    rec = read_recording(p, sites, date="2026-06-30")
    df = to_frame(rec)
    assert list(df["icao24"]) == ["4ca123"] * 5 and list(df["radar"]) == ["A"] * 5
    assert df["timestamp"].iloc[0] == pd.Timestamp("2026-06-30T01:00:00", tz="UTC")
    assert np.all(np.abs(df["height"] - 8000.0) <= 6.25 * 0.3048 / 2)
    adsb = to_frame(rec.adsb, epoch=rec.epoch)
    assert np.all(np.abs(adsb["altitude"] - 8000.0) <= 6.25 * 0.3048 / 2)


def test_frame_errors() -> None:
    rep = _adsb(np.random.default_rng(5))
    df = to_frame(rep)
    with pytest.raises(ProblemError, match=r"missing column 'icao24'"):
        from_frame(df.drop(columns="icao24"), kind="adsb")
    bad = df.copy()
    bad.loc[bad.index[2], "icao24"] = "xyz"
    with pytest.raises(ProblemError, match=r"icao24: row 2"):
        from_frame(bad)
    bad = df.copy()
    bad.loc[bad.index[1], "latitude"] = np.nan
    with pytest.raises(ProblemError, match=r"latitude: 1 non-finite"):
        from_frame(bad)
    with pytest.raises(ProblemError, match=r"epoch: only for datetime"):
        from_frame(df, epoch="2026-01-01")
    with pytest.raises(ProblemError, match=r"kind"):
        from_frame(df, kind="tracks")
    with pytest.raises(ProblemError, match=r"df: expected a pandas DataFrame"):
        from_frame({"timestamp": [0.0]})
    plots = pd.DataFrame({"timestamp": [0.0], "radar": ["Z"], "range": [1e3], "azimuth": [10.0]})
    with pytest.raises(ProblemError, match=r"radars: radar names"):
        from_frame(plots)
    with pytest.raises(ProblemError, match=r"to_frame table"):
        to_frame([1, 2, 3])


# ------------------------------------------------------- issue 28.4 / 26.2: both ways
def test_times_beyond_datetime64_ns_are_refused_not_nat() -> None:
    """to_frame with an epoch: times that datetime64[ns] cannot hold (here 1e10 s = 317
    years after 2026) are one ProblemError naming the epoch, with no RuntimeWarning and
    no NaT; the last representable day is still written exactly."""
    import warnings

    rng = np.random.default_rng(8)
    last = pd.Timestamp("2262-04-10", tz="UTC") - pd.Timestamp("2026-01-01", tz="UTC")
    edge = last.total_seconds()
    for t_big, ok in ((1e10, False), (-1e10, False), (edge, True)):
        plots = PlotTable(
            np.array([0.0, t_big]),
            np.array([0, 0]),
            np.array([1e3, 2e3]),
            rng.uniform(-1, 1, 2),
            np.array([-1, -1]),
        )
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            if not ok:
                with pytest.raises(
                    ProblemError,
                    match=r"to_frame epoch: 1 times .*"
                    r"datetime64\[ns\]",
                ):
                    to_frame(plots, epoch="2026-01-01")
                continue
            df = to_frame(plots, epoch="2026-01-01")
        assert not df["timestamp"].isna().any()
        assert df["timestamp"].iloc[1] == pd.Timestamp("2262-04-10", tz="UTC")
        back = from_frame(df, epoch="2026-01-01")
        np.testing.assert_allclose(back.time, plots.time, rtol=0, atol=TOL_T)


def _plots_frame(**over: list) -> pd.DataFrame:
    cols = {
        "timestamp": [0.0, 1.0, 2.0],
        "radar": [0, 1, 0],
        "range": [1e3, 2e3, 3e3],
        "azimuth": [10.0, 359.5, -90.0],
    }
    cols.update(over)
    return pd.DataFrame(cols)


def test_plots_from_frame_refuse_bad_radar_azimuth_object() -> None:
    radars = RadarSet(
        np.array([[0.0, 0.0], [1e4, 0.0]]), [30.0, 30.0], [1e-3, 1e-3], [2.5e5, 2.5e5], ("A", "B")
    )
    good = from_frame(_plots_frame(), radars=radars)
    np.testing.assert_allclose(good.azimuth, np.radians([10.0, 359.5, -90.0]), rtol=1e-15)
    np.testing.assert_array_equal(good.radar, [0, 1, 0])
    with pytest.raises(
        ProblemError,
        match=r"from_frame radar: 1 radar indices not ≥ 0 "
        r"\(first -1 at row 1\)",
    ):
        from_frame(_plots_frame(radar=[0, -1, 0]))
    with pytest.raises(ProblemError, match=r"radar: 1 radar indices not in 0..1 .*first 99"):
        from_frame(_plots_frame(radar=[0, 99, 0]), radars=radars)
    with pytest.raises(
        ProblemError,
        match=r"from_frame azimuth: 1 values outside ±360° .*"
        r"first 1e\+06 at row 2",
    ):
        from_frame(_plots_frame(azimuth=[10.0, 20.0, 1e6]))
    with pytest.raises(ProblemError, match=r"from_frame object: .*-2 at row 0"):
        from_frame(_plots_frame(object=[-2, 0, 1]))
    with pytest.raises(ProblemError, match=r"from_frame range: 1 negative"):
        from_frame(_plots_frame(range=[1e3, -5.0, 1e3]))
    with pytest.raises(ProblemError, match=r"from_frame radars: expected a RadarSet"):
        from_frame(_plots_frame(), radars=3)


def _traffic_frame(rng: np.random.Generator, n: int = 30) -> tuple[pd.DataFrame, dict]:
    """A frame as the traffic library's Flight.data has it (feet, knots, ft/min, tz-aware
    UTC timestamps) and the truth in SI."""
    geo_m = rng.uniform(300.0, 12000.0, n)
    baro_m = geo_m - rng.uniform(-200.0, 200.0, n)
    t = np.sort(rng.uniform(0.0, 3600.0, n))
    df = pd.DataFrame(
        {
            "timestamp": pd.Timestamp("2026-05-04", tz="UTC") + pd.to_timedelta(t, unit="s"),
            "icao24": "4ca123",
            "callsign": "EIN123",
            "latitude": rng.uniform(50, 52, n),
            "longitude": rng.uniform(-1, 1, n),
            "altitude": baro_m / 0.3048,
            "geoaltitude": geo_m / 0.3048,
            "groundspeed": rng.uniform(200, 450, n),
            "track": rng.uniform(0, 360, n),
            "vertical_rate": rng.uniform(-2000, 2000, n),
        }
    )
    return df, {"t": t, "geo": geo_m, "baro": baro_m}


def test_traffic_frames_are_converted_from_feet() -> None:
    """convention='traffic': altitude is barometric ft -> pressure altitude (m),
    geoaltitude geometric ft -> height above the ellipsoid (m); and back."""
    df, truth = _traffic_frame(np.random.default_rng(9))
    rep = from_frame(df, convention="traffic")
    np.testing.assert_allclose(rep.height, truth["geo"], rtol=1e-12)
    np.testing.assert_allclose(rep.pressure_altitude, truth["baro"], rtol=1e-12)
    np.testing.assert_allclose(rep.time, truth["t"], rtol=0, atol=TOL_T)
    # written back in the traffic convention: feet again, and marked
    out = to_frame(rep, epoch="2026-05-04", convention="traffic")
    assert out.attrs["optmodels.convention"] == "traffic"
    np.testing.assert_allclose(out["altitude"], df["altitude"], rtol=1e-12)
    np.testing.assert_allclose(out["geoaltitude"], df["geoaltitude"], rtol=1e-12)
    again = from_frame(out)  # the mark says: traffic
    np.testing.assert_allclose(again.height, truth["geo"], rtol=1e-12)
    # the traffic library without geoaltitude: height unknown (NaN), baro still read
    only_baro = from_frame(df.drop(columns="geoaltitude"), convention="traffic")
    assert np.all(np.isnan(only_baro.height))
    np.testing.assert_allclose(only_baro.pressure_altitude, truth["baro"], rtol=1e-12)


def test_ambiguous_altitude_units_are_refused() -> None:
    df, _ = _traffic_frame(np.random.default_rng(10))
    # a traffic frame without the convention: refused (it would be 3.28x heights)
    with pytest.raises(ProblemError, match=r"from_frame convention: .*traffic library's"):
        from_frame(df)
    # a hand-made frame with 'altitude' only: metres or barometric feet?
    plain = df.drop(columns="geoaltitude")
    with pytest.raises(ProblemError, match=r"'altitude' may be metres .* or the traffic"):
        from_frame(plain)
    # contradictions between the convention given and the columns or the mark
    with pytest.raises(ProblemError, match=r"'optmodels' has no 'geoaltitude'"):
        from_frame(df, convention="optmodels")
    ours = to_frame(_adsb(np.random.default_rng(11)))
    with pytest.raises(
        ProblemError,
        match=r"'traffic' given, but the frame was written "
        r"with convention 'optmodels'",
    ):
        from_frame(ours, convention="traffic")
    with pytest.raises(ProblemError, match=r"convention: expected one of"):
        from_frame(df, convention="feet")
    # stated: metres above the ellipsoid, read as they are (one aircraft, rows already in
    # time order, so the order is the frame's)
    rep = from_frame(plain, convention="optmodels")
    np.testing.assert_array_equal(rep.height, plain["altitude"].to_numpy())
    assert np.all(np.isnan(rep.pressure_altitude))
