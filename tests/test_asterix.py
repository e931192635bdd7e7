"""ASTERIX CAT048/CAT021 codec (optmodels.io.asterix): libasterix encodes simulated 3-D
traffic, the reader recovers every field to the format's resolution.

The LSBs below are typed from the category specifications (EUROCONTROL-SPEC-0149-4
CAT048 ed. 1.32, CAT021 ed. 2.x), independently of the library the code reads them from.
"""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax
from optmodels.io.asterix import framing

NM, FT = 1852.0, 0.3048
LSB = {
    "tod": 1 / 128,  # I048/140, I021/073 (s)
    "rho": NM / 256,  # I048/040 RHO (m)
    "theta": 2 * np.pi / 2**16,  # I048/040 THETA (rad)
    "fl": 0.25 * 100 * FT,  # I048/090, I021/145 (m of pressure altitude)
    "lat_hi": 180 / 2**30,  # I021/131 (deg)
    "lat_lo": 180 / 2**23,  # I021/130 (deg)
    "gh": 6.25 * FT,  # I021/140 (m)
}
EPS = 1e-9  # float noise on top of LSB/2 (relative to the values involved)

SITES = {(7, 11): (45.0, 15.5, 300.0), (7, 12): (45.6, 16.4, 150.0)}


def _traffic(
    rng: np.random.Generator, n_air: int = 6, n_t: int = 40, t0: float = 36000.0
) -> dict[str, np.ndarray]:
    """Seeded 3-D traffic: straight climbs/levels/descents at 3-12 km, 4 s scans."""
    t = t0 + 4.0 * np.arange(n_t)
    lat0 = rng.uniform(44.8, 45.8, n_air)
    lon0 = rng.uniform(15.3, 16.6, n_air)
    vn, ve = rng.uniform(-200, 200, (2, n_air))
    h0 = rng.uniform(3000, 12000, n_air)
    vz = rng.choice([-8.0, 0.0, 8.0], n_air)
    rows = {k: [] for k in ("t", "lat", "lon", "h", "addr", "m3")}
    addr = rng.choice(2**24, n_air, replace=False)
    m3 = rng.integers(0, 4096, n_air)
    for a in range(n_air):
        dt = t - t0
        rows["t"].append(t)
        rows["lat"].append(lat0[a] + vn[a] * dt / 111_000.0)
        rows["lon"].append(lon0[a] + ve[a] * dt / (111_000.0 * np.cos(np.radians(45))))
        rows["h"].append(np.clip(h0[a] + vz[a] * dt, 3000, 12000))
        rows["addr"].append(np.full(n_t, addr[a]))
        rows["m3"].append(np.full(n_t, m3[a]))
    return {k: np.concatenate(v) for k, v in rows.items()}


def _encode(tr: dict[str, np.ndarray], rng: np.random.Generator) -> tuple[bytes, dict]:
    """CAT048 of every radar (true slant range, azimuth by pymap3d) + CAT021 of every
    report, interleaved by datablock."""
    truth: dict = {"048": [], "021": None}
    blocks = []
    fl = (tr["h"] - 150.0) / (100 * FT)  # a pressure altitude, arbitrary but known
    for (sac, sic), (la, lo, hh) in SITES.items():
        az, _el, srange = pymap3d.geodetic2aer(tr["lat"], tr["lon"], tr["h"], la, lo, hh)
        tod = tr["t"] + rng.uniform(0, 4, tr["t"].size)
        blocks.append(
            ax.encode_cat048(
                tod,
                sac,
                sic,
                srange,
                np.radians(az),
                flight_level=fl,
                address=tr["addr"],
                mode3a=tr["m3"],
                per_block=13,
            )
        )
        truth["048"].append(
            dict(sac=sac, sic=sic, tod=tod, rho=srange, theta=np.radians(az), fl=fl * 100 * FT)
        )
    blocks.append(
        ax.encode_cat021(
            tr["t"],
            9,
            1,
            tr["lat"],
            tr["lon"],
            height=tr["h"],
            flight_level=fl,
            address=tr["addr"],
            per_block=7,
        )
    )
    truth["021"] = dict(tod=tr["t"], lat=tr["lat"], lon=tr["lon"], gh=tr["h"], fl=fl * 100 * FT)
    return b"".join(blocks), truth


def _close(got: np.ndarray, want: np.ndarray, lsb: float, *, angle: bool = False) -> None:
    d = got - want
    if angle:
        d = (d + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(d) <= lsb / 2 + EPS * max(1.0, float(np.max(np.abs(want))))), float(
        np.max(np.abs(d)) / lsb
    )


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    rng = np.random.default_rng(20261201)
    tr = _traffic(rng)
    data, truth = _encode(tr, rng)
    path = tmp_path_factory.mktemp("ast") / "rec.ast"
    path.write_bytes(data)
    return path, tr, truth


def test_roundtrip_every_field_to_lsb(recording: tuple) -> None:
    path, tr, truth = recording
    d = ax.read_asterix(path)
    n = tr["t"].size
    assert d.records == {21: n, 48: 2 * n} and d.skipped == {}
    assert d.dropped == {}
    c = d.cat048
    for k, want in enumerate(truth["048"]):
        sel = slice(k * n, (k + 1) * n)
        assert np.all(c.sac[sel] == want["sac"]) and np.all(c.sic[sel] == want["sic"])
        _close(c.time[sel], want["tod"], LSB["tod"])
        _close(c.range[sel], want["rho"], LSB["rho"])
        _close(c.azimuth[sel], want["theta"], LSB["theta"], angle=True)
        _close(c.pressure_altitude[sel], want["fl"], LSB["fl"])
        assert np.array_equal(c.address[sel], tr["addr"])
        assert np.array_equal(c.mode3a[sel], tr["m3"])
    a = d.cat021
    w = truth["021"]
    _close(a.time, w["tod"], LSB["tod"])
    _close(a.latitude, w["lat"], LSB["lat_hi"])
    _close(a.longitude, w["lon"], LSB["lat_hi"])
    _close(a.height, w["gh"], LSB["gh"])
    _close(a.pressure_altitude, w["fl"], LSB["fl"])
    assert np.array_equal(a.address, tr["addr"]) and np.all(a.sac == 9)
    # the byte offsets point at records: the CAT048 ones inside the first blocks
    assert np.all(np.diff(c.offset[:n]) > 0)


def test_check_all_agrees_with_layout_check(recording: tuple) -> None:
    path, _, _ = recording
    d1 = ax.read_asterix(path)
    d2 = ax.read_asterix(path, check="all")
    for name in ("time", "range", "azimuth", "pressure_altitude", "address"):
        np.testing.assert_array_equal(getattr(d1.cat048, name), getattr(d2.cat048, name))


def test_low_resolution_position_and_absent_items(tmp_path) -> None:
    rng = np.random.default_rng(5)
    lat, lon = rng.uniform(-89, 89, 30), rng.uniform(-179, 179, 30)
    h = rng.uniform(0, 12000, 30)
    h[::3] = np.nan  # no I140 in every third record
    p = tmp_path / "lo.ast"
    p.write_bytes(
        ax.encode_cat021(np.arange(30.0), 1, 2, lat, lon, height=h, high_resolution=False)
    )
    a = ax.read_asterix(p).cat021
    _close(a.latitude, lat, LSB["lat_lo"])
    _close(a.longitude, lon, LSB["lat_lo"])
    assert np.all(np.isnan(a.height[::3])) and np.all(np.isnan(a.pressure_altitude))
    _close(a.height[1::3], h[1::3], LSB["gh"])
    assert np.all(a.address == -1)


def test_variable_items_framed_by_their_fx_rep_and_subfspec(tmp_path) -> None:
    """Records with Extended (I020, I170), Compound (I130) and Repetitive (I250) items,
    written by libasterix directly: the fields behind them are still found."""
    import asterix.generated as gen

    spec = gen.Cat_048_1_32
    rho = np.array([10.0, 100.5, 200.25])
    recs = []
    for i, r in enumerate(rho):
        items = {
            "010": (("SAC", 1), ("SIC", 2)),
            "140": (100.0 + i, "s"),
            "020": ((5, 0, 0, 0, 0, 1), (0, 0, 0, 0, 0, 0, 0, 0)),
            "040": (("RHO", (float(r), "NM")), ("THETA", (45.0, "°"))),
            "130": {"SRL": 3, "SAM": 200},
            "220": 0xABC000 + i,
            "250": [0x1122334455667740] * (i + 1),
            "161": 12,
            "170": ((0, 0, 0, 0, 0, 1), (0, 0, 0, 0, 0, 0)),
            "090": (0, 0, ("FL", (350.25 - i, "FL"))),
        }
        recs.append(spec.cv_record.create(items))
    p = tmp_path / "rich.ast"
    p.write_bytes(spec.create(recs).unparse().to_bytes())
    c = ax.read_asterix(p).cat048
    _close(c.range, rho * NM, LSB["rho"])
    _close(c.pressure_altitude, (350.25 - np.arange(3)) * 100 * FT, LSB["fl"])
    assert list(c.address) == [0xABC000, 0xABC001, 0xABC002]


def test_recording_across_midnight(tmp_path) -> None:
    t = 86400.0 - 100.0 + 2.5 * np.arange(80)  # 23:58:20 → 00:01:37.5
    rho, az = np.full(80, 50e3), np.full(80, 1.0)
    whole = ax.encode_cat048(t, 1, 2, rho, az)
    p = tmp_path / "m.ast"
    p.write_bytes(whole)
    d = ax.read_asterix(p, date="2026-03-01")
    _close(d.cat048.time, t, LSB["tod"])  # continues past 86 400 s
    assert d.epoch == np.datetime64("2026-03-01T00:00:00", "ns")
    stamps = d.epoch + (d.cat048.time * 1e9).astype("timedelta64[ns]")
    assert str(stamps[-1])[:19] == "2026-03-02T00:01:37"
    # the same recording split at midnight into two files, read in order
    k = int(np.searchsorted(t, 86400.0))
    p1, p2 = tmp_path / "a.ast", tmp_path / "b.ast"
    p1.write_bytes(ax.encode_cat048(t[:k], 1, 2, rho[:k], az[:k]))
    p2.write_bytes(ax.encode_cat048(t[k:], 1, 2, rho[k:], az[k:]))
    d2 = ax.read_asterix([p1, p2])
    _close(d2.cat048.time, t, LSB["tod"])
    assert d2.epoch is None and np.all(d2.cat048.file == (np.arange(80) >= k))


def test_truncated_file_names_file_and_byte(tmp_path, recording: tuple) -> None:
    path, _, _ = recording
    data = path.read_bytes()
    n0 = int.from_bytes(data[1:3], "big")
    cut = tmp_path / "cut.ast"
    cut.write_bytes(data[: n0 + 10])  # inside the second datablock
    with pytest.raises(ProblemError, match=rf"cut\.ast.*truncated.*byte {n0}\b"):
        ax.read_asterix(cut)
    # a datablock whose records overrun it: LEN shortened by 2 bytes
    bad = bytearray(data[:n0])
    bad[1:3] = (n0 - 2).to_bytes(2, "big")
    short = tmp_path / "short.ast"
    short.write_bytes(bytes(bad[: n0 - 2]))
    with pytest.raises(ProblemError, match=r"short\.ast.*(overruns|truncated|refuses)"):
        ax.read_asterix(short)


def test_foreign_files_refused_and_detected(tmp_path, recording: tuple) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    path, _, _ = recording
    csv = tmp_path / "plots.csv"
    csv.write_text("time,radar,range,azimuth,object\n0.0,R1,1000,0.1,1\n")
    pqf = tmp_path / "plots.parquet"
    pq.write_table(pa.table({"time": [0.0], "range": [1.0]}), pqf)
    noise = tmp_path / "noise.bin"
    noise.write_bytes(np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    assert ax.is_asterix(path)
    for p in (csv, pqf, noise):
        assert not ax.is_asterix(p)
        with pytest.raises(ProblemError, match=rf"{p.name}.*not ASTERIX.*byte 0"):
            ax.read_asterix(p)
    with pytest.raises(ProblemError, match="no such file"):
        ax.read_asterix(tmp_path / "missing.ast")


def test_undefined_frn_is_refused(tmp_path) -> None:
    good = ax.encode_cat048([1.0], 1, 2, [1000.0], [0.5])
    bad = bytearray(good)
    bad[3] |= 0x01  # FX: a second FSPEC byte …
    bad.insert(4, 0x02)  # … announcing FRN 14 (I170), absent
    bad[1:3] = len(bad).to_bytes(2, "big")
    p = tmp_path / "frn.ast"
    p.write_bytes(bytes(bad))
    with pytest.raises(ProblemError, match=r"frn\.ast.*byte"):
        ax.read_asterix(p)


def test_disagreement_with_libasterix_is_refused(tmp_path, monkeypatch) -> None:
    """The layout check is live: a wrong field extraction is caught by libasterix."""
    p = tmp_path / "x.ast"
    p.write_bytes(ax.encode_cat048([1.0, 2.0], 1, 2, [1000.0, 2000.0], [0.5, 0.6]))
    monkeypatch.setattr(framing, "_raw_at", lambda buf, o, f: -1)
    with pytest.raises(ProblemError, match=r"x\.ast.*byte 3.*libasterix"):
        ax.read_asterix(p)


def test_bad_arguments() -> None:
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat048 range"):
        ax.encode_cat048([1.0], 1, 2, [300 * NM], [0.0])
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat048 azimuth"):
        ax.encode_cat048([1.0], 1, 2, [1.0], [np.nan])
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat048 sac: need integers"):
        ax.encode_cat048([1.0], 256, 2, [1.0], [0.0])
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat021 latitude"):
        ax.encode_cat021([1.0], 1, 2, [91.0], [0.0])
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat048 per_block"):
        ax.encode_cat048([1.0], 1, 2, [1.0], [0.0], per_block=0)
    with pytest.raises(ProblemError, match=r"asterix\.read check"):
        ax.read_asterix("x.ast", check="none")
    with pytest.raises(ProblemError, match=r"asterix\.read date"):
        ax.read_asterix("x.ast", date="yesterday")
    with pytest.raises(ProblemError, match="asterix editions"):
        ax.read_asterix("x.ast", editions={48: (9, 9)})


# ---------------------------------------------------------------------------------------
# optmodels.biasfield.recording: ASTERIX → 3-D PlotTable, ADS-B reports, drop report
# ---------------------------------------------------------------------------------------

SITES_CSV = """name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range
North,7,11,45.0,15.5,300,30,0.05,250000
East,7,12,45.6,16.4,150,40,0.06,250000
"""


def _flights(rng: np.random.Generator, n_air: int = 5) -> dict[str, np.ndarray]:
    """Linear 3-D flights at 4-9 km (climb/level/descent ≤ 8 m/s) over 200 s."""
    return {
        "lat0": rng.uniform(45.0, 45.6, n_air),
        "lon0": rng.uniform(15.5, 16.4, n_air),
        "vn": rng.uniform(-150, 150, n_air),
        "ve": rng.uniform(-150, 150, n_air),
        "h0": rng.uniform(4000, 9000, n_air),
        "vz": rng.choice([-8.0, 0.0, 8.0], n_air),
        "addr": rng.choice(2**24, n_air, replace=False),
    }


def _at(f: dict[str, np.ndarray], a: int, t: np.ndarray, t0: float) -> tuple:
    dt = t - t0
    return (
        f["lat0"][a] + f["vn"][a] * dt / 111_000.0,
        f["lon0"][a] + f["ve"][a] * dt / 78_600.0,
        f["h0"][a] + f["vz"][a] * dt,
    )


def _recording(tmp_path, rng: np.random.Generator, *, t0: float = 50_000.0) -> tuple:
    f = _flights(rng)
    n_air = f["addr"].size
    blocks, truth = [], []
    ta = t0 + np.arange(0.0, 200.0, 1.0)  # ADS-B every second
    for a in range(n_air - 1):  # the last aircraft has no ADS-B
        la, lo, h = _at(f, a, ta, t0)
        blocks.append(ax.encode_cat021(ta, 9, 1, la, lo, height=h, address=f["addr"][a]))
    for (sac, sic), site in [
        ((7, 11), SITES[(7, 11)]),
        ((7, 12), SITES[(7, 12)]),
        ((8, 1), (45.3, 16.0, 0.0)),
    ]:  # (8, 1): not in the CSV
        for a in range(n_air):
            tp = t0 + 10.0 + 4.0 * np.arange(40) + rng.uniform(0, 4)
            la, lo, h = _at(f, a, tp, t0)
            az, _el, sr = pymap3d.geodetic2aer(la, lo, h, *site)
            addr = np.full(tp.size, f["addr"][a])
            addr[-1] = -1  # one plot without I220 per track
            fl = (h - 200.0) / (100 * FT)
            blocks.append(
                ax.encode_cat048(tp, sac, sic, sr, np.radians(az), flight_level=fl, address=addr)
            )
            if (sac, sic) != (8, 1):
                truth.append((sac, sic, a, tp[:-1], la[:-1], lo[:-1], h[:-1], fl[:-1]))
    rec = tmp_path / "rec.ast"
    rec.write_bytes(b"".join(blocks))
    sites = tmp_path / "sites.csv"
    sites.write_text(SITES_CSV)
    return rec, sites, f, truth


def test_read_recording_heights_plane_positions_and_report(tmp_path) -> None:
    from optmodels.biasfield import geometry3d as g3
    from optmodels.biasfield.heights import fl_to_height
    from optmodels.biasfield.recording import read_recording

    rng = np.random.default_rng(42)
    rec, sites, f, truth = _recording(tmp_path, rng)
    r = read_recording(rec, sites)
    n_air = f["addr"].size
    rep = r.report
    assert rep.plots_read == 3 * n_air * 40
    assert rep.unknown_ids == ((8, 1),)
    assert (
        r.dropped
        == rep.dropped
        == {"unknown SAC/SIC": n_air * 40, "no aircraft address (I048/220)": 2 * n_air}
    )
    assert rep.as_dict()["unknown_sac_sic"] == [[8, 1]]
    assert rep.plots_kept == len(r.plots) == 2 * n_air * 39
    assert rep.heights == {"adsb": 2 * (n_air - 1) * 39, "flight level": 2 * 39, "none": 0}
    assert rep.adsb_read == rep.adsb_kept == (n_air - 1) * 200
    assert r.radars.ids == ((7, 11), (7, 12)) and r.radars.is_3d
    assert np.all(np.diff(r.plots.time) >= 0)
    # heights: ADS-B interpolated (its LSB/2 + the two time quantisations × 8 m/s), or
    # the ISA conversion of the decoded flight level for the aircraft without ADS-B
    tol_h = LSB["gh"] / 2 + 2 * 8.0 * LSB["tod"] + 1e-6
    pos_err = []
    for sac, sic, a, tp, la, lo, h, fl in truth:
        i = r.radars.index_of_id(sac, sic)
        obj = int(np.searchsorted(r.addresses, f["addr"][a]))
        sel = (r.plots.radar == i) & (r.plots.object == obj)
        assert sel.sum() == tp.size
        got_t = r.plots.time[sel]
        _close(got_t, tp, LSB["tod"])
        if a < n_air - 1:
            assert np.all(r.height_source[sel] == 1)
            assert np.max(np.abs(r.plots.height[sel] - h)) <= tol_h
        else:
            assert np.all(r.height_source[sel] == 2)
            want = fl_to_height(np.round(fl * 4) / 4 * 100 * FT)
            np.testing.assert_allclose(r.plots.height[sel], want, rtol=0, atol=1e-6)
            continue
        # the exact 3-D chain places the plot where the aircraft was (quantisation only)
        z = r.plots.subset(sel).cartesian(r.radars)
        want = g3.common_plane(la, lo, r.radars.origin)
        pos_err.append(np.max(np.hypot(*(z - want).T)))
    # bound: range LSB/2 (3.6 m) + 150 km × azimuth LSB/2 (7.2 m) + the height error
    # times the slant/ground slope (≤ 0.2 here) → 11 m
    assert max(pos_err) <= LSB["rho"] / 2 + 150e3 * LSB["theta"] / 2 + 0.2 * tol_h
    assert r.icao24[0] == f"{int(r.addresses[0]):06x}" and len(r.icao24[0]) == 6


def test_read_recording_gap_falls_back_to_flight_level(tmp_path) -> None:
    from optmodels.biasfield.recording import read_recording

    t = np.array([0.0, 1.0, 2.0, 60.0, 61.0]) + 1000.0  # ADS-B gap of 58 s
    la, lo, h = np.full(5, 45.3), np.full(5, 16.0), np.array([5e3, 5e3, 5e3, 6e3, 6e3])
    tp = np.array([1.5, 30.0, 60.5]) + 1000.0
    az, _el, sr = pymap3d.geodetic2aer(45.3, 16.0, 5500.0, *SITES[(7, 11)])
    data = ax.encode_cat021(t, 9, 1, la, lo, height=h, address=0xABCDEF) + ax.encode_cat048(
        tp,
        7,
        11,
        np.full(3, sr),
        np.full(3, np.radians(az)),
        flight_level=[150.0, 160.0, np.nan],
        address=0xABCDEF,
    )
    p = tmp_path / "gap.ast"
    p.write_bytes(data)
    sites = tmp_path / "s.csv"
    sites.write_text(SITES_CSV)
    r = read_recording(p, sites, max_gap=20.0)
    assert list(r.height_source) == [1, 2, 1]
    _close(r.plots.height[[0, 2]], np.array([5e3, 6e3]), LSB["gh"])
    assert r.plots.height[1] > 160 * 100 * FT  # ISA geometric > geopotential
    r2 = read_recording(p, sites, max_gap=100.0)  # the gap is now bridged
    assert list(r2.height_source) == [1, 1, 1]
    assert abs(r2.plots.height[1] - (5e3 + 1e3 * 28 / 58)) <= LSB["gh"]


def test_fl_to_height_isa() -> None:
    from optmodels.biasfield.heights import R_ISA, fl_to_height

    # geopotential 11 000 m (the tropopause) ↔ geometric 11 019.1 m (ICAO Doc 7488 table)
    assert abs(float(fl_to_height(11_000.0)) - 11_019.1) < 0.1
    assert abs(float(fl_to_height(0.0, 47.0)) - 47.0) < 1e-12
    hp = 9000.0
    assert abs(float(fl_to_height(hp)) - hp * (1 + hp / R_ISA + (hp / R_ISA) ** 2)) < 0.01
    with pytest.raises(ProblemError, match="geoid_undulation"):
        fl_to_height(1.0, 500.0)


def test_read_recording_bad_arguments(tmp_path) -> None:
    from optmodels.biasfield.recording import read_recording, read_sites
    from optmodels.biasfield.tables import RadarSet

    p = tmp_path / "a.ast"
    p.write_bytes(ax.encode_cat048([1.0], 7, 11, [1e4], [0.1], address=1))
    flat = RadarSet(np.array([[0.0, 0.0], [1e4, 0.0]]), 30.0, 1e-3, 2e5)
    with pytest.raises(ProblemError, match=r"read_recording radars: need a 3-D"):
        read_recording(p, flat)
    no_ids = tmp_path / "noids.csv"
    no_ids.write_text(
        "name,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        "A,45,15,0,30,0.05,2e5\nB,45.5,15.5,0,30,0.05,2e5\n"
    )
    with pytest.raises(ProblemError, match=r"noids\.csv.*sac"):
        read_sites(no_ids)
    sites = tmp_path / "s.csv"
    sites.write_text(SITES_CSV)
    with pytest.raises(ProblemError, match=r"max_gap"):
        read_recording(p, sites, max_gap=0.0)
    with pytest.raises(ProblemError, match=r"drop_out_of_range"):
        read_recording(p, sites, drop_out_of_range="yes")
    with pytest.raises(ProblemError, match=r"read_recording origin"):
        read_recording(p, read_sites(sites), origin=(45.0, 15.0, 0.0))
    # the set's own origin is accepted (the CLI passes it to both)
    rs = read_sites(sites, origin=(45.0, 15.0, 0.0))
    assert read_recording(p, rs, origin=[45.0, 15.0, 0.0]).radars is rs


def test_simulated_3d_network_encoded_and_read_back(tmp_path) -> None:
    """B1's 3-D simulator (radar_network geometry="3d": slant ranges, own-north azimuths,
    heights): its plots as CAT048 and its aircraft as CAT021 at every path instant; the
    recording gives every plot's time, slant range, azimuth to the format's resolution and
    its height from ADS-B (interpolated) to LSB/2 plus the time quantisation."""
    from optmodels.biasfield.recording import read_recording
    from optmodels.biasfield.tables import RadarSet
    from optmodels.scenarios.radar_network import radar_network

    sc = radar_network(7, n_aircraft=4, duration=90.0, geometry="3d")
    rs = sc.radars
    ids = tuple((1, i + 1) for i in range(rs.m))
    radars = RadarSet(
        None,
        rs.sigma_range,
        rs.sigma_azimuth,
        rs.max_range,
        rs.names,
        geodetic=rs.geodetic,
        origin=rs.origin,
        ids=ids,
    )
    pl = sc.plots
    order = np.argsort(pl.time, kind="stable")
    t, rad, rng_, az = pl.time[order], pl.radar[order], pl.range[order], pl.azimuth[order]
    obj, h = pl.object[order], pl.height[order]
    base_addr = 0x400000
    blocks = [
        ax.encode_cat048(
            t[rad == i], 1, i + 1, rng_[rad == i], az[rad == i], address=base_addr + obj[rad == i]
        )
        for i in range(rs.m)
    ]
    for a in range(len(sc.paths)):
        ta, _en, geo = sc.paths.track(a)
        blocks.append(
            ax.encode_cat021(
                ta + 0.0, 9, 9, geo[:, 0], geo[:, 1], height=geo[:, 2], address=base_addr + a
            )
        )
    p = tmp_path / "sim.ast"
    p.write_bytes(b"".join(blocks))
    r = read_recording(p, radars)
    assert r.report.plots_kept == len(pl) and r.report.dropped == {}
    assert r.report.heights["adsb"] == len(pl)
    # the recording's plots are time-sorted; match them to the truth by (radar, time)
    for i in range(rs.m):
        got = r.plots.subset(r.plots.radar == i)
        sel = rad == i
        _close(got.time, t[sel], LSB["tod"])
        _close(got.range, rng_[sel], LSB["rho"])
        _close(got.azimuth, az[sel], LSB["theta"], angle=True)
        np.testing.assert_array_equal(r.addresses[got.object], base_addr + obj[sel])
        vmax = 15.0  # m/s, fly_paths3d's largest climb
        assert np.max(np.abs(got.height - h[sel])) <= LSB["gh"] / 2 + 2 * vmax * LSB["tod"]


def test_time_of_applicability_fallback_and_other_categories_skipped(tmp_path) -> None:
    """I021/071 is the time when I073 is absent; CAT034 datablocks are skipped and counted."""
    import asterix.generated as gen

    c21, c34 = gen.Cat_021_2_7, gen.Cat_034_1_29
    rec = c21.cv_record.create(
        {
            "010": (("SAC", 1), ("SIC", 2)),
            "040": ((0, 0, 0, 0, 0),),
            "071": (4321.5, "s"),
            "131": (("LAT", (45.5, "°")), ("LON", (-3.25, "°"))),
            "080": 0x00ABCD,
        }
    )
    north = c34.cv_record.create({"000": 1, "010": (("SAC", 1), ("SIC", 2))})
    p = tmp_path / "mix.ast"
    p.write_bytes(
        c34.create([north]).unparse().to_bytes()
        + c21.create([rec]).unparse().to_bytes()
        + c34.create([north, north]).unparse().to_bytes()
    )
    d = ax.read_asterix(p)
    assert d.skipped == {34: 2} and d.records == {21: 1, 48: 0}
    _close(d.cat021.time, np.array([4321.5]), LSB["tod"])
    _close(d.cat021.latitude, np.array([45.5]), LSB["lat_hi"])
    _close(d.cat021.longitude, np.array([-3.25]), LSB["lat_hi"])
    assert np.isnan(d.cat021.height[0]) and d.cat021.address[0] == 0x00ABCD


def test_chunked_framing_gives_the_same_tables(recording: tuple, monkeypatch) -> None:
    """Fields are gathered every CHUNK records (bounded memory); chunk boundaries inside
    datablocks and between categories change nothing, the midnight unwrapping included."""
    path, _, _ = recording
    whole = ax.read_asterix(path)
    monkeypatch.setattr(framing, "CHUNK", 7)
    parts = ax.read_asterix(path)
    for tab in ("cat048", "cat021"):
        a, b = getattr(whole, tab), getattr(parts, tab)
        for name in a.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert parts.records == whole.records


def test_other_edition_read_with_its_own_layout(tmp_path) -> None:
    """CAT048 ed. 1.27 (libasterix's spec of that edition drives the reader)."""
    p = tmp_path / "e127.ast"
    rho, fl = np.array([1e4, 2e4, 3e5]), np.array([100.25, 200.0, 410.5])
    p.write_bytes(
        ax.encode_cat048(
            np.arange(3.0), 1, 2, rho, np.full(3, 0.2), flight_level=fl, edition=(1, 27)
        )
    )
    c = ax.read_asterix(p, editions={48: (1, 27)}).cat048
    _close(c.range, rho, LSB["rho"])
    _close(c.pressure_altitude, fl * 100 * FT, LSB["fl"])
