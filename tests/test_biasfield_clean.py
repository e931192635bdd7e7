"""Cleaning of real tracks (issue 16, item 3) and the parallel track fits (item 4).

Every test compares with an independent computation: the FieldData of the clean input
(the cleaning must give exactly it back), the injected rows (the report must list exactly
them), the dense inverse of the GLS normal matrix, or the serial fits.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from optmodels import biasfield as bf
from optmodels.biasfield import geometry3d as g3
from optmodels.biasfield.cleaning import (
    CleaningLimits,
    CleaningReport,
    clean_plots,
    clean_reports,
)
from optmodels.biasfield.geometry import to_polar
from optmodels.biasfield.ingest import read_tracks
from optmodels.biasfield.paths import AircraftPaths
from optmodels.biasfield.tables import PlotTable
from optmodels.biasfield.tracks import fit_tracks, polyline_normal
from optmodels.core import ProblemError
from optmodels.scenarios.radar_network import fly_paths3d, radar_network, simulate_plots

ORG = (55.0, 83.0, 150.0)


def _field(plots: PlotTable, radars: bf.RadarSet, cells: int = 30) -> bf.FieldData:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bf.build_field_data(plots, radars, cells=cells)[0]


def _concat(*tables: PlotTable) -> PlotTable:
    cols = ("time", "radar", "range", "azimuth", "object")
    return PlotTable(*(np.concatenate([getattr(t, c) for t in tables]) for c in cols))


def _same_table(a: PlotTable, b: PlotTable) -> None:
    for c in ("time", "radar", "range", "azimuth", "object"):
        np.testing.assert_array_equal(getattr(a, c), getattr(b, c))


# --------------------------------------------------------------- radar plots
def test_clean_plots_give_the_clean_field_data() -> None:
    """A network's plots with a 90 s gap in one track (the reference), plus 6 glitch plots
    10 km off their tracks and a taxiing aircraft (5 m/s): the cleaning drops exactly the
    injected plots, by reason, and the FieldData equals the reference's (same plots, same
    seeded k-means: to 1e-9 m). Without the cleaning it does not (> 1 m, or other cells)."""
    sc = radar_network(11, n_aircraft=25, duration=1200.0, fields="smooth")
    radars, plots = sc.radars, sc.plots
    gap = (plots.object == 0) & (plots.time > 400.0) & (plots.time < 490.0)
    ref = plots.subset(~gap)
    rng = np.random.default_rng(3)
    pick = rng.choice(np.flatnonzero(ref.object >= 0), 6, replace=False)
    z = ref.cartesian(radars)[pick]
    ang = rng.uniform(-np.pi, np.pi, 6)
    zg = z + 10e3 * np.column_stack([np.sin(ang), np.cos(ang)])
    pol = np.array([to_polar(zg[j], radars.sites[ref.radar[k]]) for j, k in enumerate(pick)])
    glitch = PlotTable(
        ref.time[pick] + 1.0, ref.radar[pick], pol[:, 0], pol[:, 1], ref.object[pick]
    )
    tt = np.arange(0.0, 901.0)
    heading = np.deg2rad(30.0) + np.where(tt > 450, np.deg2rad(90.0), 0.0)
    taxi_xy = np.cumsum(5.0 * np.column_stack([np.sin(heading), np.cos(heading)]), axis=0)
    taxi_paths = AircraftPaths(tt, taxi_xy[None], np.ones((1, tt.size), dtype=bool))
    taxi, _, _ = simulate_plots(np.random.default_rng(4), radars, taxi_paths, sc.fields)
    taxi = PlotTable(
        taxi.time,
        taxi.radar,
        taxi.range,
        taxi.azimuth,
        np.full(len(taxi), int(plots.object.max()) + 1),
    )
    dirty = _concat(ref, glitch, taxi)
    kept, rep = clean_plots(dirty, radars)
    n0, n1 = len(ref), len(ref) + len(glitch)
    _same_table(kept, ref)
    assert rep.counts == {"impossible speed": 6, "ground traffic": len(taxi)}
    np.testing.assert_array_equal(rep.rows["impossible speed"], np.arange(n0, n1))
    np.testing.assert_array_equal(rep.rows["ground traffic"], np.arange(n1, len(dirty)))
    assert rep.to_dict()["kept"] == len(ref)
    fd_ref, fd_clean = _field(ref, radars), _field(kept, radars)
    assert fd_clean.k == fd_ref.k
    np.testing.assert_allclose(fd_clean.xi, fd_ref.xi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fd_clean.xi_cov, fd_ref.xi_cov, rtol=1e-9, atol=0)
    fd_dirty = _field(dirty, radars)
    assert fd_dirty.k != fd_ref.k or np.abs(fd_dirty.xi - fd_ref.xi).max() > 1.0


def test_clean_plots_track_jump_and_clean_input() -> None:
    """Clean simulated plots lose nothing; a track whose last third is shifted 20 km (a
    track swap) keeps its longer chain and drops the other ("track jump")."""
    sc = radar_network(2, n_aircraft=10, duration=900.0, fields="zero")
    kept, rep = clean_plots(sc.plots, sc.radars)
    assert rep.total == 0 and len(kept) == len(sc.plots)
    p = sc.plots
    rows = np.flatnonzero((p.radar == 0) & (p.object == 3))
    late = rows[2 * rows.size // 3 :]
    z = p.cartesian(sc.radars)
    moved = to_polar(z[late] + [20e3, 0.0], sc.radars.sites[0])
    rng_, az = p.range.copy(), p.azimuth.copy()
    rng_[late], az[late] = moved[:, 0], moved[:, 1]
    jumped = PlotTable(p.time, p.radar, rng_, az, p.object)
    kept, rep = clean_plots(jumped, sc.radars)
    assert rep.counts == {"track jump": late.size}
    np.testing.assert_array_equal(rep.rows["track jump"], late)


# --------------------------------------------------------------- ADS-B reports
def _adsb(
    truth: AircraftPaths, gap: tuple[str, float, float] | None = None
) -> list[tuple[str, float, float, float, float]]:
    rows = []
    for a in range(len(truth)):
        t, _, geo = truth.track(a)
        assert geo is not None
        for k in range(t.size):
            name = f"F{a}"
            if gap and name == gap[0] and gap[1] <= t[k] < gap[2]:
                continue
            rows.append((name, float(t[k]), *map(float, geo[k])))
    return rows


def _write(path: Path, rows: list[tuple[str, float, float, float, float]]) -> Path:
    path.write_text(
        "object,time,lat,lon,alt\n"
        + "".join(f"{o},{t!r},{la!r},{lo!r},{h!r}\n" for o, t, la, lo, h in rows)
    )
    return path


def test_read_tracks_cleans_splits_and_gives_the_clean_field_data(tmp_path: Path) -> None:
    """ADS-B reports (1 s, 3-D) of 6 aircraft with a 60 s gap in F1 (the reference), plus
    3 glitch reports 600 m off the path (apparent speeds > 1000 m/s) and a taxiing
    aircraft (8 m/s at 150 m): read_tracks drops exactly those (by reason), splits F1 at
    its gap (no path point inside it), and the paths equal the reference's; radar plots
    simulated on them with the same seed give the same 3-D FieldData (to 1e-9 m). The old
    behaviour (no cleaning) keeps the taxi and the glitches."""
    truth = fly_paths3d(np.random.default_rng(21), 6, 900.0, origin=ORG)
    ref_rows = _adsb(truth, gap=("F1", 300.0, 360.0))
    rng = np.random.default_rng(8)
    glitches = []
    for name in ("F0", "F2", "F3"):
        mine = [r for r in ref_rows if r[0] == name]
        o, t, la, lo, h = mine[len(mine) // 2]
        en = g3.common_plane(la, lo, ORG)
        ang = rng.uniform(-np.pi, np.pi)
        gl_la, gl_lo = g3.plane_to_geodetic(en + 600.0 * np.array([np.sin(ang), np.cos(ang)]), ORG)
        glitches.append((o, t + 0.5, float(gl_la), float(gl_lo), h))
    tt = np.arange(0.0, 601.0)
    en_taxi = np.column_stack([8.0 * tt + 5e3, 2.0 * tt - 4e3])
    la_t, lo_t = g3.plane_to_geodetic(en_taxi, ORG)
    taxi = [
        ("TAXI", float(t), float(a), float(b), 150.0)
        for t, a, b in zip(tt, la_t, lo_t, strict=True)
    ]
    dirty_rows = ref_rows + glitches + taxi
    ref = read_tracks(_write(tmp_path / "ref.csv", ref_rows), ORG)
    got, rep = read_tracks(_write(tmp_path / "dirty.csv", dirty_rows), ORG, report=True)
    n0 = len(ref_rows)
    assert rep.counts["ground traffic"] == len(taxi)
    np.testing.assert_array_equal(rep.rows["ground traffic"], np.arange(n0 + 3, n0 + 3 + 601))
    jumps = np.concatenate(
        [
            rep.rows.get("impossible speed", np.zeros(0, int)),
            rep.rows.get("impossible acceleration", np.zeros(0, int)),
        ]
    )
    np.testing.assert_array_equal(np.sort(jumps), np.arange(n0, n0 + 3))
    assert rep.total == 3 + len(taxi)
    assert got.labels == ref.labels == ("F0", "F1#1", "F1#2", "F2", "F3", "F4", "F5")
    i1, i2 = got.labels.index("F1#1"), got.labels.index("F1#2")
    assert got.span(i1)[1] < 300.0 and got.span(i2)[0] >= 360.0
    for a in range(len(ref)):
        for x, y in zip(got.track(a), ref.track(a), strict=True):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)
    # the paths are the truth at the report times (the common plane: 1 mm)
    t0, en0, _ = got.track(0)
    np.testing.assert_allclose(en0, truth.at(0, t0), rtol=0, atol=1e-3)
    raw = read_tracks(tmp_path / "dirty.csv", ORG, clean=False)
    assert "TAXI" in raw.labels and len(raw) == len(got) + 1
    sc = radar_network(0, n_aircraft=1, duration=60.0, geometry="3d", origin=ORG, fields="smooth")
    fds = []
    for paths in (ref, got):
        plots, _, _ = simulate_plots(
            np.random.default_rng(5), sc.radars, paths, sc.fields, periods=[5.0, 6.0, 7.0, 8.0]
        )
        fds.append(_field(plots, sc.radars, cells=12))
    assert fds[0].k == fds[1].k
    np.testing.assert_allclose(fds[1].xi, fds[0].xi, rtol=0, atol=1e-9)


def test_clean_reports_finds_the_glitch_point() -> None:
    """Straight flight at 200 m/s, 1 s reports: a report moved 300 m sideways (apparent
    speed 360 m/s, within the speed test, 5× the acceleration bound) and one moved 5 km
    are the only points dropped; a 30 s gap splits the track; a repeated instant keeps
    its first report; a 6 km jump between two long chains splits the segment."""
    t = np.arange(0.0, 120.0)
    x = np.column_stack([200.0 * t, np.zeros_like(t), np.full_like(t, 9e3)])
    x[40, 1] += 300.0
    x[80, 1] -= 5e3
    keep = (t < 95) | (t >= 125)
    t2, x2 = np.append(t[keep], 60.0), np.vstack([x[keep], x[60] + 50.0])
    obj = np.zeros(t2.size, dtype=int)
    seg, rep = clean_reports(obj, t2, x2)
    assert rep.counts == {"impossible acceleration": 1, "impossible speed": 1, "duplicate time": 1}
    assert rep.rows["impossible acceleration"].tolist() == [40]
    assert rep.rows["impossible speed"].tolist() == [80]
    assert rep.rows["duplicate time"].tolist() == [t2.size - 1]
    assert rep.segments == 1 and set(seg[seg >= 0]) == {0}  # t ≥ 125 is past the data
    jump = x.copy()
    jump[40:, 0] += 6e3
    jump[40, 1] = jump[80, 1] = 0.0
    seg, rep = clean_reports(np.zeros(t.size), t, jump)
    assert rep.total == 0 and rep.segments == 2
    np.testing.assert_array_equal(seg, (t >= 40).astype(int))
    d = rep.to_dict(max_rows=1)
    assert d["points"] == t.size and d["kept"] == t.size and d["rows_truncated"] is False


def test_clean_reports_ground_ceiling_and_errors() -> None:
    """Slow points are ground traffic; with ``ground_ceiling`` only those at or below it;
    every bad argument is one ProblemError naming it."""
    t = np.arange(0.0, 100.0)
    x = np.column_stack([20.0 * t, np.zeros_like(t)])
    h = np.where(t < 50, 100.0, 2000.0)
    seg, rep = clean_reports(np.zeros(t.size), t, x, heights=h)
    assert rep.counts == {"ground traffic": 100} and not np.any(seg >= 0)
    lim = CleaningLimits(ground_ceiling=500.0)
    seg, rep = clean_reports(np.zeros(t.size), t, x, heights=h, limits=lim)
    np.testing.assert_array_equal(rep.rows["ground traffic"], np.arange(50))
    for kw, text in (
        ({"max_speed": -1.0}, "CleaningLimits max_speed"),
        ({"min_points": 0}, "CleaningLimits min_points"),
        ({"ground_ceiling": float("nan")}, "ground_ceiling"),
    ):
        with pytest.raises(ProblemError, match=text):
            CleaningLimits(**kw)  # type: ignore[arg-type]
    with pytest.raises(ProblemError, match="clean_reports positions"):
        clean_reports(np.zeros(3), np.arange(3.0), np.zeros((3, 4)))
    with pytest.raises(ProblemError, match="clean_reports sigma"):
        clean_reports(np.zeros(3), np.arange(3.0), np.zeros((3, 2)), sigma=[1.0, 2.0])
    with pytest.raises(ProblemError, match="clean_reports limits"):
        clean_reports(np.zeros(3), np.arange(3.0), np.zeros((3, 2)), limits={})  # type: ignore
    with pytest.raises(ProblemError, match="clean_plots plots"):
        clean_plots("plots", radar_network(0, n_aircraft=1, duration=60.0).radars)  # type: ignore
    assert CleaningReport().to_dict()["dropped"] == {}


# --------------------------------------------------------------- track fits
def test_band_covariance_equals_the_dense_inverse() -> None:
    """The block band (and every block from it, Markov recursion) equals the dense inverse
    of the GLS normal matrix, and θ its solution, to 1e-9 relative."""
    sc = radar_network(4, n_aircraft=4, duration=900.0, fields="smooth")
    fits, _ = fit_tracks(sc.plots, sc.radars)
    z = sc.plots.cartesian(sc.radars)
    for f in fits[:6]:
        vinv = np.linalg.inv(sc.radars.cartesian_cov(f.radar, z[f.rows]))
        n, b, _ = polyline_normal(sc.plots.time[f.rows], f.knots, vinv, z[f.rows])
        cov = np.linalg.inv(n)
        scale = np.abs(cov).max()
        np.testing.assert_allclose(f.cov, cov, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(f.theta.ravel(), cov @ b, rtol=0, atol=1e-6)
        tt = np.linspace(f.knots[1], f.knots[min(4, f.knots.size - 1)], 9)
        h = bf.hat_basis(tt, f.knots).mean(axis=0)
        g = np.kron(h[None, :], np.eye(2))
        mean, c = f.mean_over(tt)
        np.testing.assert_allclose(c, g @ cov @ g.T, rtol=1e-9)
        np.testing.assert_allclose(mean, g @ cov @ b, rtol=0, atol=1e-6)
        # many sets of instants at once (the cells' averaging): the same, set by set
        t_all = np.arange(f.span[0], f.span[1], 3.0)
        grp = np.searchsorted(np.linspace(*f.span, 8)[1:-1], t_all)
        means, covs = f.means_over(t_all, grp)
        for gg in np.unique(grp):
            m1, c1 = f.mean_over(t_all[grp == gg])
            np.testing.assert_allclose(means[gg], m1, rtol=0, atol=1e-6)
            np.testing.assert_allclose(covs[gg], c1, rtol=1e-9, atol=1e-12 * np.abs(c1).max())


def test_fit_tracks_serial_processes_dask_agree() -> None:
    """The same fits (to 1e-12, relative) whether run here, on 2 local processes or on a
    Dask client, in several tasks; unknown schedulers are refused."""
    from distributed import Client, LocalCluster

    sc = radar_network(6, n_aircraft=8, duration=600.0, fields="smooth")
    ref, d_ref = fit_tracks(sc.plots, sc.radars, chunk=300)
    proc, d_proc = fit_tracks(sc.plots, sc.radars, scheduler="processes", workers=2, chunk=300)
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
        ) as cluster,
        Client(cluster) as client,
    ):
        dask, d_dask = fit_tracks(sc.plots, sc.radars, scheduler=client, chunk=300)
    assert len(ref) == len(proc) == len(dask) > 20
    assert d_ref.counts == d_proc.counts == d_dask.counts
    for a, b, c in zip(ref, proc, dask, strict=True):
        assert (a.radar, a.object) == (b.radar, b.object) == (c.radar, c.object)
        for name in ("theta", "cov_diag", "cov_next", "whitened"):
            x = getattr(a, name)
            for other in (b, c):
                np.testing.assert_allclose(
                    getattr(other, name), x, rtol=1e-12, atol=1e-12 * np.abs(x).max()
                )
    with pytest.raises(ProblemError, match="fit_tracks scheduler"):
        fit_tracks(sc.plots, sc.radars, scheduler="threads")
    with pytest.raises(ProblemError, match=r"fit_tracks scheduler.*'dask'"):
        fit_tracks(sc.plots, sc.radars, scheduler="dask")  # one vocabulary: no "dask"
