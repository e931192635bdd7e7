"""Property-sweep recipes for :mod:`optmodels.io`'s files, paths and ASTERIX codec.

See :mod:`tests.sweep_support` for the vocabulary; merged into the sweep's RECIPES by
tests/test_property_sweep.py.

The good files are made once per session (:func:`~tests.sweep_support.make_file`): an
ASTERIX recording (CAT048 plots and CAT021 reports encoded with :func:`optmodels.io.
encode_cat048` / :func:`~optmodels.io.encode_cat021` from seeded values), a JSON document,
an ``.npy`` and an ``.npz`` written by NumPy, and CSV files read by
:func:`optmodels.io.read_csv_rows` for the cells of ``csv_numbers`` / ``csv_times``.
Values derived from a file are known without it where the sweep collects its cases
(``Ctx.tmp`` is None then and only their types matter): the record identifiers are the
byte offsets of records of one fixed length, the CSV cells a placeholder row.
"""

from __future__ import annotations

import io as _stdio
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from optmodels import io
from tests.sweep_support import AnyFile, Anything, Ctx, Free, Out, file_factory, make_file

R = dict[str, Callable[[Ctx], Any]]

#: CAT048 plots and CAT021 reports of the good recording (one datablock each)
N48, N21 = 8, 4


def cat048_args(n: int, seed: int = 28052) -> dict[str, Any]:
    """``n`` seeded CAT048 plots: the arguments of ``encode_cat048`` (also used by
    tests/test_io_sweep_findings.py)."""
    rng = np.random.default_rng(seed)
    return {
        "time_of_day": np.sort(rng.uniform(0.0, 600.0, n)),
        "sac": 4,
        "sic": 5,
        "range": rng.uniform(1e3, 3e5, n),
        "azimuth": rng.uniform(0.0, 2 * math.pi, n),
        "flight_level": rng.uniform(10.0, 400.0, n),
        "address": rng.choice(2**24, n, replace=False),
        "mode3a": rng.integers(0, 4096, n),
    }


def _plots(c: Ctx) -> dict[str, Any]:
    """Seeded CAT048 plots: the good arguments of ``encode_cat048``."""
    return c.get("io.plots", lambda: cat048_args(N48, seed=20261228))


def _reports(c: Ctx) -> dict[str, Any]:
    """Seeded CAT021 reports: the good arguments of ``encode_cat021``."""

    def make() -> dict[str, Any]:
        rng = np.random.default_rng(20261229)
        return {
            "time_of_day": np.sort(rng.uniform(36_000.0, 36_060.0, N21)),
            "sac": 9,
            "sic": 1,
            "latitude": rng.uniform(40.0, 50.0, N21),
            "longitude": rng.uniform(-5.0, 10.0, N21),
            "height": rng.uniform(3e3, 12e3, N21),
            "flight_level": rng.uniform(90.0, 390.0, N21),
            "address": rng.choice(2**24, N21, replace=False),
        }

    return c.get("io.reports", make)


def _cat048(c: Ctx) -> bytes:
    return c.get("io.cat048", lambda: io.encode_cat048(**_plots(c), per_block=N48))


@file_factory()
def _recording(c: Ctx) -> Path:
    """Raw datablocks: one CAT048 block of :data:`N48` plots, then one CAT021 block."""
    return make_file(c, "rec.ast", _cat048(c) + io.encode_cat021(**_reports(c), per_block=N21))


@file_factory(AnyFile)
def _any_recording(c: Ctx) -> AnyFile:
    """The recording as a path whose content ``is_asterix`` judges (never refuses)."""
    return AnyFile(_recording(c))


def _record_id(c: Ctx) -> np.ndarray:
    """``Cat048Reports.record_id`` of the plots (file 0): every record of the one CAT048
    datablock has the same items, so record k starts at byte 3 + k L (L its length).
    The good call of ``rewrite_cat048_positions`` fails if this is not what it reads."""
    size = len(_cat048(c)) - 3
    assert size % N48 == 0
    return 3 + (size // N48) * np.arange(N48, dtype=np.int64)


@file_factory()
def _json_file(c: Ctx) -> Path:
    return make_file(c, "doc.json", json.dumps({"a": [1.0, 2.5], "b": {"c": None}}))


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = _stdio.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


@file_factory()
def _npy_file(c: Ctx) -> Path:
    return make_file(c, "a.npy", _npy_bytes(np.arange(6.0).reshape(2, 3)))


@file_factory()
def _npz_file(c: Ctx) -> Path:
    buf = _stdio.BytesIO()
    np.savez(buf, x=np.arange(4.0), y=np.eye(2))
    return make_file(c, "a.npz", buf.getvalue())


_TIMES = ["2026-03-01T23:59:58.5", "2026-03-02T00:00:01.25Z", "2026-03-02 00:00:03+00:00"]


def _table(c: Ctx, name: str) -> io.CsvRows:
    """The rows of a small CSV through ``read_csv_rows`` (a placeholder at collection)."""
    if c.tmp is None:  # the sweep collects its cases: only the types matter
        return io.CsvRows(["time", "x"], [["0", "0"]], [2])
    text = "time,x\n" + "".join(f"{t},{0.5 * k - 1}\n" for k, t in enumerate(_TIMES))
    if name == "numbers.csv":
        text = "time,x\n" + "".join(f"{12.5 * k},{0.5 * k - 1}\n" for k in range(3))
    return c.get(f"io.{name}", lambda: io.read_csv_rows(make_file(c, name, text)))


def _cells(c: Ctx, name: str, j: int) -> list[str]:
    return [r[j] for r in _table(c, name).rows]


def _out(c: Ctx, name: str) -> Out:
    return Out((c.tmp or Path("/tmp")) / "io-out" / name)


_PLOT_ARGS = ("time_of_day", "sac", "sic", "range", "azimuth", "flight_level", "address", "mode3a")
_REPORT_ARGS = (
    "time_of_day",
    "sac",
    "sic",
    "latitude",
    "longitude",
    "height",
    "flight_level",
    "address",
)

RECIPES: dict[str, R] = {
    # ------------------------------------------------------------- paths
    # as_path's message names its `name` label (the caller's argument name); the label
    # given here is the swept argument's own name. A missing or folder path is good for
    # as_path (it only makes a Path), hence Free (bad: a number, a list).
    "io.as_path": {"name": lambda c: Anything("value"), "value": lambda c: Free("a/b.csv")},
    # an existing folder is good for output_dir (it writes into it): Free, not Out
    "io.output_dir": {"path": lambda c: Free(str((c.tmp or Path("/tmp")) / "io-out" / "d"))},
    "io.output_file": {"path": lambda c: _out(c, "f.txt")},
    # a context manager: the sweep's _call enters it and writes one line
    "io.atomic_write": {
        "path": lambda c: _out(c, "atomic.txt"),
        "binary": lambda c: False,
        "newline": lambda c: "",
    },
    # `arrays` (the **kwargs, here one array named "arrays"): any array NumPy stores
    # without a pickle is good (text and complex arrays too), so it is not swept here;
    # the pickled and ragged ones are refused in tests/test_io_sweep_findings.py
    "io.save_npz": {
        "path": lambda c: _out(c, "s.npz"),
        "compressed": lambda c: True,
        "arrays": lambda c: Anything(np.arange(5.0)),
    },
    # ------------------------------------------------------------- JSON, NumPy files
    "io.read_json": {"path": _json_file},
    "io.read_npy": {"path": _npy_file},
    "io.read_npz": {"path": _npz_file},
    "io.write_json": {
        "path": lambda c: _out(c, "w.json"),
        "obj": lambda c: Anything({"x": np.arange(3.0), "n": np.int64(4)}),
    },
    # a json.dumps hook: any object (TypeError for one it cannot encode is the protocol)
    "io.json_default": {"o": lambda c: Anything(np.float64(1.5))},
    # ------------------------------------------------------------- CSV columns
    # `path` only labels the messages (the cells are given): any value
    "io.csv_numbers": {
        "path": lambda c: Anything("numbers.csv"),
        "column": lambda c: Free("x"),
        "cells": lambda c: _cells(c, "numbers.csv", 1),
        "lines": lambda c: _table(c, "numbers.csv").lines,
        "finite": lambda c: True,
    },
    "io.csv_times": {
        "path": lambda c: Anything("times.csv"),
        "column": lambda c: Free("time"),
        "cells": lambda c: _cells(c, "times.csv", 0),
        "lines": lambda c: _table(c, "times.csv").lines,
        "epoch": lambda c: np.datetime64("2026-03-01", "ns"),
    },
    # ------------------------------------------------------------- ASTERIX
    "io.encode_cat048": {
        **{k: (lambda c, k=k: _plots(c)[k]) for k in _PLOT_ARGS},
        "per_block": lambda c: 5,
        "edition": lambda c: (1, 32),
    },
    "io.encode_cat021": {
        **{k: (lambda c, k=k: _reports(c)[k]) for k in _REPORT_ARGS},
        "high_resolution": lambda c: True,
        "per_block": lambda c: 3,
        "edition": lambda c: (2, 7),
    },
    "io.is_asterix": {
        "path": _any_recording,
        "blocks": lambda c: 4,
        "editions": lambda c: {48: (1, 32)},
    },
    "io.read_asterix": {
        "paths": _recording,
        "date": lambda c: "2026-03-01",
        "editions": lambda c: {48: (1, 32), 21: (2, 7)},
        "check": lambda c: "layouts",
    },
    "io.rewrite_cat048_positions": {
        "paths": _recording,
        "out_path": lambda c: _out(c, "rewritten.ast"),
        "record_id": _record_id,
        "range_m": lambda c: np.linspace(1e4, 3e4, N48),
        "azimuth_rad": lambda c: np.linspace(0.1, 6.0, N48),
        "editions": lambda c: {48: (1, 32)},
    },
}

#: public entry points without a recipe yet, each with the reason
NOT_YET: dict[str, str] = {}
