"""What a study run gives back: :class:`MonteCarloResult` (values and summary of the
successful trials, the failures) and ``_result`` which builds it from the engine's
finished and failed trials.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from optmodels.montecarlo.studies import Study

__all__ = ["MonteCarloResult"]


@dataclass
class MonteCarloResult:
    """Per-trial values of the successful trials and the study's summary.

    ``trials`` are the indices of the successful trials (ascending) and ``values[key][j]``
    is trial ``trials[j]``'s value; ``summary`` is computed over them alone (``n_ok``
    trials). ``failures`` lists ``(index, message)`` of the trials that raised (recorded
    ones from the checkpoint included); ``requested`` the number of trials asked for;
    ``resumed`` how many results came from the checkpoint; ``skipped_lines`` the
    checkpoint lines that could not be read; ``interrupted`` marks a partial result
    (:class:`Interrupted`)."""

    study: str
    seed: int
    trials: np.ndarray
    values: dict[str, np.ndarray]
    summary: dict[str, Any] = field(default_factory=dict)
    resumed: int = 0
    engine: str = ""
    failures: list[tuple[int, str]] = field(default_factory=list)
    requested: int = 0
    skipped_lines: int = 0
    interrupted: bool = False
    summary_error: str = ""

    @property
    def n_ok(self) -> int:
        """Number of successful trials (those the values and the summary are over)."""
        return int(self.trials.size)

    def mean(self, key: str) -> float:
        v = self.values[key]
        return float(np.mean(v)) if v.size else float("nan")

    def se(self, key: str) -> float:
        """Standard error of the mean of ``values[key]`` (NaN below two trials)."""
        v = self.values[key]
        return float(np.std(v, ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")


def _result(
    study: Study,
    name: str,
    seed: int,
    trials: int,
    done: dict[int, dict[str, float]],
    failed: dict[int, str],
    resumed: int,
    engine: str,
    skipped: int,
    interrupted: bool = False,
) -> MonteCarloResult:
    ok = sorted(done)
    fails = dict(failed)
    keys = list(done[ok[0]]) if ok else []
    for i in ok[1:]:
        if set(done[i]) != set(keys):
            fails[i] = f"returned keys {sorted(done[i])}, expected {sorted(keys)}"
    ok = [i for i in ok if i not in fails]
    values = {k: np.array([done[i][k] for i in ok], dtype=float) for k in keys}
    summary: dict[str, Any] = {}
    summary_error = ""
    if ok and hasattr(study, "summarise"):
        try:
            with np.errstate(all="ignore"):
                summary = dict(study.summarise(values))
        except Exception as exc:  # e.g. a covariance from a single trial
            summary_error = f"{type(exc).__name__}: {exc}"[:300]
    return MonteCarloResult(
        name,
        seed,
        np.array(ok, dtype=int),
        values,
        summary,
        resumed,
        engine,
        sorted(fails.items()),
        trials,
        skipped,
        interrupted,
        summary_error,
    )
