"""Shared checks and types."""

import json

import numpy as np
import pytest

from optmodels.core import (
    ProblemError,
    Solution,
    SolveError,
    Status,
    as_finite_array,
    check_spd,
    check_spd_stack,
)


def test_as_finite_array_names_argument() -> None:
    with pytest.raises(ProblemError, match="points: 1 entries are NaN"):
        as_finite_array("points", [[1.0, np.nan, 2.0]])
    with pytest.raises(ProblemError, match=r"points: expected shape \(\*, 3\)"):
        as_finite_array("points", np.zeros((4, 2)), shape=(None, 3))
    with pytest.raises(ProblemError, match="points: not a numeric array"):
        as_finite_array("points", [["a", "b"]])


def test_spd_checks() -> None:
    check_spd("cov", np.eye(3))
    with pytest.raises(ProblemError, match="cov is not symmetric"):
        check_spd("cov", np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(ProblemError, match=r"cov is not positive definite"):
        check_spd("cov", np.diag([1.0, -1.0]))
    stack = np.stack([np.eye(2), np.diag([1.0, 0.0])])
    with pytest.raises(ProblemError, match=r"cov\[1\]"):
        check_spd_stack("cov", stack)


def test_solution_require_ok_and_json() -> None:
    good = Solution(
        status=Status.OPTIMAL, objective=1.0, method="x", residuals={"a": 1e-12, "b": 3e-10}
    )
    assert good.require_ok() is good
    assert good.max_residual == 3e-10
    json.dumps(good.to_dict())
    bad = Solution(status=Status.ITERATION_LIMIT, objective=float("nan"), method="x")
    with pytest.raises(SolveError, match="iteration_limit") as exc:
        bad.require_ok()
    assert exc.value.solution is bad
    assert json.loads(json.dumps(bad.to_dict()))["objective"] is None


# ------------------------------------------------- ragged / object arrays (issue 28.4)
RAGGED = [
    [[1.0, 2.0, 3.0], [4.0, 5.0]],  # rows of different lengths
    [1.0, [2.0, 3.0]],  # a scalar beside a row
    [[[1.0, 2.0], [3.0, 4.0]], [[1.0, 2.0], [3.0]]],  # ragged one level down
    np.array([np.zeros(2), np.zeros(3)], dtype=object),  # an object array of rows
    [np.zeros(2), np.zeros(3)],
]


@pytest.mark.parametrize("value", RAGGED, ids=range(len(RAGGED)))
def test_ragged_input_is_one_problem_error(value: object) -> None:
    with pytest.raises(ProblemError, match=r"^points: a ragged nested sequence"):
        as_finite_array("points", value)


@pytest.mark.parametrize(
    "value, what",
    [
        (["1.5", "2"], "text entries"),
        ([1.0, None], "NoneType"),
        ("1.5", "str"),
        (None, "None"),
        ({"a": 1.0}, "dict"),
        ([1.0, 2j], "complex"),
        (np.array(["2026-01-01"], dtype="datetime64[ns]"), "datetime64"),
        (np.array([1.0, "x"], dtype=object), "str"),
    ],
)
def test_non_numeric_input_is_refused(value: object, what: str) -> None:
    with pytest.raises(ProblemError, match=f"^x: .*{what}"):
        as_finite_array("x", value)


def test_numeric_object_arrays_and_booleans_are_read() -> None:
    got = as_finite_array("x", np.array([1, 2.5, np.float32(3.0), True], dtype=object))
    np.testing.assert_array_equal(got, [1.0, 2.5, 3.0, 1.0])
    assert got.dtype == np.float64


# ------------------------------------------------------------- the one JSON encoder
def test_one_encoder_for_to_dict_and_cli() -> None:
    """Solution.to_dict(), core.json_text and the CLI's --json printer give the same
    strict document: NaN and ±inf are null (README, "Command line"), arrays lists."""
    from optmodels.cli.contract import _dumps
    from optmodels.core import json_text, to_jsonable

    sol = Solution(
        status=Status.OPTIMAL,
        objective=float("inf"),
        method="x",
        residuals={"a": float("-inf"), "b": 1e-9},
        info={
            "v": np.array([1.0, np.nan, np.inf]),
            "k": np.int64(3),
            "t": (np.float32(0.5), -np.inf),
        },
    )
    want = {
        "objective": None,
        "residuals": {"a": None, "b": 1e-9},
        "info": {"v": [1.0, None, None], "k": 3, "t": [0.5, None]},
    }
    d = sol.to_dict()
    for key, value in want.items():
        assert d[key] == value
    assert d["status"] == "optimal"
    assert json.loads(json_text(sol.to_dict())) == d
    assert json.loads(_dumps({"solution": sol.to_dict(), "bound": np.inf})) == {
        "solution": d,
        "bound": None,
    }
    assert to_jsonable({1: np.bool_(True)}) == {"1": True}
    with pytest.raises(TypeError):
        json_text({"x": object()})


# ----------------------------------------------------------- Solution as a table
def test_plane_solution_rows_and_frame() -> None:
    from optmodels import plane

    rng = np.random.default_rng(7)
    pts = rng.normal(size=(9, 3)) * [100.0, 100.0, 1.0]
    sol = plane.closed_form(plane.PlaneData(pts, np.eye(3)))
    rows = sol.to_rows()
    assert [r["point"] for r in rows] == list(range(9))
    got = np.array([[r["x_m"], r["y_m"], r["z_m"]] for r in rows])
    np.testing.assert_array_equal(got, sol.projected)
    # the projections lie on the fitted plane n·x = d (independent re-check)
    np.testing.assert_allclose(got @ sol.normal, sol.offset, atol=1e-9 * 100)
    df = sol.to_frame()
    assert list(df.columns) == ["point", "x_m", "y_m", "z_m"]
    np.testing.assert_array_equal(df[["x_m", "y_m", "z_m"]].to_numpy(), sol.projected)
    assert df.attrs["status"] == "optimal" and df.attrs["objective"] == sol.objective


def test_field_solution_frame_per_cell_and_radar() -> None:
    from optmodels import biasfield as bf

    fd = bf.synthetic_field_data(0, cells=12)[0]
    sol = bf.closed_form(fd)
    df = sol.to_frame()
    k, m = sol.field.shape[:2]
    assert len(df) == k and list(df["cell"]) == list(range(k))
    np.testing.assert_array_equal(df[["x_m", "y_m"]].to_numpy(), sol.centers)
    for j in range(m):
        np.testing.assert_array_equal(df[f"radar{j}_range_bias_m"], sol.field[:, j, 0])
        np.testing.assert_array_equal(df[f"radar{j}_azimuth_bias_rad"], sol.field[:, j, 1])
        np.testing.assert_array_equal(df[f"radar{j}_range_active"], sol.active[:, j, 0])
    assert len(sol.to_rows()) == k


def test_trajectory_and_assignment_rows() -> None:
    from optmodels import assignment as asg
    from optmodels import trajectories as tr

    rng = np.random.default_rng(3)
    t = [np.arange(10.0), np.arange(12.0)]
    sol = tr.closed_form(
        tr.TrajectoryData(t, [2 * t[0] + rng.normal(size=10), -t[1] + rng.normal(size=12)], 1.0)
    )
    rows = sol.to_rows()
    np.testing.assert_array_equal([r["velocity"] for r in rows], sol.velocity)
    np.testing.assert_array_equal([r["start"] for r in rows], sol.start)
    a = asg.AssignmentData(
        np.array([[0.0, 0.0], [10.0, 0.0]]),
        np.stack([np.eye(2)] * 2),
        np.array([[0.1, -0.2], [9.8, 0.3], [5.0, 5.0]]),
        np.eye(2),
        400.0,
        0.9,
        0.2,
    )
    s = asg.solve(a)
    assert [r["group"] for r in s.to_rows()] == s.assignment.tolist()
    assert s.to_frame()["measurement"].tolist() == [0, 1, 2]


def test_non_tabular_and_failure_forms() -> None:
    from optmodels import fusion as fu
    from optmodels import plane
    from optmodels.core import failure

    with pytest.raises(ProblemError, match=r"FusionSolution.to_rows: .*not a table"):
        fu.fuse([1.0, 2.0], np.eye(2), [1.0, 3.0], 2 * np.eye(2)).to_rows()
    with pytest.raises(ProblemError, match=r"Solution.to_rows"):
        Solution(status=Status.OPTIMAL, objective=0.0, method="x").to_frame()
    f = failure(plane.PlaneSolution, "closed_form", "collinear")
    assert f.to_rows() == []
    assert list(f.to_frame().columns) == ["point", "x_m", "y_m", "z_m"]


def test_json_document_refuses_duplicate_keys_and_constants() -> None:
    from optmodels.core import json_document

    assert json_document('{"a": [1, 2.5], "b": {"c": null}}', where="case.json") == {
        "a": [1, 2.5],
        "b": {"c": None},
    }
    with pytest.raises(ProblemError, match=r"^case.json: the key 'pd' is given twice"):
        json_document('{"pd": 0.9, "rho": 0.1, "pd": 0.5}', where="case.json")
    with pytest.raises(ProblemError, match=r"^x: the key 'k' is given twice"):
        json_document('[{"o": {"k": 1, "k": 1}}]', where="x")
    with pytest.raises(ProblemError, match=r"^--param: NaN is not valid JSON"):
        json_document('{"a": NaN}', where="--param")
    with pytest.raises(ProblemError, match=r"^f: not valid JSON \(line 2, column 1"):
        json_document('{"a": 1,\n}', where="f")
    with pytest.raises(ProblemError, match=r"nested too deeply"):
        json_document("[" * 100000 + "]" * 100000, where="f")


def test_empty_matrices_are_one_problem_error() -> None:
    """(0, 0) covariances (fuse on empty arrays raised a raw reshape ValueError)."""
    from optmodels import fusion as fu

    with pytest.raises(ProblemError, match=r"^cov: empty \(0 × 0\)"):
        check_spd("cov", np.zeros((0, 0)))
    check_spd_stack("covs", np.zeros((0, 2, 2)))  # no matrices: nothing to check
    for args in (
        (np.zeros(0), np.zeros((0, 0)), np.zeros(0), np.zeros((0, 0))),
        (np.zeros((0, 0)),) * 4,
    ):
        with pytest.raises(ProblemError, match=r"^fusion.fuse S1: empty"):
            fu.fuse(*args)
    with pytest.raises(ProblemError, match=r"^fusion.weight_matrix S1: empty"):
        fu.weight_matrix(np.zeros((0, 0)), np.zeros((0, 0)))
