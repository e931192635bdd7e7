"""Command line: ``optmodels <problem> <verb> ... [--json]``, ``optmodels demo``,
``optmodels compare``, ``optmodels montecarlo``.

The contract (README, "Command line"):

- stdout carries only the result: the human text, or with ``--json`` exactly one JSON
  document (non-finite numbers written as ``null``). Everything else -- progress bars,
  warnings, solver banners printed from C (HiGHS) -- goes to stderr.
- Exit status: 0 solved (status OK: optimal or optimal_inaccurate); 1 finished but not
  OK (infeasible, unbounded, iteration/time limit, solver error, or for the multi-part
  commands a part that failed); 2 bad input or usage (a wrong flag value, an unreadable
  or malformed file, an unwritable output path, an unreachable scheduler, a solver that
  is not installed); 3 internal error (a bug: rerun with ``--debug`` for the traceback);
  130 interrupted (Ctrl-C).
- Every error is one line on stderr, ``optmodels: error: <message>``, never a traceback;
  with ``--json`` stdout then holds ``{"error": <message>, "exit_code": <code>}``.
- Flags are written in full: no abbreviation is accepted (``--sigma`` is not ``--sigma2``);
  an unknown flag is a usage error naming the verb's ``--help`` and the flags it may mean.
- One grammar: every ``--help`` shows the defaults (a switch's help says in words what
  happens without it); ``--out`` is a FOLDER for the verbs
  that write several files (``demo``, ``compare``, ``biasfield solve``) and a FILE for
  those that write one (named in each verb's help); a verb that writes prints the path
  it wrote; the closed form is ``closed-form``, a value of ``--method`` wherever a verb
  offers it.
"""

# The package (docs/architecture.md):
#   contract.py    exit statuses, error mapping (_execute), _reading, output paths, the
#                  fd-1 redirect, strict JSON printing, the one-line-error argparse class
#                  and the help formatter every parser inherits
#   args.py        argparse types built on optmodels.core's as_* checks
#   problems/      one module per problem: its verbs (register), demo hook, --details hook;
#                  discovered by name through the registry -- no list of problem names here.
#                  They import their problem package only inside the handlers, so that
#                  `optmodels --help` imports no problem (issue 23 item 4).
#   demo.py, compare.py, montecarlo.py   the multi-problem commands

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from optmodels.cli import problems
from optmodels.cli.contract import (
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_NOT_OK,
    EXIT_OK,
    Outcome,
    _execute,
    _Parser,
)

#: The problems with a CLI module (:mod:`optmodels.cli.problems`), in the harness's order.
PROBLEMS = problems.names()


def _version() -> str:
    """The installed distribution's version (:mod:`importlib.metadata`), else the
    package's ``__version__`` (a source tree that is not installed)."""
    from importlib import metadata

    try:
        return metadata.version("optmodels")
    except metadata.PackageNotFoundError:
        from optmodels import __version__

        return __version__


def build_parser() -> argparse.ArgumentParser:
    """The whole command line: the multi-problem commands, then each problem module's
    verbs (:func:`optmodels.cli.problems.modules`, sorted by name). Every parser is a
    :class:`~optmodels.cli.contract._Parser` (one-line errors, defaults in ``--help``)."""
    from optmodels.cli import compare, demo, montecarlo

    ap = _Parser(prog="optmodels", description=__doc__)
    ap.add_argument("--version", action="version", version=f"optmodels {_version()}")
    ap.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    demo.register(sub)
    compare.register(sub)
    montecarlo.register(sub)
    for mod in problems.modules():
        mod.register(sub)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (module docstring). Usage errors
    raise ``SystemExit(2)`` from argparse after one line on stderr."""
    argv = list(sys.argv[1:] if argv is None else argv)
    _Parser.json_errors = "--json" in argv
    ap = build_parser()
    args = ap.parse_args(argv)
    return _execute(args)


__all__ = [
    "EXIT_INPUT",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_OK",
    "EXIT_OK",
    "PROBLEMS",
    "Outcome",
    "build_parser",
    "main",
]
