"""The shape of a robot-check cache entry (design §14.2; issue 28 item 3: state that heals).

:func:`entry_problem` says why a JSON value read from the cache is not an entry a run can use
(``""``: it is). :func:`bioform_mj.assess.prerun.cached_check` then ignores it, checks the robot again and
rewrites the entry, with one warning naming the file: a cache never makes a run fail.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["VERDICTS", "entry_problem"]

#: the verdicts a cache entry may hold (``error`` entries are never written)
VERDICTS = ("pass", "warn", "fail")


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _pair(x: Any, optional: bool) -> bool:
    """``{"a": number, "b": number}`` (each may be None when ``optional``: not identified)."""
    return (
        isinstance(x, dict)
        and {"a", "b"} <= set(x)
        and all(_number(x[k]) or (optional and x[k] is None) for k in ("a", "b"))
    )


def entry_problem(entry: Any, fmt: int) -> str:
    """Why ``entry`` is not a robot-check cache entry of format ``fmt`` (``""``: it is one).

    Expected: ``{"format": fmt, "verdict": "pass"|"warn"|"fail", "fail_reasons": [str, …],
    "cause": None | {"kind": str, "detail": str}, "formula": {"a", "b"} (numbers),
    "identified": {"a", "b"} (numbers or None), "relative_error": {"a", "b"} (numbers or None),
    "resistances": [{"kind": str, …}, …], "seconds": number}``.
    """
    if not isinstance(entry, dict):
        return f"not a JSON object ({type(entry).__name__})"
    if entry.get("format") != fmt:
        return f"format {entry.get('format')!r}, not {fmt}"
    if entry.get("verdict") not in VERDICTS:
        return f"verdict {entry.get('verdict')!r} is not one of {', '.join(VERDICTS)}"
    reasons = entry.get("fail_reasons")
    if not isinstance(reasons, list) or not all(isinstance(r, str) for r in reasons):
        return "fail_reasons is not a list of strings"
    cause = entry.get("cause", "absent")
    if cause is not None and not (
        isinstance(cause, dict) and isinstance(cause.get("kind"), str) and isinstance(cause.get("detail"), str)
    ):
        return "cause is neither null nor {kind, detail}"
    if not _pair(entry.get("formula"), optional=False):
        return "formula is not {a, b} numbers"
    for key in ("identified", "relative_error"):
        if not _pair(entry.get(key), optional=True):
            return f"{key} is not {{a, b}} numbers or null"
    res = entry.get("resistances")
    if not isinstance(res, list) or not all(isinstance(r, dict) and isinstance(r.get("kind"), str) for r in res):
        return "resistances is not a list of {kind, …}"
    if not _number(entry.get("seconds")):
        return "seconds is not a number"
    return ""
