"""Datablocks and records of one ASTERIX byte stream: content detection, framing with a
per-FSPEC layout cache, the libasterix cross-check and the NumPy field gather."""

from __future__ import annotations

from array import array
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import ProblemError, as_count
from optmodels.io.asterix.capture import capture_kind
from optmodels.io.asterix.layout import (
    _FIELDS,
    _Bad,
    _Field,
    _Layout,
    _lib,
    _spec,
    as_editions,
)


def is_asterix(
    path: str | Path, *, blocks: int = 4, editions: dict[int, tuple[int, int]] | None = None
) -> bool:
    """Whether a file's content is an ASTERIX recording.

    Raw datablocks: the first ``blocks`` datablocks (CAT byte, LEN ≥ 4 bytes) chain exactly
    (or to the end of the file), every CAT is one libasterix knows, and the first record of
    the first CAT048/CAT021 block parses strictly with libasterix in the ``editions`` given
    (default :data:`EDITIONS`; a file cut inside a later block still counts:
    :func:`read_asterix` then reports the truncation). A pcap/pcapng capture (detected by
    its magic number): its first UDP payloads that are whole datablocks pass the same test.
    Reads at most 256 KiB (a capture: its first 64 ASTERIX datagrams); whatever the
    content of a readable file (empty, text, damaged), the answer is True or False.

    Raises
    ------
    ProblemError
        For a ``path`` that is not a path or not a readable file (missing, a folder: a
        question about content that has no answer, refused rather than answered False),
        a bad ``blocks`` or ``editions``.
    """
    from optmodels.io.asterix.capture import read_capture
    from optmodels.io.paths import input_file

    blocks = as_count("asterix.is_asterix blocks", blocks, minimum=1)
    editions = as_editions("asterix.is_asterix editions", editions)
    p = input_file(path, what="recording (ASTERIX)", name="asterix.is_asterix path")
    try:
        with open(p, "rb") as fh:
            head = fh.read(1 << 18)
            size = fh.seek(0, 2)
    except OSError:
        return False
    if capture_kind(head):
        try:
            cap = read_capture(p, limit=64)
        except (ProblemError, OSError):
            return False
        return is_asterix_bytes(cap.stream, len(cap.stream), blocks, editions)
    return is_asterix_bytes(head, size, blocks, editions)


def is_asterix_bytes(
    head: bytes, size: int, blocks: int, editions: dict[int, tuple[int, int]] | None
) -> bool:
    """The test of :func:`is_asterix` on the first bytes ``head`` of a stream of ``size``
    bytes."""
    if len(head) < 4 or head[:4] == b"PAR1" or head[:2] == b"PK":
        return False
    # framing first (cheap, no library import): CSV/Parquet/text fail here
    pos = 0
    found: list[tuple[int, int, int]] = []  # (category, offset, length) of each block
    while pos < len(head) and len(found) < blocks:
        if pos + 3 > len(head):
            break
        cat, n = head[pos], int.from_bytes(head[pos + 1 : pos + 3], "big")
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
            res = rec.parse(
                base.ParsingMode.StrictParsing, base.Bits(head, 8 * (pos + 3), 8 * (pos + n))
            )
            return not isinstance(res, ValueError)
    return True


#: the binary formats the package reads, for the refusals of the text readers
BINARY_ACCEPTED = (
    "accepted binary inputs: ASTERIX recordings (raw CAT048/CAT021 "
    "datablocks, pcap/pcapng captures of ASTERIX over UDP) where plots are "
    "read, Parquet (.parquet), NumPy .npz/.npy"
)


def describe_binary(data: bytes) -> str | None:
    """For the text readers: what binary bytes are, if they look like a recording (a
    capture, or ASTERIX damaged from its first datablock on), else None."""
    kind = capture_kind(data)
    if kind:
        return (
            f"a {kind} capture without readable ASTERIX over UDP (a capture is read "
            "as a recording when its UDP payloads are ASTERIX datablocks), not text"
        )
    why = diagnose(data)
    return None if why is None else f"damaged ASTERIX recording: {why}"


def diagnose(data: bytes) -> str | None:
    """What is wrong with bytes that start like an ASTERIX recording (a CAT byte
    libasterix knows, a datablock LEN ≥ 3, binary), or None if they do not: the framing's
    first error with its byte offset, e.g. for a damaged first datablock."""
    if len(data) < 3 or capture_kind(data):
        return None
    try:
        _, gen = _lib()
    except ProblemError:
        return None
    n = int.from_bytes(data[1:3], "big")
    if data[0] not in gen.manifest["CATS"] or n < 3 or b"\x00" not in data[:4096]:
        return None
    layouts = {c: _Layout(_spec(c, None)) for c in (48, 21)}
    try:
        for _ in _frame(data, "recording", layouts, "all", {}, limit=64):
            pass
    except ProblemError as exc:
        return str(exc).replace("asterix.read recording: ", "")
    return None


#: records framed before their fields are gathered (bounds the framing's memory:
#: 8 bytes per record and per item read, ~56 MB per chunk for CAT048)
CHUNK = 1 << 20


def _frame(
    buf: Any,
    name: str,
    layouts: dict[int, _Layout],
    check: str,
    skipped: dict[int, int],
    *,
    limit: int | None = None,
) -> Iterator[dict[int, tuple[Any, Any]]]:
    """Walk the datablocks and records of one file (bytes or a read-only mmap); yield,
    every :data:`CHUNK` records and at the end, per category the record offsets and the
    flat item offsets (−1 absent), ``len(layout.items)`` per record (``array('q')``).
    Datablocks of other categories are counted in ``skipped``; ``limit``: stop after that
    many datablocks."""
    _lib()  # the library is needed for the layout check
    out: dict[int, tuple[Any, Any]] = {c: (array("q"), array("q")) for c in layouts}
    pos, size = 0, len(buf)
    validated: set[tuple[int, bytes]] = set()
    nblocks = 0
    while pos < size and (limit is None or nblocks < limit):
        nblocks += 1
        if pos + 3 > size:
            raise ProblemError(
                f"asterix.read {name}: truncated datablock header at byte "
                f"{pos} ({size - pos} bytes left)"
            )
        cat, n = buf[pos], int.from_bytes(buf[pos + 1 : pos + 3], "big")
        if n < 3:
            raise ProblemError(
                f"asterix.read {name}: not ASTERIX or corrupt: datablock at "
                f"byte {pos} has length {n} (< 3)"
            )
        end = pos + n
        if end > size:
            raise ProblemError(
                f"asterix.read {name}: truncated: the CAT{cat:03d} datablock "
                f"at byte {pos} announces {n} bytes, {size - pos} left"
            )
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
            raise ProblemError(
                f"asterix.read {name}: corrupt CAT{cat:03d} record at byte {r0}: {exc}"
            ) from None
        except IndexError:
            raise ProblemError(
                f"asterix.read {name}: truncated CAT{cat:03d} record at byte "
                f"{r0} (file ends at byte {size})"
            ) from None
        pos = end
        if sum(len(r) for r, _ in out.values()) >= CHUNK:
            yield out
            out = {c: (array("q"), array("q")) for c in layouts}
    yield out


def _validate(
    buf: bytes, r0: int, q: int, end: int, lay: _Layout, offs: list[int], name: str
) -> None:
    """libasterix's strict parse of the record at ``r0`` must end at ``q`` and give the
    same raw value of every field read here."""
    base, _ = _lib()
    chunk = bytes(buf[r0:end])
    res = lay.record.parse(base.ParsingMode.StrictParsing, base.Bits(chunk, 0, 8 * len(chunk)))
    if isinstance(res, ValueError):
        raise _Bad(f"libasterix refuses it ({res})")
    rec, rest = res
    if rest.bit_offset1 != 8 * (q - r0):
        raise _Bad(f"libasterix ends it at byte {r0 + rest.bit_offset1 // 8}, the framing at {q}")
    for f in lay.fields:
        item = rec.get_item(f.item)
        o = offs[lay.slot[f.item]]
        if (item is None) != (o < 0):
            raise _Bad(f"I{f.item} presence differs from libasterix")
        if item is None:
            continue
        node = item if len(f.path) == 1 else item.variation.get_item(f.path[1])
        lib_raw = node.unparse().to_uinteger() if len(f.path) > 1 else item.unparse().to_uinteger()
        mine = _raw_at(buf, o, f)
        if int(lib_raw) != mine:
            raise _Bad(
                f"I{f.item} {'/'.join(f.path[1:])}: raw {mine} here, {lib_raw} by libasterix"
            )


def _raw_at(buf: bytes, o: int, f: _Field) -> int:
    nb = (f.offset + f.size + 7) // 8
    v = int.from_bytes(buf[o : o + nb], "big")
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
