"""The bias field's rooms (issue 23 item 2): its modules in the order the data travels.

Stages, in order: inputs → tracks → field data → selection → use. A module imports only
modules of its own or an earlier stage (top-level or lazy imports alike), and no module
imports another module's private (underscored) name. The known exceptions are listed
here with the reason, so that a new one fails this test.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import optmodels.biasfield as bf
from optmodels.biasfield import polyline

PACKAGE = Path(bf.__file__).parent

#: The stage of every module of optmodels.biasfield (``__init__`` sees them all).
STAGES: dict[str, int] = {
    # 0 inputs: the tables, their geometry, the files, the cleaning, the truth models
    "about": 0,
    "geometry": 0,
    "geometry3d": 0,
    "fields": 0,
    "paths": 0,
    "tables": 0,
    "cleaning": 0,
    "ingest": 0,
    "heights": 0,
    "recording": 0,
    "frames": 0,
    # 1 tracks: the polyline fits (3) and the parametric baseline (2)-(4)
    "polyline": 1,
    "tracks": 1,
    "baseline": 1,
    # 2 field data: cells, averages (6)-(7), FieldData and its sets (10), the chain's owner
    "data": 2,
    "averaging": 2,
    "cells": 2,
    "pipeline": 2,
    # 3 selection, in the one skeleton: the original problem (8)-(10), the solution, the
    # re-checks and the gate, closed form (11), the generic QP and Lipschitz SOCP
    "problem": 3,
    "solution": 3,
    "verify": 3,
    "closedform": 3,
    "generic": 3,
    # 4 use: the map, correcting plots, registration, ADS-B as the referee
    "fieldmap": 4,
    "correction": 4,
    "registration": 4,
    "summary": 4,
    "usage": 4,
    "referee": 4,
    "referee_system": 4,
}

STAGE_NAMES = ("inputs", "tracks", "field data", "selection", "use")

#: Imports against the flow, with the reason (module, imported module).
UPSTREAM_ALLOWED = {
    # FieldSolution.map/at/covered return the use layer's FieldMap (public API); the
    # import is lazy and the map is cached on the solution
    ("solution", "usage"),
}

#: Private names imported across modules (module, imported module, name): files owned by
#: another helper in issue 23 (see notes/rooms.md "For the integrator").
PRIVATE_ALLOWED: set[tuple[str, str, str]] = set()


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(imported biasfield module, names) of every import statement in ``path``."""
    out: list[tuple[str, list[str]]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [a.name for a in node.names]
            if node.module == "optmodels.biasfield":
                out.extend((n, []) for n in names if n in STAGES)
            elif node.module.startswith("optmodels.biasfield."):
                out.append((node.module.split(".")[2], names))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("optmodels.biasfield."):
                    out.append((a.name.split(".")[2], []))
    return out


def test_every_module_has_a_stage() -> None:
    found = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__"}
    assert found == set(STAGES), found ^ set(STAGES)


@pytest.mark.parametrize("module", sorted(STAGES))
def test_imports_follow_the_data(module: str) -> None:
    for target, _ in _imports(PACKAGE / f"{module}.py"):
        if (module, target) in UPSTREAM_ALLOWED:
            continue
        assert STAGES[target] <= STAGES[module], (
            f"{module} ({STAGE_NAMES[STAGES[module]]}) imports {target} "
            f"({STAGE_NAMES[STAGES[target]]}), a later stage"
        )


@pytest.mark.parametrize("module", [*sorted(STAGES), "__init__"])
def test_no_private_name_crosses_modules(module: str) -> None:
    for target, names in _imports(PACKAGE / f"{module}.py"):
        for name in names:
            if name.startswith("_") and not name.startswith("__"):
                assert (module, target, name) in PRIVATE_ALLOWED, (
                    f"{module} imports the private {target}.{name}"
                )


def test_allowed_exceptions_are_still_needed() -> None:
    """An exception that no import uses any more is removed from the lists above."""
    used_up = set()
    used_priv = set()
    for module in STAGES:
        for target, names in _imports(PACKAGE / f"{module}.py"):
            if STAGES[target] > STAGES[module]:
                used_up.add((module, target))
            used_priv.update((module, target, n) for n in names if n.startswith("_"))
    assert UPSTREAM_ALLOWED <= used_up
    assert PRIVATE_ALLOWED <= used_priv


def _block_tridiagonal(rng: np.random.Generator, k: int) -> tuple[np.ndarray, ...]:
    """A random SPD block-tridiagonal N (2×2 blocks) as (diag, upper, rhs) and dense."""
    a = rng.normal(size=(2 * k + 6, 2 * k))
    mask = np.abs(np.subtract.outer(np.arange(2 * k) // 2, np.arange(2 * k) // 2)) <= 1
    n = (a.T @ a + 2 * k * np.eye(2 * k)) * mask
    diag = np.stack([n[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] for j in range(k)])
    upper = np.stack([n[2 * j : 2 * j + 2, 2 * j + 2 : 2 * j + 4] for j in range(k - 1)])
    rhs = rng.normal(size=(k, 2))
    return diag, upper, rhs, n


def test_band_solves_equal_the_dense_inverse() -> None:
    """θ = N⁻¹b and the block band of N⁻¹ from the block Cholesky recursion (one piece and
    the batched arrays, pieces of different sizes) against numpy's dense solve/inverse."""
    rng = np.random.default_rng(23)
    bands, dense = [], []
    for k in (2, 5, 9, 3):
        diag, upper, rhs, n = _block_tridiagonal(rng, k)
        bands.append((diag, upper, rhs))
        dense.append((np.linalg.solve(n, rhs.reshape(-1)), np.linalg.inv(n)))
    batched = polyline.solve_bands(bands)
    for (diag, upper, rhs), (theta_ref, inv), got in zip(bands, dense, batched, strict=True):
        k = diag.shape[0]
        one = polyline.solve_band(diag, upper, rhs)
        for sol in (one, got):
            assert sol is not None
            theta, cdiag, cnext = sol
            np.testing.assert_allclose(theta.reshape(-1), theta_ref, rtol=1e-10, atol=1e-12)
            for j in range(k):
                np.testing.assert_allclose(
                    cdiag[j], inv[2 * j : 2 * j + 2, 2 * j : 2 * j + 2], rtol=1e-10, atol=1e-13
                )
            for j in range(k - 1):
                np.testing.assert_allclose(
                    cnext[j], inv[2 * j : 2 * j + 2, 2 * j + 2 : 2 * j + 4], rtol=1e-10, atol=1e-13
                )


def test_band_solve_refuses_a_singular_matrix() -> None:
    """A normal matrix that is not positive definite gives None (the piece is dropped)."""
    diag = np.array([np.eye(2), np.zeros((2, 2))])
    upper = np.zeros((1, 2, 2))
    rhs = np.ones((2, 2))
    assert polyline.solve_band(diag, upper, rhs) is None
    assert polyline.solve_bands([(diag, upper, rhs)]) == [None]
