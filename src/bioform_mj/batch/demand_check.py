"""The batch engine's pre-run demand check (design §21, §11): what a single run says before it starts.

A single MuJoCo run compares the scenario's demand (its ideal twin, :func:`bioform_mj.run.demand.before_run`) with
its robots' limits, warns each exceeded limit and keeps the comparison in ``summary.json: demand``. A batch runs
one scene (one set of robots) for every world; :func:`demand_of_worlds` checks each distinct scenario once — worlds
that differ only in their seed or name are one scenario, so a batch of 256 seeds of one scenario runs one ideal twin
(the seed moves the start jitter, not what the scenario asks; the twin itself is cached across runs and processes,
:func:`bioform_mj.run.demand.peaks`). Each distinct scenario's ``warning:`` lines are said once, naming the worlds
when the batch holds several scenarios; each world's summary gets its scenario's ``demand``. Skipped, as for a
single run, where the robot check is (``BIOFORM_NO_ROBOT_CHECK``) or the plant is not MuJoCo's.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from typing import Any

from bioform_mj.scenario.config import Scenario

__all__ = ["demand_of_worlds", "scenario_key"]


def scenario_key(sc: Scenario) -> str:
    """What makes two worlds' demand the same: the scenario's resolved values without its seed and name."""
    d = sc.to_dict()
    d.pop("name", None)
    d.get("sim", {}).pop("seed", None)
    return json.dumps(d, sort_keys=True, default=str)


def demand_of_worlds(scenarios: Sequence[Scenario], plant: Any, robot_check: dict[str, Any] | None) -> list[Any]:
    """Per world, :func:`bioform_mj.run.demand.before_run` of its scenario (None where not checked: a plant that is
    not MuJoCo's, the robot check skipped). Warns (a ``RobotWarning`` each) every line once per distinct scenario
    (:func:`scenario_key`), before any world runs."""
    from bioform_mj.core.errors import RobotWarning

    if robot_check is None or robot_check.get("skipped"):
        return [None] * len(scenarios)
    from bioform_mj.run.demand import before_run

    groups: dict[str, list[int]] = {}
    for w, sc in enumerate(scenarios):
        groups.setdefault(scenario_key(sc), []).append(w)
    out: list[Any] = [None] * len(scenarios)
    for worlds in groups.values():
        d = before_run(scenarios[worlds[0]], plant, robot_check)
        for w in worlds:
            out[w] = d
        which = "" if len(groups) == 1 else f"world{'s' if len(worlds) > 1 else ''} {_ranges(worlds)}: "
        for line in d["warnings"]:
            warnings.warn(which + line, RobotWarning, stacklevel=3)
    return out


def _ranges(ws: list[int]) -> str:
    """``[0, 1, 2, 5]`` as ``0-2, 5``."""
    parts, start = [], ws[0]
    for a, b in zip(ws, [*ws[1:], None]):
        if b != a + 1:
            parts.append(f"{start}" if start == a else f"{start}-{a}")
            start = b
    return ", ".join(parts)
