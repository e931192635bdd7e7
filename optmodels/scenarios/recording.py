r"""A simulated ASTERIX recording to try the bias field on (paper 001, the plots of (1)):
a radar network, traffic, biases and noise → CAT048 plots + CAT021 ADS-B reports in one
file of raw datablocks, and the sites CSV that :func:`~optmodels.biasfield.recording.read_sites`
(and ``optmodels biasfield build --radars``) reads.

:func:`simulate_recording` runs :func:`~optmodels.scenarios.radar_network.radar_network`
in 3-D (geodetic sites on a ring about ``origin``, slant ranges, each radar's own north,
aircraft at 3-12 km with climbs, descents and holding patterns, each radar's smooth bias
field f_i(x) and Gaussian polar noise) and encodes it with
:func:`optmodels.io.encode_cat048` / :func:`optmodels.io.encode_cat021`: per plot its
radar's SAC/SIC (``sac``, ``first_sic`` + i), time of day (``start`` s after UTC midnight +
the simulated time), slant range, azimuth, the aircraft's 24-bit ICAO address and its
flight level (the ISA pressure altitude of the true height: FL = H_p / 30.48 m / 100,
H_p = R·h/(R + h), R = 6 356 766 m, the inverse of
:func:`~optmodels.biasfield.heights.fl_to_height`); per aircraft every ``adsb_interval``
s an ADS-B report of its true position and geometric height. The datablocks are written
in time order (one block per source and minute, sources interleaved), as a recorder
taps them off the network.

How the simulated traffic differs from real traffic (what a user should not read into a
result on it): the aircraft enter at uniform random places and times in a square and fly
random legs and turns (no airways, no terminal areas, no flows between airports); every
radar sees every aircraft in range and above its horizon on every scan (no missed plots,
no clutter, no multipath, no false plots, no beam-shape shadows besides the 40° cone of
silence); ADS-B is the exact truth (no position error, no latency, every aircraft
equipped) except for the ``adsb_spikes`` altitude spikes injected on request; the flight
levels are the exact standard-atmosphere image of the true heights (a real atmosphere
departs from the ISA by up to hundreds of metres); and each radar's bias is a smooth
function of the position on the common plane, constant in time and height.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optmodels.biasfield.heights import R_ISA
from optmodels.core import (
    FloatArray,
    as_choice,
    as_count,
    as_number,
    as_positive,
)

if TYPE_CHECKING:
    from optmodels.scenarios.radar_network import RadarNetworkScenario

__all__ = ["SimulatedRecording", "simulate_recording"]

#: Metres per foot (ASTERIX flight levels are hundreds of feet).
FT = 0.3048
#: The altitude error of an injected ADS-B spike (m): the +7.8 km of the issue-24 case.
SPIKE = 7800.0


@dataclass(frozen=True)
class SimulatedRecording:
    """What :func:`simulate_recording` wrote and how: ``recording`` (the ASTERIX file),
    ``sites`` (the sites CSV), ``scenario`` (the
    :class:`~optmodels.scenarios.radar_network.RadarNetworkScenario`: plots, radars, true
    fields, paths, true positions and biases at every plot), ``addresses`` (per aircraft
    its 24-bit ICAO address), ``start`` (s after UTC midnight of simulated time 0),
    ``counts`` (records written: ``cat048``, ``cat021``; ``spikes`` injected) and
    ``spike_rows`` (the CAT021 reports given an altitude spike, as (aircraft, time of day
    s) pairs), ``ids`` (per radar its (SAC, SIC))."""

    recording: Path
    sites: Path
    scenario: RadarNetworkScenario
    addresses: np.ndarray
    start: float
    counts: dict[str, int]
    spike_rows: tuple[tuple[int, float], ...] = ()
    ids: tuple[tuple[int, int], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (paths, radars, counts)."""
        r = self.scenario.radars
        return {
            "recording": str(self.recording),
            "sites": str(self.sites),
            "radars": list(r.names),
            "sac_sic": [list(i) for i in self.ids],
            "aircraft": int(self.addresses.size),
            "start_s": self.start,
            "plots": len(self.scenario.plots),
            **self.counts,
        }


def _flight_level(height: FloatArray) -> FloatArray:
    """FL (hundreds of feet) of a geometric height h (m): the ISA geopotential altitude
    H_p = R·h/(R + h), the exact inverse of :func:`~optmodels.biasfield.heights.fl_to_height`
    (geoid undulation 0)."""
    h = np.asarray(height, dtype=float)
    return R_ISA * h / (R_ISA + h) / FT / 100.0


def _write_sites(path: Path, radars: Any, sac: int, first_sic: int) -> None:
    from optmodels.io import write_csv

    assert radars.geodetic is not None
    rows = [
        {
            "name": radars.names[i],
            "sac": sac,
            "sic": first_sic + i,
            "lat": float(radars.geodetic[i, 0]),
            "lon": float(radars.geodetic[i, 1]),
            "alt": float(radars.geodetic[i, 2]),
            "sigma_range": float(radars.sigma_range[i]),
            "sigma_azimuth": float(np.rad2deg(radars.sigma_azimuth[i])),
            "max_range": float(radars.max_range[i]),
        }
        for i in range(radars.m)
    ]
    write_csv(path, rows)


def _by_minute(t: FloatArray) -> list[np.ndarray]:
    """Row indices of ``t`` (sorted) per whole minute."""
    if t.size == 0:
        return []
    minute = np.floor(t / 60.0).astype(np.int64)
    cuts = np.flatnonzero(np.diff(minute)) + 1
    return np.split(np.arange(t.size), cuts)


def _cat048_blocks(
    sc: RadarNetworkScenario, start: float, sac: int, first_sic: int, addr: np.ndarray
) -> list[tuple[float, bytes]]:
    """The plots as CAT048 datablocks, one per radar and minute, each with the time of
    day (s) of its first record: SAC ``sac``, SIC ``first_sic`` + i, slant range, azimuth,
    the flight level of the true height and the aircraft's address ``addr``."""
    from optmodels.io import encode_cat048

    r, p = sc.radars, sc.plots
    assert p.height is not None  # a 3-D scenario's plots carry the true heights
    blocks: list[tuple[float, bytes]] = []
    for i in range(r.m):
        sel = np.flatnonzero(p.radar == i)
        t = p.time[sel] + start
        fl = _flight_level(p.height[sel])
        for rows in _by_minute(t):
            k = sel[rows]
            blocks.append(
                (
                    float(t[rows[0]]),
                    encode_cat048(
                        t[rows],
                        sac,
                        first_sic + i,
                        p.range[k],
                        p.azimuth[k],
                        flight_level=fl[rows],
                        address=addr[p.object[k]],
                    ),
                )
            )
    return blocks


@dataclass(frozen=True)
class _Adsb:
    """The CAT021 side of a recording: ``blocks`` (time of day of the first record, the
    datablock), per report its ``time`` of day (s) and aircraft ``who``, and the reports
    given an altitude spike (``spikes``, indices into ``time``)."""

    blocks: list[tuple[float, bytes]]
    time: FloatArray
    who: np.ndarray
    spikes: np.ndarray


def _cat021_blocks(
    sc: RadarNetworkScenario,
    start: float,
    sac: int,
    addr: np.ndarray,
    *,
    step: int,
    spikes: int,
    seed: int,
) -> _Adsb:
    """Every ``step``-th path point of each aircraft as a CAT021 ADS-B report (SAC ``sac``,
    SIC 200: true position, geometric height, the flight level of the true height), in
    time order, one datablock per minute; ``spikes`` reports drawn from
    ``default_rng([seed, 21])`` get a :data:`SPIKE` on their height."""
    from optmodels.io import encode_cat021

    parts = [sc.paths.track(a) for a in range(len(sc.paths))]
    t21 = np.concatenate([q[0][::step] for q in parts]) + start
    geo = np.vstack([q[2][::step] for q in parts if q[2] is not None])
    who = np.concatenate([np.full(q[0][::step].size, a) for a, q in enumerate(parts)])
    order = np.argsort(t21, kind="stable")
    t21, geo, who = t21[order], geo[order], who[order]
    height = geo[:, 2].copy()
    rng = np.random.default_rng([int(seed), 21])
    spike_idx = (
        np.sort(rng.choice(t21.size, size=min(spikes, t21.size), replace=False))
        if spikes
        else np.zeros(0, np.int64)
    )
    height[spike_idx] += SPIKE
    blocks: list[tuple[float, bytes]] = []
    for rows in _by_minute(t21):
        blocks.append(
            (
                float(t21[rows[0]]),
                encode_cat021(
                    t21[rows],
                    sac,
                    200,
                    geo[rows, 0],
                    geo[rows, 1],
                    height=height[rows],
                    flight_level=_flight_level(geo[rows, 2]),
                    address=addr[who[rows]],
                ),
            )
        )
    return _Adsb(blocks, t21, who, spike_idx)


def simulate_recording(
    folder: str | os.PathLike[str],
    *,
    seed: int = 0,
    radars: int = 4,
    aircraft: int = 30,
    duration: float = 1800.0,
    spacing: float = 150e3,
    max_range: float = 250e3,
    region: float = 150e3,
    biases: str = "smooth",
    sigma_range: float = 60.0,
    sigma_azimuth_deg: float = 0.08,
    origin: tuple[float, float, float] = (55.0, 83.0, 150.0),
    start: float = 36000.0,
    adsb_interval: float = 1.0,
    adsb_spikes: int = 0,
    sac: int = 25,
    first_sic: int = 1,
    first_address: int = 0x3C0000,
) -> SimulatedRecording:
    """Simulate a radar network and write it as ASTERIX (module docstring).

    Parameters
    ----------
    folder
        Output folder (created): ``recording.ast`` and ``sites.csv`` are written there
        (atomically, :func:`optmodels.io.atomic_write`).
    seed
        Seed of every random draw (sites' bias fields, traffic, scan phases, noise).
    radars
        Number of radars, on a ring of radius ``spacing`` (m) about the origin.
    aircraft, duration
        Number of aircraft and simulated span (s).
    max_range, region
        Each radar's maximum slant range (m); the half-side (m) of the square the traffic
        enters in.
    biases
        Each radar's bias field: ``"smooth"`` (a constant plus Gaussian bumps, range ±150 m,
        azimuth ±0.3°), ``"linear"``, ``"constant"`` (azimuth ±0.1-0.3°) or ``"zero"``.
    sigma_range, sigma_azimuth_deg
        Polar noise, 1σ: metres and degrees.
    origin
        The common plane's origin: lat (deg), lon (deg), h (m above WGS-84).
    start
        Time of day (s after UTC midnight) of simulated time 0.
    adsb_interval
        Seconds between two ADS-B reports of an aircraft (a multiple of the 1 s path grid).
    adsb_spikes
        Number of CAT021 reports given a +7.8 km altitude spike (a corrupted geometric
        height, as seen in real recordings; the reader's cleaning should reject them).
    sac, first_sic, first_address
        SAC of every radar, SIC of the first (then + 1 each), ICAO address of the first
        aircraft (then + 1 each). The CAT021 reports carry SAC ``sac``, SIC 200.

    Returns
    -------
    SimulatedRecording

    Raises
    ------
    ProblemError
        Naming the argument for a bad value; naming the folder if it cannot be written.
    """
    from optmodels.io import atomic_write, output_dir
    from optmodels.scenarios.radar_network import radar_network, ring_sites

    fn = "biasfield.simulate_recording"
    out = output_dir(folder, name=f"{fn} folder")
    m = as_count(f"{fn} radars", radars, minimum=2, maximum=64)
    n_air = as_count(f"{fn} aircraft", aircraft, minimum=1, maximum=100_000)
    duration = as_positive(f"{fn} duration (s)", duration)
    spacing = as_positive(f"{fn} spacing (m)", spacing)
    biases = as_choice(f"{fn} biases", biases, ("smooth", "linear", "constant", "zero"))
    start = as_number(
        f"{fn} start (s after UTC midnight)", start, low=0.0, high=86400.0, high_open=True
    )
    step = as_count(f"{fn} adsb_interval (s)", adsb_interval, minimum=1, maximum=3600)
    spikes = as_count(f"{fn} adsb_spikes", adsb_spikes, minimum=0)
    sac = as_count(f"{fn} sac", sac, minimum=0, maximum=255)
    first_sic = as_count(f"{fn} first_sic", first_sic, minimum=0, maximum=255 - (m - 1))
    first_address = as_count(f"{fn} first_address", first_address, minimum=0, maximum=2**24 - n_air)
    sc = radar_network(
        seed,
        n_aircraft=n_air,
        duration=duration,
        sites=ring_sites(m, spacing),
        fields=biases,  # type: ignore[arg-type]
        sigma_range=sigma_range,
        sigma_azimuth=np.deg2rad(
            as_positive(f"{fn} sigma_azimuth_deg", sigma_azimuth_deg, allow_zero=True)
        ),
        max_range=max_range,
        region=region,
        geometry="3d",
        origin=origin,
    )
    r, p = sc.radars, sc.plots
    addr = first_address + np.arange(n_air, dtype=np.int64)
    sources = _cat048_blocks(sc, start, sac, first_sic, addr)
    adsb = _cat021_blocks(sc, start, sac, addr, step=step, spikes=spikes, seed=seed)
    sources += adsb.blocks
    sources.sort(key=lambda s: s[0])
    rec = out / "recording.ast"
    with atomic_write(rec, name=f"{fn} folder", binary=True) as fh:  # OSError -> ProblemError
        for _, block in sources:
            fh.write(block)
    sites = out / "sites.csv"
    _write_sites(sites, r, sac, first_sic)
    return SimulatedRecording(
        rec,
        sites,
        sc,
        addr,
        start,
        {"cat048": len(p), "cat021": int(adsb.time.size), "spikes": int(adsb.spikes.size)},
        tuple((int(adsb.who[j]), float(adsb.time[j])) for j in adsb.spikes),
        tuple((sac, first_sic + i) for i in range(r.m)),
    )
