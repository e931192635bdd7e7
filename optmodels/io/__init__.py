"""Readers and writers for user data (CSV, ``.npz``) and results (CSV, Markdown, JSON).

Every reader turns a file it cannot use into one :class:`~optmodels.core.ProblemError`
naming the file (and, where it helps, the line, column or byte): a missing file, a
directory, a file without read permission, text that is not UTF-8 (with its byte offset),
binary data, a truncated or foreign archive. CSV files are read as UTF-8 with or without
the byte-order mark that spreadsheet programs write ("CSV UTF-8").

Every writer creates the missing parent folders of its output path and refuses a path
that is an existing directory (or whose parent is a file) with a ProblemError naming it.

Modules (the public names are re-exported here unchanged, ``from optmodels.io import ...``):

- :mod:`~optmodels.io.paths` — path arguments, checked input files, UTF-8 text, output
  files and folders;
- :mod:`~optmodels.io.tables` — CSV: :func:`read_csv_rows`, :func:`csv_numbers`, the plane
  (paper 000) and trajectory (paper 002) track files;
- :mod:`~optmodels.io.binary` — ``.npz`` / ``.npy`` arrays and JSON documents;
- :mod:`~optmodels.io.writers` — CSV, plane CSV, JSON and Markdown writers;
- :mod:`~optmodels.io.asterix` — ASTERIX recordings (raw datablocks or pcap/pcapng
  captures of ASTERIX over UDP): CAT048 (monoradar target reports) and CAT021 (ADS-B
  reports) read into SI arrays on one time axis across files and radars (the format
  tables from libasterix, imported lazily), :func:`is_asterix` (content detection), the
  vectorised encoders and :func:`rewrite_cat048_positions` (a corrected CAT048 recording).
"""

from __future__ import annotations

from optmodels.io.asterix import (
    AsterixData,
    Cat021Reports,
    Cat048Reports,
    encode_cat021,
    encode_cat048,
    is_asterix,
    read_asterix,
    rewrite_cat048_positions,
)
from optmodels.io.binary import read_json, read_npy, read_npz
from optmodels.io.paths import (
    as_path,
    atomic_write,
    input_file,
    output_dir,
    output_file,
    read_text,
    save_npz,
)
from optmodels.io.tables import (
    CsvRows,
    PlaneCsv,
    csv_numbers,
    csv_times,
    read_csv_rows,
    read_plane_csv,
    read_trajectory_csv,
)
from optmodels.io.writers import (
    csv_cell,
    json_default,
    markdown_table,
    write_csv,
    write_json,
    write_plane_csv,
)

__all__ = [
    "AsterixData",
    "Cat021Reports",
    "Cat048Reports",
    "CsvRows",
    "PlaneCsv",
    "as_path",
    "atomic_write",
    "csv_cell",
    "csv_numbers",
    "csv_times",
    "encode_cat021",
    "encode_cat048",
    "input_file",
    "is_asterix",
    "json_default",
    "markdown_table",
    "output_dir",
    "output_file",
    "read_asterix",
    "read_csv_rows",
    "read_json",
    "read_npy",
    "read_npz",
    "read_plane_csv",
    "read_text",
    "read_trajectory_csv",
    "rewrite_cat048_positions",
    "save_npz",
    "write_csv",
    "write_json",
    "write_plane_csv",
]
