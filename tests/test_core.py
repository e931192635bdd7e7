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
    good = Solution(status=Status.OPTIMAL, objective=1.0, method="x",
                    residuals={"a": 1e-12, "b": 3e-10})
    assert good.require_ok() is good
    assert good.max_residual == 3e-10
    json.dumps(good.to_dict())
    bad = Solution(status=Status.ITERATION_LIMIT, objective=float("nan"), method="x")
    with pytest.raises(SolveError, match="iteration_limit") as exc:
        bad.require_ok()
    assert exc.value.solution is bad
    assert json.loads(json.dumps(bad.to_dict()))["objective"] is None
