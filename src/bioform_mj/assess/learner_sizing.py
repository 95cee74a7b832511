"""Opt-in sizing of the sliding gain and the disturbance estimate to the resistance ``robot check`` identifies
(issue 27 item 5; design §14). The paper's defaults stay the paper's: both are off unless a scenario asks.

The paper's torque law (eqs. 38–39) rejects what its model lacks with the sign terms ``c_a sgn(υ̃)``,
``c_b sgn(ω̃)``: a resistance larger than ``c`` (as an acceleration) is not rejected, and the learner reads it
as a smaller ``â`` (design §8, §14). A wheel dead band of ``τ_db`` N·m on ``τ_a`` (on ``τ_b``) is a resistance
of ``a τ_db`` m/s² (``b τ_db`` rad/s²). Two options:

- ``torque.resistance_margin = m`` (> 0): ``c_a, c_b`` at least ``m`` times that resistance, the largest over
  the run's robots (one gain for all followers, as the paper's);
- ``learner.kd_deadband = [kd_a, kd_b]``: the disturbance estimate ``d̂' = −kd S`` (``learner.kd``) switched on
  with these gains where a dead band is identified (its ``d̂`` takes the constant part of the resistance instead
  of ``â``).

The resistance is the identified dead band of ``robot check``'s identification (``prerun``'s cached check: the
same check a run makes anyway); where the check is skipped, the wheel joints' own frictionloss (``2 f`` on both
channels) stands for it and :func:`sizing` says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bioform_mj.control.params import register_sizing
from bioform_mj.plants.base import RobotModels

__all__ = ["DEADBAND_MIN_NM", "resistance", "sizing"]

#: an identified dead band below this (N·m on τ_a or τ_b) is none (the fit's noise on a robot without one)
DEADBAND_MIN_NM = 1e-3


def resistance(sc: Any, plant: Any) -> list[dict[str, Any]]:
    """Per distinct robot of a built MuJoCo ``plant``: ``{"followers", "deadband_torque_Nm": [on τ_a, on τ_b],
    "source"}`` — robot check's identified dead band (``source`` ``"identified"``), or the wheel joints'
    frictionloss ``2 f`` where the check is skipped or identified none (``"frictionloss"``)."""
    from bioform_mj.assess.prerun import cached_check, robot_key
    from bioform_mj.assess.skip import skipped
    from bioform_mj.robots.entries import resolve_robot

    out: list[dict[str, Any]] = []
    entries = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    seen: dict[str, dict[str, Any]] = {}
    for i, e in enumerate(entries[: sc.n]):
        ref = resolve_robot(e)
        key = repr(ref)
        if key in seen:
            seen[key]["followers"].append(i + 1)
            continue
        f = float(plant.params[i].wheel_frictionloss)
        row: dict[str, Any] = {"followers": [i + 1], "deadband_torque_Nm": [2 * f, 2 * f], "source": "frictionloss"}
        if not skipped():
            entry = cached_check(ref, robot_key(ref), float(plant.model.opt.timestep))
            db = entry.get("deadband_torque_Nm")
            if db and all(v is not None for v in db):
                row = {**row, "deadband_torque_Nm": [max(0.0, float(v)) for v in db], "source": "identified"}
        seen[key] = row
        out.append(row)
    return out


def sizing(sc: Any, plant: Any, c_true: np.ndarray) -> dict[str, Any] | None:
    """The sliding gain ``c_gain`` (2,) [m/s², rad/s²] and the disturbance gain ``kd`` (2,) of a run whose scenario
    asks for either option, with the resistance they were sized to (``resistance``, m/s² and rad/s² per
    robot) and why; None when neither is asked (the paper's ``torque.c`` and ``learner.kd`` stand); on a plant that
    is not MuJoCo's the scenario's gains, saying so. ``c_true`` (n, 2): each follower's ``(a, b)``."""
    margin = float(sc.torque.resistance_margin)
    kd_db = tuple(sc.learner.kd_deadband)
    if margin <= 0 and not kd_db:
        return None
    if not isinstance(plant, RobotModels):  # no robot models (design §22): said, never silently the paper's gains
        return {
            "c_gain": list(map(float, sc.torque.c)),
            "kd": list(map(float, sc.learner.kd)),
            "robots": [],
            "why": "no MuJoCo robot to identify a resistance on (ideal plant): torque.c and learner.kd as given",
        }
    rows = resistance(sc, plant)
    acc = np.zeros(2)
    for row in rows:
        i = row["followers"][0] - 1
        row["resistance"] = [float(c_true[i, k] * row["deadband_torque_Nm"][k]) for k in range(2)]
        acc = np.maximum(acc, row["resistance"])
    c_gain = np.array(sc.torque.c, dtype=float)
    why = []
    if margin > 0:
        c_gain = np.maximum(c_gain, margin * acc)
        why.append(
            f"torque.c = max(torque.c, {margin:g} × the resistance {acc[0]:.3g} m/s², {acc[1]:.3g} rad/s²) = "
            f"({c_gain[0]:.3g}, {c_gain[1]:.3g})"
        )
    kd = np.array(sc.learner.kd, dtype=float)
    has_db = any(max(r["deadband_torque_Nm"]) > DEADBAND_MIN_NM for r in rows)
    if kd_db and has_db:
        kd = np.array(kd_db, dtype=float)
        why.append(f"a dead band identified: learner.kd = ({kd[0]:g}, {kd[1]:g}) (learner.kd_deadband)")
    elif kd_db:
        why.append("no dead band identified: learner.kd stays the scenario's")
    return {"c_gain": c_gain.tolist(), "kd": kd.tolist(), "robots": rows, "why": "; ".join(why)}


register_sizing(sizing)  # the controller's builder sizes the opt-in gains with it (design §14.4)
