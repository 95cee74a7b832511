"""The identification at the time steps that are simulated: the model's own and the run's (design §14.2).

:func:`~bioform_mj.assess.identify.identify` measures a robot dominated by wheel damping at a step fine enough that
MuJoCo integrates the damping as the continuous model (``DRAG_STEP / k``). A run does not: it steps at its
``sim.physics_dt``, ``robot check`` alone at the model's own step. A paper robot with wheel damping
13.9 N·m·s/rad (a drag rate of 111 1/s, 556 1/s turning) identifies at 3.6e-5 s within 7 % of the formula, at
the run's 1 ms a −91 %, b −85 %, and at its own 2 ms not at all: the verdict of the fine step says nothing
about the robot the run simulates. :func:`identify_at_steps` repeats the identification at each simulated step
that differs from the one measured; :func:`step_reasons` turns what it finds into ``robot check``'s reasons.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["STEP_SAME", "identify_at_steps", "step_reasons"]

#: two time steps closer than this (relative) are one
STEP_SAME = 0.01


def _row(what: str, dt: float, res: dict[str, Any]) -> dict[str, Any]:
    """One row of :func:`identify_at_steps` from an identification result ``res`` at step ``dt`` (s)."""
    ok = bool(res.get("identifiable"))
    return {
        "at": what,
        "timestep_s": float(dt),
        "identifiable": ok,
        "a": res["identified"]["a"] if ok else None,
        "b": res["identified"]["b"] if ok else None,
        "relative_error": res["relative_error"] if ok else {"a": None, "b": None},
        "not_identified": None if ok else res.get("not_identified"),
    }


def identify_at_steps(
    entry: Any, ident: dict[str, Any], model_step: float, run_step: float | None = None
) -> list[dict[str, Any]]:
    """``ident`` (an :func:`~bioform_mj.assess.identify.identify` result) and the identification of ``entry`` at
    ``model_step`` (the file's own, s) and ``run_step`` (the run's ``sim.physics_dt``, s) where they differ
    from the step already measured (by more than :data:`STEP_SAME`): one row per step, ``at``
    (``identification``, ``model``, ``run`` or ``model and run``), ``timestep_s``, ``identifiable``, ``a``,
    ``b``, ``relative_error`` against the formula, ``not_identified``."""
    from bioform_mj.assess.identify import identify

    rows = [_row("identification", ident["test"]["timestep_s"], ident)]
    wanted: list[tuple[str, float]] = []
    for what, dt in (("model", model_step), ("run", run_step)):
        if dt is None or not (math.isfinite(dt) and dt > 0):
            continue
        same = [w for w in wanted if abs(dt / w[1] - 1) <= STEP_SAME]
        if same:
            wanted[wanted.index(same[0])] = (f"{same[0][0]} and {what}", same[0][1])
        else:
            wanted.append((what, float(dt)))
    for what, dt in wanted:
        if abs(dt / rows[0]["timestep_s"] - 1) <= STEP_SAME:
            rows[0]["at"] += f", {what}"
            continue
        try:
            res = identify(entry, timestep=dt)
        except (ArithmeticError, np.linalg.LinAlgError) as exc:
            res = {"identifiable": False, "not_identified": f"{type(exc).__name__}: {exc}"}
        rows.append(_row(what, dt, res))
    return rows


def step_reasons(
    rows: list[dict[str, Any]], drag_rate: float, warn_at: float, fail_at: float, simulated: str = "model"
) -> tuple[list[str], list[str]]:
    """``(fail, warn)`` reasons of :func:`identify_at_steps`' rows at steps other than the one measured: a robot
    that cannot be identified there, or one more than ``fail_at`` (``warn_at``) off the formula (relative) — a
    fail only at the step that is ``simulated`` (``model`` for ``robot check``, ``run`` before a run; at the
    other, a warning). ``drag_rate``: the wheels' largest drag rate k, 1/s (the usual cause: MuJoCo integrates
    the damping coarsely where ``k dt`` is not small)."""
    from bioform_mj.assess.identify import DRAG_STEP

    fail: list[str] = []
    warn: list[str] = []
    measured = rows[0]["timestep_s"]
    for row in rows[1:]:
        where = {"model": "the model's own step", "run": "the run's step"}.get(
            row["at"], "the model's own and run's step"
        )
        head = f"at {where} {row['timestep_s']:g} s (identified at {measured:.2g} s)"
        fix = (
            f": MuJoCo integrates the wheel drag k = {drag_rate:.3g} 1/s coarsely there (k dt = "
            f"{drag_rate * row['timestep_s']:.2g}); run with sim.physics_dt <= {DRAG_STEP / drag_rate:.2g} s"
            if drag_rate > 0
            else ""
        )
        sink = fail if simulated in row["at"] else warn
        if not row["identifiable"]:
            sink.append(f"{head} the robot cannot be identified ({row['not_identified']}){fix}")
            continue
        err = row["relative_error"]
        worst = max(abs(err["a"]), abs(err["b"]))
        msg = f"{head} a = {row['a']:.4g} ({err['a']:+.1%}), b = {row['b']:.4g} ({err['b']:+.1%}) from the formula{fix}"
        if worst > fail_at:
            sink.append(msg)
        elif worst > warn_at:
            warn.append(msg)
    return fail, warn
