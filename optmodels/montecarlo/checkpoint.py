"""The Monte Carlo checkpoint format: JSON lines, a header ``{"study": NAME, "seed": SEED}``
(names only, no module paths), then one line per finished chunk (``[[i, {name: value}],
...]``) and one per chunk with failures (``{"failed": [[i, message], ...]}``).
``_load_checkpoint`` reads them back (and repairs a damaged file through
:class:`~optmodels.execution.LineLog`).
"""

from __future__ import annotations

import json
from typing import Any

from optmodels.core import ProblemError
from optmodels.execution import LineLog


def _pair_ok(p: Any) -> bool:
    return (
        isinstance(p, list)
        and len(p) == 2
        and isinstance(p[0], int)
        and not isinstance(p[0], bool)
        and p[0] >= 0
    )


def _load_checkpoint(
    ck: LineLog, header: dict[str, Any]
) -> tuple[dict[int, dict[str, float]], dict[int, str], int]:
    """Finished and failed trials recorded in the checkpoint, and the number of lines
    skipped. Writes the header of a new (or empty) file; repairs a damaged one."""
    head_line = json.dumps(header)
    lines, tail = ck.open_with_header(head_line, "a Monte Carlo checkpoint")
    if not lines:
        return {}, {}, 0
    try:
        head = json.loads(lines[0])
    except (json.JSONDecodeError, UnicodeDecodeError):
        head = None
    if head != header:
        what = (
            "is not a Monte Carlo checkpoint (its first line is not a header)"
            if not isinstance(head, dict) or "study" not in head
            else f"belongs to another study or seed ({head})"
        )
        raise ProblemError(
            f"{ck.what}: {ck.path} {what}; expected {header}. Use another path or delete it."
        )
    done: dict[int, dict[str, float]] = {}
    failed: dict[int, str] = {}
    keep, dropped = [head_line], []
    for raw in lines[1:]:
        if not raw.strip():
            continue  # blank lines (older versions started each resume with one)
        try:
            rec = json.loads(raw)
            if isinstance(rec, list) and all(
                _pair_ok(p)
                and isinstance(p[1], dict)
                and p[1]
                and all(
                    isinstance(v, int | float) and not isinstance(v, bool) for v in p[1].values()
                )
                for p in rec
            ):
                for i, vals in rec:
                    done[i] = {str(k): float(v) for k, v in vals.items()}
            elif (
                isinstance(rec, dict)
                and set(rec) == {"failed"}
                and isinstance(rec["failed"], list)
                and all(_pair_ok(p) and isinstance(p[1], str) for p in rec["failed"])
            ):
                for i, msg in rec["failed"]:
                    failed[i] = msg
            else:
                raise ValueError("not a record")
        except (ValueError, UnicodeDecodeError):  # JSONDecodeError is a ValueError
            dropped.append(raw)
            continue
        keep.append(raw.decode())
    skipped = ck.keep(keep, dropped, tail)
    failed = {i: m for i, m in failed.items() if i not in done}
    return done, failed, skipped
