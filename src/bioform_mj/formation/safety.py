"""Safety configuration and the per-follower contact and proximity outcomes (design §19).

``[safety]`` sets the distance below which two robots (or a robot and an obstacle) count as too
close (``too_close`` time), and the optional safety filter. The MuJoCo plant watches contacts
and distances in its loop (:mod:`bioform_mj.plants.mujoco.contacts`); :func:`follower_fields`
turns what it watched into ``summary.json`` fields and outcomes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bioform_mj.core.errors import ScenarioError
from bioform_mj.core.units import unit

FILTERS = ("none", "cbf")


@dataclass(frozen=True)
class SafetyCfg:
    """``distance`` m: a follower closer than this to another robot or an obstacle (chassis to
    chassis, MuJoCo's geometry) is ``too_close`` (time summed; 0: not watched). ``filter``: the
    safety filter between the kinematic command and the torque law (``none``: the paper's;
    ``cbf``: a control barrier function on a point ``lookahead`` m ahead of the axle with gain
    ``gain`` 1/s, keeping robots and obstacles ``distance`` m apart, :mod:`bioform_mj.control.cbf`;
    neighbours within ``range`` m enter its QP; ``pass_right``: the right-hand rule that breaks the
    deadlock of two robots meeting, 0: off)."""

    distance: float = unit(0.0, "m")
    filter: str = unit("none", "-")
    lookahead: float = unit(0.1, "m")
    gain: float = unit(5.0, "1/s")
    range: float = unit(2.0, "m")
    pass_right: float = unit(1.0, "1")


def validate(cfg: SafetyCfg) -> None:
    if not cfg.distance >= 0:
        raise ScenarioError("safety.distance", f"must be >= 0 m, got {cfg.distance:g}")
    if cfg.distance > 100:
        raise ScenarioError("safety.distance", f"must be <= 100 m, got {cfg.distance:g}")
    if cfg.filter not in FILTERS:
        raise ScenarioError("safety.filter", f"unknown filter '{cfg.filter}' (expected one of: {', '.join(FILTERS)})")
    for key in ("lookahead", "gain", "range"):
        if not getattr(cfg, key) > 0:
            raise ScenarioError(f"safety.{key}", f"must be > 0, got {getattr(cfg, key):g}")
    if not 0 <= cfg.pass_right <= 10:
        raise ScenarioError("safety.pass_right", f"must lie in [0, 10], got {cfg.pass_right:g}")


def _name(k: int, kind: int, obstacle_names: list[str]) -> str:
    if k < 0:
        return "?"
    return f"follower {k + 1}" if kind == 0 else (obstacle_names[k] if k < len(obstacle_names) else f"obstacle {k + 1}")


def follower_fields(watch: Any, i: int, dt: float, obstacle_names: list[str]) -> tuple[dict[str, Any], list[dict]]:
    """``summary.json`` fields of follower ``i`` (0-based) from a plant's contact watch
    (:class:`~bioform_mj.plants.mujoco.contacts.Watched`) and its outcomes: a ``collided``
    per kind of partner it touched (robots, obstacles), a ``too_close`` if it spent time below
    ``safety.distance``. ``dt`` s: the control period (the proximity watch looks every ``w.every``
    control steps; each look below the distance counts for that long)."""
    w = watch
    out: dict[str, Any] = {}
    exact = bool(w.sep_exact[i])
    sep = float(w.min_sep[i])
    out["min_separation_m"] = sep if np.isfinite(sep) else None
    out["min_separation_exact"] = exact if np.isfinite(sep) else None
    out["min_separation_t"] = float(w.min_sep_t[i]) if np.isfinite(sep) else None
    out["min_separation_with"] = _name(int(w.min_sep_with[i]), 0, obstacle_names) if np.isfinite(sep) else None
    clr = float(w.min_clear[i])
    out["min_obstacle_clearance_m"] = clr if np.isfinite(clr) else None
    out["min_obstacle_clearance_with"] = (
        _name(int(w.min_clear_with[i]), 1, obstacle_names) if np.isfinite(clr) else None
    )
    outcomes: list[dict] = []
    out["contacts_watched"] = not w.off  # False: MuJoCo's contact list could not be read (said before the run)
    for kind, label in ((0, "robot"), (1, "obstacle")):
        ev = int(w.events[i, kind])
        out[f"{label}_contacts"] = ev
        out[f"{label}_contact_max_impulse_ns"] = float(w.max_imp[i, kind])
        out[f"{label}_contact_peak_force_n"] = float(w.peak_f[i, kind])
        out[f"{label}_contact_time_s"] = float(w.touch_steps[i, kind] * w.hdt)
        if ev:
            who = _name(int(w.partner[i, kind]), kind, obstacle_names)
            t = float(w.first_t[i, kind])
            outcomes.append(
                {
                    "kind": "collided",
                    "detail": f"touched {who} at t = {t:.3f} s ({ev} contact event{'s' if ev > 1 else ''}, "
                    f"largest impulse {w.max_imp[i, kind]:.3g} N·s, peak force {w.peak_f[i, kind]:.3g} N)",
                    "t": t,
                }
            )
    close = float(w.close_steps[i] * w.every * dt)
    out["too_close_s"] = close if w.safety > 0 else None
    if w.safety > 0 and w.close_steps[i] > 0:
        outcomes.append(
            {
                "kind": "too_close",
                "detail": f"closer than safety.distance = {w.safety:g} m for {close:.3f} s "
                f"(first at t = {w.close_t[i]:.3f} s)",
                "t": float(w.close_t[i]),
            }
        )
    return out, outcomes
