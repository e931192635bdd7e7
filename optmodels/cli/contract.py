"""The command line's contract (README, "Command line"; :mod:`optmodels.cli`'s
docstring): the exit statuses and the mapping of an exception to one of them, the
``_reading`` wrapper at input boundaries, the output-path checks, the fd-1 redirect that
keeps stdout for the result alone, strict JSON printing, and the argparse class whose
usage errors are one line (with ``--json``, also the error document).

Every verb's handler returns an :data:`Outcome`; :func:`_execute` runs it.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import os
import sys
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from optmodels.core import (
    OptModelsError,
    ProblemError,
    SolveError,
    SolverNotAvailable,
    json_text,
)

#: Exit statuses (:mod:`optmodels.cli`'s docstring).
EXIT_OK, EXIT_NOT_OK, EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED = 0, 1, 2, 3, 130

#: What every handler returns: the result document and whether it is OK (exit 0 or 1).
Outcome = tuple[dict[str, Any], bool]

_OK_STATUSES = ("optimal", "optimal_inaccurate")


# ------------------------------------------------------------------ input boundaries
@contextlib.contextmanager
def _reading(label: str) -> Iterator[None]:
    """Errors raised while reading or validating the user's input are the user's: a raw
    exception from a reader or a data constructor (``float(None)``, a ragged list, a file
    that is not UTF-8, ...) becomes one :class:`ProblemError` naming ``label`` (the file
    or the flag), i.e. exit 2 instead of a traceback; a ProblemError about the content
    is prefixed with the file's name ``label`` unless it names it already (a label
    that is a flag, ``--s1/--s2``, is left to the verb, which names the flag)."""
    try:
        yield
    except ProblemError as exc:
        # a data class's refusal of a file's content ("... means: a ragged nested
        # sequence") also names the file (a flag's block names its flag itself)
        if label and not label.startswith("--") and label not in str(exc):
            raise ProblemError(f"{label}: {exc}") from exc
        raise
    except OptModelsError:
        raise
    except UnicodeDecodeError as exc:
        raise ProblemError(
            f"{label}: not UTF-8 text (byte {exc.start}: {exc.reason}); save it as UTF-8"
        ) from exc
    except json.JSONDecodeError as exc:
        raise ProblemError(f"{label}: not valid JSON ({exc})") from exc
    except OSError as exc:
        raise ProblemError(f"{label}: {exc.strerror or exc}") from exc
    except (
        ValueError,
        TypeError,
        KeyError,
        IndexError,
        ArithmeticError,
        np.linalg.LinAlgError,
    ) as exc:
        raise ProblemError(f"{label}: {type(exc).__name__}: {exc}") from exc


def _out_dir(flag: str, path: str | Path) -> Path:
    """``--out FOLDER``: created if missing; refused (exit 2) before any work is done if
    it, or a parent, is an existing file."""
    from optmodels.io import output_dir

    try:
        return output_dir(path, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None


def _out_file(flag: str, path: str | Path) -> Path:
    """``--out FILE``: missing parent folders are created; an existing directory (or a
    parent that is a file) is refused before any work is done."""
    from optmodels.io import output_file

    try:
        return output_file(path, name=flag)
    except ProblemError as exc:
        raise ProblemError(f"{flag}: {exc}") from None


# ---------------------------------------------------------- stdout, JSON, errors
def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (a solver's ``printf`` to a pipe sits there
    until exit, after fd 1 is back on stdout)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no libc symbols (non-POSIX)
        pass


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """While the work runs, every write to stdout -- Python's, a C library's (HiGHS prints
    its banner on fd 1), a child process's -- goes to stderr: fd 1 points at fd 2 and
    ``sys.stdout`` is ``sys.stderr``. Both are restored on the way out, so the result
    alone is printed on stdout."""
    for stream in (sys.stdout, sys.__stdout__, sys.stderr):
        with contextlib.suppress(Exception):
            if stream is not None:
                stream.flush()
    saved: int | None = None
    try:
        saved = os.dup(1)
        os.dup2(2, 1)
    except OSError:  # no fd 1/2 (embedded interpreter): Python-level redirection only
        if saved is not None:
            os.close(saved)
        saved = None
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        for stream in (sys.__stdout__, sys.stderr):
            with contextlib.suppress(Exception):
                if stream is not None:
                    stream.flush()
        _flush_c_stdio()
        if saved is not None:
            os.dup2(saved, 1)
            os.close(saved)


def _dumps(obj: Any) -> str:
    """One strict JSON document through the package's one encoder
    (:func:`optmodels.core.json_text`: NumPy arrays and scalars as lists and numbers,
    NaN/±inf as ``null``), the same as ``Solution.to_dict()``."""
    return json_text(obj, indent=2)


def _emit(text: str) -> None:
    """Write the result on stdout (a closed pipe, ``| head``, is not an error)."""
    try:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        with contextlib.suppress(OSError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())


def _fail(args: argparse.Namespace | None, code: int, message: str) -> int:
    """One line on stderr (and with --json the error document on stdout); the code."""
    line = " ".join(message.split())  # a message never spans lines
    print(f"optmodels: error: {line}", file=sys.stderr, flush=True)
    if args is not None and getattr(args, "json", False):
        _emit(_dumps({"error": line, "exit_code": code}))
    return code


def _execute(args: argparse.Namespace) -> int:
    """Run the parsed command (``args.func``) with stdout sent to stderr, then print its
    result alone on stdout (``args.printer``'s text, or with ``--json`` one JSON
    document); an exception becomes its exit status and one line on stderr. Returns the
    exit status (:mod:`optmodels.cli`'s docstring)."""
    debug = bool(getattr(args, "debug", False))
    text, ok, code, message = "", False, EXIT_OK, ""
    result: dict[str, Any] = {}
    with _stdout_to_stderr():
        try:
            result, ok = args.func(args)
            if args.json:
                text = _dumps(result)
            else:
                buf: list[str] = []
                with contextlib.redirect_stdout(_Lines(buf)):
                    args.printer(result)
                text = "".join(buf)
        except KeyboardInterrupt as exc:
            # montecarlo.Interrupted says what was saved and where
            code, message = EXIT_INTERRUPTED, str(exc) or "interrupted"
        except (ProblemError, SolverNotAvailable) as exc:
            code, message = EXIT_INPUT, str(exc)
        except SolveError as exc:
            code, message = EXIT_NOT_OK, f"not solved: {exc}"
        except OptModelsError as exc:
            code, message = EXIT_NOT_OK, str(exc)
        except OSError as exc:  # the environment: a file, a folder, a network address
            name = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            code, message = EXIT_INPUT, f"{name}{exc.strerror or exc}"
        except Exception as exc:  # a bug: one line, the traceback on request
            if debug:
                traceback.print_exc()
            code = EXIT_INTERNAL
            message = f"internal error: {type(exc).__name__}: {exc}" + (
                "" if debug else " (rerun with --debug for the traceback)"
            )
    if code != EXIT_OK:
        return _fail(args, code, message)
    _emit(text)
    if not ok:
        status = result.get("status")
        # a multi-part result without a status says why in its "message", if it can
        why = result.get("message") if not status else None
        what = (
            f"status {status}"
            if status
            else f"{why}"
            if why
            else "some part failed (see the output)"
        )
        extra = f" ({result['message']})" if status and result.get("message") else ""
        print(f"optmodels: not OK: {what}{extra}", file=sys.stderr, flush=True)
    return EXIT_OK if ok else EXIT_NOT_OK


class _Lines:
    """A minimal text sink collecting what a printer writes (printed in one go)."""

    def __init__(self, buf: list[str]) -> None:
        self.buf = buf

    def write(self, text: str) -> int:
        self.buf.append(text)
        return len(text)

    def flush(self) -> None:
        pass


# --------------------------------------------------------------------------- parser
class _Help(argparse.RawDescriptionHelpFormatter):
    """The one help formatter (every :class:`_Parser`, hence every sub-command, uses it):
    descriptions and epilogs as written, and each option's default appended as
    ``(default: X)`` -- as :class:`argparse.ArgumentDefaultsHelpFormatter`, but also for
    options without a help text, and not for flags whose default is "off" (``None``,
    ``False``) or whose help already states it."""

    def _format_action(self, action: argparse.Action) -> str:
        if not action.help and action.option_strings and _shows_default(action):
            action.help = "(default: %(default)s)"
        return super()._format_action(action)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if _shows_default(action) and "%(default)" not in text and "(default" not in text:
            text = f"{text.rstrip()} (default: %(default)s)".lstrip()
        return text


def _shows_default(action: argparse.Action) -> bool:
    """Whether ``--help`` states ``action``'s default (options only; a default that is
    "off" -- ``None``, ``False``, suppressed -- is not a value worth showing, nor is the
    default of a switch (``store_true``/``store_false``: "(default: True)" under
    ``--no-clean`` reads as "--no-clean is on"; such a flag's help says in words what
    happens without it))."""
    return (
        bool(action.option_strings)
        and action.default is not None
        and action.default is not False
        and action.default is not argparse.SUPPRESS
        and not isinstance(
            action,
            argparse._HelpAction
            | argparse._VersionAction
            | argparse._StoreTrueAction
            | argparse._StoreFalseAction
            | argparse._StoreConstAction,
        )
    )


#: The attribute of the parsed namespace naming the innermost parser that ran (the verb's):
#: an unknown flag is reported against that verb's ``--help``, not the root's.
_LEAF_ATTR = "_optmodels_leaf_parser"


def _did_you_mean(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """`` (did you mean --sigma2?)`` for the unknown flags among ``extras`` that start a
    flag of ``parser`` or are close to one (abbreviations are not accepted: a flag is
    written in full); ``""`` when none is close. Hidden flags (former spellings) are not
    suggested."""
    import difflib

    known = [
        s
        for a in parser._actions
        if a.help is not argparse.SUPPRESS
        for s in a.option_strings
        if s.startswith("--")
    ]
    hints: list[str] = []
    for text in extras:
        flag = text.split("=", 1)[0]
        if not flag.startswith("--") or flag in known:
            continue
        close = [s for s in known if s.startswith(flag)] or difflib.get_close_matches(
            flag, known, n=2, cutoff=0.75
        )
        hints += [c for c in close[:3] if c not in hints]
    return f" (did you mean {' or '.join(hints)}?)" if hints else ""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors and one prefix: ``optmodels: error: plane fit:
    argument --sigma2: must be > 0, got -1 (see optmodels plane fit --help)``, exit 2;
    every parser (sub-commands included) shows its defaults (:class:`_Help`)."""

    #: set by :func:`main` when ``--json`` is on the command line: the usage error is
    #: then also the one JSON document on stdout
    json_errors = False

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _Help)
        # no abbreviations, on every parser (the sub-commands' parsers are this class
        # too): `plane fit --sigma 25` was read as --sigma2 25, a variance in m²
        kwargs["allow_abbrev"] = False
        super().__init__(*args, **kwargs)

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """argparse's, recording on the namespace the innermost parser that ran (a verb's
        parser runs inside its group's, inside the root's: the first to set it wins)."""
        ns, extras = super().parse_known_args(args, namespace)
        if not hasattr(ns, _LEAF_ATTR):
            setattr(ns, _LEAF_ATTR, self)
        return ns, extras

    def parse_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> argparse.Namespace:
        """argparse's, but an unknown flag is the verb's usage error (``see optmodels
        plane fit --help``), with the flags it may have meant."""
        ns, extras = self.parse_known_args(args, namespace)
        leaf = getattr(ns, _LEAF_ATTR, self)
        if hasattr(ns, _LEAF_ATTR):
            delattr(ns, _LEAF_ATTR)
        if extras:
            leaf.error(f"unrecognized arguments: {' '.join(extras)}{_did_you_mean(leaf, extras)}")
        return ns

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("optmodels").strip()
        line = " ".join(f"{where + ': ' if where else ''}{message}".split())
        if _Parser.json_errors:
            _emit(_dumps({"error": line, "exit_code": EXIT_INPUT}))
        self.exit(EXIT_INPUT, f"optmodels: error: {line} (see {self.prog} --help)\n")


def _leaf(sub: Any, name: str, help_: str) -> argparse.ArgumentParser:
    """A command parser with the common flags --json and --debug."""
    p = sub.add_parser(name, help=help_, description=help_)
    p.add_argument("--json", action="store_true", help="print exactly one JSON document on stdout")
    p.add_argument(
        "--debug",
        action="store_true",
        default=argparse.SUPPRESS,
        help="show the traceback of an internal error",
    )
    return p


def _group(sub: Any, name: str, help_: str) -> Any:
    """A problem's sub-command ``optmodels <name>`` and the sub-parsers of its verbs."""
    p = sub.add_parser(name, help=help_, description=help_)
    return p.add_subparsers(dest="verb", required=True, metavar="VERB")


def _wrote(path: str | Path | None) -> str:
    """The absolute path a verb wrote, for its printed text (never a silent write)."""
    return str(Path(path).resolve()) if path is not None else ""
