"""What the study classes share: :func:`_set`, which stores a checked parameter on a frozen
dataclass (in ``__post_init__``). Not a problem's module (its name starts with ``_``, which
no problem's can), so :data:`~optmodels.montecarlo.studies.STUDIES` never looks here.
"""

from __future__ import annotations

from typing import Any


def _set(obj: Any, key: str, value: Any) -> None:
    object.__setattr__(obj, key, value)  # the studies are frozen dataclasses
