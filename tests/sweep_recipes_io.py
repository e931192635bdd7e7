"""Property-sweep recipes for :mod:`optmodels.io`'s files, paths and ASTERIX codec.

See :mod:`tests.sweep_support` for the vocabulary; merged into the sweep's RECIPES by
tests/test_property_sweep.py.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from tests.sweep_support import Ctx

R = dict[str, Callable[[Ctx], Any]]

RECIPES: dict[str, R] = {}

#: public entry points without a recipe yet, each with the reason
NOT_YET: dict[str, str] = {
    "io.csv_times": "a CSV column reader (tests/test_io_csv_times.py)",
    "io.rewrite_cat048_positions": "ASTERIX files (tests/test_asterix_rewrite.py)",
    "io.as_path": "a path helper: its message names its own `name` label",
    "io.atomic_write": "a context manager (tests/test_io*.py)",
    "io.csv_numbers": "needs CsvRows of a file",
    "io.encode_cat021": "ASTERIX encoders (tests/test_asterix*.py)",
    "io.encode_cat048": "ASTERIX encoders (tests/test_asterix*.py)",
    "io.is_asterix": "ASTERIX files (tests/test_asterix*.py)",
    "io.json_default": "a json.dumps hook (TypeError is its contract)",
    "io.output_dir": "paths (tests/test_io*.py)",
    "io.output_file": "paths (tests/test_io*.py)",
    "io.read_asterix": "ASTERIX files (tests/test_asterix*.py)",
    "io.read_json": "JSON files (tests/test_files.py)",
    "io.read_npy": "binary files (tests/test_files.py)",
    "io.read_npz": "binary files (tests/test_files.py)",
    "io.save_npz": "binary files (tests/test_io*.py)",
    "io.write_json": "JSON files (tests/test_io*.py)",
}
