"""``optmodels biasfield build`` on recordings (issue 16, item 5): the installed console
script in a subprocess, as a user runs it; the result equals the library chain on the
same files (read_radars/read_plots → clean_plots → build_field_data)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from optmodels import biasfield as bf
from optmodels.biasfield.cleaning import clean_plots
from tests.test_cli import assert_error, run_cli, run_many

ORG = (55.0, 83.0, 150.0)


def write_sites(path: Path, r: bf.RadarSet) -> Path:
    """The sites CSV of a 3-D radar set, keyed by SAC/SIC (SAC 25, SIC 10 + i)."""
    assert r.geodetic is not None
    path.write_text(
        "name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        + "".join(
            f"{r.names[i]},25,{10 + i},"
            + ",".join(
                repr(float(v))
                for v in (
                    *r.geodetic[i],
                    r.sigma_range[i],
                    np.rad2deg(r.sigma_azimuth[i]),
                    r.max_range[i],
                )
            )
            + "\n"
            for i in range(r.m)
        )
    )
    return path


def encode_scene(sc: object, tod0: float, addr: np.ndarray) -> tuple[bytes, bytes, int]:
    """A simulated 3-D scene as ASTERIX: CAT048 of every radar (SAC 25, SIC 10 + i; the
    aircraft addresses ``addr``) and CAT021 of every aircraft's true track (geometric
    height); times of day from ``tod0`` s. Returns (cat048, cat021, CAT021 reports)."""
    from optmodels.io import asterix as ax

    r, p, paths = sc.radars, sc.plots, sc.paths  # type: ignore[attr-defined]
    cat048 = b"".join(
        ax.encode_cat048(
            p.time[p.radar == i] + tod0,
            25,
            10 + i,
            p.range[p.radar == i],
            p.azimuth[p.radar == i],
            address=addr[p.object[p.radar == i]],
        )
        for i in range(r.m)
    )
    parts = [paths.track(a) for a in range(len(paths))]
    t21 = np.concatenate([q[0] for q in parts]) + tod0
    geo = np.vstack([q[2] for q in parts if q[2] is not None])
    who = np.concatenate([np.full(q[0].size, addr[a]) for a, q in enumerate(parts)])
    cat021 = ax.encode_cat021(t21, 25, 99, geo[:, 0], geo[:, 1], height=geo[:, 2], address=who)
    return cat048, cat021, int(t21.size)


def _files(tmp_path: Path) -> tuple[Path, Path, Path, Path, int, int]:
    """A 3-D network as a sites CSV (SAC/SIC, lat, lon, alt) and a plots CSV with heights,
    4 glitch plots (8 km off, 1 s after a real plot) appended; an ADS-B CSV of the truth
    with 1 glitch report; an x, y sites CSV. Returns the paths, the number of plot rows
    and the glitch count."""
    from optmodels.scenarios.radar_network import radar_network

    sc = radar_network(9, n_aircraft=16, duration=900.0, geometry="3d", origin=ORG)
    r = sc.radars
    assert r.geodetic is not None
    sites = write_sites(tmp_path / "sites.csv", r)
    flat = tmp_path / "flat.csv"
    flat.write_text(
        "name,x,y,sigma_range,sigma_azimuth,max_range\n"
        + "".join(
            f"{r.names[i]},{float(r.sites[i, 0])!r},{float(r.sites[i, 1])!r},50,0.08,250000\n"
            for i in range(r.m)
        )
    )
    p = sc.plots
    assert p.height is not None
    rows = [
        f"{float(t)!r},{r.names[k]},{float(g)!r},{float(np.rad2deg(a))!r},A{o},{float(h)!r}\n"
        for t, k, g, a, o, h in zip(
            p.time, p.radar, p.range, p.azimuth, p.object, p.height, strict=True
        )
    ]
    pick = np.random.default_rng(2).choice(len(p), 4, replace=False)
    rows += [
        f"{float(p.time[j]) + 1.0!r},{r.names[p.radar[j]]},{float(p.range[j]) + 8e3!r},"
        f"{float(np.rad2deg(p.azimuth[j]))!r},A{p.object[j]},{float(p.height[j])!r}\n"
        for j in pick
    ]
    plots = tmp_path / "plots.csv"
    plots.write_text("time,radar,range,azimuth,object,height\n" + "".join(rows))
    t, _, geo = sc.paths.track(0)
    assert geo is not None
    lines = [
        f"A0,{float(tk)!r},{float(g[0])!r},{float(g[1])!r},{float(g[2])!r}\n"
        for tk, g in zip(t, geo, strict=True)
    ]
    k = t.size // 2
    lines.append(
        f"A0,{float(t[k]) + 0.5!r},{float(geo[k, 0]) + 0.01!r},{float(geo[k, 1])!r},"
        f"{float(geo[k, 2])!r}\n"
    )
    adsb = tmp_path / "adsb.csv"
    adsb.write_text("object,time,lat,lon,alt\n" + "".join(lines))
    return sites, plots, adsb, flat, len(rows), 4


def test_build_from_csv_3d_with_adsb(tmp_path: Path) -> None:
    """3-D build from CSV: one JSON document, exit 0; the 4 glitches are the only plots
    the cleaning drops; the ADS-B file's glitch is reported; the origin defaults to the
    mean of the sites (computed here from the file); the FieldData equals the library's.
    Bad flags exit 2 with one line naming them (old ``--box`` included)."""
    sites, plots, adsb, flat, n_rows, n_glitch = _files(tmp_path)
    npz = tmp_path / "fd.npz"
    ok, bad_origin, three, flat3d, cells1 = run_many(
        [
            [
                "biasfield",
                "build",
                plots,
                adsb,
                "--radars",
                sites,
                "--cells",
                "15",
                "--out",
                npz,
                "--json",
            ],
            [
                "biasfield",
                "build",
                plots,
                "--radars",
                sites,
                "--origin",
                "55,83",
                "--json",
                "--out",
                tmp_path / "x.npz",
            ],
            [
                "biasfield",
                "build",
                plots,
                adsb,
                adsb,
                "--radars",
                sites,
                "--out",
                tmp_path / "y.npz",
            ],
            [
                "biasfield",
                "build",
                plots,
                "--radars",
                flat,
                "--geometry",
                "3d",
                "--out",
                tmp_path / "z.npz",
            ],
            [
                "biasfield",
                "build",
                plots,
                "--radars",
                sites,
                "--cells",
                "1",
                "--out",
                tmp_path / "w.npz",
            ],
        ],
        expect=None,
    )
    assert ok.code == 0, ok.err
    res = ok.json()
    assert res["geometry"] == "3d" and res["source"] == "table"
    assert res["plots"] == n_rows
    assert res["dropped_plots"].get("impossible speed", 0) == n_glitch
    assert res["cleaning"]["dropped"] == {"impossible speed": n_glitch}
    assert res["cleaning"]["rows"]["impossible speed"] == list(range(n_rows - n_glitch, n_rows))
    assert res["adsb"]["points"] > 100 and sum(res["adsb"]["dropped"].values()) == 1
    geo = np.loadtxt(sites, delimiter=",", skiprows=1, usecols=(3, 4, 5))
    np.testing.assert_allclose(res["origin"], geo.mean(axis=0), rtol=1e-12)
    assert res["origin_source"] == "mean of the sites"
    radars, _ = bf.read_radars(sites, origin="mean", geometry="3d")
    table, _ = bf.read_plots(plots, radars)
    kept, _ = clean_plots(table, radars)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, _ = bf.build_field_data(kept, radars, cells=15, coverage="union")
    fd = bf.FieldData.load(npz)
    assert fd.k == ref.k == res["cells"]
    assert res["coverage"] == "union"
    np.testing.assert_allclose(fd.xi, ref.xi, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fd.subsets, ref.subsets)
    assert sum(res["radars_per_cell"].values()) == fd.k
    assert_error(bad_origin, 2, "--origin", "LAT,LON,H")
    assert_error(three, 2, "RECORDING", "at most two")
    assert_error(flat3d, 2, "--geometry 3d", "lat, lon")
    assert_error(cells1, 2, "--cells")


def test_solve_box_unit_in_the_flag(tmp_path: Path) -> None:
    """``--box-deg K1,K2`` (metres, degrees) bounds the field as the API's box=(K1,
    radians(K2)): a box at 1e-3 of the closed form's largest bias is infeasible (exit 1,
    the result on stdout); the old ``--box`` exits 2 naming the new flag and its units."""
    fd, _ = bf.synthetic_field_data(3, cells=40)
    npz = tmp_path / "fd.npz"
    fd.save(npz)
    big = np.abs(bf.closed_form(fd).field).max(axis=(0, 1))
    box = f"{float(1e-3 * big[0])!r},{float(np.rad2deg(1e-3 * big[1]))!r}"
    tight, old = run_many(
        [
            ["biasfield", "solve", npz, "--box-deg", box, "--out", tmp_path / "a", "--json"],
            ["biasfield", "solve", npz, "--box", box, "--out", tmp_path / "b", "--json"],
        ],
        expect=None,
    )
    assert tight.code == 1 and tight.json()["status"] == "infeasible"
    lib = bf.solve(fd, box=(1e-3 * big[0], 1e-3 * big[1]))
    assert lib.status.value == "infeasible"
    assert_error(old, 2, "--box", "--box-deg", "DEGREES", "radians")
    res = run_cli("biasfield", "solve", "--help").out
    assert "--box-deg" in res and "DEGREES" in res


def test_build_from_asterix_one_or_two_files(tmp_path: Path) -> None:
    """Simulated 3-D traffic encoded as CAT048 (each radar's plots, aircraft address) +
    CAT021 (the aircraft's ADS-B, geometric height): ``build`` detects ASTERIX from the
    content (the files have no telling suffix), in one file or in two, with the same
    FieldData as the library chain (read_recording → locatable → clean_plots →
    build_field_data), exit 0, one JSON document counting what was read and dropped."""
    from optmodels.biasfield.recording import read_recording
    from optmodels.scenarios.radar_network import radar_network

    sc = radar_network(9, n_aircraft=12, duration=900.0, geometry="3d", origin=ORG)
    r, p = sc.radars, sc.plots
    assert r.geodetic is not None
    sites = write_sites(tmp_path / "sites.csv", r)
    cat048, cat021, n21 = encode_scene(sc, 36000.0, 0x400000 + np.arange(12))
    both, f48, f21 = tmp_path / "rec.bin", tmp_path / "plots.dat", tmp_path / "adsb.dat"
    both.write_bytes(cat048 + cat021)
    f48.write_bytes(cat048)
    f21.write_bytes(cat021)
    one, two = run_many(
        [
            [
                "biasfield",
                "build",
                both,
                "--radars",
                sites,
                "--cells",
                "12",
                "--out",
                tmp_path / "one.npz",
                "--json",
            ],
            [
                "biasfield",
                "build",
                f48,
                f21,
                "--radars",
                sites,
                "--cells",
                "12",
                "--out",
                tmp_path / "two.npz",
                "--json",
            ],
        ],
        expect=None,
    )
    assert one.code == 0, one.err
    assert two.code == 0, two.err
    res = one.json()
    assert res["source"] == "asterix" and res["geometry"] == "3d"
    assert res["plots"] == len(p) and res["adsb"]["reports"] == n21
    assert res["adsb"]["records"] == {"CAT048": len(p), "CAT021": n21}
    rec = read_recording([both], sites)
    plots = rec.plots.subset(rec.plots.locatable(rec.radars))
    kept, _ = clean_plots(plots, rec.radars)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, _ = bf.build_field_data(kept, rec.radars, cells=12, coverage="union")
    for name in ("one.npz", "two.npz"):
        fd = bf.FieldData.load(tmp_path / name)
        assert fd.k == ref.k
        np.testing.assert_allclose(fd.xi, ref.xi, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(fd.subsets, ref.subsets)
