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
"""

# The package (issue 15, phase 1; docs/architecture.md):
#   contract.py    exit statuses, error mapping (_execute), _reading, output paths, the
#                  fd-1 redirect, strict JSON printing, the one-line-error argparse class
#   args.py        argparse types built on optmodels.core's as_* checks
#   problems/      one module per problem: its verbs (register), demo hook, --details hook;
#                  discovered by name through the registry -- no list of problem names here
#   demo.py, compare.py, montecarlo.py   the multi-problem commands
# Every name the single-module cli.py had is re-exported below (hence the file-wide F401).
# ruff: noqa: F401

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from optmodels import fusion, plane, trajectories
from optmodels.cli import compare, demo, montecarlo, problems
from optmodels.cli.args import (
    _count,
    _finite,
    _flag_type,
    _int_list,
    _level,
    _names,
    _positive,
    _whole,
)
from optmodels.cli.compare import (
    _check_selection,
    _compare,
    _print_written,
    _run_compare,
    _run_harness,
)
from optmodels.cli.contract import (
    _OK_STATUSES,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_NOT_OK,
    EXIT_OK,
    Outcome,
    _dumps,
    _emit,
    _execute,
    _fail,
    _flush_c_stdio,
    _jsonable,
    _leaf,
    _Lines,
    _out_dir,
    _out_file,
    _Parser,
    _reading,
    _stdout_to_stderr,
)
from optmodels.cli.demo import _demo
from optmodels.cli.montecarlo import _montecarlo, _print_montecarlo
from optmodels.cli.problems.assignment import (
    _CASE_FIELDS,
    _assignment_count,
    _assignment_solve,
    _print_assignment_count,
    _print_assignment_solve,
    _read_case,
)
from optmodels.cli.problems.biasfield import (
    _biasfield_build,
    _biasfield_solve,
    _npz_name,
    _parse_box,
    _print_biasfield_build,
    _print_biasfield_solve,
)
from optmodels.cli.problems.fusion import _fusion_weights, _matrix_arg, _print_fusion_weights
from optmodels.cli.problems.plane import _parse_cov, _plane_fit, _print_plane_fit
from optmodels.cli.problems.trajectories import _print_trajectories_fit, _trajectories_fit

#: The problems with a CLI module (:mod:`optmodels.cli.problems`), in the harness's order.
PROBLEMS = problems.names()


def build_parser() -> argparse.ArgumentParser:
    """The whole command line: the multi-problem commands, then each problem module's
    verbs (:func:`optmodels.cli.problems.modules`, sorted by name)."""
    ap = _Parser(prog="optmodels", description=__doc__,
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--debug", action="store_true",
                    help="show the traceback of an internal error")
    sub = ap.add_subparsers(dest="command", required=True)
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
    ap = build_parser()
    _Parser.json_errors = "--json" in argv
    args = ap.parse_args(argv)
    return _execute(args)


__all__ = ["EXIT_INPUT", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_NOT_OK", "EXIT_OK",
           "PROBLEMS", "Outcome", "build_parser", "main"]
