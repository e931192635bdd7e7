"""What every back-end returns: the common fields of :class:`optmodels.core.Solution`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from optmodels.core import Status


@dataclass
class BackendResult:
    """Outcome of one back-end solve, before the problem module adds its own fields."""

    status: Status
    method: str
    build_time: float
    solve_time: float
    iterations: int | None
    message: str
    objective: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    def common(self) -> dict[str, Any]:
        """Keyword arguments for a :class:`~optmodels.core.Solution` subclass."""
        return {
            "status": self.status,
            "method": self.method,
            "build_time": self.build_time,
            "solve_time": self.solve_time,
            "iterations": self.iterations,
            "message": self.message,
        }
