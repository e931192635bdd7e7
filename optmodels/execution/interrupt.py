"""Ctrl-C after what had finished was saved: :class:`Interrupted`."""

from __future__ import annotations

from typing import Any

__all__ = ["Interrupted"]


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a study or a comparison sweep, after what had finished was saved.

    A ``KeyboardInterrupt`` (so ``except Exception`` does not swallow it) whose message
    is one line saying what was kept; ``partial`` is the partial result (a
    ``MonteCarloResult`` with ``interrupted=True``, or the sweep's rows)."""

    def __init__(self, message: str, partial: Any = None) -> None:
        super().__init__(message)
        self.partial = partial

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "interrupted"
