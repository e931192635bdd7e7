"""Readers and writers of user files (issue 14, slice "files").

Every malformed file is generated in ``tmp_path``. A file that can be used (a UTF-8 BOM,
CRLF line ends, a trailing empty column) must give the same numbers as the plain file; a
file that cannot be used must give one :class:`ProblemError` naming the file (and the
line/column or byte where that is cheap), never a raw ``UnicodeDecodeError``,
``ArrowInvalid``, ``BadZipFile``, ``KeyError``, ``OSError`` or ``LinAlgError``.

Parsed floats are compared exactly where the same decimal text is parsed twice (or written
with 17 significant digits, which round-trips a double exactly): that is parsing, not a
solver's result.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from optmodels import biasfield as bf
from optmodels import io
from optmodels.biasfield.paths import AircraftPaths
from optmodels.core import ProblemError

ORIGIN = (55.0, 83.0, 150.0)  # lat, lon (deg), alt (m)
BOM = "\ufeff"


def _radar_rows(rng: np.random.Generator, m: int = 3) -> list[list[str]]:
    lat = ORIGIN[0] + rng.uniform(-1.0, 1.0, m)
    lon = ORIGIN[1] + rng.uniform(-1.0, 1.0, m)
    alt = rng.uniform(0.0, 500.0, m)
    return [
        [
            f"R{i}",
            repr(float(lat[i])),
            repr(float(lon[i])),
            repr(float(alt[i])),
            "50.0",
            "0.08",
            "300000.0",
        ]
        for i in range(m)
    ]


RADAR_HEADER = ["name", "lat", "lon", "alt", "sigma_range", "sigma_azimuth", "max_range"]


def _write(
    path: Path, header: list[str], rows: list[list[str]], *, bom: bool = False, crlf: bool = False
) -> Path:
    eol = "\r\n" if crlf else "\n"
    text = eol.join(",".join(r) for r in [header, *rows]) + eol
    path.write_bytes(((BOM if bom else "") + text).encode("utf-8"))
    return path


# --------------------------------------------------------------------------- BOM
def test_bom_and_crlf_csv_read_as_plain_in_every_reader(tmp_path: Path) -> None:
    """ "CSV UTF-8" from a spreadsheet (BOM + CRLF) gives exactly the numbers of the plain
    file in all five readers, and those numbers are the ones written (repr round trip);
    the lat/lon radar sites equal pymap3d's ENU of the written coordinates to 1 mm."""
    rng = np.random.default_rng(11)
    pts = rng.normal(scale=1e3, size=(8, 3))
    t = np.arange(8.0)
    plane_rows = [[repr(float(v)) for v in (*p, ti)] for p, ti in zip(pts, t, strict=True)]
    traj_rows = [
        [o, repr(float(ti)), repr(float(y))]
        for o, ti, y in zip("aabbaabb", t, rng.normal(size=8), strict=True)
    ]
    radar_rows = _radar_rows(rng)
    plot_rows = [
        [repr(float(k)), f"R{k % 3}", repr(float(1e4 + 100 * k)), repr(float(10 * k)), f"AC{k % 2}"]
        for k in range(9)
    ]
    track_rows = [
        [f"F{k % 2}", repr(float(k)), repr(55.0 + 1e-3 * k), repr(83.0 - 1e-3 * k), "9000.0"]
        for k in range(10)
    ]
    cases = {
        "plane": (["x", "y", "z", "t"], plane_rows, io.read_plane_csv),
        "traj": (["object", "t", "y"], traj_rows, io.read_trajectory_csv),
        "radars": (RADAR_HEADER, radar_rows, lambda p: bf.read_radars(p)),
        "tracks": (
            ["object", "time", "lat", "lon", "alt"],
            track_rows,
            lambda p: bf.read_tracks(p, ORIGIN),
        ),
    }
    got: dict[str, tuple] = {}
    for key, (header, rows, read) in cases.items():
        plain = read(_write(tmp_path / f"{key}.csv", header, rows))
        bom = read(_write(tmp_path / f"{key}_bom.csv", header, rows, bom=True, crlf=True))
        got[key] = (plain, bom)
    plane, plane_bom = got["plane"]
    np.testing.assert_array_equal(plane_bom["points"], plane["points"])
    np.testing.assert_array_equal(plane["points"], pts)
    np.testing.assert_array_equal(plane_bom["t"], t)
    traj, traj_bom = got["traj"]
    assert traj_bom["objects"] == traj["objects"] == ["a", "b"]
    for a, b in zip(traj["values"], traj_bom["values"], strict=True):
        np.testing.assert_array_equal(a, b)
    (radars, org), (radars_bom, org_bom) = got["radars"]
    assert radars_bom.names == radars.names == ("R0", "R1", "R2") and org_bom == org
    np.testing.assert_array_equal(radars_bom.sites, radars.sites)
    lat, lon, alt = (np.array([float(r[j]) for r in radar_rows]) for j in (1, 2, 3))
    e, n, _ = pymap3d.geodetic2enu(lat, lon, alt, lat[0], lon[0], alt[0])
    np.testing.assert_allclose(radars.sites, np.column_stack([e, n]), atol=1e-3)
    tracks, tracks_bom = got["tracks"]
    np.testing.assert_array_equal(tracks_bom.positions, tracks.positions)
    np.testing.assert_array_equal(tracks_bom.active, tracks.active)
    header = ["time", "radar", "range", "azimuth", "object"]
    plots, _ = bf.read_plots(_write(tmp_path / "plots.csv", header, plot_rows), radars)
    plots_bom, _ = bf.read_plots(
        _write(tmp_path / "plots_bom.csv", header, plot_rows, bom=True, crlf=True), radars
    )
    np.testing.assert_array_equal(plots_bom.range, plots.range)
    np.testing.assert_array_equal(plots_bom.radar, np.arange(9) % 3)
    # degrees -> radians: 1 ulp of 2π
    np.testing.assert_allclose(
        plots_bom.azimuth, np.deg2rad(10.0 * np.arange(9)), rtol=0, atol=1e-15
    )


def test_read_csv_rows_public_lines_and_spreadsheet_artefacts(tmp_path: Path) -> None:
    """read_csv_rows (the public name of the old io._read_rows, used by the bias-field
    ingest) reports the file line of every row, skipping blank lines; a trailing empty
    column (a trailing comma on every line) is dropped and gives the plain file's values."""
    p = tmp_path / "a.csv"
    p.write_text("X, Y ,z,\n1,2,3,\n\n4,5,6,\n,,,\n7,8,9.5,\n")
    header, rows, lines = io.read_csv_rows(p)
    assert header == ["x", "y", "z"] and lines == [2, 4, 6]
    assert rows == [["1", "2", "3"], ["4", "5", "6"], ["7", "8", "9.5"]]
    ref = tmp_path / "ref.csv"
    ref.write_text("x,y,z\n1,2,3\n4,5,6\n7,8,9.5\n")
    np.testing.assert_array_equal(io.read_plane_csv(p)["points"], io.read_plane_csv(ref)["points"])
    assert not hasattr(io, "_read_rows")


# --------------------------------------------------------------------------- encodings
def test_latin1_csv_refused_with_file_line_and_byte(tmp_path: Path) -> None:
    data = (
        "name,x,y,sigma_range,sigma_azimuth,max_range\nA,0,0,50,0.1,1e5\n"
        "München,1e4,0,50,0.1,1e5\n".encode("latin-1")
    )
    p = tmp_path / "radars.csv"
    p.write_bytes(data)
    pos = data.index(b"\xfc")
    with pytest.raises(ProblemError) as err:
        bf.read_radars(p)
    msg = str(err.value)
    assert str(p) in msg and "UTF-8" in msg and f"byte {pos}," in msg and "line 3" in msg
    # the same bytes behind a BOM: the position is counted in the file, BOM included
    p.write_bytes(b"\xef\xbb\xbf" + data)
    with pytest.raises(ProblemError, match=f"byte {pos + 3}, line 3"):
        bf.read_radars(p)
    q = tmp_path / "plane.csv"
    q.write_bytes("x,y,z\n1,2,3\n4,5,6\n7,8,9 # café\n".encode("cp1252"))
    with pytest.raises(ProblemError, match="not UTF-8 text"):
        io.read_plane_csv(q)


def test_binary_utf16_and_foreign_formats_refused(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    blob = tmp_path / "blob.csv"
    raw = rng.integers(0, 256, 4096, dtype=np.uint8).tobytes()
    blob.write_bytes(raw)
    with pytest.raises(ProblemError) as err:
        io.read_plane_csv(blob)
    assert str(blob) in str(err.value)
    assert "binary data" in str(err.value) or "not UTF-8" in str(err.value)
    nul = tmp_path / "nul.csv"
    nul.write_bytes(b"x,y,z\n1,2,3\n4,\x005,6\n")
    with pytest.raises(ProblemError, match=r"NUL byte at byte 14, line 3"):
        io.read_plane_csv(nul)
    utf16 = tmp_path / "u16.csv"
    utf16.write_bytes("x,y,z\n1,2,3\n".encode("utf-16"))
    with pytest.raises(ProblemError, match="UTF-16"):
        io.read_plane_csv(utf16)
    import pyarrow as pa
    import pyarrow.parquet as pq

    real = tmp_path / "plots.csv"  # a real Parquet file with the wrong suffix
    pq.write_table(pa.table({"time": [0.0]}), real)
    with pytest.raises(ProblemError, match="Parquet file"):
        io.read_trajectory_csv(real)
    npz = tmp_path / "fd.csv"
    with npz.open("wb") as fh:
        np.savez(fh, a=np.zeros(2))
    with pytest.raises(ProblemError, match="ZIP archive"):
        io.read_plane_csv(npz)


def test_semicolon_duplicate_and_ragged_csv(tmp_path: Path) -> None:
    p = tmp_path / "a.csv"
    p.write_text("x;y;z\n1,5;2;3\n")
    with pytest.raises(ProblemError, match="semicolon"):
        io.read_plane_csv(p)
    p.write_text("x,y,z,X\n1,2,3,4\n")
    with pytest.raises(ProblemError, match="'x' appears more than once"):
        io.read_plane_csv(p)
    p.write_text("x,y,z\n1,2,3\n\n4,5\n")
    with pytest.raises(ProblemError, match="line 4 has 2 fields, the header has 3"):
        io.read_plane_csv(p)
    p.write_text("x,y,z\n1,2,3\n4,abc,6\n")
    with pytest.raises(ProblemError, match="line 3, column 'y': 'abc' is not a number"):
        io.read_plane_csv(p)
    p.write_text("object,t,y\na,0,1\na,1,nan\n")
    with pytest.raises(ProblemError, match=r"line 3, column 'y'.*NaN/inf"):
        io.read_trajectory_csv(p)
    p.write_text("object,t,y\na,0,1\n ,1,2\n")
    with pytest.raises(ProblemError, match="line 3: empty 'object' label"):
        io.read_trajectory_csv(p)
    p.write_text('x,y,z\n1,2,"3\n')
    with pytest.raises(ProblemError, match=str(p)):
        io.read_plane_csv(p)


# --------------------------------------------------------------------------- paths
def test_missing_directory_and_unreadable_files(tmp_path: Path, monkeypatch) -> None:
    radars = bf.RadarSet(np.array([[0.0, 0.0], [1e4, 0.0]]), 50.0, 1e-3, 1e5, ("A", "B"))
    readers = [
        io.read_plane_csv,
        io.read_trajectory_csv,
        bf.read_radars,
        lambda p: bf.read_plots(p, radars),
        lambda p: bf.read_tracks(p, ORIGIN),
        lambda p: io.read_npz(p),
    ]
    folder = tmp_path / "folder.parquet"
    folder.mkdir()
    for read in readers:
        with pytest.raises(ProblemError, match="no such file"):
            read(tmp_path / "missing.csv")
        with pytest.raises(ProblemError, match="is a directory"):
            read(tmp_path)
    with pytest.raises(ProblemError, match=f"{folder}: is a directory"):
        bf.read_plots(folder, radars)
    with pytest.raises(ProblemError, match="expected a file path"):
        io.read_plane_csv(3.5)  # type: ignore[arg-type]
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"")
    with pytest.raises(ProblemError, match="empty file"):
        bf.read_radars(empty)
    header_only = tmp_path / "header.csv"
    header_only.write_text(BOM + "x,y,z\n\n")
    with pytest.raises(ProblemError, match="no data rows"):
        io.read_plane_csv(header_only)
    # no permission: the tests may run as root (who reads anything), so the OS error is
    # injected where the file is read
    ok = tmp_path / "ok.csv"
    ok.write_text("x,y,z\n1,2,3\n")

    def denied(self: Path) -> bytes:
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_bytes", denied)
    with pytest.raises(ProblemError, match=f"{ok}: permission denied"):
        io.read_plane_csv(ok)


# --------------------------------------------------------------------------- Parquet
def test_fake_empty_and_malformed_parquet(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    radars = bf.RadarSet(np.array([[0.0, 0.0], [1e4, 0.0]]), 50.0, 1e-3, 1e5, ("A", "B"))
    fake = tmp_path / "plots.parquet"
    fake.write_text("time,radar,range,azimuth\n0,A,1000,10\n")
    with pytest.raises(ProblemError, match=f"{fake}: not a readable Parquet file"):
        bf.read_plots(fake, radars)
    fake.write_bytes(b"")
    with pytest.raises(ProblemError, match="not a readable Parquet file"):
        bf.read_plots(fake, radars)
    good = tmp_path / "good.parquet"
    pq.write_table(
        pa.table(
            {
                "time": [0.0, 1.0],
                "radar": ["A", "B"],
                "range": [1000.0, 2000.0],
                "azimuth": [10.0, 20.0],
            }
        ),
        good,
    )
    raw = good.read_bytes()
    cut = tmp_path / "cut.parquet"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ProblemError, match="not a readable Parquet file"):
        bf.read_plots(cut, radars)
    table, _ = bf.read_plots(good, radars)
    np.testing.assert_allclose(table.azimuth, np.deg2rad([10.0, 20.0]), rtol=1e-15)
    nulls = tmp_path / "nulls.parquet"
    pq.write_table(
        pa.table(
            {
                "time": [0.0, 1.0],
                "radar": ["A", "B"],
                "range": pa.array(["1000", None]),
                "azimuth": [1.0, 2.0],
            }
        ),
        nulls,
    )
    with pytest.raises(ProblemError, match="row 2, column 'range': nan \\(NaN/inf"):
        bf.read_plots(nulls, radars)
    dup = tmp_path / "dup.parquet"
    pq.write_table(
        pa.table({"time": [0.0], "Time": [1.0], "radar": ["A"], "range": [1.0], "azimuth": [1.0]}),
        dup,
    )
    with pytest.raises(ProblemError, match="'time' appears more than once"):
        bf.read_plots(dup, radars)
    none = tmp_path / "none.parquet"
    pq.write_table(
        pa.table(
            {
                "time": pa.array([], pa.float64()),
                "radar": pa.array([], pa.string()),
                "range": pa.array([], pa.float64()),
                "azimuth": pa.array([], pa.float64()),
            }
        ),
        none,
    )
    with pytest.raises(ProblemError, match="no data rows"):
        bf.read_plots(none, radars)


# --------------------------------------------------------------------------- .npz
def _field_npz(tmp_path: Path) -> tuple[Path, bf.FieldData]:
    fd, _ = bf.synthetic_field_data(0, cells=12)
    path = tmp_path / "fd.npz"
    fd.save(path)
    return path, fd


NPZ_KEYS = {
    "what": "FieldData .npz",
    "required": ("radars", "centers", "xi", "P"),
    "one_of": ("edges", "adjacency"),
}


def test_read_npz_round_trip_and_truncated_archives(tmp_path: Path) -> None:
    """A saved FieldData reads back exactly through read_npz; every prefix of it (cut at
    10 places, 0 bytes included) is refused as one ProblemError naming the file."""
    path, fd = _field_npz(tmp_path)
    arrays = io.read_npz(path, **NPZ_KEYS)
    np.testing.assert_array_equal(arrays["xi"], fd.xi)
    np.testing.assert_array_equal(arrays["radars"], fd.radars)
    raw = path.read_bytes()
    cut = tmp_path / "cut.npz"
    for n in np.unique(np.linspace(0, len(raw) - 1, 10).astype(int)):
        cut.write_bytes(raw[:n])
        with pytest.raises(ProblemError, match=f"{cut}: "):
            io.read_npz(cut, **NPZ_KEYS)
    flipped = bytearray(raw)
    flipped[len(raw) // 3] ^= 0xFF  # inside a member: bad CRC or a broken deflate stream
    cut.write_bytes(bytes(flipped))
    with pytest.raises(ProblemError, match=r"corrupt|missing"):
        io.read_npz(cut, **NPZ_KEYS)


def test_read_npz_foreign_text_npy_and_pickles(tmp_path: Path) -> None:
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(ProblemError, match=r"missing array.*radars.*edges or adjacency.*has a"):
        io.read_npz(foreign, **NPZ_KEYS)
    text = tmp_path / "text.npz"
    text.write_text("radars,centers\n1,2\n")
    with pytest.raises(ProblemError, match="not a ZIP archive"):
        io.read_npz(text, **NPZ_KEYS)
    npy = tmp_path / "one.npz"
    with npy.open("wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(ProblemError, match=r"single NumPy .npy array"):
        io.read_npz(npy, **NPZ_KEYS)
    pickled = tmp_path / "obj.npz"
    np.savez(pickled, radars=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ProblemError, match="pickled"):
        io.read_npz(pickled, **NPZ_KEYS)
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ProblemError, match="empty file"):
        io.read_npz(empty, **NPZ_KEYS)


# --------------------------------------------------------------------------- radars
def test_read_radars_geodetic_ranges(tmp_path: Path) -> None:
    """lat = 95 (which pymap3d folds to a site 4109 km North) and lon = 400 are refused
    with the file, line and column; the ±180 and 0-360 longitude conventions give the same
    sites (to 1e-6 m, round-off of the trigonometry at 100 km); the poles are accepted."""
    rng = np.random.default_rng(5)
    rows = _radar_rows(rng)
    p = tmp_path / "r.csv"
    for col, value, text in (
        (1, "95", "'lat': 95° is outside \\[-90, 90\\]°"),
        (1, "-90.5", "'lat': -90.5°"),
        (2, "400", "'lon': 400° is outside \\[-180, 360\\)°"),
        (2, "-180.5", "'lon': -180.5°"),
        (2, "360", "'lon': 360°"),
        (3, "nan", "'alt'.*NaN/inf"),
        (1, "", "'lat': '' is not a number"),
    ):
        bad = [r.copy() for r in rows]
        bad[1][col] = value
        _write(p, RADAR_HEADER, bad)
        with pytest.raises(ProblemError, match=f"{p}: line 3, column {text}"):
            bf.read_radars(p)
    west = [r.copy() for r in rows]
    east = [r.copy() for r in rows]
    for i, lon in enumerate((-10.0, -0.5, 170.0)):
        west[i][2] = repr(lon)
        east[i][2] = repr(lon % 360.0)
    r_w, org_w = bf.read_radars(_write(tmp_path / "w.csv", RADAR_HEADER, west))
    r_e, _ = bf.read_radars(_write(tmp_path / "e.csv", RADAR_HEADER, east), origin=org_w)
    np.testing.assert_allclose(r_e.sites, r_w.sites, rtol=0, atol=1e-6)
    assert r_w.sites[2, 0] != 0  # the third radar is really elsewhere
    pole = [r.copy() for r in rows]
    pole[1][1] = "90"
    r_p, _ = bf.read_radars(_write(tmp_path / "pole.csv", RADAR_HEADER, pole))
    # independent ENU of the pole (WGS84 by hand): ECEF difference projected on North
    a, e2 = 6378137.0, 6.69437999014e-3
    phi, lam, h0 = (np.deg2rad(float(rows[0][1])), np.deg2rad(float(rows[0][2])), float(rows[0][3]))
    n0 = a / np.sqrt(1.0 - e2 * np.sin(phi) ** 2)
    x0 = np.array(
        [
            (n0 + h0) * np.cos(phi) * np.cos(lam),
            (n0 + h0) * np.cos(phi) * np.sin(lam),
            (n0 * (1.0 - e2) + h0) * np.sin(phi),
        ]
    )
    d = np.array([0.0, 0.0, a * np.sqrt(1.0 - e2) + float(pole[1][3])]) - x0
    north = (
        -np.sin(phi) * np.cos(lam) * d[0] - np.sin(phi) * np.sin(lam) * d[1] + np.cos(phi) * d[2]
    )
    assert abs(r_p.sites[1, 0]) < 1e-6  # straight North: no East component
    assert r_p.sites[1, 1] == pytest.approx(north, abs=1e-3)  # ~1e-10 relative at 3600 km


def test_read_radars_values_names_and_origin(tmp_path: Path) -> None:
    rows = _radar_rows(np.random.default_rng(6))
    p = tmp_path / "r.csv"
    for col, value, text in (
        (4, "-50", "'sigma_range': -50 \\(must be positive\\)"),
        (5, "0", "'sigma_azimuth': 0 \\(must be positive\\)"),
        (6, "inf", "'max_range'.*NaN/inf"),
    ):
        bad = [r.copy() for r in rows]
        bad[2][col] = value
        _write(p, RADAR_HEADER, bad)
        with pytest.raises(ProblemError, match=f"line 4, column {text}"):
            bf.read_radars(p)
    dup = [r.copy() for r in rows]
    dup[2][0] = "R0"
    _write(p, RADAR_HEADER, dup)
    with pytest.raises(ProblemError, match="line 4: radar name 'R0' repeats line 2"):
        bf.read_radars(p)
    dup[2][0] = " "
    _write(p, RADAR_HEADER, dup)
    with pytest.raises(ProblemError, match="line 4: empty radar name"):
        bf.read_radars(p)
    _write(p, RADAR_HEADER, rows[:1])
    with pytest.raises(ProblemError, match=f"{p}: .*at least 2 radars"):
        bf.read_radars(p)
    _write(p, RADAR_HEADER, rows)
    for origin, text in (
        ((95.0, 0.0, 0.0), "origin lat: must be <= 90"),
        ((0.0, 400.0, 0.0), "origin lon: must be < 360"),
        ((0.0, 0.0), "origin: expected \\(lat, lon, alt\\)"),
        ("55,83,0", "origin: expected \\(lat, lon, alt\\)"),
        ((0.0, 0.0, float("nan")), "origin alt: got NaN"),
    ):
        with pytest.raises(ProblemError, match=f"biasfield.read_radars {text}"):
            bf.read_radars(p, origin=origin)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- plots
def test_read_plots_values(tmp_path: Path) -> None:
    radars = bf.RadarSet(np.array([[0.0, 0.0], [1e4, 0.0]]), 50.0, 1e-3, 1e5, ("A", "B"))
    p = tmp_path / "p.csv"
    header = "time,radar,range,azimuth\n"
    for body, text in (
        ("0,A,-1,10\n", "line 2, column 'range': -1 m is negative"),
        ("0,A,1000,nan\n", "line 2, column 'azimuth'.*NaN/inf"),
        ("0,A,1000,400\n", "line 2, column 'azimuth': 400° is outside"),
        ("0,A,1e3,1\ninf,B,1e3,1\n", "line 3, column 'time'.*NaN/inf"),
        ("0,A,1e3,1\n1,C,1e3,1\n", "unknown radar id.*first at line 3"),
    ):
        p.write_text(header + body)
        with pytest.raises(ProblemError, match=f"{p}: {text}"):
            bf.read_plots(p, radars)
    p.write_text(header + "0,A,1000,90\n1,1,2000,180\n")
    with pytest.raises(ProblemError, match=r"outside \[-6.28319, 6.28319\] rad"):
        bf.read_plots(p, radars, azimuth_unit="rad")  # degrees read as radians
    table, _ = bf.read_plots(p, radars)
    np.testing.assert_array_equal(table.radar, [0, 1])
    # range 1000 m due East of radar A (azimuth 90° clockwise from North), 1 nm
    np.testing.assert_allclose(table.cartesian(radars)[0], [1000.0, 0.0], atol=1e-9)
    with pytest.raises(ProblemError, match="azimuth_unit: expected one of 'deg', 'rad'"):
        bf.read_plots(p, radars, azimuth_unit="grad")
    with pytest.raises(ProblemError, match="drop_out_of_range: expected True or False"):
        bf.read_plots(p, radars, drop_out_of_range="yes")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="radars: expected a RadarSet"):
        bf.read_plots(p, "radars.csv")  # type: ignore[arg-type]


def test_read_tracks_values_and_grid_guard(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    header = "object,time,lat,lon\n"
    for body, text in (
        ("a,0,95,37\na,1,95.01,37\n", "line 2, column 'lat': 95°"),
        ("a,0,55,37\na,1,55,400\n", "line 3, column 'lon': 400°"),
        ("a,0,55,37\na,0,55.1,37\n", "fewer than 2 reports at distinct"),
        (",0,55,37\na,1,55.1,37\n", "line 2: empty 'object' label"),
        ("a,0,55,37\na,1.7e12,55.1,37\n", "grid values .*times in seconds"),
    ):
        p.write_text(header + body)
        with pytest.raises(ProblemError, match=text):
            bf.read_tracks(p, ORIGIN)
    p.write_text(header + "a,0,55,83\na,10,55.001,83\n")
    for step in (0.0, -1.0, float("nan"), "1"):
        with pytest.raises(ProblemError, match="read_tracks step"):
            bf.read_tracks(p, ORIGIN, step=step)  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="read_tracks origin lat"):
        bf.read_tracks(p, (95.0, 0.0, 0.0))
    got = bf.read_tracks(p, (55.0, 83.0, 0.0), step=2.0)
    np.testing.assert_array_equal(got.times, np.arange(0.0, 12.0, 2.0))
    # 0.001° of latitude north of the origin ≈ 111.4 m (WGS84 at 55°, to 0.1 %)
    assert got.positions[0, 5, 1] == pytest.approx(111.4, rel=1e-3)
    assert abs(got.positions[0, 5, 0]) < 1e-6


# --------------------------------------------------------------------------- data.py
def test_radar_set_plot_table_and_paths_validation() -> None:
    sites = np.array([[0.0, 0.0], [1e4, 0.0]])
    with pytest.raises(ProblemError, match="RadarSet sigma_range: expected one value or 2"):
        bf.RadarSet(sites, [50.0, 50.0, 50.0], 1e-3, 1e5)
    with pytest.raises(ProblemError, match="RadarSet names: expected a sequence"):
        bf.RadarSet(sites, 50.0, 1e-3, 1e5, "AB")  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="RadarSet names: need 2 distinct"):
        bf.RadarSet(sites, 50.0, 1e-3, 1e5, (1, "1"))  # type: ignore[arg-type]
    radars = bf.RadarSet(sites, 50.0, 1e-3, 1e5)
    with pytest.raises(ProblemError, match="unknown radar id True"):
        radars.index(True)
    with pytest.raises(ProblemError, match="coincides with the radar site"):
        radars.cartesian_cov(1, [1e4, 0.0])
    with pytest.raises(ProblemError, match="cartesian_cov i"):
        radars.cartesian_cov(2, [1.0, 1.0])
    # V(x) for a point 1 km North of radar 0: diag(σ_r², (r σ_az)²) in (East, North) axes
    # rotated: the range axis is North, the azimuth axis East
    v = radars.cartesian_cov(0, [0.0, 1000.0])
    np.testing.assert_allclose(v, np.diag([(1000.0 * 1e-3) ** 2, 50.0**2]), rtol=1e-12, atol=1e-9)
    table = bf.PlotTable(
        np.array([0.0, 1.0]),
        np.array([0, 5]),
        np.array([1e3, 2e3]),
        np.zeros(2),
        np.zeros(2, dtype=int),
    )
    with pytest.raises(ProblemError, match="unknown radar index 5"):
        table.cartesian(radars)  # rows of radar 5 were left uninitialised (np.empty)
    with pytest.raises(ProblemError, match="AircraftPaths times"):  # np.interp gave junk
        AircraftPaths(np.array([0.0, 2.0, 1.0]), np.zeros((1, 3, 2)), np.ones((1, 3), bool))
    with pytest.raises(ProblemError, match="subset mask: expected 2 booleans"):
        table.subset(np.array([True]))
    with pytest.raises(ProblemError, match="AircraftPaths times: need at least 2 strictly"):
        AircraftPaths(np.array([1.0, 0.0]), np.zeros((1, 2, 2)), np.ones((1, 2), bool))
    with pytest.raises(ProblemError, match="AircraftPaths active"):
        AircraftPaths(np.array([0.0, 1.0]), np.zeros((1, 2, 2)), np.ones((1, 2)))
    with pytest.raises(ProblemError, match="AircraftPaths positions"):
        AircraftPaths(np.array([0.0, 1.0]), np.full((1, 2, 2), np.nan), np.ones((1, 2), bool))
    paths = AircraftPaths(
        np.array([0.0, 10.0]), np.array([[[0.0, 0.0], [100.0, -50.0]]]), np.ones((1, 2), bool)
    )
    np.testing.assert_allclose(paths.at(0, 2.5), [25.0, -12.5], rtol=1e-15)
    with pytest.raises(ProblemError, match=r"AircraftPaths.at a"):
        paths.at(1, 0.0)


# --------------------------------------------------------------------------- writers
def test_writers_create_parents_and_refuse_directories(tmp_path: Path) -> None:
    rows = [{"a": 1.0 / 3.0, "b": "x"}, {"a": 2.5, "c": 7}]
    out = tmp_path / "new" / "deeper" / "r.csv"
    io.write_csv(out, rows)
    back = list(csv.DictReader(out.open()))
    assert [float(r["a"]) for r in back] == pytest.approx([1.0 / 3.0, 2.5], rel=5e-10)  # 10 digits
    assert back[1]["c"] == "7" and back[0]["c"] == ""
    js = tmp_path / "j" / "s.json"
    io.write_json(js, {"v": np.arange(3.0), "k": np.int64(4)})
    assert json.loads(js.read_text()) == {"v": [0.0, 1.0, 2.0], "k": 4}
    pts = np.random.default_rng(2).normal(scale=1e4, size=(6, 3))
    pc = tmp_path / "p" / "plane.csv"
    io.write_plane_csv(pc, pts, alpha2=np.linspace(1.0, 2.0, 6))
    back_p = io.read_plane_csv(pc)
    np.testing.assert_array_equal(back_p["points"], pts)  # %.17g round-trips exactly
    np.testing.assert_array_equal(back_p["alpha2"], np.linspace(1.0, 2.0, 6))
    for write in (
        lambda p: io.write_csv(p, rows),
        lambda p: io.write_json(p, {}),
        lambda p: io.write_plane_csv(p, pts),
    ):
        with pytest.raises(ProblemError, match=f"{tmp_path}: is an existing directory"):
            write(tmp_path)
        with pytest.raises(ProblemError, match="is an existing file"):
            write(js / "below_a_file.csv")
    with pytest.raises(ProblemError, match="is an existing file"):
        io.output_dir(js)
    assert io.output_dir(tmp_path / "d1" / "d2").is_dir()
    with pytest.raises(ProblemError, match="write_plane_csv points: expected \\(N, 3\\)"):
        io.write_plane_csv(pc, pts[:, :2])
    with pytest.raises(ProblemError, match="write_csv rows: row 0 is a list"):
        io.write_csv(pc, [[1, 2]])  # type: ignore[list-item]


# --------------------------------------------------------------------------- JSON, .npy
def test_read_json_and_npy(tmp_path: Path) -> None:
    """Helpers for the CLI's matrix and case files: a BOM JSON reads as the plain one; bad
    JSON names the line and column; NaN is refused; a .npy reads back exactly, a cut one,
    a pickle or an .npz under the .npy name is one ProblemError naming the file."""
    doc = {"pd": 0.9, "m": [[1.0, 0.2], [0.2, 2.0]]}
    plain, bom = tmp_path / "a.json", tmp_path / "b.json"
    plain.write_text(json.dumps(doc))
    bom.write_bytes(b"\xef\xbb\xbf" + json.dumps(doc).encode())
    assert io.read_json(bom) == io.read_json(plain) == doc
    bad = tmp_path / "bad.json"
    bad.write_text('{"pd": 0.9,\n "m": [1, 2,]}')
    with pytest.raises(ProblemError, match=f"{bad}: not valid JSON \\(line 2, column 13"):
        io.read_json(bad)
    bad.write_text('{"pd": NaN}')
    with pytest.raises(ProblemError, match="NaN is not valid JSON"):
        io.read_json(bad)
    m = np.random.default_rng(9).normal(size=(3, 4))
    npy = tmp_path / "m.npy"
    np.save(npy, m)
    np.testing.assert_array_equal(io.read_npy(npy), m)
    raw = npy.read_bytes()
    for n in (0, 5, 40, len(raw) - 8):
        cut = tmp_path / f"cut{n}.npy"
        cut.write_bytes(raw[:n])
        with pytest.raises(ProblemError, match=f"{cut}: "):
            io.read_npy(cut)
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([{"a": 1}], dtype=object))
    with pytest.raises(ProblemError, match="pickled"):
        io.read_npy(obj)
    npz = tmp_path / "z.npy"
    with npz.open("wb") as fh:
        np.savez(fh, a=m)
    with pytest.raises(ProblemError, match=r"an \.npz archive, expected"):
        io.read_npy(npz)


def test_field_data_npz_revalidates_xi_cov(tmp_path: Path) -> None:
    """A FieldData saved with SPD xi_cov loads back exactly; an .npz whose xi_cov has one
    indefinite cell (eigenvalues 3 and -1) is refused on load, naming the cell."""
    fd, _ = bf.synthetic_field_data(1, cells=10)
    rng = np.random.default_rng(4)
    a = rng.normal(size=(fd.k, fd.m, 2, 2))
    cov = a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(2)
    good = bf.FieldData(fd.radars, fd.centers, fd.xi, fd.adjacency, fd.P, cov)
    path = tmp_path / "fd.npz"
    good.save(path)
    back = bf.FieldData.load(path)
    np.testing.assert_array_equal(back.xi_cov, cov)
    bad = cov.copy()
    bad[2, 1] = [[1.0, 2.0], [2.0, 1.0]]
    assert np.linalg.eigvalsh(bad[2, 1]).min() == pytest.approx(-1.0, abs=1e-12)
    arrays = io.read_npz(path, **NPZ_KEYS)
    np.savez(path, **{**arrays, "xi_cov": bad})
    with pytest.raises(ProblemError, match=r"xi_cov\[2, 1\]"):
        bf.FieldData.load(path)
