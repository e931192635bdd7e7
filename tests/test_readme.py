"""The README's "A first look at each problem" runs as written (issue 26).

Each walk-through of that section (a paragraph opening with a bold title and its guide
link, up to the next one) is run on its own in an empty folder: its fenced ``python``
blocks with this environment's interpreter, its ``sh`` blocks with ``bash -e -o pipefail``
and ``optmodels`` resolved to this environment's console script (next to
``sys.executable``, as in ``test_cli.py``), in the order they appear. Every block must
exit 0 without a traceback, and the files the walk-through says it writes must exist
afterwards. A walk-through added to the README without an entry in ``WRITES`` fails
``test_every_walkthrough_is_tested``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
SECTION = "## A first look at each problem"
#: the console script and interpreter of this environment
BIN = Path(sys.executable).parent
OPTMODELS = BIN / "optmodels"

#: per walk-through (its bold title): the files it writes, relative to its folder
WRITES: dict[str, tuple[str, ...]] = {
    "Plane of maneuver": ("track.csv", "turn.csv", "steps.csv"),
    "Dependent trajectories": ("objects.csv",),
    "Fusion of two estimates": (),
    "Radar bias field": (
        "sim/recording.ast",
        "sim/sites.csv",
        "sim/fielddata.npz",
        "sim/field/field.npz",
        "sim/field/field.csv",
        "sim/corrected.csv",
        "sim/corrected.ast",
    ),
    "Joint assignment with merged measurements": ("case.json",),
    "Solver comparison and Monte Carlo": ("runs/compare/report.md", "runs/plane.jsonl"),
}
#: walk-throughs too long for the default run (a solver sweep: ~15-20 s on 2 shared cores)
SLOW = {"Solver comparison and Monte Carlo"}

FENCE = re.compile(r"^```([A-Za-z0-9_+-]*)[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)
#: a walk-through opens a paragraph: **Title** ([guide](docs/guide/...)
TITLE = re.compile(r"^\*\*([^*]+)\*\* \(\[guide\]", re.M)


@dataclass(frozen=True)
class Block:
    """One fenced block: its language (``python`` or ``sh``) and text."""

    lang: str
    code: str


def section_text() -> str:
    """The README's walk-through section, from its heading to the next ``## `` heading."""
    text = README.read_text(encoding="utf-8")
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    return text[start : end if end >= 0 else len(text)]


def walkthroughs() -> dict[str, list[Block]]:
    """The section's walk-throughs in order: bold title -> its fenced blocks in order."""
    text = section_text()
    titles = list(TITLE.finditer(text))
    out: dict[str, list[Block]] = {}
    for k, m in enumerate(titles):
        end = titles[k + 1].start() if k + 1 < len(titles) else len(text)
        chunk = text[m.start() : end]
        out[m.group(1).strip()] = [Block(f.group(1), f.group(2)) for f in FENCE.finditer(chunk)]
    return out


WALKTHROUGHS = walkthroughs()


def test_every_walkthrough_is_tested() -> None:
    """Every walk-through has its expected files here, and only python/sh blocks."""
    assert list(WALKTHROUGHS) == list(WRITES), (
        f"README walk-throughs {list(WALKTHROUGHS)} != WRITES {list(WRITES)}"
    )
    for title, blocks in WALKTHROUGHS.items():
        assert blocks, f"{title}: no fenced block"
        langs = {b.lang for b in blocks}
        assert langs <= {"python", "sh"}, f"{title}: blocks in {langs - {'python', 'sh'}}"
        assert any(b.lang == "sh" for b in blocks), f"{title}: no command-line block"


def _run(block: Block, index: int, folder: Path) -> subprocess.CompletedProcess[str]:
    """Run one block in ``folder``: a python block with this interpreter, an sh block with
    bash (errexit, pipefail) and this environment's bin first on PATH."""
    if block.lang == "python":
        script = folder / f"_readme_block{index}.py"
        script.write_text(block.code, encoding="utf-8")
        argv = [sys.executable, script.name]
    else:
        script = folder / f"_readme_block{index}.sh"
        script.write_text(block.code, encoding="utf-8")
        argv = ["bash", "-e", "-o", "pipefail", script.name]
    env = {
        **os.environ,
        "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}",
        "MPLBACKEND": "Agg",
        "PYTHONWARNINGS": "ignore",
    }
    return subprocess.run(
        argv, cwd=folder, env=env, capture_output=True, text=True, timeout=600, check=False
    )


@pytest.mark.parametrize(
    "title",
    [pytest.param(t, marks=pytest.mark.slow) if t in SLOW else t for t in WRITES],
)
def test_walkthrough_runs_as_written(title: str, tmp_path: Path) -> None:
    """The walk-through's blocks, in order, in an empty folder: exit 0, no traceback, the
    files it writes exist and are not empty."""
    assert OPTMODELS.is_file(), f"console script not installed at {OPTMODELS}"
    blocks = WALKTHROUGHS.get(title)
    assert blocks, f"README has no walk-through {title!r}"
    for i, block in enumerate(blocks):
        proc = _run(block, i, tmp_path)
        where = f"{title}, block {i} ({block.lang}):\n{block.code}"
        assert "Traceback" not in proc.stderr, f"{where}\nstderr:\n{proc.stderr[-3000:]}"
        assert proc.returncode == 0, (
            f"{where}\nexit {proc.returncode}\nstdout:\n{proc.stdout[-2000:]}\n"
            f"stderr:\n{proc.stderr[-3000:]}"
        )
        assert proc.stdout.strip(), f"{where}\nprinted nothing"
    for name in WRITES[title]:
        path = tmp_path / name
        assert path.is_file() and path.stat().st_size > 0, f"{title}: {name} not written"
