"""ASTERIX record layouts from libasterix's specification classes: each UAP item's size
(fixed, or a function of the bytes for Extended/Repetitive/Explicit/Compound items) and the
bit offset, width, sign and LSB of every field read or written."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from optmodels.core import ProblemError

NM = 1852.0  # m per nautical mile (exact)
FT = 0.3048  # m per foot (exact)
FL = 100.0 * FT  # m of pressure altitude per flight level
DAY = 86400.0  # s
#: default editions read and written (category → (major, minor)); any edition libasterix
#: ships can be asked for through ``editions=``.
EDITIONS: dict[int, tuple[int, int]] = {48: (1, 32), 21: (2, 7)}
_UNITS = {"NM": NM, "°": math.pi / 180.0, "ft": FT, "FL": FL, "s": 1.0}


def _lib() -> tuple[Any, Any]:
    try:
        import asterix.base as base
        import asterix.generated as gen
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ProblemError(
            "asterix: reading ASTERIX needs the libasterix package (pip install 'libasterix>=0.36')"
        ) from exc
    if not hasattr(gen, "manifest"):  # pragma: no cover - the C++ asterix-decoder
        raise ProblemError(
            "asterix: the installed module 'asterix' is not libasterix "
            "(asterix-decoder installs the same name); install libasterix"
        )
    return base, gen


def _spec(cat: int, editions: dict[int, tuple[int, int]] | None) -> Any:
    _, gen = _lib()
    ed = {**EDITIONS, **(editions or {})}.get(cat)
    for s in gen.manifest["CATS"].get(cat, []):
        if s.cv_edition == tuple(ed or ()):
            return s
    known = [s.cv_edition for s in gen.manifest["CATS"].get(cat, [])]
    raise ProblemError(
        f"asterix editions: CAT{cat:03d} edition {ed} is not in libasterix (known: {known})"
    )


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

            def extended(
                buf: bytes, q: int, _n: list[int] = nbytes, _fx: list[bool] = fx_ends
            ) -> int:
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
                return _rb + _e * int.from_bytes(buf[q : q + _rb], "big")

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

        # per sub-FSPEC: the size of its fixed subitems, and the sizers of all its subitems
        # in order when one of them is variable (None: all fixed)
        memo: dict[bytes, tuple[int, list[Sizer] | None]] = {}

        def compound(
            buf: bytes,
            q: int,
            _subs: list[Sizer | None] = subs,
            _memo: dict[bytes, tuple[int, list[Sizer] | None]] = memo,
        ) -> int:
            p = q
            while buf[p] & 1:
                p += 1
            p += 1
            fs = buf[q:p]
            hit = _memo.get(fs)
            if hit is None:  # sub-FSPEC seen first: its subitems' sizers
                present = [
                    7 * k + bit for k, b in enumerate(fs) for bit in range(7) if b & (0x80 >> bit)
                ]
                sizers: list[Sizer] = []
                for frn in present:
                    sz = _subs[frn] if frn < len(_subs) else None
                    if sz is None:
                        raise _Bad(f"compound subfield {frn + 1} not in the specification")
                    sizers.append(sz)
                fixed = sum(s for s in sizers if isinstance(s, int))
                variable = any(not isinstance(s, int) for s in sizers)
                hit = _memo[bytes(fs)] = (fixed, sizers if variable else None)
            # all subitems fixed: the size is known from the sub-FSPEC alone; else walk
            # them (a variable subitem is sized at its own offset)
            fixed, walk = hit
            if walk is None:
                return p - q + fixed
            for sz in walk:
                p += sz if isinstance(sz, int) else sz(buf, p)
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
        chunk = bytes(buf[q : q + 65536])  # an item never exceeds its datablock
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
    offset: int  # bit offset inside the item
    size: int  # bits
    signed: bool
    scale: float  # raw → SI
    path: tuple[str, ...]
    lsb: float = 1.0  # raw → the specification's unit (``unit``)
    unit: str = ""


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
    scale, signed, lsb, unit = 1.0, False, 1.0, ""
    if issubclass(content, base.ContentQuantity):
        lsb, unit = float(content.cv_lsb), str(content.cv_unit)
        scale = lsb * _UNITS[unit]
        signed = content.cv_signedness is base.Signed
    return _Field(name, path[0], off, var.cv_bit_size, signed, scale, path, lsb, unit)


_FIELDS = {
    48: {
        "sac": ("010", "SAC"),
        "sic": ("010", "SIC"),
        "tod": ("140",),
        "rho": ("040", "RHO"),
        "theta": ("040", "THETA"),
        "fl": ("090", "FL"),
        "fl_v": ("090", "V"),
        "fl_g": ("090", "G"),
        "address": ("220",),
        "mode3a": ("070", "MODE3A"),
    },
    21: {
        "sac": ("010", "SAC"),
        "sic": ("010", "SIC"),
        "t073": ("073",),
        "t071": ("071",),
        "lat_hi": ("131", "LAT"),
        "lon_hi": ("131", "LON"),
        "lat_lo": ("130", "LAT"),
        "lon_lo": ("130", "LON"),
        "gh": ("140",),
        "fl": ("145",),
        "address": ("080",),
    },
}


class _Layout:
    """Per category: the UAP sizers, the fields wanted and a cache FSPEC → plan."""

    def __init__(self, spec: Any) -> None:
        base, _ = _lib()
        if not issubclass(spec.cv_uap, base.UapSingle):
            raise ProblemError(
                f"asterix: CAT{spec.cv_category:03d} has several UAPs; not supported"
            )
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
        frns = [7 * k + bit for k, b in enumerate(fspec) for bit in range(7) if b & (0x80 >> bit)]
        sizes: list[Sizer] = []
        need: list[int] = []
        for frn in frns:
            name, s = self.uap[frn] if frn < len(self.uap) else (None, None)
            if name is None or s is None:
                raise _Bad(
                    f"FSPEC announces FRN {frn + 1}, which CAT"
                    f"{self.spec.cv_category:03d} edition {self.spec.cv_edition} "
                    "does not define"
                )
            sizes.append(s)
            need.append(self.slot.get(name, -1))
        out = (sizes, need)
        self.cache[fspec] = out
        return out


def as_edition(name: str, edition: Any) -> tuple[int, int]:
    """One edition checked: a (major, minor) pair of whole numbers (tuple or list)."""
    if not (
        isinstance(edition, tuple | list)
        and len(edition) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in edition)
    ):
        raise ProblemError(
            f"{name}: expected (major, minor) whole numbers, e.g. (1, 32), got "
            f"{type(edition).__name__} {edition!r:.40}"
        )
    return int(edition[0]), int(edition[1])


def as_editions(name: str, editions: Any) -> dict[int, tuple[int, int]] | None:
    """``editions`` checked: None or a dict category (int) → (major, minor) ints."""
    if editions is None:
        return None
    if not isinstance(editions, dict):
        raise ProblemError(
            f"{name}: expected a dict category → (major, minor), e.g. "
            f"{{48: (1, 32)}}, got {type(editions).__name__} {editions!r:.40}"
        )
    out: dict[int, tuple[int, int]] = {}
    for cat, ed in editions.items():
        if not isinstance(cat, int) or isinstance(cat, bool):
            raise ProblemError(
                f"{name}: expected category (int) → (major, minor) ints, got "
                f"{cat!r:.20}: {ed!r:.20}"
            )
        out[cat] = as_edition(f"{name}[{cat}]", ed)
    return out
