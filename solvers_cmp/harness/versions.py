"""The ``solver_version`` column: the package and version behind a solver name."""

from __future__ import annotations

import functools
import platform
from importlib import metadata

#: Non-CVXPY solver names of the adapters → package (CVXPY's come from
#: :data:`optmodels.backends.cvxpy_backend.PIP_NAMES`; the rest are CasADi plugins).
_OTHER_PACKAGES = {"numpy": "numpy", "scipy": "scipy", "SCIPY": "scipy"}


@functools.cache
def solver_version(solver: str) -> str:
    """Package and version behind a solver name (CasADi plugins: the casadi version)."""
    if solver == "python":
        return f"python {platform.python_version()}"
    from optmodels.backends.cvxpy_backend import PIP_NAMES

    pkg = PIP_NAMES.get(solver) or _OTHER_PACKAGES.get(solver, "casadi")
    try:
        return f"{pkg} {metadata.version(pkg)}"
    except metadata.PackageNotFoundError:
        return pkg
