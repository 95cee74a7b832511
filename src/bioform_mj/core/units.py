"""Scenario fields that carry their unit (design §21): the one place a key's unit, and why it is kept or where the
paper mixes units, is written; the generated scenario reference and the similarity scaling read it."""

from __future__ import annotations

import dataclasses
from typing import Any


def unit(default: Any, unit: Any, *, kept: str = "", mixed: str = "", **extra: Any) -> Any:
    """A scenario dataclass field with its ``unit`` (a string, or a tuple per element / column) as
    metadata; ``kept``: why the key is not scaled; ``mixed``: the paper's mixed-unit place it is."""
    meta: dict[str, Any] = {"unit": unit, **extra}
    if kept:
        meta["kept"] = kept
    if mixed:
        meta["mixed"] = mixed
    return dataclasses.field(default=default, metadata=meta)
