"""ASTERIX argument checks and diagnoses (issue 28 item 4): wrong argument types give one
ProblemError naming the argument (not TypeError), a damaged first datablock is diagnosed as
damaged ASTERIX with its byte offset (in the library and through the installed CLI, where
it used to read "expected a text plots CSV"), and a pcap capture is a recording for
``biasfield build``."""

from __future__ import annotations

from pathlib import Path

import dpkt
import numpy as np
import pytest

from optmodels.core import ProblemError
from optmodels.io import asterix as ax
from tests.test_cli import assert_error, run_many


@pytest.fixture()
def good(tmp_path: Path) -> Path:
    p = tmp_path / "good.ast"
    p.write_bytes(
        ax.encode_cat048(
            np.arange(30.0), 1, 2, np.full(30, 1e4), np.linspace(0, 6, 30), address=np.arange(30)
        )
    )
    return p


@pytest.mark.parametrize(
    ("call", "pattern"),
    [
        (lambda p: ax.read_asterix(None), r"asterix\.read paths: expected a file path"),
        (lambda p: ax.read_asterix([p, None]), r"asterix\.read paths: expected a file path"),
        (lambda p: ax.read_asterix(12), r"asterix\.read paths: expected a file path"),
        (
            lambda p: ax.read_asterix(p, editions="1.32"),
            r"asterix\.read editions: expected a "
            r"dict",
        ),
        (lambda p: ax.read_asterix(p, editions={48: "1.32"}), r"asterix\.read editions"),
        (lambda p: ax.read_asterix(p, date=12345), r"asterix\.read date: .*the number 12345"),
        (lambda p: ax.read_asterix(p, date=True), r"asterix\.read date"),
        (lambda p: ax.read_asterix(p, check=None), r"asterix\.read check"),
        (lambda p: ax.is_asterix(None), r"asterix\.is_asterix path: expected a file path"),
        (lambda p: ax.is_asterix(p, blocks=0), r"asterix\.is_asterix blocks"),
        (lambda p: ax.is_asterix(p, editions=[48]), r"asterix\.is_asterix editions"),
    ],
)
def test_argument_types_give_one_problem_error(good: Path, call, pattern: str) -> None:
    with pytest.raises(ProblemError, match=pattern):
        call(good)


def test_date_still_accepted_in_every_documented_form(good: Path) -> None:
    import datetime as dt

    for date in (
        "2026-03-01",
        dt.date(2026, 3, 1),
        dt.datetime(2026, 3, 1, 17, 5),
        np.datetime64("2026-03-01"),
    ):
        assert ax.read_asterix(good, date=date).epoch == np.datetime64("2026-03-01", "ns")


def _damaged(good: Path, tmp_path: Path) -> list[tuple[Path, str]]:
    data = bytearray(good.read_bytes())
    long_len = bytearray(data)
    long_len[1:3] = (5000).to_bytes(2, "big")  # first LEN beyond the file
    bad_fspec = bytearray(data)
    bad_fspec[3:6] = b"\xff\xff\xff"  # first FSPEC runs away
    out = []
    for name, b, why in (
        ("len.ast", long_len, "datablock at byte 0 announces 5000 bytes"),
        ("fspec.ast", bad_fspec, "record at byte 3"),
    ):
        p = tmp_path / name
        p.write_bytes(bytes(b))
        out.append((p, why))
    return out


def test_damaged_first_datablock_is_damaged_asterix(good: Path, tmp_path: Path) -> None:
    from optmodels.io import read_text

    for p, why in _damaged(good, tmp_path):
        assert not ax.is_asterix(p)
        with pytest.raises(ProblemError, match=rf"{p.name}: damaged ASTERIX: .*{why}"):
            ax.read_asterix(p)
        with pytest.raises(
            ProblemError,
            match=rf"{p.name}: damaged ASTERIX recording: "
            rf".*{why}",
        ):
            read_text(p, what="plots CSV")


def test_cli_damaged_asterix_and_pcap_recording(good: Path, tmp_path: Path) -> None:
    """The installed CLI: a damaged first datablock exits 2 naming damaged ASTERIX and the
    byte; the same recording in a pcap capture builds as the raw file does."""
    sites = tmp_path / "sites.csv"
    sites.write_text(
        "name,sac,sic,lat,lon,alt,sigma_range,sigma_azimuth,max_range\n"
        "A,1,2,45,15,100,30,0.05,400000\nB,1,3,45.5,15.5,100,30,0.05,400000\n"
    )
    cap = tmp_path / "good.pcap"
    with open(cap, "wb") as fh:
        w = dpkt.pcap.Writer(fh, snaplen=65535)
        udp = dpkt.udp.UDP(sport=1, dport=2, data=good.read_bytes())
        udp.ulen = len(udp)
        ip = dpkt.ip.IP(src=b"\x0a\0\0\1", dst=b"\x0a\0\0\2", p=dpkt.ip.IP_PROTO_UDP, data=udp)
        ip.len = len(ip)
        w.writepkt(
            bytes(dpkt.ethernet.Ethernet(data=ip, type=dpkt.ethernet.ETH_TYPE_IP)),
            ts=1_780_000_000.0,
        )
    (p1, why1), (p2, _) = _damaged(good, tmp_path)
    runs = run_many(
        [
            [
                "biasfield",
                "build",
                p,
                "--radars",
                sites,
                "--out",
                tmp_path / f"{p.stem}.npz",
                "--json",
            ]
            for p in (p1, p2)
        ],
        expect=None,
    )
    for r, p in zip(runs, (p1, p2), strict=True):
        assert_error(r, 2, p.name, "damaged ASTERIX")
    assert why1 in runs[0].err
    # a pcap: detected from content, read as the raw recording (the build itself may
    # refuse one radar, but not the file: the message is about the data, not the format)
    raw, pc = run_many(
        [
            [
                "biasfield",
                "build",
                f,
                "--radars",
                sites,
                "--out",
                tmp_path / f"{f.suffix[1:]}.npz",
                "--json",
            ]
            for f in (good, cap)
        ],
        expect=None,
    )
    assert raw.code == pc.code
    if raw.code == 0:
        assert raw.json()["plots"] == pc.json()["plots"] == 30
    else:
        assert raw.err.replace(str(good), "") == pc.err.replace(str(cap), "")
