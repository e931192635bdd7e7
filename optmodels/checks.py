"""The input checks every entry point uses: arrays (ragged, object, complex and non-finite
values refused), SPD covariance stacks, scalars, choices, counts, seeds and instances.

Each check returns the value converted (a float64 array, a float, an int ...) or raises one
:class:`~optmodels.errors.ProblemError` naming the argument. Re-exported by
:mod:`optmodels.core`, where the rest of the package imports them from.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optmodels.errors import ProblemError

__all__ = [
    "MAX_MAGNITUDE",
    "as_choice",
    "as_count",
    "as_finite_array",
    "as_flag",
    "as_float_array",
    "as_generator",
    "as_instance",
    "as_number",
    "as_positive",
    "as_probability",
    "check_spd",
    "check_spd_stack",
]

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- checks
def _entries(n: int | None) -> str:
    return "a scalar" if n is None else f"{n} entr{'y' if n == 1 else 'ies'}"


def _ragged_text(value: Any, depth: int = 0) -> str:
    """Where a nested sequence stops being rectangular ("item 1 has 2 entries, item 0 has
    3", "in item 4: ..."), for the message of a ragged input; "" if it cannot tell."""
    if depth > 8 or not isinstance(value, list | tuple | np.ndarray):
        return ""
    lens = [
        len(v) if isinstance(v, list | tuple) or (isinstance(v, np.ndarray) and v.ndim) else None
        for v in value
    ]
    for j, n in enumerate(lens):
        if n != lens[0]:
            return f"item {j} has {_entries(n)}, item 0 has {_entries(lens[0])}"
    for i, item in enumerate(value):
        inner = _ragged_text(item, depth + 1)
        if inner:
            return f"in item {i}: {inner}"
    return ""


_REAL_TYPES = (bool, int, float, np.bool_, np.integer, np.floating)


def as_float_array(name: str, value: Any) -> FloatArray:
    """``value`` as a float64 array, or one :class:`ProblemError` naming ``name``: the root
    of every array check (:func:`as_finite_array` and the data classes' ``__post_init__``).

    Refused: ragged nested sequences (rows of different lengths, which NumPy ≥ 1.24 turns
    into a raw ``ValueError``, or an object array of rows), object arrays holding anything
    but real numbers, strings and bytes (``"1.5"`` would otherwise be parsed silently),
    ``None`` entries, complex values, dates and mappings. Booleans are read as 0/1. Shape
    and finiteness are not checked here.
    """
    if value is None:
        raise ProblemError(f"{name}: not a numeric array (got None)")
    if isinstance(value, str | bytes | Mapping | set | frozenset):
        raise ProblemError(
            f"{name}: not a numeric array (got {type(value).__name__} {_scalar_text(value)})"
        )
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        where = _ragged_text(value)
        if "inhomogeneous" in str(exc) or where:
            raise ProblemError(
                f"{name}: a ragged nested sequence (rows of different "
                f"lengths{': ' + where if where else ''}); give a "
                f"rectangular array"
            ) from None
        raise ProblemError(f"{name}: not a numeric array ({exc})") from None
    kind = raw.dtype.kind
    if kind == "c":
        raise ProblemError(f"{name}: complex values are not accepted (give real numbers)")
    if kind in "USV":
        raise ProblemError(
            f"{name}: not a numeric array (text entries, dtype {raw.dtype}: "
            f"text is not parsed here, convert it first)"
        )
    if kind in "mM":
        raise ProblemError(
            f"{name}: not a numeric array (dtype {raw.dtype}: convert times to seconds first)"
        )
    if kind == "O":
        # one pass over the entries' types (C speed), not over the entries
        for typ in set(map(type, raw.flat)):
            if issubclass(typ, _REAL_TYPES):
                continue
            if issubclass(typ, np.ndarray | list | tuple):
                where = _ragged_text(value)
                raise ProblemError(
                    f"{name}: a ragged nested sequence (rows of different "
                    f"lengths{': ' + where if where else ''}); give a "
                    f"rectangular array"
                )
            if issubclass(typ, complex | np.complexfloating):
                raise ProblemError(f"{name}: complex values are not accepted (give real numbers)")
            raise ProblemError(f"{name}: not a numeric array (an entry of type {typ.__name__})")
    try:
        return np.asarray(raw, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ProblemError(f"{name}: not a numeric array ({exc})") from None


def as_finite_array(
    name: str,
    value: ArrayLike,
    *,
    ndim: int | tuple[int, ...] | None = None,
    shape: tuple[int | None, ...] | None = None,
    max_abs: float | None = None,
) -> FloatArray:
    """Convert ``value`` to a float64 array and check shape and finiteness (and, with
    ``max_abs``, magnitude: see :data:`MAX_MAGNITUDE`).

    Raises
    ------
    ProblemError
        Naming ``name``, if the value is not numeric, has the wrong number of dimensions
        or shape (``None`` in ``shape`` matches any length), or has NaN/inf entries.
    """
    arr = as_float_array(name, value)
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else ndim
        if arr.ndim not in allowed:
            raise ProblemError(
                f"{name}: expected {' or '.join(map(str, allowed))} dimensions, "
                f"got shape {arr.shape}"
            )
    if shape is not None:
        ok = arr.ndim == len(shape) and all(
            s is None or s == a for s, a in zip(shape, arr.shape, strict=True)
        )
        if not ok:
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise ProblemError(f"{name}: expected shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ProblemError(f"{name}: {bad} entries are NaN or infinite")
    if max_abs is not None and arr.size and float(np.max(np.abs(arr))) > max_abs:
        raise ProblemError(
            f"{name}: |entries| up to {float(np.max(np.abs(arr))):.3g}, above "
            f"{max_abs:.0e} (squares and sums of squares would overflow "
            "float64; change units)"
        )
    return arr


#: Largest magnitude accepted where a problem squares its inputs (least-squares sums):
#: (1e100)² · N stays far below float64's 1.8e308. Found by the robustness sweep
#: (tests/test_robustness.py): 1e150-scale times overflowed Σt² into inf.
MAX_MAGNITUDE = 1e100


def check_spd_stack(name: str, mats: FloatArray, *, rtol: float = 1e-10) -> None:
    """Check that every matrix of a stack (..., d, d) is symmetric positive definite.

    Symmetry is checked relative to the matrix's largest entry (``rtol``); definiteness
    by a Cholesky factorisation. Raises :class:`ProblemError` naming ``name`` and the
    index of the first offending matrix.
    """
    if mats.ndim < 2 or mats.shape[-1] != mats.shape[-2]:
        raise ProblemError(f"{name}: expected square matrices, got shape {mats.shape}")
    if mats.shape[-1] == 0:  # found by the sweep: a raw "cannot reshape" from fuse((0, 0))
        raise ProblemError(
            f"{name}: empty (0 × 0) matrices (shape {mats.shape}): a "
            f"covariance needs a dimension ≥ 1"
        )
    if mats.size == 0:  # a stack of no matrices: nothing to check
        return
    flat = mats.reshape(-1, mats.shape[-1], mats.shape[-1])
    scale = np.max(np.abs(flat), axis=(1, 2))
    asym = np.max(np.abs(flat - flat.transpose(0, 2, 1)), axis=(1, 2))
    bad = np.flatnonzero(asym > rtol * np.maximum(scale, np.finfo(float).tiny))
    if bad.size:
        where = _index_text(name, mats, int(bad[0]))
        raise ProblemError(f"{where} is not symmetric (max |A - A^T| = {asym[bad[0]]:.3g})")
    sym = 0.5 * (flat + flat.transpose(0, 2, 1))
    # Cholesky of the whole stack at once; on failure find the first bad matrix.
    try:
        np.linalg.cholesky(sym)
    except np.linalg.LinAlgError:
        for i, m in enumerate(sym):
            try:
                np.linalg.cholesky(m)
            except np.linalg.LinAlgError:
                w = np.linalg.eigvalsh(m)
                where = _index_text(name, mats, i)
                raise ProblemError(
                    f"{where} is not positive definite (smallest eigenvalue {w[0]:.3g})"
                ) from None
    # Cholesky accepts matrices that are PD only to round-off; demand a sane condition.
    w = np.linalg.eigvalsh(sym)
    cond_bad = np.flatnonzero(w[:, 0] <= 1e-14 * w[:, -1])
    if cond_bad.size:
        i = int(cond_bad[0])
        where = _index_text(name, mats, i)
        raise ProblemError(
            f"{where} is numerically singular (eigenvalues {w[i, 0]:.3g} ... {w[i, -1]:.3g})"
        )


def check_spd(name: str, mat: FloatArray, *, rtol: float = 1e-10) -> None:
    """:func:`check_spd_stack` for a single matrix."""
    check_spd_stack(name, np.asarray(mat), rtol=rtol)


def _index_text(name: str, mats: FloatArray, flat_index: int) -> str:
    if mats.ndim == 2:
        return name
    idx = np.unravel_index(flat_index, mats.shape[:-2])
    return f"{name}[{', '.join(map(str, idx))}]"


# --------------------------------------------------------------------------- scalars
# One small set of scalar checks used by every entry point: a scalar argument of the wrong
# type or value becomes a ProblemError naming the argument, never a raw TypeError from
# float()/int(), a silent truncation (k=2.5 -> 2) or a NaN that propagates.


def _scalar_text(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def as_number(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    allow_inf: bool = False,
) -> float:
    """A real scalar as ``float``, checked against ``[low, high]`` (open ends with
    ``low_open``/``high_open``).

    Booleans, strings, ``None``, complex numbers, arrays of size ≠ 1 and NaN are refused;
    ±inf only with ``allow_inf``.

    Raises
    ------
    ProblemError
        Naming ``name`` and the value received.
    """
    if isinstance(value, bool | np.bool_) or value is None or isinstance(value, str | bytes):
        raise ProblemError(f"{name}: expected a real number, got {_scalar_text(value)}")
    if isinstance(value, complex | np.complexfloating):
        raise ProblemError(f"{name}: expected a real number, got complex {value!r}")
    if isinstance(value, np.ndarray):
        if value.size != 1 or np.iscomplexobj(value):
            raise ProblemError(f"{name}: expected a real number, got an array {value.shape}")
        value = value.reshape(()).item()
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ProblemError(f"{name}: expected a real number, got {_scalar_text(value)}") from None
    if np.isnan(x):
        raise ProblemError(f"{name}: got NaN")
    if np.isinf(x) and not allow_inf:
        raise ProblemError(f"{name}: got {x} (must be finite)")
    if low is not None and (x < low or (low_open and x == low)):
        raise ProblemError(f"{name}: must be {'>' if low_open else '>='} {low:g}, got {x:g}")
    if high is not None and (x > high or (high_open and x == high)):
        raise ProblemError(f"{name}: must be {'<' if high_open else '<='} {high:g}, got {x:g}")
    return x


def as_positive(
    name: str, value: Any, *, allow_zero: bool = False, allow_inf: bool = False
) -> float:
    """A scalar > 0 (≥ 0 with ``allow_zero``); see :func:`as_number`."""
    return as_number(name, value, low=0.0, low_open=not allow_zero, allow_inf=allow_inf)


def as_probability(
    name: str, value: Any, *, low_open: bool = False, high_open: bool = False
) -> float:
    """A probability in [0, 1] (ends excluded on request); see :func:`as_number`."""
    return as_number(name, value, low=0.0, high=1.0, low_open=low_open, high_open=high_open)


def as_count(name: str, value: Any, *, minimum: int = 0, maximum: int | None = None) -> int:
    """A whole number ≥ ``minimum`` (and ≤ ``maximum``) as ``int``.

    Integral floats (``3.0``) are accepted; ``2.5``, NaN, inf, booleans and strings are
    refused rather than truncated.
    """
    if isinstance(value, bool | np.bool_) or value is None or isinstance(value, str | bytes):
        raise ProblemError(f"{name}: expected a whole number, got {_scalar_text(value)}")
    if isinstance(value, int | np.integer):
        n = int(value)
    else:
        x = as_number(name, value)
        if x != np.floor(x):
            raise ProblemError(f"{name}: expected a whole number, got {x:g}")
        n = int(x)
    if n < minimum:
        raise ProblemError(f"{name}: must be >= {minimum}, got {n}")
    if maximum is not None and n > maximum:
        raise ProblemError(f"{name}: must be <= {maximum}, got {n}")
    return n


def as_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """One of ``choices`` (exact string match); the message lists them."""
    options = tuple(choices)
    if not isinstance(value, str) or value not in options:
        raise ProblemError(
            f"{name}: expected one of {', '.join(map(repr, options))}, got {_scalar_text(value)}"
        )
    return value


def as_flag(name: str, value: Any) -> bool:
    """A boolean switch: ``True``/``False`` (NumPy's too) only; ``1``, ``"yes"`` or ``None``
    are refused rather than read as truthy."""
    if not isinstance(value, bool | np.bool_):
        raise ProblemError(f"{name}: expected True or False, got {_scalar_text(value)}")
    return bool(value)


def as_generator(where: str, seed: Any) -> np.random.Generator:
    """A ``numpy.random.Generator`` as given, or seeded from a whole number ≥ 0 (or a
    sequence of them); anything else is one :class:`ProblemError` "<where> seed: ..."."""
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool | np.bool_ | float | str | bytes) or seed is None:
        raise ProblemError(
            f"{where} seed: expected a whole number >= 0 or a numpy.random.Generator, got {seed!r}"
        )
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:
        raise ProblemError(
            f"{where} seed: expected a whole number >= 0 or a "
            f"numpy.random.Generator, got {seed!r} ({exc})"
        ) from None


def as_instance(name: str, value: Any, cls: type) -> Any:
    """``value`` if it is a ``cls`` (the problem's data object), else a ProblemError naming
    ``name`` and the type received (instead of an AttributeError deep inside)."""
    if not isinstance(value, cls):
        raise ProblemError(f"{name}: expected a {cls.__name__}, got {type(value).__name__}")
    return value
