"""ASTERIX CAT048 (monoradar target reports) and CAT021 (ADS-B target reports) in and out.

Decoding route (chosen by measurement, see ``solvers_cmp/bench_asterix.py``): the record
layouts (the UAP, each item's size and each subfield's bit offset, width, signedness, LSB
and unit) come from the maintained pure-Python library *libasterix* (module ``asterix``,
``asterix.generated``), which also **validates**: the first record of every distinct FSPEC
layout in a file is parsed strictly by libasterix and its consumed length and the raw
value of every field read here must agree with this module's (``check="layouts"``, the
default), or every datablock is (``check="all"``, ~2 000 records/s). The records are
framed in Python with a per-FSPEC layout cache (item sizes from the library's spec
classes; Extended/Repetitive/Explicit/Compound items sized from their FX bits, repetition
counts, length bytes or sub-FSPEC; anything else sized by the library's own parser) and
the fixed-size fields wanted are read from all records at once with NumPy, every
:data:`CHUNK` records (bounded memory; the file is memory-mapped). On the project's shared
2-core machine libasterix's normal use (``Uap.parse``) reached 500-2 200 records/s, the
C++ *asterix-decoder* 3 400-17 000 (its ``verbose=False``), both below the 50 000 target;
this route 84 000-250 000 records/s.

Recordings are raw datablocks or pcap/pcapng captures of ASTERIX over UDP (read through
dpkt, :mod:`~optmodels.io.asterix.capture`); times are placed on one axis per (category,
SAC/SIC) across files (:mod:`~optmodels.io.asterix.timeline`).

Encoding (:func:`encode_cat048`, :func:`encode_cat021`) is vectorised NumPy from the same
libasterix layouts, byte for byte what libasterix writes for the same values (the oracle,
:mod:`~optmodels.io.asterix.libencode`, in the tests), with every field's range checked.
:func:`rewrite_cat048_positions` writes a recording back with only I048/040 replaced.

Units (SI, stated): times s (time of day of the record, unwrapped across midnight, see
:func:`read_asterix`), slant range m (I048/040 RHO, LSB 1/256 NM, 1 NM = 1852 m), azimuth rad
clockwise from the radar's north (I048/040 THETA, LSB 360°/2¹⁶), latitude/longitude deg
(WGS-84, I021/131 LSB 180°/2³⁰, I021/130 LSB 180°/2²³), geometric height m (I021/140, LSB
6.25 ft, height above the WGS-84 ellipsoid per the CAT021 definition), pressure altitude m
(flight level × 100 ft, I048/090 and I021/145, LSB 1/4 FL; it is *not* a geometric height).
Addresses are the 24-bit ICAO aircraft address (I048/220, I021/080) as an int, −1 where
absent; Mode 3/A (I048/070) the 12-bit code as an int (``oct()`` gives the usual 4 digits),
−1 where absent.

Modules (job by job): :mod:`~optmodels.io.asterix.layout` (layouts from libasterix),
:mod:`~optmodels.io.asterix.framing` (content detection, framing, the libasterix check),
:mod:`~optmodels.io.asterix.capture` (pcap/pcapng), :mod:`~optmodels.io.asterix.timeline`
(the time axis), :mod:`~optmodels.io.asterix.read` (:func:`read_asterix`),
:mod:`~optmodels.io.asterix.reports` (the result tables), :mod:`~optmodels.io.asterix.encode`
(the encoders), :mod:`~optmodels.io.asterix.rewrite` (the corrected CAT048 writer),
:mod:`~optmodels.io.asterix.libencode` (the reference encoders through libasterix).
"""

from __future__ import annotations

from optmodels.io.asterix.encode import encode_cat021, encode_cat048
from optmodels.io.asterix.framing import CHUNK, is_asterix
from optmodels.io.asterix.layout import DAY, EDITIONS, FL, FT, NM
from optmodels.io.asterix.read import read_asterix
from optmodels.io.asterix.reports import AsterixData, Cat021Reports, Cat048Reports
from optmodels.io.asterix.rewrite import rewrite_cat048_positions

__all__ = [
    "CHUNK",
    "DAY",
    "EDITIONS",
    "FL",
    "FT",
    "NM",
    "AsterixData",
    "Cat021Reports",
    "Cat048Reports",
    "encode_cat021",
    "encode_cat048",
    "is_asterix",
    "read_asterix",
    "rewrite_cat048_positions",
]
