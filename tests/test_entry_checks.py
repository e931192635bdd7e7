"""Public entry points behind the package's checks (issue 28 item 4): a bad argument of
plane.angle_error / plane_errors, trajectories.predict / objective / constraint_residuals /
design_matrix, fusion.fused_covariance, io.write_csv / markdown_table is one
:class:`~optmodels.ProblemError` naming the argument (the property sweep,
tests/test_property_sweep.py, generates the values; these are the direct cases), and a good
call still gives the numbers of an independent computation."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from optmodels import ProblemError, io, plane
from optmodels import fusion as fu
from optmodels import trajectories as tr

_N = np.array([0.1, -0.2, 1.0])
_Z = np.array([0.0, 0.0, 1.0])
_S1 = np.array([[2.0, 0.3], [0.3, 1.0]])
_S2 = np.array([[1.0, -0.2], [-0.2, 3.0]])
_W = fu.weight_matrix(_S1, _S2)
_T = [np.arange(6.0), np.arange(5.0)]
_TD = tr.TrajectoryData(_T, [2.0 * _T[0] + 1.0, 1.0 - _T[1]], 1.0)
_RAGGED = [[0.0], [1.0, 1.0]]
_NONE = [[1.0, None, 2.0]] * 2


@pytest.mark.parametrize(
    "call, named",
    [
        (lambda: plane.angle_error(_RAGGED, _Z), "angle_error normal: a ragged"),
        (lambda: plane.angle_error(_N, _NONE), "angle_error true_normal: not a numeric"),
        (lambda: plane.plane_errors(_NONE, 0.0, _Z, 0.0), "plane_errors normal: not a numeric"),
        (lambda: plane.plane_errors(_N, np.nan, _Z, 0.0), "plane_errors offset: NaN"),
        (lambda: plane.plane_errors(_N, "1.5", _Z, 0.0), "plane_errors offset: not a numeric"),
        (lambda: plane.plane_errors(_N, [0.0, 1.0], _Z, 0.0), "plane_errors offset: expected"),
        (lambda: plane.plane_errors(_N, 0.0, _RAGGED, 0.0), "plane_errors true_normal: a ragged"),
        (lambda: tr.predict("x", [0, 0], [0, 0]), "predict data: expected a TrajectoryData"),
        (lambda: tr.objective({"a": 1}, [0, 0], [0, 0]), "objective data: expected a Traj"),
        (
            lambda: tr.constraint_residuals(3.5, "diverging", [0, 0], [0, 0]),
            "constraint_residuals data: expected a TrajectoryData, got float",
        ),
        (lambda: tr.design_matrix("", "parallel"), "design_matrix data: expected a Traj"),
        (lambda: fu.fused_covariance(_W, _RAGGED, _S2), "fused_covariance S1: a ragged"),
        (lambda: fu.fused_covariance(_W, _S1, {"a": 1.0}), "fused_covariance S2: not a numeric"),
        (lambda: fu.fused_covariance(_W * 1j, _S1, _S2), "fused_covariance W: complex"),
        (lambda: fu.fused_covariance(_W, _S1, _S2, _NONE), "fused_covariance s12: not a numeric"),
        (lambda: fu.fused_covariance(_W, np.eye(3), _S2), "fused_covariance S1: expected square"),
        (lambda: fu.fused_covariance(_W[0], _S1, _S2), "fused_covariance W: expected square"),
        (
            lambda: fu.fused_covariance(np.stack([_W] * 3), np.stack([_S1] * 2), _S2),
            "do not broadcast",
        ),
        (lambda: io.markdown_table("ab", ["a"]), "markdown_table rows: expected a sequence"),
        (lambda: io.markdown_table([{"a": 1}], "ab"), "markdown_table columns: expected"),
        (lambda: io.markdown_table([{"a": 1}], {"a": 1}), "markdown_table columns: expected"),
        (lambda: io.markdown_table([{"a": 1}], [[0.0], "a"]), r"markdown_table columns\[0\]"),
        (lambda: io.markdown_table([["a"]], ["a"]), "markdown_table rows: row 0 is a list"),
    ],
)
def test_bad_argument_is_one_problem_error_naming_it(call: Callable[[], Any], named: str) -> None:
    with pytest.raises(ProblemError, match=named):
        call()


@pytest.mark.parametrize("rows", ["", "ab", {"a": 1.0}, 3.5])
def test_write_csv_refuses_rows_that_are_not_a_sequence_of_mappings(
    rows: Any, tmp_path: Path
) -> None:
    out = tmp_path / "r.csv"
    with pytest.raises(ProblemError, match=r"io\.write_csv rows"):
        io.write_csv(out, rows)
    assert not out.exists()


def test_write_csv_reads_rows_of_a_generator_once(tmp_path: Path) -> None:
    """The rows are read into a list first: a generator's rows are all written (the column
    pass used to exhaust it, leaving only the header)."""
    out = tmp_path / "g.csv"
    io.write_csv(out, ({"a": float(i), "b": i} for i in range(3)))
    assert out.read_text().splitlines() == ["a,b", "0,0", "1,1", "2,2"]


def test_plane_errors_keeps_nan_rows_of_unresolved_steps() -> None:
    """NaN offsets stay accepted where the normal row is NaN (PlaneSequence's unresolved
    steps): those rows give NaN, the others their numbers."""
    normals = np.array([_N, [np.nan] * 3])
    ang, off = plane.plane_errors(normals, np.array([5.0, np.nan]), -_Z, 2.0)
    assert np.isnan(ang[1]) and np.isnan(off[1])
    assert off[0] == pytest.approx(-5.0 - 2.0)  # sign of (n, a) aligned to the truth


def test_good_calls_give_the_numbers_of_an_independent_computation() -> None:
    rng = np.random.default_rng(28)
    # angle: arccos of the normalised |dot| (moderate angles, where arccos is accurate)
    n, m = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    cos = np.abs(np.sum(n * m, axis=1)) / (np.linalg.norm(n, axis=1) * np.linalg.norm(m, axis=1))
    np.testing.assert_allclose(plane.angle_error(n, m), np.arccos(cos), rtol=1e-12, atol=1e-12)
    # plane errors: (n, a) flipped to the truth's side, then a − a_true
    a = rng.normal(size=20)
    sign = np.sign(np.sum(n * _Z, axis=1))
    ang, off = plane.plane_errors(n, a, _Z, 0.5)
    np.testing.assert_allclose(ang, plane.angle_error(n, _Z), rtol=0, atol=0)
    np.testing.assert_allclose(off, sign * a - 0.5, rtol=0, atol=0)
    # fused covariance: (I − W)S1(I − W)ᵀ + WS2Wᵀ + cross terms, and (C1 + C2)⁻¹ for the
    # paper's W
    s12 = np.array([[0.1, 0.05], [0.0, -0.1]])
    v = np.eye(2) - _W
    want = v @ _S1 @ v.T + _W @ _S2 @ _W.T + v @ s12 @ _W.T + _W @ s12.T @ v.T
    np.testing.assert_allclose(fu.fused_covariance(_W, _S1, _S2, s12), want, rtol=1e-14)
    inv = np.linalg.inv(np.linalg.inv(_S1) + np.linalg.inv(_S2))
    np.testing.assert_allclose(fu.fused_covariance(_W, _S1, _S2), inv, rtol=1e-12)
    stack = fu.fused_covariance(np.stack([_W, np.eye(2)]), _S1, _S2)  # stacks broadcast
    np.testing.assert_allclose(stack[1], _S2, rtol=1e-15)
    # trajectories: the lines y = 2t + 1 and y = 1 − t give 0 objective, 0 violations
    start, velocity = np.array([[1.0], [1.0]]), np.array([[2.0], [-1.0]])
    np.testing.assert_array_equal(
        tr.predict(_TD, start, velocity)[:, 0], np.r_[2.0 * _T[0] + 1.0, 1.0 - _T[1]]
    )
    assert tr.objective(_TD, start, velocity) == pytest.approx(0.0, abs=1e-20)
    assert tr.constraint_residuals(_TD, "diverging", start, velocity) == {
        "shared_start": 0.0,
        "shared_velocity": 0.0,
    }
    a_mat = tr.design_matrix(_TD, "diverging").toarray()
    assert a_mat.shape == (11, 3)
    np.testing.assert_array_equal(a_mat[:, 0], np.ones(11))
    np.testing.assert_array_equal(a_mat[:, 1:].sum(axis=1), np.r_[_T[0], _T[1]])
    # the Markdown table
    table = io.markdown_table([{"a": 1 / 3, "b": "x"}, {"b": 2}], ("a", "b"), {"a": ".2f"})
    assert table == "| a | b |\n|---|---|\n| 0.33 | x |\n|  | 2 |\n"
