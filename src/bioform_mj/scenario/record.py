"""A run's own record: the resolved configuration as a scenario that repeats the run bit for bit.

:func:`resolved_config` is what ``summary.json`` holds as ``config`` and ``resolved.toml`` as a file:
every value as the run used it (the scale already applied, so ``formation.scale = 1``; robot models
by shipped name or absolute path). ``bioform run runs/X/resolved.toml`` or ``bioform run
runs/X/summary.json`` loads it as it stands (:func:`bioform_mj.scenario.loader.load`) and gives the same log
on the same machine and engine (``tests/test_scenario_record.py``). :func:`to_toml` writes it as TOML
(``tomllib`` reads TOML but writes none).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import UNSAFE_TEXT
from bioform_mj.robots.refs import is_shipped
from bioform_mj.scenario.config import Scenario


def resolved_config(sc: Scenario) -> dict[str, Any]:
    """The configuration of ``sc`` as plain data that :func:`~bioform_mj.scenario.loader.load` takes back unchanged.

    ``sc`` is a loaded scenario: its lengths are already × ``formation.scale`` (and the headings'
    jitter resolved), so the record says ``scale = 1`` and loading it does not scale again. Relative
    robot model paths become absolute (the record may be read from another folder)."""
    d = sc.to_dict()
    d["formation"]["scale"] = 1.0
    d["formation"]["time_scale"] = 1.0  # design §21: the times are already × σ

    def absolute(model: str) -> str:
        if is_shipped(model) or Path(model).is_absolute():
            return model
        p = Path(model)
        return str(p.resolve()) if p.is_file() else model

    robots = []
    for r in d["plant"]["robots"]:
        if isinstance(r, dict):
            robots.append({**r, "model": absolute(r["model"])})
        else:
            robots.append(absolute(r))
    d["plant"]["robots"] = robots
    return d


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)  # the shortest text that reads back to the same float
    if isinstance(v, str):
        # JSON's escapes are TOML basic-string escapes; bidi/format characters escaped too (\u202e, issue 28)
        return UNSAFE_TEXT.sub(lambda m: f"\\u{ord(m.group()):04x}", json.dumps(v, ensure_ascii=False))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as TOML")


def to_toml(config: dict[str, Any], header: str = "") -> str:
    """A nested dict of plain values as TOML: top-level values first, then one ``[table]`` per dict;
    arrays of tables (``events``, robot tables) as inline tables."""
    lines = [f"# {ln}" for ln in header.splitlines()]
    tables = {k: v for k, v in config.items() if isinstance(v, dict)}
    for k, v in config.items():
        if k not in tables:
            lines.append(f"{k} = {_value(v)}")
    for name, table in tables.items():
        lines += ["", f"[{name}]"]
        lines += [f"{k} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"
