"""Regression tests of the defects the property sweep found in :mod:`optmodels.io` (issue 28
item 5, tests/sweep_recipes_io.py): each bad value is refused with one ProblemError naming
the argument, and the good path still gives the right numbers."""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

import numpy as np
import pytest

from optmodels import io
from optmodels.core import ProblemError
from optmodels.io.asterix.layout import FT, NM
from tests.sweep_recipes_io import cat048_args


# --------------------------------------------------------------------------- atomic_write
def test_atomic_write_refuses_a_binary_that_is_not_a_flag(tmp_path: Path) -> None:
    p = tmp_path / "a.txt"
    for bad in ("1.5", [[0.0], [1.0, 1.0]], 1):
        with pytest.raises(ProblemError, match=r"io\.atomic_write binary: expected True or False"):
            with io.atomic_write(p, binary=bad) as fh:  # type: ignore[arg-type]
                fh.write(b"x")
    assert not p.exists()  # nothing written
    with io.atomic_write(p, binary=True) as fh:
        fh.write(b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"


def test_atomic_write_refuses_a_newline_open_does_not_take(tmp_path: Path) -> None:
    p = tmp_path / "a.txt"
    for bad in ("qxz", 3.5, [[0.0], [1.0, 1.0]]):  # were open()'s raw ValueError/TypeError
        with pytest.raises(ProblemError, match=r"io\.atomic_write newline: expected None or"):
            with io.atomic_write(p, newline=bad) as fh:  # type: ignore[arg-type]
                fh.write("x")
    assert not p.exists()
    with io.atomic_write(p, newline="") as fh:  # "" keeps the line ends as written
        fh.write("a\r\nb\n")
    assert p.read_bytes() == b"a\r\nb\n"
    with io.atomic_write(p, newline="\r\n") as fh:
        fh.write("a\nb\n")
    assert p.read_bytes() == b"a\r\nb\r\n"


# --------------------------------------------------------------------------- csv columns
def _numbers_csv(tmp_path: Path) -> tuple[io.CsvRows, np.ndarray]:
    rng = np.random.default_rng(28051)
    x = rng.normal(scale=1e3, size=7)
    p = tmp_path / "n.csv"
    p.write_text("time,x\n" + "".join(f"{k * 2.5},{v:.17g}\n" for k, v in enumerate(x)))
    return io.read_csv_rows(p), x


@pytest.mark.parametrize("fn", [io.csv_numbers, io.csv_times])
def test_csv_columns_refuse_cells_that_are_not_one_per_row(fn, tmp_path: Path) -> None:
    rows, x = _numbers_csv(tmp_path)
    name = fn.__name__
    # ragged nested lists were a raw ValueError; text, a mapping and a 2-D table were
    # refused without naming `cells` (a letter, a key read as a cell)
    for bad in ([[0.0], [1.0, 1.0]], "1.5", {"a": 1.0}, [[1.0, 2.0], [3.0, 4.0]]):
        with pytest.raises(ProblemError, match=rf"io\.{name} cells: expected one "):
            fn("n.csv", "x", bad)
    got = io.csv_numbers("n.csv", "x", [r[1] for r in rows.rows], rows.lines)
    np.testing.assert_array_equal(got, x)  # 17 digits: the floats round-trip exactly


@pytest.mark.parametrize("fn", [io.csv_numbers, io.csv_times])
def test_csv_columns_refuse_a_column_name_that_is_not_text(fn) -> None:
    for bad in (3.5, [[0.0], [1.0, 1.0]]):  # were accepted silently
        with pytest.raises(ProblemError, match=rf"io\.{fn.__name__} column: expected the"):
            fn("n.csv", bad, ["1", "2"])


@pytest.mark.parametrize("fn", [io.csv_numbers, io.csv_times])
def test_csv_columns_refuse_lines_that_are_not_one_line_number_per_cell(fn) -> None:
    cells = ["1.5", "x"]
    # a short list was an IndexError while the message for "x" was written; the others
    # were accepted silently (they are only read for a message)
    for bad in ([2], [["a"] * 3] * 2, [[1.0, None, 2.0]] * 2, {"a": 1.0}, [2.0, 3.0]):
        with pytest.raises(
            ProblemError,
            match=rf"io\.{fn.__name__} lines: expected (2 file line|one value per row)",
        ):
            fn("n.csv", "x", cells, bad)
    with pytest.raises(ProblemError, match=r"n\.csv: line 9, column 'x': 'x' is not a number"):
        fn("n.csv", "x", cells, [8, 9])


def test_csv_numbers_refuses_a_finite_that_is_not_a_flag() -> None:
    for bad in ("1.5", [[0.0], [1.0, 1.0]]):
        with pytest.raises(ProblemError, match=r"io\.csv_numbers finite: expected True or False"):
            io.csv_numbers("n.csv", "x", ["1", "nan"], finite=bad)  # type: ignore[arg-type]
    got = io.csv_numbers("n.csv", "x", ["1", "nan"], finite=False)
    assert got[0] == 1.0 and np.isnan(got[1])
    with pytest.raises(ProblemError, match=r"row 2, column 'x': nan"):
        io.csv_numbers("n.csv", "x", ["1", "nan"])


def test_csv_times_refuses_an_epoch_that_is_not_a_date_time() -> None:
    cells = ["2026-03-01T23:59:58.5", "2026-03-02T00:00:01.25Z"]
    # "" and "NaT" gave a NaT epoch and every time NaN; a number was read as ns since 1970;
    # "now" as the clock's time
    for bad in ("", "NaT", 0, 3.5, "now", {"a": 1.0}, np.datetime64("NaT")):
        with pytest.raises(ProblemError, match=r"io\.csv_times epoch: expected a date-time"):
            io.csv_times("t.csv", "time", cells, epoch=bad)
    want = np.array([86398.5, 86401.25])  # s since 2026-03-01T00:00Z, by hand
    for good in (
        "2026-03-01",
        "2026-03-01T01:00+01:00",  # an offset: the same instant
        dt.datetime(2026, 3, 1, 1, 0, tzinfo=dt.timezone(dt.timedelta(hours=1))),
        dt.date(2026, 3, 1),
        np.datetime64("2026-03-01T00:00", "s"),
    ):
        got, epoch = io.csv_times("t.csv", "time", cells, epoch=good)
        assert epoch == np.datetime64("2026-03-01", "ns"), good
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- encoders
def test_encoders_refuse_values_that_are_not_real_numbers(tmp_path: Path) -> None:
    good = cat048_args(5)
    n = good["range"].size
    # complex values were a raw ComplexWarning (without the tests' warning filter: the
    # imaginary part silently dropped); text and booleans were read as numbers
    bad_values = {
        "range": np.ones(n) * (1 + 1j),
        "azimuth": np.array(["1"] * n),
        "sac": True,
        "sic": "1",
        "mode3a": [[1.0, None, 2.0]] * n,
        "address": [[0.0], [1.0, 1.0]],
    }
    for arg, bad in bad_values.items():
        with pytest.raises(ProblemError, match=rf"asterix\.encode_cat048 {arg}: expected real"):
            io.encode_cat048(**{**good, arg: bad})
    with pytest.raises(ProblemError, match=r"asterix\.encode_cat021 latitude: expected real"):
        io.encode_cat021([1.0], 1, 2, [45.0 + 1j], [5.0])
    p = tmp_path / "ok.ast"
    p.write_bytes(io.encode_cat048(**good))
    got = io.read_asterix(p).cat048
    assert np.all(np.abs(got.range - good["range"]) <= NM / 256 / 2 + 1e-9)
    np.testing.assert_array_equal(got.address, good["address"])
    np.testing.assert_array_equal(got.mode3a, good["mode3a"])


def test_encoders_refuse_an_edition_that_is_not_two_whole_numbers() -> None:
    good = cat048_args(2)
    # an array edition was a raw ValueError (the truth value of an array is ambiguous)
    for bad in (np.ones((2, 3)) * (1 + 1j), [[0.0], [1.0, 1.0]], {"a": 1.0}, (1.0, 32.0)):
        with pytest.raises(ProblemError, match=r"asterix\.encode_cat048 edition: expected"):
            io.encode_cat048(**good, edition=bad)
        with pytest.raises(ProblemError, match=r"asterix\.encode_cat021 edition: expected"):
            io.encode_cat021([1.0], 1, 2, [45.0], [5.0], edition=bad)
    assert io.encode_cat048(**good, edition=[1, 32]) == io.encode_cat048(**good)
    # an edition libasterix does not ship is still named as such
    with pytest.raises(ProblemError, match=r"CAT048 edition \(9, 9\) is not in libasterix"):
        io.encode_cat048(**good, edition=(9, 9))


def test_encoders_name_the_argument_of_the_wrong_length_and_range() -> None:
    # a two-value sac against one-record arrays was blamed on time_of_day
    with pytest.raises(ProblemError, match=r"encode_cat048 sac: expected 1 values .*got 2"):
        io.encode_cat048([1.0], [1, 2], 2, [1000.0], [0.5])
    with pytest.raises(ProblemError, match=r"encode_cat048 range: expected 2 values .*got 3"):
        io.encode_cat048([1.0, 2.0], 1, 2, [1.0, 2.0, 3.0], [0.5, 0.6])
    # latitude and longitude were refused together ("latitude/longitude")
    with pytest.raises(ProblemError, match=r"encode_cat021 latitude: need -90° to 90°, got 90.5"):
        io.encode_cat021([1.0], 1, 2, [90.5], [5.0])
    with pytest.raises(
        ProblemError, match=r"encode_cat021 longitude: need -180° to 180°, got -181"
    ):
        io.encode_cat021([1.0], 1, 2, [45.0], [-181.0])
    # outside an item: refused, not wrapped (one value per item)
    for arg, bad in (
        ("sac", 256),
        ("range", [256 * NM]),
        ("flight_level", [2048.0]),
        ("address", [2**24]),
        ("mode3a", [4096]),
    ):
        args = {"time_of_day": [1.0], "sac": 1, "sic": 2, "range": [1e3], "azimuth": [0.5]}
        with pytest.raises(ProblemError, match=rf"asterix\.encode_cat048 {arg}: need"):
            io.encode_cat048(**{**args, arg: bad})
    for arg, bad in (("height", [70e3]), ("flight_level", [-8200.0]), ("sic", -1)):
        args = {"time_of_day": [1.0], "sac": 1, "sic": 2, "latitude": [45.0], "longitude": [5.0]}
        with pytest.raises(ProblemError, match=rf"asterix\.encode_cat021 {arg}: need"):
            io.encode_cat021(**{**args, arg: bad})


def test_rewrite_names_record_id_and_refuses_complex_positions(tmp_path: Path) -> None:
    good = cat048_args(3)
    p = tmp_path / "r.ast"
    p.write_bytes(io.encode_cat048(**good))
    rep = io.read_asterix(p).cat048
    out = tmp_path / "o.ast"
    # ragged identifiers were refused as "range_m/azimuth_rad: expected numbers"
    with pytest.raises(ProblemError, match=r"rewrite_cat048_positions record_id: expected"):
        io.rewrite_cat048_positions(p, out, [[0.0], [1.0, 1.0]], [1.0, 2.0], [0.1, 0.2])
    # complex positions were a raw ComplexWarning
    for arg in ("range_m", "azimuth_rad"):
        args = {"range_m": np.full(3, 1e4), "azimuth_rad": np.full(3, 0.5)}
        args[arg] = args[arg] * (1 + 1j)
        with pytest.raises(ProblemError, match=rf"rewrite_cat048_positions {arg}: expected real"):
            io.rewrite_cat048_positions(p, out, rep.record_id, **args)
    assert not out.exists()
    new_range = np.array([1e4, 2e4, 3e4])
    io.rewrite_cat048_positions(p, out, rep.record_id, new_range, rep.azimuth)
    back = io.read_asterix(out).cat048
    assert np.all(np.abs(back.range - new_range) <= NM / 256 / 2 + 1e-9)
    np.testing.assert_array_equal(back.azimuth, rep.azimuth)


# --------------------------------------------------------------------------- recordings
def test_is_asterix_refuses_a_missing_path_and_a_folder(tmp_path: Path) -> None:
    # both were answered False, as if the file were there and of another kind
    with pytest.raises(ProblemError, match=r"missing\.ast: no such file"):
        io.is_asterix(tmp_path / "missing.ast")
    with pytest.raises(ProblemError, match="is a directory"):
        io.is_asterix(tmp_path)
    p = tmp_path / "r.ast"
    p.write_bytes(io.encode_cat048(**cat048_args(2)))
    empty = tmp_path / "empty.ast"
    empty.write_bytes(b"")
    assert io.is_asterix(p) and not io.is_asterix(empty)  # any readable file: an answer


def test_read_asterix_refuses_an_empty_file(tmp_path: Path) -> None:
    good = cat048_args(4)
    p = tmp_path / "r.ast"
    p.write_bytes(io.encode_cat048(**good))
    empty = tmp_path / "empty.ast"
    empty.write_bytes(b"")
    # an empty file was read as a recording without records
    for paths in (empty, [p, empty]):
        with pytest.raises(ProblemError, match=r"empty\.ast: empty file \(expected a recording"):
            io.read_asterix(paths)
    with pytest.raises(ProblemError, match=r"empty\.ast: empty file"):
        io.rewrite_cat048_positions(empty, tmp_path / "o.ast", [], [], [])
    rec = io.read_asterix(p).cat048
    np.testing.assert_allclose(rec.time, good["time_of_day"], rtol=0, atol=1 / 256 + 1e-9)
    fl = good["flight_level"] * 100 * FT
    assert np.all(np.abs(rec.pressure_altitude - fl) <= 25 * FT / 2 + 1e-9)


# --------------------------------------------------------------------------- writers
def test_save_npz_refuses_a_compressed_that_is_not_a_flag(tmp_path: Path) -> None:
    p = tmp_path / "a.npz"
    for bad in ("1.5", [[0.0], [1.0, 1.0]]):
        with pytest.raises(ProblemError, match=r"io\.save_npz compressed: expected True or"):
            io.save_npz(p, compressed=bad, x=np.zeros(2))  # type: ignore[arg-type]
    assert not p.exists()


def test_save_npz_refuses_arrays_it_would_pickle(tmp_path: Path) -> None:
    p = tmp_path / "a.npz"
    # ragged lists were a raw ValueError; None entries and mappings were pickled into an
    # archive that read_npz refuses
    for bad in ([[0.0], [1.0, 1.0]], [[1.0, None, 2.0]], {"a": 1.0}):
        with pytest.raises(ProblemError, match=r"io\.save_npz y: expected an array of numbers"):
            io.save_npz(p, x=np.zeros(2), y=bad)
    assert not p.exists()
    rng = np.random.default_rng(28053)
    x, z = rng.normal(size=(3, 2)), np.array(["a", "bc"])
    for compressed in (True, False):
        io.save_npz(p, compressed=compressed, x=x, z=z, w=x * (1 + 2j))
        got = io.read_npz(p, required=("x", "z", "w"))
        np.testing.assert_array_equal(got["x"], x)
        np.testing.assert_array_equal(got["z"], z)
        np.testing.assert_array_equal(got["w"], x * (1 + 2j))


def test_write_json_refuses_an_object_json_has_no_form_for(tmp_path: Path) -> None:
    p = tmp_path / "a.json"
    cycle: list = []
    cycle.append(cycle)
    for bad in ({"a": object()}, cycle):  # were a raw TypeError / RecursionError
        with pytest.raises(ProblemError, match=r"io\.write_json obj: not JSON serialisable"):
            io.write_json(p, bad)
    assert not p.exists()
    io.write_json(p, {"x": np.arange(3.0), "n": np.int64(4), "nan": float("nan")})
    assert json.loads(p.read_text()) == {"x": [0.0, 1.0, 2.0], "n": 4, "nan": None}


def test_as_path_refuses_a_path_like_of_bytes() -> None:
    class BytesPath(os.PathLike):
        def __fspath__(self) -> bytes:  # type: ignore[override]
            return b"/tmp/x"

    # was a raw TypeError ("'in <bytes>' requires a bytes-like object")
    with pytest.raises(ProblemError, match=r"--in: expected a text file path, got bytes"):
        io.as_path("--in", BytesPath())
    assert io.as_path("--in", Path("a") / "b.csv") == Path("a/b.csv")
