"""The vocabulary of the property sweep's recipes (tests/test_property_sweep.py).

The recipes live in three modules -- the sweep itself (the array and model entry points),
:mod:`tests.sweep_recipes_io` (files, paths and the ASTERIX codec of :mod:`optmodels.io`)
and :mod:`tests.sweep_recipes_biasfield` (the recording readers and the plots -> FieldData
pipeline) -- and share the types below. A recipe maps each swept argument to a factory
``Ctx -> good value``; the *type* of the good value chooses the kinds of bad value tried:

* :class:`Free` -- free text (a name): no "unknown choice";
* :class:`Out` -- an output path: a number or an existing folder is bad, a missing folder
  is created;
* :class:`pathlib.Path` -- an input file: a number, a missing path, a folder, a file of
  foreign bytes and an empty file are bad;
* :class:`TextFile` -- an input text file whose content is not judged beyond being
  text: number, missing, folder and foreign (undecodable) bytes are bad;
* :class:`AnyFile` -- an input path whose content is not judged (a predicate such as
  ``is_asterix``, or a function that only checks the path): number, missing, folder;
* :class:`Anything` -- any value is good (a JSON hook, a CSV cell): good path only.

A factory that needs a file (``Ctx.tmp`` is None while the cases are collected) raises
``AssertionError``; the sweep then takes its kinds from :data:`FILE_FACTORIES`, which a
recipe module fills with :func:`file_factory` (so an :class:`AnyFile` factory is known as
one before any file exists).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any


class Free(str):
    """A free-text argument (a name, a label): no 'unknown choice' for it."""


class Out(type(Path())):  # type: ignore[misc]
    """An output path (a missing folder is created, so 'missing' is not bad for it)."""


class TextFile(type(Path())):  # type: ignore[misc]
    """An input text file whose content is not judged (an empty file is good)."""


class AnyFile(type(Path())):  # type: ignore[misc]
    """An input path whose content is not judged: a foreign or empty file is good."""


@dataclasses.dataclass(frozen=True)
class Anything:
    """An argument that takes any value (a CSV cell, a message label): good path only."""

    value: Any


@dataclasses.dataclass(frozen=True)
class BadFile:
    """A bad input file the sweep writes before the call (foreign bytes, or empty)."""

    content: bytes


@dataclasses.dataclass
class Ctx:
    """Good data shared by the recipes (built once per session)."""

    tmp: Path | None
    cache: dict[str, Any] = dataclasses.field(default_factory=dict)

    def get(self, key: str, make: Callable[[], Any]) -> Any:
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]


def make_file(c: Ctx, name: str, data: str | bytes) -> Path:
    """The file ``name`` in the session's folder, written once with ``data``."""
    assert c.tmp is not None, "files are made when a test runs"
    p = c.tmp / name
    if not p.exists():
        if isinstance(data, bytes):
            p.write_bytes(data)
        else:
            p.write_text(data, encoding="utf-8")
    return p


#: file factory -> the type of path it makes (Path: an input file judged by content;
#: AnyFile: content not judged; Out: an output)
FILE_FACTORIES: dict[Callable[[Ctx], Any], type] = {}

#: the first bytes of every generated foreign file: not UTF-8 (0xFF never is), not an
#: ASTERIX datablock (category 0 is not one), not a pcap or npz magic
FOREIGN_PREFIX = b"\x00\xff\x00\xff"


def file_factory(kind: type = Path) -> Callable[[Callable[[Ctx], Any]], Callable[[Ctx], Any]]:
    """Register a factory that makes a file (its good value's type, known at collection)."""

    def mark(f: Callable[[Ctx], Any]) -> Callable[[Ctx], Any]:
        FILE_FACTORIES[f] = kind
        return f

    return mark
