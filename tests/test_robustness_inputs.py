"""Robustness sweep, part 2: the classes of failure the audit of issue 14 found.

* **Scalars of the wrong type or value** at every public entry point: each scalar argument
  gets every value of :data:`POOL` (strings, ``None``, booleans, NaN, ±inf, complex, lists,
  arrays, negative, zero, fractional, huge). An invalid value must raise
  :class:`~optmodels.core.ProblemError` -- never a raw ``TypeError``/``ValueError``, never a
  silent truncation (``k=2.5`` -> 2) or a NaN that propagates. A valid value must give an
  honest answer (the ``accept`` property of :mod:`tests.test_robustness`). The sweep is
  exhaustive (every case × every value), not sampled: 20-odd arguments × 17 values.
* **Large time offsets**: the same trajectories at POSIX-like clock offsets must give the
  same velocities (or a refusal / non-OK status, never a different OK answer).
* **Degenerate data in sequences**: collinear prefixes of a plane sequence must never be
  reported planar with a normal.

Files (BOM, Latin-1, binary, truncated, foreign) are swept in ``tests/test_files.py`` and
the Monte Carlo engine's faults in ``tests/test_montecarlo.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from optmodels import assignment as asg
from optmodels import biasfield as bf
from optmodels import fusion as fu
from optmodels import io, plane
from optmodels import montecarlo as mc
from optmodels import trajectories as tr
from optmodels.core import OptModelsError, ProblemError
from tests.test_robustness import accept

# ------------------------------------------------------------------------ the pool
POOL: list[Any] = [
    "high",
    None,
    True,
    np.nan,
    np.inf,
    -np.inf,
    complex(1.0, 1.0),
    [1.0, 2.0],
    np.array([1.0, 2.0]),
    -1,
    0,
    0.5,
    2.5,
    3,
    np.int64(3),
    np.float64(0.3),
    1e300,
]
POOL_IDS = [
    "str",
    "None",
    "bool",
    "nan",
    "inf",
    "-inf",
    "complex",
    "list",
    "array",
    "-1",
    "0",
    "0.5",
    "2.5",
    "3",
    "int64",
    "float64",
    "1e300",
]


def _real(v: Any) -> float | None:
    """``v`` as a finite real, or None when it is not one (type or value)."""
    if isinstance(v, bool | np.bool_ | str | complex | list) or v is None:
        return None
    if isinstance(v, np.ndarray):
        return None
    x = float(v)
    return x if np.isfinite(x) else None


# Each rule returns True (valid: an honest answer), False (invalid: ProblemError) or
# None (either is acceptable: a boundary whose treatment is the problem's own choice).
def real(v: Any) -> bool | None:
    return _real(v) is not None


def positive(v: Any) -> bool | None:
    x = _real(v)
    return None if x is not None and x > 1e100 else (x is not None and x > 0)


def open_unit(v: Any) -> bool | None:
    x = _real(v)
    return x is not None and 0 < x < 1


def probability(v: Any) -> bool | None:
    x = _real(v)
    if x is None or x < 0 or x > 1:
        return False
    return None if x in (0.0, 1.0) else True


def count(least: int, *, bounded: bool = True) -> Callable[[Any], bool | None]:
    """A whole number; ``least`` and above valid, below invalid (0..least-1 either way
    when ``least`` > 1, as problems may legitimately refuse too-small samples). Without
    ``bounded`` (the work grows with the value), 1e300 must be refused."""

    def rule(v: Any) -> bool | None:
        x = _real(v)
        if x is None or x != np.floor(x) or x < 0:
            return False
        if x > 1e6:
            return None if bounded else False
        if x < least:
            return None if x >= 1 else False
        return True

    return rule


def or_none(rule: Callable[[Any], bool | None]) -> Callable[[Any], bool | None]:
    return lambda v: True if v is None else rule(v)


# ------------------------------------------------------------------------ the data
_RNG = np.random.default_rng(20261201)
_PTS = plane.PlaneData(
    np.c_[np.cos(np.linspace(0, 3, 30)), np.sin(np.linspace(0, 3, 30)), np.zeros(30)] * 1e3
    + _RNG.normal(scale=5.0, size=(30, 3)),
    25.0 * np.eye(3),
)
_PTS_CF = plane.closed_form(_PTS)
_T = [np.arange(10.0), np.arange(12.0)]
_Y = [2.0 * _T[0] + 1.0 + _RNG.normal(size=10), -1.0 * _T[1] + 1.0 + _RNG.normal(size=12)]
_TD = tr.TrajectoryData(_T, _Y, 1.0)
_S1, _S2 = np.array([[2.0, 0.3], [0.3, 1.0]]), np.array([[1.0, -0.2], [-0.2, 3.0]])
_A = dict(
    means=np.array([[0.0, 0.0], [10.0, 0.0]]),
    covs=np.stack([np.eye(2)] * 2),
    measurements=np.array([[0.1, -0.2], [9.8, 0.3], [5.0, 5.0]]),
    meas_cov=np.eye(2),
    volume=400.0,
    pd=0.9,
    rho=0.2,
)
_AD = asg.AssignmentData(**_A)
_FD = bf.synthetic_field_data(0, cells=12)[0]


def _assignment_data(**kw: Any) -> asg.AssignmentData:
    return asg.AssignmentData(**{**_A, **kw})


CASES: dict[str, tuple[Callable[[Any], Any], Callable[[Any], bool | None]]] = {
    "plane.planarity_test level": (
        lambda v: plane.planarity_test(_PTS, _PTS_CF, level=v),
        open_unit,
    ),
    "plane.identify_sequence level": (
        lambda v: plane.identify_sequence(np.arange(30.0), _PTS.points, 25.0 * np.eye(3), level=v),
        open_unit,
    ),
    "plane.solve starts": (
        lambda v: plane.solve(_PTS, "reduced", starts=v),
        count(1, bounded=False),
    ),
    "trajectories.TrajectoryData epoch": (
        lambda v: tr.closed_form(tr.TrajectoryData(_T, _Y, 1.0, epoch=v)),
        real,
    ),
    # σ² may also be one value per object: a list/array of two is a valid per-object σ²
    "trajectories.TrajectoryData sigma2": (
        lambda v: tr.closed_form(tr.TrajectoryData(_T, _Y, v)),
        lambda v: True if isinstance(v, list | np.ndarray) else positive(v),
    ),
    "trajectories.family_test level": (lambda v: tr.family_test(_TD, level=v), open_unit),
    "trajectories.eta n": (lambda v: tr.eta(v), count(2)),
    "fusion.weight_covariance n1": (
        lambda v: fu.weight_covariance(_S1, _S2, v, 30, mean="sample"),
        count(4),
    ),
    "fusion.sample_covariance_moments n": (
        lambda v: fu.sample_covariance_moments(_S1, v),
        count(1),
    ),
    "fusion.monte_carlo_weight trials": (
        lambda v: fu.monte_carlo_weight(_S1, _S2, 10, 10, trials=v, seed=1),
        count(1, bounded=False),
    ),
    "fusion.TwoSiteSystem.on_baseline baseline": (
        lambda v: fu.TwoSiteSystem.on_baseline(v).covariances([0.0, 30e3]),
        positive,
    ),
    "fusion.TwoSiteSystem.on_baseline sigma_azimuth": (
        lambda v: fu.TwoSiteSystem.on_baseline(sigma_azimuth=v).covariances([0.0, 30e3]),
        positive,
    ),
    "assignment.AssignmentData pd": (lambda v: asg.solve(_assignment_data(pd=v)), probability),
    "assignment.AssignmentData volume": (lambda v: asg.solve(_assignment_data(volume=v)), positive),
    "assignment.AssignmentData rho": (lambda v: asg.solve(_assignment_data(rho=v)), probability),
    "assignment.k_best k": (lambda v: asg.k_best(_AD, v), count(1, bounded=False)),
    "assignment.count_hypotheses q": (lambda v: asg.count_hypotheses(v, 3), count(0)),
    "assignment.solve mip_gap": (
        lambda v: asg.solve(_AD, mip_gap=v),
        lambda v: (lambda x: x is not None and 0 <= x < 1 if x is None or x < 1e100 else None)(
            _real(v)
        ),
    ),
    "assignment.solve time_limit": (lambda v: asg.solve(_AD, time_limit=v), or_none(positive)),
    # a pair is the only valid box: [1, 2] / array([1, 2]) are pairs (for this field a
    # proven-infeasible one), every scalar is refused
    "biasfield.solve box": (
        lambda v: bf.solve(_FD, box=v),
        lambda v: (
            True if v is None else (None if np.size(v) == 2 and not isinstance(v, str) else False)
        ),
    ),
    "biasfield.solve_lipschitz cap": (lambda v: bf.solve_lipschitz(_FD, cap=v), or_none(positive)),
    "biasfield.synthetic_field_data cells": (
        lambda v: bf.synthetic_field_data(0, cells=v),
        count(4, bounded=False),
    ),
    "montecarlo.run trials": (
        lambda v: mc.run(mc.TrajectoriesEta(q=2, n=3), v, 0, scheduler="serial"),
        count(1, bounded=False),
    ),
}


@pytest.mark.parametrize("value", POOL, ids=POOL_IDS)
@pytest.mark.parametrize("case", list(CASES))
def test_scalar_arguments(case: str, value: Any) -> None:
    """Invalid scalars raise ProblemError naming the argument; valid ones give an honest
    answer (or a documented optmodels exception)."""
    call, rule = CASES[case]
    verdict = rule(value)
    if verdict is False:
        with pytest.raises(ProblemError) as info:
            call(value)
        arg = case.rsplit(" ", 1)[1]
        assert arg in str(info.value), f"the message does not name {arg!r}: {info.value}"
    else:
        accept(lambda: call(value))


# ------------------------------------------------------------ large clock offsets
@settings(
    max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    offset=st.sampled_from([1.0e6, 1.7e9, 1.7e9 + 0.123456, 1e10, -3e9]),
    family=st.sampled_from(["diverging", "parallel", "independent"]),
    method=st.sampled_from(["closed_form", "CLARABEL"]),
    seed=st.integers(0, 2**16),
)
def test_clock_origin_does_not_change_velocities(
    offset: float, family: str, method: str, seed: int
) -> None:
    """Shifting every time stamp by the same offset (POSIX time) gives the same velocities
    to 1e-9 relative, or an explicit refusal / non-OK status; never another OK answer."""
    rng = np.random.default_rng(seed)
    # time stamps on a 1/1024 s grid: t + offset is exact in float64 for |offset| < 2^42 s,
    # so the shifted data are the same data and only the arithmetic can differ
    times = [np.sort(rng.integers(0, 100 * 1024, size=n)) / 1024.0 for n in (40, 55)]
    vals = [2.0 * t + 5.0 + rng.normal(size=t.size) for t in times]

    def fit(shift: float) -> Any:
        d = tr.TrajectoryData([t + shift for t in times], vals, 1.0, epoch=shift)
        if method == "closed_form":
            return tr.closed_form(d, family)  # type: ignore[arg-type]
        return tr.solve(d, family, solver=method)  # type: ignore[arg-type]

    ref = fit(0.0)
    assert ref.ok
    try:
        got = fit(offset)
    except OptModelsError:
        return
    if not got.ok:
        return
    # velocities: 1e-9 relative. Starts: a mean time stamp at the offset is rounded to
    # its ulp (2.4e-7 s at 1.7e9 s), which moves the line at the epoch by |V| times that;
    # allow |V| · 4 ulp on top of 1e-9 relative.
    v_ref, v_got = np.asarray(ref.velocity), np.asarray(got.velocity)
    assert np.allclose(v_got, v_ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(v_ref))), (
        offset,
        family,
        method,
        v_got,
        v_ref,
    )
    s_tol = 4 * np.spacing(abs(offset)) * np.max(np.abs(v_ref)) + 1e-9 * np.max(np.abs(ref.start))
    assert np.max(np.abs(np.asarray(got.start) - ref.start)) <= s_tol, (
        offset,
        family,
        method,
        got.start,
        ref.start,
    )
    assert np.all(np.isfinite(got.covariance))


# ------------------------------------------------------- degenerate sequences
@settings(
    max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    n_line=st.integers(4, 30),
    scale=st.sampled_from([1.0, 1e3, 1e5]),
    noise=st.sampled_from([0.0, 1e-9, 1e-3]),
    seed=st.integers(0, 2**16),
)
def test_collinear_steps_are_never_planar(
    n_line: int, scale: float, noise: float, seed: int
) -> None:
    """A collinear prefix (noise far below σ) does not determine the plane: every step
    over it is unresolved and not planar; the steps after the arc starts are resolved."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    line = np.outer(np.arange(n_line, dtype=float), d) * scale
    ang = np.linspace(0.2, 2.5, 20)
    u = np.cross(d, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    arc = line[-1] + scale * 10.0 * (np.outer(np.sin(ang), d) + np.outer(1 - np.cos(ang), u))
    pts = np.vstack([line, arc]) + noise * scale * rng.normal(size=(n_line + 20, 3))
    sigma2 = (0.01 * scale) ** 2
    seq = plane.identify_sequence(np.arange(n_line + 20.0), pts, sigma2 * np.eye(3))
    resolved = np.asarray(seq.resolved)
    planar = np.asarray(seq.planar)
    on_line = np.asarray(seq.n_points) <= n_line
    assert on_line.any()
    assert not np.any(planar & ~resolved), "a step reported planar without a resolved plane"
    assert not np.any(resolved[on_line]), "a collinear step reported resolved"
    assert np.all(np.isnan(np.asarray(seq.normal)[~resolved]))
    assert resolved[-1] and planar[-1]


# ------------------------------------------------------------- malformed files
def _plane_text(rng: np.random.Generator) -> str:
    pts = rng.normal(size=(8, 3)) * 1e3
    return "x,y,z\n" + "".join(f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in pts)


def _trajectory_text(rng: np.random.Generator) -> str:
    rows = [
        f"{j},{t:.17g},{2.0 * t + j + rng.normal():.17g}\n"
        for j in range(2)
        for t in np.arange(6.0)
    ]
    return "object,t,y\n" + "".join(rows)


def _radars_text(rng: np.random.Generator) -> str:
    return "name,x,y,sigma_range,sigma_azimuth,max_range\n" + "".join(
        f"R{i},{rng.uniform(-5e4, 5e4):.17g},{rng.uniform(-5e4, 5e4):.17g},50,0.08,300000\n"
        for i in range(3)
    )


READERS: dict[str, tuple[Callable[[np.random.Generator], str], Callable[[Any], Any]]] = {
    "plane": (_plane_text, lambda p: io.read_plane_csv(p)),
    "trajectories": (_trajectory_text, lambda p: io.read_trajectory_csv(p)),
    "radars": (_radars_text, lambda p: bf.read_radars(p)),
}


def _mutate(raw: bytes, kind: str, rng: np.random.Generator) -> bytes:
    """One damage a real file suffers: a BOM, Latin-1 text, a cut, inserted bytes, a
    damaged cell, another delimiter, a NUL, an empty file."""
    if kind == "bom":
        return b"\xef\xbb\xbf" + raw
    if kind == "bom_crlf":
        return b"\xef\xbb\xbf" + raw.replace(b"\n", b"\r\n")
    if kind == "latin1":
        return raw.replace(b"\n", " é\n".encode("latin-1"), 1)
    if kind == "cut":
        return raw[: int(rng.integers(0, len(raw)))]
    if kind == "insert":
        at = int(rng.integers(0, len(raw)))
        return (
            raw[:at]
            + rng.integers(0, 256, size=int(rng.integers(1, 8))).astype(np.uint8).tobytes()
            + raw[at:]
        )
    if kind == "cell":
        lines = raw.split(b"\n")
        i = int(rng.integers(1, max(len(lines) - 1, 2)))
        cells = lines[i].split(b",")
        cells[int(rng.integers(0, len(cells)))] = [b"nan", b"", b"abc", b"inf", b"1e999", b"-"][
            int(rng.integers(0, 6))
        ]
        lines[i] = b",".join(cells)
        return b"\n".join(lines)
    if kind == "semicolon":
        return raw.replace(b",", b";")
    if kind == "nul":
        return raw[:5] + b"\x00" + raw[5:]
    return b""


@settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    reader=st.sampled_from(sorted(READERS)),
    kind=st.sampled_from(
        ["bom", "bom_crlf", "latin1", "cut", "insert", "cell", "semicolon", "nul", "empty"]
    ),
    seed=st.integers(0, 2**16),
)
def test_damaged_files_are_read_or_refused(
    tmp_path_factory: pytest.TempPathFactory, reader: str, kind: str, seed: int
) -> None:
    """Every reader, every damage: a BOM (with or without CRLF) gives exactly the plain
    file's numbers; anything else is read or refused with one ProblemError naming the
    file -- never a raw UnicodeDecodeError/ValueError/IndexError."""
    rng = np.random.default_rng(seed)
    make, read = READERS[reader]
    d = tmp_path_factory.mktemp("damaged")
    plain, damaged = d / "plain.csv", d / "damaged.csv"
    raw = make(rng).encode()
    plain.write_bytes(raw)
    damaged.write_bytes(_mutate(raw, kind, rng))
    ref = read(plain)
    try:
        got = read(damaged)
    except ProblemError as exc:
        assert kind not in ("bom", "bom_crlf"), f"a BOM file was refused: {exc}"
        assert "damaged.csv" in str(exc), f"the message does not name the file: {exc}"
        return
    if kind in ("bom", "bom_crlf"):
        _same_reading(got, ref)


def _same_reading(a: Any, b: Any) -> None:
    """The same parsed content: dict/tuple/dataclass fields compared array by array (the
    same decimal text is parsed, so the floats are identical)."""
    if isinstance(a, tuple):
        for x, y in zip(a, b, strict=True):
            _same_reading(x, y)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _same_reading(a[k], b[k])
    elif hasattr(a, "__dataclass_fields__"):
        for k in a.__dataclass_fields__:
            _same_reading(getattr(a, k), getattr(b, k))
    elif isinstance(a, np.ndarray | list | float | int):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    else:
        assert a == b


# ----------------------------------------------------- Monte Carlo under faults
@settings(
    max_examples=30,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    p=st.sampled_from([0.0, 0.1, 0.5, 1.1]),
    stop=st.integers(0, 40),
    damage=st.sampled_from(["none", "cut", "garbage", "empty", "blank"]),
    seed=st.integers(0, 1000),
)
def test_montecarlo_resume_after_faults_equals_one_run(
    tmp_path_factory: pytest.TempPathFactory, p: float, stop: int, damage: str, seed: int
) -> None:
    """Trials that raise, a run stopped after ``stop`` trials, and a checkpoint damaged
    the way a crash leaves it (last line cut, garbage appended, emptied, blank lines):
    the resumed study equals one uninterrupted run -- the same successful trials with
    bit-identical values and the same recorded failures."""
    from tests.harness_adapters import Flaky

    ckpt = tmp_path_factory.mktemp("mc") / "c.jsonl"
    once = mc.run(Flaky(p), 40, seed, scheduler="serial")
    assert once.n_ok + len(once.failures) == 40
    if stop:
        mc.run(Flaky(p), stop, seed, scheduler="serial", checkpoint=ckpt)
        raw = ckpt.read_bytes()
        if damage == "cut":
            raw = raw[: max(len(raw) - 7, 0)]
        elif damage == "garbage":
            raw = raw + b'{"trial": 3, "val\xff\n[1, 2\n'
        elif damage == "empty":
            raw = b""
        elif damage == "blank":
            raw = raw.replace(b"\n", b"\n\n")
        ckpt.write_bytes(raw)
    res = mc.run(Flaky(p), 40, seed, scheduler="serial", checkpoint=ckpt)
    np.testing.assert_array_equal(res.trials, once.trials)
    assert res.failures == once.failures
    for k in once.values:
        np.testing.assert_array_equal(res.values[k], once.values[k])
