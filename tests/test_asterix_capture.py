"""pcap / pcapng captures of ASTERIX over UDP (issue 24 item 5): the tests write their own
captures with dpkt (Ethernet / IPv4 / UDP, one to three datablocks a datagram, other traffic
mixed in) and read them back as the raw recording reads; the capture's date places the
times of day."""

from __future__ import annotations

import datetime as dt

import dpkt  # the 'recordings' extra (in the 'test' extra too)
import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax
from optmodels.io import read_text

DAY = 86400.0
LSB = 1 / 128
MIDNIGHT = dt.datetime(2026, 6, 1, tzinfo=dt.UTC).timestamp()  # POSIX s of the date


def _blocks(data: bytes) -> list[bytes]:
    out, pos = [], 0
    while pos < len(data):
        n = int.from_bytes(data[pos + 1 : pos + 3], "big")
        out.append(data[pos : pos + n])
        pos += n
    return out


def _frame(payload: bytes, *, proto: str = "udp") -> bytes:
    if proto == "udp":
        l4 = dpkt.udp.UDP(sport=40000, dport=8600, data=payload)
        l4.ulen = len(l4)
        p = dpkt.ip.IP_PROTO_UDP
    else:
        l4 = dpkt.tcp.TCP(sport=40000, dport=80, data=payload)
        p = dpkt.ip.IP_PROTO_TCP
    ip = dpkt.ip.IP(src=bytes([10, 0, 0, 1]), dst=bytes([239, 0, 0, 1]), p=p, data=l4)
    ip.len = len(ip)
    return bytes(
        dpkt.ethernet.Ethernet(
            src=b"\x02" * 6,
            dst=b"\x01\x00\x5e\x00\x00\x01",
            type=dpkt.ethernet.ETH_TYPE_IP,
            data=ip,
        )
    )


def _write(path, datagrams: list[tuple[float, bytes]], kind: str, rng: np.random.Generator) -> None:
    with open(path, "wb") as fh:
        w = (dpkt.pcapng.Writer if kind == "pcapng" else dpkt.pcap.Writer)(fh, snaplen=65535)
        for ts, payload in datagrams:
            w.writepkt(_frame(payload), ts=ts)
            if rng.random() < 0.2:  # other traffic on the link
                w.writepkt(_frame(b"\x12\x34\x01\x00 DNS-like"), ts=ts)
                w.writepkt(_frame(b"GET / HTTP/1.1\r\n", proto="tcp"), ts=ts)


def _traffic(rng: np.random.Generator, t0: float, n: int) -> tuple[bytes, np.ndarray, list]:
    """CAT048 of two radars and CAT021, true times from ``t0`` (s from MIDNIGHT, may pass
    a midnight); the datagrams (capture time = report time + 50 ms) and the raw stream."""
    t = t0 + 0.25 * np.arange(n)
    data = [
        ax.encode_cat048(
            t,
            1,
            s,
            rng.uniform(1e3, 3e5, n),
            rng.uniform(0, 6.28, n),
            address=rng.integers(0, 2**24, n),
            per_block=4,
        )
        for s in (1, 2)
    ]
    data.append(
        ax.encode_cat021(t, 9, 1, rng.uniform(40, 50, n), rng.uniform(10, 20, n), per_block=4)
    )
    grams, raw = [], []
    blocks = [b for d in data for b in _blocks(d)]
    first = [t[4 * k] for d in data for k in range(len(_blocks(d)))]
    order = np.argsort(first, kind="stable")
    k = 0
    while k < len(order):
        m = int(rng.integers(1, 4))
        chunk = b"".join(blocks[j] for j in order[k : k + m])
        grams.append((MIDNIGHT + first[order[k]] + 0.05, chunk))
        raw.append(chunk)
        k += m
    return b"".join(raw), t, grams


@pytest.mark.parametrize("kind", ["pcap", "pcapng"])
def test_capture_reads_as_the_raw_recording(tmp_path, kind: str) -> None:
    rng = np.random.default_rng(2405)
    raw, t, grams = _traffic(rng, 3600.0 * 9, 400)
    cap, rawf = tmp_path / f"rec.{kind}", tmp_path / "rec.ast"
    _write(cap, grams, kind, rng)
    rawf.write_bytes(raw)
    assert ax.is_asterix(cap)
    d, r = ax.read_asterix(cap), ax.read_asterix(rawf, date="2026-06-01")
    assert d.epoch == np.datetime64("2026-06-01", "ns")  # the capture's own date
    assert d.records == r.records == {21: 400, 48: 800}
    for name in ("time", "sac", "sic", "range", "azimuth", "address", "offset"):
        np.testing.assert_array_equal(getattr(d.cat048, name), getattr(r.cat048, name))
    np.testing.assert_array_equal(d.cat021.latitude, r.cat021.latitude)
    for s in (1, 2):
        assert np.max(np.abs(d.cat048.time[d.cat048.sic == s] - t)) <= LSB / 2 + 1e-9
    n_other = d.captures.get("UDP datagram not ASTERIX", 0)
    assert d.captures["ASTERIX datagrams"] == len(grams)
    assert n_other == d.captures.get("not UDP", 0) > 0


def test_capture_dates_place_files_a_raw_recording_could_not(tmp_path) -> None:
    """Captures at 01:00 and 20:00 of one day and 05:00 of the next: a raw recording with
    a 19 h pause cannot be placed (refused); the captures' dates place it."""
    rng = np.random.default_rng(2406)
    paths, raws, want = [], [], []
    for j, t0 in enumerate((3600.0, 72000.0, DAY + 18000.0)):
        raw, t, grams = _traffic(rng, t0, 40)
        p = tmp_path / f"c{j}.pcap"
        _write(p, grams, "pcap", rng)
        paths.append(p)
        q = tmp_path / f"c{j}.ast"
        q.write_bytes(raw)
        raws.append(q)
        want.append(t)
    d = ax.read_asterix(paths)
    c = d.cat048
    for j, t in enumerate(want):
        got = c.time[(c.file == j) & (c.sic == 1)]
        assert np.max(np.abs(got - t)) <= LSB / 2 + 1e-9
    assert d.epoch == np.datetime64("2026-06-01", "ns")
    # with a date given, the same
    d2 = ax.read_asterix(paths, date="2026-06-01")
    np.testing.assert_array_equal(d2.cat048.time, c.time)
    with pytest.raises(ProblemError, match=r"c1\.ast: cannot place"):
        ax.read_asterix(raws[:2])


def test_capture_without_asterix_and_other_binary_refused(tmp_path) -> None:
    rng = np.random.default_rng(2407)
    p = tmp_path / "dns.pcap"
    with open(p, "wb") as fh:
        w = dpkt.pcap.Writer(fh)
        for k in range(5):
            w.writepkt(_frame(b"\x12\x34\x01\x00 no ASTERIX"), ts=MIDNIGHT + k)
    assert not ax.is_asterix(p)
    with pytest.raises(
        ProblemError,
        match=r"dns\.pcap: a pcap capture without ASTERIX "
        r"over UDP \(5 UDP datagram not ASTERIX\)",
    ):
        ax.read_asterix(p)
    junk = tmp_path / "junk.bin"
    junk.write_bytes(rng.integers(0, 256, 2048, dtype=np.uint8).tobytes())
    with pytest.raises(
        ProblemError,
        match=r"junk\.bin: not ASTERIX.*accepted: raw ASTERIX "
        r"datablocks.*pcap/pcapng",
    ):
        ax.read_asterix(junk)
    # a CSV reader given a capture says what it is, not only "binary data"
    with pytest.raises(ProblemError, match=r"dns\.pcap: a pcap capture"):
        read_text(p, what="plots CSV")
