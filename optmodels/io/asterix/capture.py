"""pcap / pcapng captures of ASTERIX over UDP (issue 24 item 5), through *dpkt*.

A capture is read as the ASTERIX byte stream its UDP payloads make, in capture order: every
UDP datagram whose payload is a whole number of datablocks (the LEN fields chain exactly to
the end of the payload, every CAT one libasterix knows) is kept; other datagrams (another
protocol on the same link, an IP fragment, which dpkt does not reassemble) are counted and
left out. Each payload's capture time (UTC, POSIX s) goes with it, so that the reader can put
the ASTERIX times of day on the capture's own date.

Link layers read: Ethernet (with 802.1Q tags), Linux cooked (SLL, SLL2), raw IP, BSD
loopback; IPv4 and IPv6. The library (``pip install 'optmodels[recordings]'``, dpkt ≥ 1.9.8)
is imported only when a capture is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from optmodels.core import ProblemError

#: the first bytes of a pcap (µs or ns, either byte order) and of a pcapng file
PCAP_MAGIC = (b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d")
PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"


def capture_kind(head: bytes) -> str | None:
    """``"pcap"``, ``"pcapng"`` or None, from a file's first bytes."""
    if head[:4] in PCAP_MAGIC:
        return "pcap"
    if head[:4] == PCAPNG_MAGIC:
        return "pcapng"
    return None


@dataclass
class Capture:
    """The ASTERIX stream of one capture: ``stream`` (the kept UDP payloads, concatenated),
    ``starts`` (offset of each payload in ``stream``), ``times`` (its capture time, POSIX s
    UTC), ``counts`` (datagrams by outcome)."""

    kind: str
    stream: bytes
    starts: np.ndarray
    times: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)

    def time_of(self, offsets: np.ndarray) -> np.ndarray:
        """Capture time (POSIX s) of the payload holding each stream offset."""
        j = np.searchsorted(self.starts, offsets, side="right") - 1
        return self.times[np.maximum(j, 0)]


def _dpkt() -> Any:
    try:
        import dpkt
    except ImportError:  # pragma: no cover - depends on the installation
        raise ProblemError(
            "asterix: reading a pcap/pcapng capture needs dpkt "
            "(pip install 'optmodels[recordings]')"
        ) from None
    return dpkt


def _udp_payload(dpkt: Any, linktype: int, buf: bytes) -> tuple[bytes | None, str]:
    """The UDP payload of one captured frame, or None and why not."""
    try:
        if linktype == dpkt.pcap.DLT_EN10MB:
            pkt = dpkt.ethernet.Ethernet(buf).data
        elif linktype == dpkt.pcap.DLT_LINUX_SLL:
            pkt = dpkt.sll.SLL(buf).data
        elif linktype == dpkt.pcap.DLT_LINUX_SLL2:
            pkt = dpkt.sll2.SLL2(buf).data
        elif linktype in (dpkt.pcap.DLT_NULL, dpkt.pcap.DLT_LOOP):
            pkt = dpkt.loopback.Loopback(buf).data
        elif linktype in (dpkt.pcap.DLT_RAW, 12, 14):
            pkt = (dpkt.ip6.IP6 if buf and buf[0] >> 4 == 6 else dpkt.ip.IP)(buf)
        else:
            return None, f"link type {linktype} not read"
    except (dpkt.UnpackError, ValueError, IndexError):
        return None, "frame not decoded"
    if isinstance(pkt, dpkt.ip.IP):
        if pkt.mf or pkt.offset:
            return None, "IP fragment (not reassembled)"
    elif not isinstance(pkt, dpkt.ip6.IP6):
        return None, "not IP"
    udp = pkt.data
    if not isinstance(udp, dpkt.udp.UDP):
        return None, "not UDP"
    return bytes(udp.data), ""


def _chains(payload: bytes, cats: Any) -> bool:
    """Whether a payload is a whole number of datablocks of known categories."""
    pos, n = 0, len(payload)
    while pos < n:
        if pos + 3 > n:
            return False
        ln = int.from_bytes(payload[pos + 1 : pos + 3], "big")
        if ln < 3 or payload[pos] not in cats:
            return False
        pos += ln
    return pos == n and n > 0


def read_capture(path: Path, *, limit: int | None = None) -> Capture:
    """The ASTERIX stream of a pcap/pcapng file (``limit``: stop after that many kept
    payloads or 16 × that many packets, for content detection).

    Raises
    ------
    ProblemError
        Naming the file: not a capture dpkt reads (with dpkt's reason), a truncated capture.
    """
    from optmodels.io.asterix.layout import _lib

    dpkt = _dpkt()
    _, gen = _lib()
    cats = set(gen.manifest["CATS"])
    with open(path, "rb") as fh:
        kind = capture_kind(fh.read(4)) or "capture"
        fh.seek(0)
        try:
            reader = (dpkt.pcapng.Reader if kind == "pcapng" else dpkt.pcap.Reader)(fh)
        except (ValueError, dpkt.Error) as exc:
            raise ProblemError(
                f"asterix.read {path}: not a {kind} file dpkt reads ({exc})"
            ) from None
        linktype = int(reader.datalink())
        parts: list[bytes] = []
        starts: list[int] = []
        times: list[float] = []
        counts: dict[str, int] = {}
        pos = 0
        try:
            for ts, buf in reader:
                if limit is not None and sum(counts.values()) >= 16 * limit:
                    break
                payload, why = _udp_payload(dpkt, linktype, buf)
                if payload is not None and not _chains(payload, cats):
                    payload, why = None, "UDP datagram not ASTERIX"
                if payload is None:
                    counts[why] = counts.get(why, 0) + 1
                    continue
                counts["ASTERIX datagrams"] = counts.get("ASTERIX datagrams", 0) + 1
                parts.append(payload)
                starts.append(pos)
                times.append(float(ts))
                pos += len(payload)
                if limit is not None and len(parts) >= limit:
                    break
        except (ValueError, dpkt.Error, EOFError) as exc:
            raise ProblemError(
                f"asterix.read {path}: damaged {kind} capture after "
                f"{sum(counts.values())} packets ({exc})"
            ) from None
    return Capture(
        kind, b"".join(parts), np.asarray(starts, np.int64), np.asarray(times, float), counts
    )
