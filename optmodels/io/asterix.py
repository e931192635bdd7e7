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

Encoding (tests, benchmarks, users who need to write a recording) is libasterix's
(:func:`encode_cat048`, :func:`encode_cat021`).

Units (SI, stated): times s (time of day of the record, unwrapped across midnight, see
:func:`read_asterix`), slant range m (I048/040 RHO, LSB 1/256 NM, 1 NM = 1852 m), azimuth rad
clockwise from the radar's north (I048/040 THETA, LSB 360°/2¹⁶), latitude/longitude deg
(WGS-84, I021/131 LSB 180°/2³⁰, I021/130 LSB 180°/2²³), geometric height m (I021/140, LSB
6.25 ft, height above the WGS-84 ellipsoid per the CAT021 definition), pressure altitude m
(flight level × 100 ft, I048/090 and I021/145, LSB 1/4 FL; it is *not* a geometric height).
Addresses are the 24-bit ICAO aircraft address (I048/220, I021/080) as an int, −1 where
absent; Mode 3/A (I048/070) the 12-bit code as an int (``oct()`` gives the usual 4 digits),
−1 where absent.
"""

from __future__ import annotations

import datetime as _dt
import math
import mmap
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import FloatArray, ProblemError, as_choice, as_count, as_flag

__all__ = [
    "EDITIONS",
    "AsterixData",
    "Cat021Reports",
    "Cat048Reports",
    "encode_cat021",
    "encode_cat048",
    "is_asterix",
    "read_asterix",
]

NM = 1852.0            # m per nautical mile (exact)
FT = 0.3048            # m per foot (exact)
FL = 100.0 * FT        # m of pressure altitude per flight level
DAY = 86400.0          # s
#: default editions read and written (category → (major, minor)); any edition libasterix
#: ships can be asked for through ``editions=``.
EDITIONS: dict[int, tuple[int, int]] = {48: (1, 32), 21: (2, 7)}
_UNITS = {"NM": NM, "°": math.pi / 180.0, "ft": FT, "FL": FL, "s": 1.0}


def _lib() -> tuple[Any, Any]:
    try:
        import asterix.base as base
        import asterix.generated as gen
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ProblemError("asterix: reading ASTERIX needs the libasterix package "
                           "(pip install 'libasterix>=0.36')") from exc
    if not hasattr(gen, "manifest"):  # pragma: no cover - the C++ asterix-decoder
        raise ProblemError("asterix: the installed module 'asterix' is not libasterix "
                           "(asterix-decoder installs the same name); install libasterix")
    return base, gen


def _spec(cat: int, editions: dict[int, tuple[int, int]] | None) -> Any:
    _, gen = _lib()
    ed = {**EDITIONS, **(editions or {})}.get(cat)
    for s in gen.manifest["CATS"].get(cat, []):
        if s.cv_edition == tuple(ed or ()):
            return s
    known = [s.cv_edition for s in gen.manifest["CATS"].get(cat, [])]
    raise ProblemError(f"asterix editions: CAT{cat:03d} edition {ed} is not in libasterix "
                       f"(known: {known})")


# ---------------------------------------------------------------------------------------
# Layout engine: sizes from libasterix's spec classes
# ---------------------------------------------------------------------------------------

Sizer = int | Callable[[bytes, int], int]


def _variation_sizer(var: Any, nsp: Any) -> Sizer:
    """Bytes of one item of variation class ``var`` (an int if fixed, else a function of
    (buffer, offset)). Falls back on libasterix's own parser for anything irregular."""
    base, _ = _lib()
    if issubclass(var, base.Element | base.Group) and var.cv_bit_size % 8 == 0:
        return var.cv_bit_size // 8
    if issubclass(var, base.Extended):
        sizes = []
        for grp in var.cv_items_list:
            bits = sum(sz for it in grp if it is not None for _, sz in [it])
            bits += sum(1 for it in grp if it is None)
            sizes.append(bits)
        if all(b % 8 == 0 for b in sizes):
            nbytes = [b // 8 for b in sizes]
            fx_ends = [grp[-1] is None for grp in var.cv_items_list]

            def extended(buf: bytes, q: int, _n: list[int] = nbytes,
                         _fx: list[bool] = fx_ends) -> int:
                p = q
                for nb, fx in zip(_n, _fx, strict=True):
                    p += nb
                    if not fx or not (buf[p - 1] & 1):
                        return p - q
                raise _Bad("extended item: FX set in its last part")
            return extended
    if issubclass(var, base.Repetitive):
        elem = _variation_sizer(var.cv_variation, nsp)
        rb = var.cv_rep_bytes
        if isinstance(elem, int) and rb is not None:
            def repetitive(buf: bytes, q: int, _e: int = elem, _rb: int = rb) -> int:
                return _rb + _e * int.from_bytes(buf[q:q + _rb], "big")
            return repetitive
    if issubclass(var, base.Explicit):
        def explicit(buf: bytes, q: int) -> int:
            n = buf[q]
            if n < 1:
                raise _Bad("explicit item with length 0")
            return n
        return explicit
    if issubclass(var, base.Compound):
        subs = [None if s is None else _rule_sizer(s) for s in var.cv_items_list]

        memo: dict[bytes, tuple[int, list[Sizer]]] = {}

        def compound(buf: bytes, q: int, _subs: list[Sizer | None] = subs,
                     _memo: dict[bytes, tuple[int, list[Sizer]]] = memo) -> int:
            p = q
            while buf[p] & 1:
                p += 1
            p += 1
            fs = buf[q:p]
            hit = _memo.get(fs)
            if hit is None:  # sub-FSPEC seen first: its fixed part and variable subitems
                present = [7 * k + bit for k, b in enumerate(fs) for bit in range(7)
                           if b & (0x80 >> bit)]
                fixed, var = 0, []
                for frn in present:
                    if frn >= len(_subs) or _subs[frn] is None:
                        raise _Bad(f"compound subfield {frn + 1} not in the specification")
                    sz = _subs[frn]
                    if isinstance(sz, int):
                        fixed += sz
                    else:
                        var.append(sz)  # type: ignore[arg-type]
                hit = _memo[bytes(fs)] = (fixed, var)
            # all subitems fixed: the size is known from the sub-FSPEC alone; else walk
            # them (a variable subitem is sized at its own offset)
            fixed, var = hit
            if not var:
                return p - q + fixed
            present = [7 * k + bit for k, b in enumerate(fs) for bit in range(7)
                       if b & (0x80 >> bit)]
            for frn in present:
                sz = _subs[frn]
                p += sz if isinstance(sz, int) else sz(buf, p)  # type: ignore[operator,misc]
            return p - q
        return compound
    return _library_sizer(nsp)


def _rule_sizer(nsp: Any) -> Sizer:
    base, _ = _lib()
    rule = nsp.cv_rule
    if issubclass(rule, base.RuleVariationContextFree):
        return _variation_sizer(rule.cv_variation, nsp)
    cases = [rule.cv_default_variation] + [v for _, v in rule.cv_cases]
    sizes = {_variation_sizer(v, nsp) for v in cases}
    if len(sizes) == 1 and isinstance(next(iter(sizes)), int):
        return next(iter(sizes))
    return _library_sizer(nsp)


def _library_sizer(nsp: Any) -> Sizer:
    base, _ = _lib()

    def by_library(buf: Any, q: int) -> int:
        chunk = bytes(buf[q:q + 65536])  # an item never exceeds its datablock
        res = nsp.parse(base.Bits(chunk, 0, 8 * len(chunk)))
        if isinstance(res, ValueError):
            raise _Bad(f"item I{nsp.cv_name}: {res}")
        return res[1].bit_offset1 // 8
    return by_library


class _Bad(Exception):
    """Internal: malformed record (turned into a ProblemError with file and offset)."""


@dataclass(frozen=True)
class _Field:
    name: str
    item: str
    offset: int          # bit offset inside the item
    size: int            # bits
    signed: bool
    scale: float         # raw → SI
    path: tuple[str, ...]


def _field(record: Any, name: str, path: tuple[str, ...]) -> _Field | None:
    """Bit offset, width, sign and SI scale of subfield ``path`` (item[, subitem]) from the
    library's spec; None if the edition has no such item."""
    base, _ = _lib()
    nsp = record.cv_items_dict.get(path[0])
    if nsp is None:
        return None
    var = nsp.cv_rule.cv_variation
    off = 0
    if len(path) > 1:
        for it, sz in var.cv_items_list:
            if hasattr(it, "cv_non_spare") and it.cv_non_spare.cv_name == path[1]:
                var = it.cv_non_spare.cv_rule.cv_variation
                break
            off += sz
        else:
            return None
    if not issubclass(var, base.Element):
        return None
    content = var.cv_rule.cv_content
    scale, signed = 1.0, False
    if issubclass(content, base.ContentQuantity):
        scale = content.cv_lsb * _UNITS[content.cv_unit]
        signed = content.cv_signedness is base.Signed
    return _Field(name, path[0], off, var.cv_bit_size, signed, scale, path)


_FIELDS = {
    48: {"sac": ("010", "SAC"), "sic": ("010", "SIC"), "tod": ("140",),
         "rho": ("040", "RHO"), "theta": ("040", "THETA"), "fl": ("090", "FL"),
         "fl_v": ("090", "V"), "fl_g": ("090", "G"), "address": ("220",),
         "mode3a": ("070", "MODE3A")},
    21: {"sac": ("010", "SAC"), "sic": ("010", "SIC"), "t073": ("073",), "t071": ("071",),
         "lat_hi": ("131", "LAT"), "lon_hi": ("131", "LON"), "lat_lo": ("130", "LAT"),
         "lon_lo": ("130", "LON"), "gh": ("140",), "fl": ("145",), "address": ("080",)},
}


class _Layout:
    """Per category: the UAP sizers, the fields wanted and a cache FSPEC → plan."""

    def __init__(self, spec: Any) -> None:
        base, _ = _lib()
        if not issubclass(spec.cv_uap, base.UapSingle):
            raise ProblemError(f"asterix: CAT{spec.cv_category:03d} has several UAPs; "
                               "not supported")
        self.spec = spec
        self.record = spec.cv_uap.cv_record
        self.max_fspec = self.record.cv_fspec_max_bytes
        self.uap: list[tuple[str | None, Sizer | None]] = []
        for it in self.record.cv_items_list:
            if issubclass(it, base.UapItem):
                nsp = it.cv_non_spare
                self.uap.append((nsp.cv_name, _rule_sizer(nsp)))
            else:  # spare or RFS slot: refused if present
                self.uap.append((None, None))
        fields = [_field(self.record, k, p) for k, p in _FIELDS[spec.cv_category].items()]
        self.fields = [f for f in fields if f is not None]
        self.items = sorted({f.item for f in self.fields})
        self.slot = {name: j for j, name in enumerate(self.items)}
        self.cache: dict[bytes, tuple[list[Sizer], list[int]]] = {}

    def plan(self, fspec: bytes) -> tuple[list[Sizer], list[int]]:
        frns = [7 * k + bit for k, b in enumerate(fspec) for bit in range(7)
                if b & (0x80 >> bit)]
        sizes: list[Sizer] = []
        need: list[int] = []
        for frn in frns:
            if frn >= len(self.uap) or self.uap[frn][0] is None:
                raise _Bad(f"FSPEC announces FRN {frn + 1}, which CAT"
                           f"{self.spec.cv_category:03d} edition {self.spec.cv_edition} "
                           "does not define")
            name, s = self.uap[frn]
            sizes.append(s)  # type: ignore[arg-type]
            need.append(self.slot.get(name, -1))  # type: ignore[arg-type]
        out = (sizes, need)
        self.cache[fspec] = out
        return out


# ---------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Cat048Reports:
    """CAT048 target reports, one row each, in file order.

    ``time`` (s since the epoch of :class:`AsterixData`, I140 unwrapped across midnight),
    ``sac``/``sic`` (I010), ``range`` (m, slant, I040 RHO), ``azimuth`` (rad, clockwise from
    the radar's north, I040 THETA), ``pressure_altitude`` (m = FL × 30.48, I090; NaN where
    absent, not validated (V) or garbled (G)), ``address`` (I220, −1 if absent),
    ``mode3a`` (I070, −1 if absent), ``offset`` (byte offset of the record in its file),
    ``file`` (index into :attr:`AsterixData.files`). Rows without I010, I140 or I040 are
    not kept; their number is in :attr:`AsterixData.dropped`.
    """

    time: FloatArray
    sac: np.ndarray
    sic: np.ndarray
    range: FloatArray
    azimuth: FloatArray
    pressure_altitude: FloatArray
    address: np.ndarray
    mode3a: np.ndarray
    offset: np.ndarray
    file: np.ndarray

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class Cat021Reports:
    """CAT021 ADS-B reports, one row each, in file order.

    ``time`` (s since the epoch, I073 time of reception of position, else I071 time of
    applicability for position), ``sac``/``sic`` (I010 of the ground station),
    ``latitude``/``longitude`` (deg WGS-84, I131 high resolution, else I130), ``height``
    (m above the WGS-84 ellipsoid, I140 geometric height; NaN if absent),
    ``pressure_altitude`` (m, I145 FL × 30.48; NaN if absent), ``address`` (I080, −1 if
    absent), ``offset``, ``file``. Rows without a time or a position are not kept (counted
    in :attr:`AsterixData.dropped`).
    """

    time: FloatArray
    sac: np.ndarray
    sic: np.ndarray
    latitude: FloatArray
    longitude: FloatArray
    height: FloatArray
    pressure_altitude: FloatArray
    address: np.ndarray
    offset: np.ndarray
    file: np.ndarray

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class AsterixData:
    """What :func:`read_asterix` read: ``cat048``, ``cat021``, ``epoch`` (numpy
    ``datetime64[ns]`` of the UTC midnight the times count from, or None without a
    ``date``), ``files``, ``records`` (CAT048 and CAT021 records read), ``dropped``
    (reports not kept, by reason), ``skipped`` (datablocks of other categories, by
    category)."""

    cat048: Cat048Reports
    cat021: Cat021Reports
    epoch: np.datetime64 | None
    files: tuple[str, ...]
    records: dict[int, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    skipped: dict[int, int] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------

def is_asterix(path: str | Path, *, blocks: int = 4,
               editions: dict[int, tuple[int, int]] | None = None) -> bool:
    """Whether a file's content is ASTERIX: the first ``blocks`` datablocks (CAT byte, LEN
    ≥ 4 bytes) chain exactly (or to the end of the file), every CAT is one libasterix
    knows, and the first record of the first CAT048/CAT021 block parses strictly with
    libasterix in the ``editions`` given (default :data:`EDITIONS`; a file cut inside a
    later block still counts: :func:`read_asterix` then reports the truncation). Reads at
    most 256 KiB; never raises for a readable file (an unknown edition raises)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 18)
            size = fh.seek(0, 2)
    except OSError:
        return False
    if len(head) < 4 or head[:4] == b"PAR1" or head[:2] == b"PK":
        return False
    # framing first (cheap, no library import): CSV/Parquet/text fail here
    pos, found = 0, []
    while pos < len(head) and len(found) < blocks:
        if pos + 3 > len(head):
            break
        cat, n = head[pos], int.from_bytes(head[pos + 1:pos + 3], "big")
        if n < 4:
            return False
        if pos + n > size:  # truncated after complete blocks: still ASTERIX
            if not found:
                return False
            break
        found.append((cat, pos, n))
        pos += n
    if not found:
        return False
    base, gen = _lib()
    if any(cat not in gen.manifest["CATS"] for cat, _, _ in found):
        return False
    for cat, pos, n in found:
        if cat in _FIELDS and pos + n <= len(head):
            rec = _spec(cat, editions).cv_uap.cv_record
            res = rec.parse(base.ParsingMode.StrictParsing,
                            base.Bits(head, 8 * (pos + 3), 8 * (pos + n)))
            return not isinstance(res, ValueError)
    return True


#: records framed before their fields are gathered (bounds the framing's memory:
#: 8 bytes per record and per item read, ~56 MB per chunk for CAT048)
CHUNK = 1 << 20


def _frame(buf: Any, name: str, layouts: dict[int, _Layout], check: str,
           skipped: dict[int, int]) -> Iterator[dict[int, tuple[Any, Any]]]:
    """Walk the datablocks and records of one file (bytes or a read-only mmap); yield,
    every :data:`CHUNK` records and at the end, per category the record offsets and the
    flat item offsets (−1 absent), ``len(layout.items)`` per record (``array('q')``).
    Datablocks of other categories are counted in ``skipped``."""
    _lib()  # the library is needed for the layout check
    out: dict[int, tuple[Any, Any]] = {c: (array("q"), array("q")) for c in layouts}
    pos, size = 0, len(buf)
    validated: set[tuple[int, bytes]] = set()
    while pos < size:
        if pos + 3 > size:
            raise ProblemError(f"asterix.read {name}: truncated datablock header at byte "
                               f"{pos} ({size - pos} bytes left)")
        cat, n = buf[pos], int.from_bytes(buf[pos + 1:pos + 3], "big")
        if n < 3:
            raise ProblemError(f"asterix.read {name}: not ASTERIX or corrupt: datablock at "
                               f"byte {pos} has length {n} (< 3)")
        end = pos + n
        if end > size:
            raise ProblemError(f"asterix.read {name}: truncated: the CAT{cat:03d} datablock "
                               f"at byte {pos} announces {n} bytes, {size - pos} left")
        lay = layouts.get(cat)
        if lay is None:
            skipped[cat] = skipped.get(cat, 0) + 1
            pos = end
            continue
        recs, flat = out[cat]
        nslot = len(lay.items)
        cache = lay.cache
        q = pos + 3
        try:
            while q < end:
                r0 = q
                while buf[q] & 1:
                    q += 1
                q += 1
                if q - r0 > lay.max_fspec:
                    raise _Bad(f"FSPEC of {q - r0} bytes (at most {lay.max_fspec})")
                fs = buf[r0:q]
                plan = cache.get(fs)
                if plan is None:
                    plan = lay.plan(fs)
                sizes, need = plan
                offs = [-1] * nslot
                for s, j in zip(sizes, need, strict=True):
                    if j >= 0:
                        offs[j] = q
                    q += s if s.__class__ is int else s(buf, q)  # type: ignore[operator]
                if q > end:
                    raise _Bad(f"record overruns its datablock (ends at byte {end})")
                if check == "all" or (cat, fs) not in validated:
                    _validate(buf, r0, q, end, lay, offs, name)
                    validated.add((cat, fs))
                recs.append(r0)
                flat.extend(offs)
        except _Bad as exc:
            raise ProblemError(f"asterix.read {name}: corrupt CAT{cat:03d} record at byte "
                               f"{r0}: {exc}") from None
        except IndexError:
            raise ProblemError(f"asterix.read {name}: truncated CAT{cat:03d} record at byte "
                               f"{r0} (file ends at byte {size})") from None
        pos = end
        if sum(len(r) for r, _ in out.values()) >= CHUNK:
            yield out
            out = {c: (array("q"), array("q")) for c in layouts}
    yield out


def _validate(buf: bytes, r0: int, q: int, end: int, lay: _Layout, offs: list[int],
              name: str) -> None:
    """libasterix's strict parse of the record at ``r0`` must end at ``q`` and give the
    same raw value of every field read here."""
    base, _ = _lib()
    chunk = bytes(buf[r0:end])
    res = lay.record.parse(base.ParsingMode.StrictParsing, base.Bits(chunk, 0, 8 * len(chunk)))
    if isinstance(res, ValueError):
        raise _Bad(f"libasterix refuses it ({res})")
    rec, rest = res
    if rest.bit_offset1 != 8 * (q - r0):
        raise _Bad(f"libasterix ends it at byte {r0 + rest.bit_offset1 // 8}, the framing "
                   f"at {q}")
    for f in lay.fields:
        item = rec.get_item(f.item)
        o = offs[lay.slot[f.item]]
        if (item is None) != (o < 0):
            raise _Bad(f"I{f.item} presence differs from libasterix")
        if item is None:
            continue
        node = item if len(f.path) == 1 else item.variation.get_item(f.path[1])
        lib_raw = node.unparse().to_uinteger() if len(f.path) > 1 else \
            item.unparse().to_uinteger()
        mine = _raw_at(buf, o, f)
        if int(lib_raw) != mine:
            raise _Bad(f"I{f.item} {'/'.join(f.path[1:])}: raw {mine} here, {lib_raw} by "
                       "libasterix")


def _raw_at(buf: bytes, o: int, f: _Field) -> int:
    nb = (f.offset + f.size + 7) // 8
    v = int.from_bytes(buf[o:o + nb], "big")
    return (v >> (8 * nb - f.offset - f.size)) & ((1 << f.size) - 1)


def _gather(arr: np.ndarray, offs: np.ndarray, f: _Field) -> tuple[np.ndarray, np.ndarray]:
    """Raw (signed if the field is) int64 values of field ``f`` at item offsets ``offs``
    (−1 absent), and the presence mask."""
    have = offs >= 0
    o = np.where(have, offs, 0)
    nb = (f.offset + f.size + 7) // 8
    v = np.zeros(o.shape, dtype=np.uint64)
    for k in range(nb):
        v = (v << np.uint64(8)) | arr[o + k].astype(np.uint64)
    v = (v >> np.uint64(8 * nb - f.offset - f.size)) & np.uint64((1 << f.size) - 1)
    out = v.astype(np.int64)
    if f.signed:
        out = np.where(out >= (1 << (f.size - 1)), out - (1 << f.size), out)
    return out, have


def _as_date(date: Any) -> np.datetime64 | None:
    if date is None:
        return None
    try:
        if isinstance(date, _dt.datetime):
            date = date.date()
        d = np.datetime64(date, "D")
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"asterix.read date: expected a date (YYYY-MM-DD, datetime.date "
                           f"or numpy datetime64), got {date!r:.60}") from exc
    if np.isnat(d):
        raise ProblemError("asterix.read date: NaT is not a date")
    return d.astype("datetime64[ns]")


def read_asterix(paths: str | Path | Iterable[str | Path], *, date: Any = None,
                 editions: dict[int, tuple[int, int]] | None = None,
                 check: str = "layouts") -> AsterixData:
    """Read CAT048 and CAT021 records of one or more ASTERIX files (raw datablocks, as
    recorded: no pcap or final-format headers). Other categories are skipped (counted in
    ``records``).

    Parameters
    ----------
    paths
        One file or several; they are read in the given order.
    date
        UTC date of the first record of the first file (``"YYYY-MM-DD"``,
        ``datetime.date``, ``numpy.datetime64``). ASTERIX carries only the time of day
        (I048/140, I021/073, I021/071, s since UTC midnight, LSB 1/128 s): the times of
        each category in each file are unwrapped in file order (a step back of more than
        12 h is a new day: ``numpy.unwrap`` with period 86 400 s), and each such sequence
        after the first is put on the day that brings its first time within 12 h of the
        first sequence's first time (so a recording must not pause for 12 h or more).
        ``time`` counts from midnight of ``date`` (``AsterixData.epoch``); without a date
        it counts from midnight of the (unknown) first day and ``epoch`` is None.
    editions
        Category → (major, minor) edition to read, default :data:`EDITIONS` (CAT048 1.32,
        CAT021 2.7; libasterix ships CAT048 1.27-1.32, CAT021 0.23-2.7; the CAT021 0.2x
        editions have another position item and are not read).
    check
        ``"layouts"`` (default): the first record of each FSPEC layout is also parsed by
        libasterix and must agree; ``"all"``: every record is (slow).

    Raises
    ------
    ProblemError
        Naming the file and the byte offset: a missing or unreadable file, a file that
        is not ASTERIX, a truncated datablock or record, a record libasterix refuses.
    """
    from optmodels.io.paths import input_file

    check = as_choice("asterix.read check", check, ("layouts", "all"))
    epoch = _as_date(date)
    layouts = {c: _Layout(_spec(c, editions)) for c in (48, 21)}
    if isinstance(paths, str | Path):
        paths = [paths]
    files = [input_file(p, what="recording (ASTERIX)", name="asterix.read paths")
             for p in paths]
    if not files:
        raise ProblemError("asterix.read paths: no file given")
    counts: dict[int, int] = {48: 0, 21: 0}
    skipped: dict[int, int] = {}
    rows_of = {48: _cat048, 21: _cat021}
    per_cat: dict[int, list[dict[str, np.ndarray]]] = {48: [], 21: []}
    t_first: float | None = None
    dropped: dict[str, int] = {}
    for k, path in enumerate(files):
        buf = _map(path)
        if len(buf) and not is_asterix(path, editions=editions):
            raise ProblemError(f"asterix.read {path}: not ASTERIX (byte 0: CAT "
                               f"{buf[0]}, the datablock lengths do not chain or the first "
                               "record does not parse)")
        arr = np.frombuffer(buf, dtype=np.uint8) if len(buf) else np.zeros(0, np.uint8)
        last: dict[int, float | None] = {48: None, 21: None}
        for framed in _frame(buf, str(path), layouts, check, skipped):
            for cat, (recs, flat) in framed.items():
                lay = layouts[cat]
                counts[cat] += len(recs)
                offs = np.frombuffer(flat, dtype=np.int64).reshape(-1, len(lay.items)) \
                    if len(flat) else np.zeros((0, len(lay.items)), np.int64)
                cols: dict[str, Any] = {}
                for f in lay.fields:
                    cols[f.name] = (*_gather(arr, offs[:, lay.slot[f.item]], f), f.scale)
                del offs, flat
                # the kept rows in SI now (the chunk's raw columns are freed)
                rows = rows_of[cat](k, np.array(recs, dtype=np.int64), cols, dropped)
                del cols
                tod = rows["time"]
                if tod.size:
                    # unwrap this file's times of day of this category in file order,
                    # continuing from the previous chunk; a new sequence is put on the
                    # day closest to the first sequence's start
                    if last[cat] is None:
                        u = np.unwrap(tod, period=DAY)
                        if t_first is None:
                            t_first = float(u[0])
                        else:
                            u = u + DAY * np.round((t_first - u[0]) / DAY)
                    else:
                        u = np.unwrap(np.concatenate([[last[cat]], tod]), period=DAY)[1:]
                    rows["time"] = u
                    last[cat] = float(u[-1])
                per_cat[cat].append(rows)
        del arr
    cat048 = Cat048Reports(**_join(per_cat[48], Cat048Reports))
    cat021 = Cat021Reports(**_join(per_cat[21], Cat021Reports))
    return AsterixData(cat048, cat021, epoch, tuple(str(p) for p in files),
                       dict(sorted(counts.items())), dropped, dict(sorted(skipped.items())))


def _join(parts: list[dict[str, np.ndarray]], cls: type | None = None
          ) -> dict[str, np.ndarray]:
    """Column-wise concatenation (no copy for a single part); empty tables typed."""
    if len(parts) == 1:
        return parts[0]
    if parts:  # column by column, freeing the parts' columns as it goes (peak: + 1 column)
        out = {}
        for name in list(parts[0]):
            out[name] = np.concatenate([p.pop(name) for p in parts])
        return out
    assert cls is not None
    ints = ("sac", "sic", "address", "mode3a", "offset", "file")
    return {name: np.zeros(0, np.int64 if name in ints else float)
            for name in cls.__dataclass_fields__}


def _map(path: Path) -> Any:
    """The file's bytes, memory-mapped read-only (empty files: ``b""``)."""
    try:
        with open(path, "rb") as fh:
            if fh.seek(0, 2) == 0:
                return b""
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as exc:
        raise ProblemError(f"{path}: cannot read the recording (ASTERIX) "
                           f"({exc.strerror or exc})") from None


def _tod(cat: int, cols: dict[str, Any], n: int) -> np.ndarray:
    names = ("tod",) if cat == 48 else ("t073", "t071")
    t = np.full(n, np.nan)
    for nm in reversed(names):
        if nm in cols:
            raw, have, scale = cols[nm]
            t = np.where(have, raw * scale, t)
    return t


def _val(cols: dict[str, Any], name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    if name not in cols:
        return np.full(n, np.nan), np.zeros(n, bool)
    raw, have, scale = cols[name]
    return np.where(have, raw * scale, np.nan), have


def _int(cols: dict[str, Any], name: str, n: int) -> np.ndarray:
    if name not in cols:
        return np.full(n, -1, np.int64)
    raw, have, _ = cols[name]
    return np.where(have, raw, -1)


def _count(dropped: dict[str, int], reason: str, mask: np.ndarray) -> None:
    if mask.any():
        dropped[reason] = dropped.get(reason, 0) + int(mask.sum())


def _cat048(k: int, recs: np.ndarray, cols: dict[str, Any],
            dropped: dict[str, int]) -> dict[str, np.ndarray]:
    """The kept CAT048 rows of one chunk in SI (``time``: the time of day, unwrapped
    later); drops counted."""
    n = recs.size
    sac = _int(cols, "sac", n)
    t = _tod(48, cols, n)
    rng, have_r = _val(cols, "rho", n)
    keep = (sac >= 0) & have_r & np.isfinite(t)
    _count(dropped, "cat048 no I010 (SAC/SIC)", sac < 0)
    _count(dropped, "cat048 no I140 (time)", ~np.isfinite(t))
    _count(dropped, "cat048 no I040 (polar position)", ~have_r)
    fl, have_fl = _val(cols, "fl", n)
    bad_fl = (_int(cols, "fl_v", n) == 1) | (_int(cols, "fl_g", n) == 1)
    _count(dropped, "cat048 I090 not validated or garbled (flight level unused)",
           bad_fl & have_fl & keep)
    fl[bad_fl] = np.nan
    sel = slice(None) if keep.all() else keep
    out = {"time": t[sel], "sac": sac[sel], "sic": _int(cols, "sic", n)[sel],
           "range": rng[sel], "azimuth": _val(cols, "theta", n)[0][sel],
           "pressure_altitude": fl[sel], "address": _int(cols, "address", n)[sel],
           "mode3a": _int(cols, "mode3a", n)[sel], "offset": recs[sel]}
    out["file"] = np.full(out["time"].size, k, np.int64)
    return out


def _cat021(k: int, recs: np.ndarray, cols: dict[str, Any],
            dropped: dict[str, int]) -> dict[str, np.ndarray]:
    """The kept CAT021 rows of one chunk in SI (``time``: the time of day)."""
    n = recs.size
    lat_hi, have_hi = _val(cols, "lat_hi", n)
    lat_lo, have_lo = _val(cols, "lat_lo", n)
    t = _tod(21, cols, n)
    have_pos = have_hi | have_lo
    keep = have_pos & np.isfinite(t)
    _count(dropped, "cat021 no I073/I071 (time)", ~np.isfinite(t))
    _count(dropped, "cat021 no I131/I130 (position)", ~have_pos)
    sel = slice(None) if keep.all() else keep
    deg = 180.0 / math.pi
    lat = np.where(have_hi, lat_hi, lat_lo)[sel] * deg
    lon = np.where(have_hi, _val(cols, "lon_hi", n)[0], _val(cols, "lon_lo", n)[0])[sel] * deg
    out = {"time": t[sel], "sac": _int(cols, "sac", n)[sel],
           "sic": _int(cols, "sic", n)[sel], "latitude": lat, "longitude": lon,
           "height": _val(cols, "gh", n)[0][sel],
           "pressure_altitude": _val(cols, "fl", n)[0][sel],
           "address": _int(cols, "address", n)[sel], "offset": recs[sel]}
    out["file"] = np.full(out["time"].size, k, np.int64)
    return out


# ---------------------------------------------------------------------------------------
# Encoding (libasterix)
# ---------------------------------------------------------------------------------------

def _blocks(spec: Any, records: list[Any], per_block: int) -> bytes:
    per_block = as_count("asterix.encode per_block", per_block, minimum=1)
    return b"".join(spec.create(records[i:i + per_block]).unparse().to_bytes()
                    for i in range(0, len(records), per_block))


def _cols(fn: str, **arrays: Any) -> dict[str, np.ndarray]:
    """Numeric 1-D (or scalar) columns of one length; NaN allowed only where it means
    "item absent" (``flight_level``, ``height``)."""
    out: dict[str, np.ndarray] = {}
    for name, v in arrays.items():
        if v is None:
            continue
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ProblemError(f"asterix.{fn} {name}: expected numbers, got "
                               f"{type(v).__name__}") from exc
        if a.ndim > 1:
            raise ProblemError(f"asterix.{fn} {name}: expected one value per record, got "
                               f"shape {a.shape}")
        bad = ~np.isfinite(a) if name not in ("flight_level", "height") else np.isinf(a)
        if bad.any():
            raise ProblemError(f"asterix.{fn} {name}: {int(bad.sum())} non-finite values")
        out[name] = a
    n = max((a.size for a in out.values() if a.ndim == 1), default=1)
    for name, a in out.items():
        if a.ndim == 0:
            out[name] = np.broadcast_to(a, (n,))
        elif a.shape != (n,):
            raise ProblemError(f"asterix.{fn} {name}: expected {n} values, got {a.shape}")
    return out


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
            raise ProblemError(f"asterix.{fn} {name}: need integers 0-{top}, got "
                               f"{v[bad][0]!r}")


def encode_cat048(time_of_day: Any, sac: Any, sic: Any, range: Any, azimuth: Any, *,
                  flight_level: Any = None, address: Any = None, mode3a: Any = None,
                  per_block: int = 20, edition: tuple[int, int] = EDITIONS[48]) -> bytes:
    """CAT048 datablocks through libasterix (``per_block`` records each).

    ``time_of_day`` s since UTC midnight (I140, wrapped into [0, 86400)), ``range`` slant
    range m (I040 RHO, < 256 NM), ``azimuth`` rad clockwise from the radar's north (I040
    THETA, wrapped into [0, 2π)), ``flight_level`` in FL (I090; NaN: item absent),
    ``address`` 24-bit int (I220; < 0: absent), ``mode3a`` 12-bit int (I070; < 0: absent).
    Values are rounded to the format's LSB by libasterix. Every record also carries I020
    (target report descriptor: single Mode S roll-call, an extended item).
    """
    c = _cols("encode_cat048", time_of_day=time_of_day, sac=sac, sic=sic, range=range,
              azimuth=azimuth, flight_level=flight_level, address=address, mode3a=mode3a)
    _ints("encode_cat048", c, {"sac": 255, "sic": 255, "address": 2**24 - 1,
                                "mode3a": 4095})
    if np.any(c["range"] < 0) or np.any(c["range"] >= 256 * NM):
        raise ProblemError("asterix.encode_cat048 range: need 0 ≤ range < 256 NM "
                           "(474 112 m)")
    spec = _spec(48, {48: edition})
    tod = np.mod(c["time_of_day"], DAY)
    az = np.degrees(np.mod(c["azimuth"], 2 * math.pi))
    recs = []
    for i in np.arange(tod.size):
        items: dict[str, Any] = {
            "010": (("SAC", int(c["sac"][i])), ("SIC", int(c["sic"][i]))),
            "140": (float(tod[i]), "s"),
            "020": ((5, 0, 0, 0, 0, 0),),
            "040": (("RHO", (float(c["range"][i]) / NM, "NM")),
                    ("THETA", (float(az[i]), "°"))),
        }
        if "mode3a" in c and c["mode3a"][i] >= 0:
            items["070"] = (0, 0, 0, 0, ("MODE3A", f"{int(c['mode3a'][i]):04o}"))
        if "flight_level" in c and np.isfinite(c["flight_level"][i]):
            items["090"] = (0, 0, ("FL", (float(c["flight_level"][i]), "FL")))
        if "address" in c and c["address"][i] >= 0:
            items["220"] = int(c["address"][i])
        recs.append(spec.cv_record.create(items))
    return _blocks(spec, recs, per_block)


def encode_cat021(time_of_day: Any, sac: Any, sic: Any, latitude: Any, longitude: Any, *,
                  height: Any = None, flight_level: Any = None, address: Any = None,
                  high_resolution: bool = True, per_block: int = 20,
                  edition: tuple[int, int] = EDITIONS[21]) -> bytes:
    """CAT021 datablocks through libasterix.

    ``time_of_day`` s (I073 time of message reception for position), ``latitude`` /
    ``longitude`` deg WGS-84 (I131 if ``high_resolution`` else I130), ``height`` m above
    the ellipsoid (I140 geometric height, LSB 6.25 ft; NaN: absent), ``flight_level`` FL
    (I145; NaN: absent), ``address`` (I080; < 0: absent). Every record carries I040
    (target report descriptor, extended).
    """
    c = _cols("encode_cat021", time_of_day=time_of_day, sac=sac, sic=sic, latitude=latitude,
              longitude=longitude, height=height, flight_level=flight_level, address=address)
    _ints("encode_cat021", c, {"sac": 255, "sic": 255, "address": 2**24 - 1})
    if np.any(np.abs(c["latitude"]) > 90) or np.any(np.abs(c["longitude"]) > 180):
        raise ProblemError("asterix.encode_cat021 latitude/longitude: need |lat| ≤ 90°, "
                           "|lon| ≤ 180°")
    spec = _spec(21, {21: edition})
    tod = np.mod(c["time_of_day"], DAY)
    pos_item = "131" if as_flag("asterix.encode_cat021 high_resolution",
                                high_resolution) else "130"
    recs = []
    for i in np.arange(tod.size):
        items: dict[str, Any] = {
            "010": (("SAC", int(c["sac"][i])), ("SIC", int(c["sic"][i]))),
            "040": ((0, 0, 0, 0, 0),),
            "073": (float(tod[i]), "s"),
            pos_item: (("LAT", (float(c["latitude"][i]), "°")),
                       ("LON", (float(c["longitude"][i]), "°"))),
        }
        if "height" in c and np.isfinite(c["height"][i]):
            items["140"] = (float(c["height"][i]) / FT, "ft")
        if "flight_level" in c and np.isfinite(c["flight_level"][i]):
            items["145"] = (float(c["flight_level"][i]), "FL")
        if "address" in c and c["address"][i] >= 0:
            items["080"] = int(c["address"][i])
        recs.append(spec.cv_record.create(items))
    return _blocks(spec, recs, per_block)
