"""ASTERIX ingest speed (issue 16 item 2): records/s of :func:`optmodels.io.asterix.read_asterix`
against the two maintained decoders in their normal use, on the same generated file.

The file: ``--distinct`` CAT048 records written by libasterix with the items a Mode S
radar sends (I010, I140, I020 extended, I040, I070, I090, I130 compound, I220, I240, I250
repetitive, I161, I200, I170 extended) and as many CAT021 reports (I010, I040, I073, I131,
I140, I145, I080), 20 records per datablock, tiled to ``--records`` records in all (the
decoders' speed does not depend on the values). Timings are medians of ``--repeats`` runs
on a shared machine.

- ``optmodels``: :func:`read_asterix` (framing with a per-FSPEC layout cache from
  libasterix's specs, NumPy field extraction, libasterix's strict parse of the first record
  of each layout) into SI arrays; also with ``check="all"`` (libasterix parses every
  record) on the first ``--distinct`` records.
- ``optmodels read_recording``: the same file into the bias-field tables (radar by
  SAC/SIC, objects by address, heights: ADS-B interpolation or flight level).
- ``libasterix``: ``RawDatablock.parse_single`` + ``Uap.parse`` + ``get_item`` of the
  fields read (its normal use), on the first ``--distinct`` records.
- ``asterix-decoder`` (C++; it installs a module ``asterix`` too, so it lives in another
  interpreter, ``--astd-python``): ``asterix.parse(data)`` and ``verbose=False``, then the
  same fields into NumPy arrays.

Encoding (issue 26 item 6, ``--encode``): records/s of the vectorised
:func:`~optmodels.io.asterix.encode_cat048` / ``encode_cat021`` against the former encoders
through libasterix (:mod:`optmodels.io.asterix.libencode`), timed in the same run,
interleaved (new, old, new, old …), median of ``--repeats`` rounds; the new output is
checked byte for byte against the old on the records both encoded; the load average is
printed with the figures.

Usage::

    .venv/bin/python -m solvers_cmp.bench_asterix [--records 200000] [--repeats 5]
        [--astd-python /tmp/venv-astd/bin/python]
    .venv/bin/python -m solvers_cmp.bench_asterix --encode [--records 200000]
        [--old-records 6000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

_ASTD = r"""
import sys, time, statistics, json
import numpy as np
import asterix
data = open(sys.argv[1], 'rb').read()
reps = int(sys.argv[2])
out = {}
for verbose in (True, False):
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        recs = asterix.parse(data, verbose=verbose)
        r48 = [r for r in recs if r['category'] == 48]
        rho = np.array([r['I040']['RHO']['val'] for r in r48]) * 1852.0
        th = np.radians([r['I040']['THETA']['val'] for r in r48])
        tod = np.array([r['I140']['ToD']['val'] for r in r48])
        fl = np.array([r['I090']['FL']['val'] if 'I090' in r else np.nan for r in r48])
        ts.append(time.perf_counter() - t)
    out['verbose' if verbose else 'quiet'] = len(recs) / statistics.median(ts)
print(json.dumps(out))
"""


def make_file(path: Path, records: int, distinct: int) -> int:
    """Write the benchmark file; the number of records in it."""
    import asterix.generated as gen

    from optmodels.io.asterix import encode_cat021

    c48 = gen.Cat_048_1_32
    rng = np.random.default_rng(16)
    half = distinct // 2
    recs = []
    for i in range(half):
        recs.append(
            c48.cv_record.create(
                {
                    "010": (("SAC", 1), ("SIC", 2)),
                    "140": (36000.0 + 0.01 * i, "s"),
                    "020": ((5, 0, 0, 0, 0, 0),),
                    "040": (
                        ("RHO", (float(rng.uniform(1, 250)), "NM")),
                        ("THETA", (float(rng.uniform(0, 359)), "°")),
                    ),
                    "070": (0, 0, 0, 0, ("MODE3A", "1234")),
                    "090": (0, 0, ("FL", (float(rng.uniform(0, 450)), "FL"))),
                    "130": {"SRL": 3, "SAM": 200},
                    "220": int(rng.integers(0, 2**24)),
                    "240": 0,
                    "250": [0x1122334455667740] * int(rng.integers(1, 4)),
                    "161": i % 4096,
                    "200": 0,
                    "170": ((0, 0, 0, 0, 0, 0),),
                }
            )
        )
    b48 = b"".join(c48.create(recs[k : k + 20]).unparse().to_bytes() for k in range(0, half, 20))
    b21 = encode_cat021(
        36000.0 + 0.01 * np.arange(half),
        3,
        4,
        rng.uniform(40, 50, half),
        rng.uniform(10, 20, half),
        height=rng.uniform(0, 12000, half),
        flight_level=rng.uniform(0, 450, half),
        address=rng.integers(0, 2**24, half),
    )
    unit = b48 + b21
    tiles = max(1, records // (2 * half))
    path.write_bytes(unit * tiles)
    return 2 * half * tiles


def _median_rate(fn: Any, n: int, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return n / statistics.median(ts)


def libasterix_normal(data: bytes) -> int:
    """libasterix's normal use: every record parsed, the fields read by name."""
    import asterix.base as base
    import asterix.generated as gen

    specs = {48: gen.Cat_048_1_32, 21: gen.Cat_021_2_7}
    rest = base.Bits.from_bytes(data)
    n = 0
    out: list[float] = []
    while len(rest) > 0:
        res = base.RawDatablock.parse_single(rest)
        assert not isinstance(res, ValueError), res
        db, rest = res
        spec = specs[db.get_category()]
        recs = spec.cv_uap.parse(db.get_raw_records())
        assert not isinstance(recs, ValueError), recs
        for r in recs:
            if db.get_category() == 48:
                i040 = r.get_item("040")
                out.append(
                    i040.variation.get_item("RHO").variation.content.as_quantity("NM") * 1852.0
                )
                out.append(r.get_item("140").variation.content.as_quantity("s"))
            else:
                i131 = r.get_item("131")
                out.append(i131.variation.get_item("LAT").variation.content.as_quantity("°"))
            n += 1
    return n


def benchmark(
    records: int = 200_000, repeats: int = 5, distinct: int = 4000, astd_python: str | None = None
) -> dict[str, Any]:
    """Records/s of each route (see the module docstring)."""
    from optmodels.io.asterix import read_asterix

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.ast"
        n = make_file(path, records, distinct)
        small = Path(tmp) / "small.ast"
        make_file(small, distinct, distinct)
        out: dict[str, Any] = {"records": n, "bytes": path.stat().st_size, "repeats": repeats}
        d = read_asterix(path)
        assert len(d.cat048) + len(d.cat021) == n
        out["optmodels read_asterix"] = _median_rate(lambda: read_asterix(path), n, repeats)
        from optmodels.biasfield.recording import read_recording

        sites = Path(tmp) / "sites.csv"
        sites.write_text(
            "name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
            "A,1,2,45,15,100,30,0.05,500000\nB,1,3,46,16,100,30,0.05,500000\n"
        )
        out["optmodels read_recording (plots + ADS-B heights)"] = _median_rate(
            lambda: read_recording(path, sites), n, repeats
        )
        out["optmodels read_asterix check='all'"] = _median_rate(
            lambda: read_asterix(small, check="all"), distinct, max(1, repeats // 2)
        )
        data = small.read_bytes()
        out["libasterix Uap.parse"] = _median_rate(
            lambda: libasterix_normal(data), distinct, max(1, repeats // 2)
        )
        if astd_python:
            res = subprocess.run(
                [astd_python, "-c", _ASTD, str(small), str(repeats)],
                capture_output=True,
                text=True,
                check=False,
            )
            if res.returncode == 0:
                rates = json.loads(res.stdout)
                out["asterix-decoder parse"] = rates["verbose"]
                out["asterix-decoder parse verbose=False"] = rates["quiet"]
            else:
                out["asterix-decoder"] = f"failed: {res.stderr.strip()[-200:]}"
    return out


def encode_benchmark(
    records: int = 200_000, old_records: int = 6000, repeats: int = 5
) -> dict[str, Any]:
    """Records/s of the vectorised encoders and of the libasterix ones (interleaved
    rounds, medians), with the byte-for-byte check; the load average before and after."""
    import os

    from optmodels.io.asterix import encode_cat021, encode_cat048, libencode

    rng = np.random.default_rng(26)
    n = records
    tod = 36000.0 + 0.01 * np.arange(n)
    a48 = (tod, 1, 2, rng.uniform(1e3, 4.5e5, n), rng.uniform(0, 2 * np.pi, n))
    k48 = {
        "flight_level": rng.uniform(0, 450, n),
        "address": rng.integers(0, 2**24, n),
        "mode3a": rng.integers(0, 4096, n),
    }
    a21 = (tod, 3, 4, rng.uniform(40, 50, n), rng.uniform(10, 20, n))
    k21 = {
        "height": rng.uniform(0, 12000, n),
        "flight_level": rng.uniform(0, 450, n),
        "address": rng.integers(0, 2**24, n),
    }
    m = min(old_records, n)

    def head(args: tuple, kw: dict) -> tuple[tuple, dict]:
        return (
            tuple(a[:m] if isinstance(a, np.ndarray) else a for a in args),
            {k: v[:m] for k, v in kw.items()},
        )

    out: dict[str, Any] = {
        "records (new)": n,
        "records (old)": m,
        "repeats": repeats,
        "load before": os.getloadavg(),
    }
    for cat, new, old, args, kw in (
        ("CAT048", encode_cat048, libencode.encode_cat048, a48, k48),
        ("CAT021", encode_cat021, libencode.encode_cat021, a21, k21),
    ):
        oa, ok = head(args, kw)
        assert new(*oa, **ok) == old(*oa, **ok), f"{cat}: bytes differ"
        t_new, t_old = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            new(*args, **kw)
            t_new.append(time.perf_counter() - t)
            t = time.perf_counter()
            old(*oa, **ok)
            t_old.append(time.perf_counter() - t)
        out[f"{cat} new records/s"] = n / statistics.median(t_new)
        out[f"{cat} old (libasterix) records/s"] = m / statistics.median(t_old)
        out[f"{cat} speed-up"] = (
            out[f"{cat} new records/s"] / out[f"{cat} old (libasterix) records/s"]
        )
    out["bytes identical"] = "yes (CAT048 and CAT021, the old run's records)"
    out["load after"] = os.getloadavg()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--records", type=int, default=200_000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--distinct", type=int, default=4000)
    ap.add_argument(
        "--astd-python", default=None, help="an interpreter with asterix-decoder installed"
    )
    ap.add_argument(
        "--encode",
        action="store_true",
        help="benchmark the encoders (vectorised against libasterix)",
    )
    ap.add_argument(
        "--old-records",
        type=int,
        default=6000,
        help="records given to the libasterix encoders (--encode)",
    )
    a = ap.parse_args(argv)
    if a.encode:
        res = encode_benchmark(a.records, a.old_records, a.repeats)
    else:
        res = benchmark(a.records, a.repeats, a.distinct, a.astd_python)
    for k, v in res.items():
        print(f"{k:40s} {v:,.0f}" if isinstance(v, float) else f"{k:40s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
