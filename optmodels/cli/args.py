"""argparse ``type=`` callables for the numeric and list flags, built on
:mod:`optmodels.core`'s scalar checks (``as_positive``, ``as_number``, ``as_probability``,
``as_count``): a bad value is a usage error (exit 2) naming the flag."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from optmodels.core import ProblemError, as_count, as_number, as_positive, as_probability


def _flag_type(
    what: str, check: Callable[[Any], Any], parse: Callable[[str], Any] = float
) -> Callable[[str], Any]:
    """An argparse ``type=``: ``parse`` the text, then ``check`` it with one of
    :mod:`optmodels.core`'s scalar checks (called with the name ``"value"``); a failure is
    a usage error (exit 2) naming the flag."""

    def convert(text: str) -> Any:
        try:
            value = parse(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            return check(value)
        except ProblemError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("value: ")) from None

    convert.__name__ = what
    return convert


def _whole(text: str) -> int | float:
    """``"12"`` → 12 exactly; ``"1e3"`` → 1000.0 (as_count then refuses ``"2.5"``)."""
    try:
        return int(text)
    except ValueError:
        return float(text)


def _positive() -> Callable[[str], float]:
    return _flag_type("a positive number", lambda v: as_positive("value", v))


def _finite() -> Callable[[str], float]:
    return _flag_type("a finite number", lambda v: as_number("value", v))


def _level() -> Callable[[str], float]:
    return _flag_type(
        "a probability in (0, 1)",
        lambda v: as_probability("value", v, low_open=True, high_open=True),
    )


def _count(minimum: int) -> Callable[[str], int]:
    return _flag_type(
        f"a whole number >= {minimum}", lambda v: as_count("value", v, minimum=minimum), _whole
    )


def _int_list(text: str) -> list[int]:
    """``--sizes 100,1000``: positive whole numbers."""
    try:
        vals = [as_count("value", _whole(x), minimum=1) for x in text.split(",") if x.strip()]
    except (ValueError, OverflowError) as exc:  # ProblemError is a ValueError
        raise argparse.ArgumentTypeError(
            f"expected positive whole numbers like 100,1000 ({str(exc).removeprefix('value: ')})"
        ) from None
    if not vals:
        raise argparse.ArgumentTypeError("expected positive whole numbers like 100,1000")
    return vals


def _names(text: str | None) -> list[str] | None:
    """A comma-separated list of names (``None`` when the flag is not given)."""
    if text is None:
        return None
    names = [x.strip() for x in text.split(",") if x.strip()]
    return names
