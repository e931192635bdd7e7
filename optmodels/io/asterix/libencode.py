"""The reference encoders through libasterix (one record object per report; ~3 000
records/s): the oracle :mod:`~optmodels.io.asterix.encode` is checked against, byte for
byte, by the tests and ``solvers_cmp/bench_asterix.py``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from optmodels.core import ProblemError, as_count, as_flag
from optmodels.io.asterix.encode import _cols
from optmodels.io.asterix.layout import DAY, EDITIONS, FT, NM, _spec, as_edition


def _blocks(spec: Any, records: list[Any], per_block: int) -> bytes:
    per_block = as_count("asterix.encode per_block", per_block, minimum=1)
    return b"".join(
        spec.create(records[i : i + per_block]).unparse().to_bytes()
        for i in range(0, len(records), per_block)
    )


def _ints(fn: str, c: dict[str, np.ndarray], limits: dict[str, int]) -> None:
    """Integer fields: whole numbers in [0, limit] (negative allowed = absent, for the
    optional ones)."""
    for name, top in limits.items():
        if name not in c:
            continue
        v = c[name]
        low = -np.inf if name in ("address", "mode3a") else 0
        bad = (v != np.round(v)) | (v < low) | (v > top)
        if bad.any():
            raise ProblemError(f"asterix.{fn} {name}: need integers 0-{top}, got {v[bad][0]!r}")


def encode_cat048(
    time_of_day: Any,
    sac: Any,
    sic: Any,
    range: Any,
    azimuth: Any,
    *,
    flight_level: Any = None,
    address: Any = None,
    mode3a: Any = None,
    per_block: int = 20,
    edition: tuple[int, int] = EDITIONS[48],
) -> bytes:
    """CAT048 datablocks through libasterix (``per_block`` records each).

    ``time_of_day`` s since UTC midnight (I140, wrapped into [0, 86400)), ``range`` slant
    range m (I040 RHO, < 256 NM), ``azimuth`` rad clockwise from the radar's north (I040
    THETA, wrapped into [0, 2π)), ``flight_level`` in FL (I090; NaN: item absent),
    ``address`` 24-bit int (I220; < 0: absent), ``mode3a`` 12-bit int (I070; < 0: absent).
    Values are rounded to the format's LSB by libasterix. Every record also carries I020
    (target report descriptor: single Mode S roll-call, an extended item).
    """
    c = _cols(
        "encode_cat048",
        time_of_day=time_of_day,
        sac=sac,
        sic=sic,
        range=range,
        azimuth=azimuth,
        flight_level=flight_level,
        address=address,
        mode3a=mode3a,
    )
    _ints("encode_cat048", c, {"sac": 255, "sic": 255, "address": 2**24 - 1, "mode3a": 4095})
    if np.any(c["range"] < 0) or np.any(c["range"] >= 256 * NM):
        raise ProblemError("asterix.encode_cat048 range: need 0 ≤ range < 256 NM (474 112 m)")
    spec = _spec(48, {48: as_edition("asterix.encode_cat048 edition", edition)})
    tod = np.mod(c["time_of_day"], DAY)
    az = np.degrees(np.mod(c["azimuth"], 2 * math.pi))
    recs = []
    for i in np.arange(tod.size):
        items: dict[str, Any] = {
            "010": (("SAC", int(c["sac"][i])), ("SIC", int(c["sic"][i]))),
            "140": (float(tod[i]), "s"),
            "020": ((5, 0, 0, 0, 0, 0),),
            "040": (("RHO", (float(c["range"][i]) / NM, "NM")), ("THETA", (float(az[i]), "°"))),
        }
        if "mode3a" in c and c["mode3a"][i] >= 0:
            items["070"] = (0, 0, 0, 0, ("MODE3A", f"{int(c['mode3a'][i]):04o}"))
        if "flight_level" in c and np.isfinite(c["flight_level"][i]):
            items["090"] = (0, 0, ("FL", (float(c["flight_level"][i]), "FL")))
        if "address" in c and c["address"][i] >= 0:
            items["220"] = int(c["address"][i])
        recs.append(spec.cv_record.create(items))
    return _blocks(spec, recs, per_block)


def encode_cat021(
    time_of_day: Any,
    sac: Any,
    sic: Any,
    latitude: Any,
    longitude: Any,
    *,
    height: Any = None,
    flight_level: Any = None,
    address: Any = None,
    high_resolution: bool = True,
    per_block: int = 20,
    edition: tuple[int, int] = EDITIONS[21],
) -> bytes:
    """CAT021 datablocks through libasterix.

    ``time_of_day`` s (I073 time of message reception for position), ``latitude`` /
    ``longitude`` deg WGS-84 (I131 if ``high_resolution`` else I130), ``height`` m above
    the ellipsoid (I140 geometric height, LSB 6.25 ft; NaN: absent), ``flight_level`` FL
    (I145; NaN: absent), ``address`` (I080; < 0: absent). Every record carries I040
    (target report descriptor, extended).
    """
    c = _cols(
        "encode_cat021",
        time_of_day=time_of_day,
        sac=sac,
        sic=sic,
        latitude=latitude,
        longitude=longitude,
        height=height,
        flight_level=flight_level,
        address=address,
    )
    _ints("encode_cat021", c, {"sac": 255, "sic": 255, "address": 2**24 - 1})
    if np.any(np.abs(c["latitude"]) > 90) or np.any(np.abs(c["longitude"]) > 180):
        raise ProblemError(
            "asterix.encode_cat021 latitude/longitude: need |lat| ≤ 90°, |lon| ≤ 180°"
        )
    spec = _spec(21, {21: as_edition("asterix.encode_cat021 edition", edition)})
    tod = np.mod(c["time_of_day"], DAY)
    pos_item = "131" if as_flag("asterix.encode_cat021 high_resolution", high_resolution) else "130"
    recs = []
    for i in np.arange(tod.size):
        items: dict[str, Any] = {
            "010": (("SAC", int(c["sac"][i])), ("SIC", int(c["sic"][i]))),
            "040": ((0, 0, 0, 0, 0),),
            "073": (float(tod[i]), "s"),
            pos_item: (
                ("LAT", (float(c["latitude"][i]), "°")),
                ("LON", (float(c["longitude"][i]), "°")),
            ),
        }
        if "height" in c and np.isfinite(c["height"][i]):
            items["140"] = (float(c["height"][i]) / FT, "ft")
        if "flight_level" in c and np.isfinite(c["flight_level"][i]):
            items["145"] = (float(c["flight_level"][i]), "FL")
        if "address" in c and c["address"][i] >= 0:
            items["080"] = int(c["address"][i])
        recs.append(spec.cv_record.create(items))
    return _blocks(spec, recs, per_block)
