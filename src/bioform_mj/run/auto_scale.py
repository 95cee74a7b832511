"""``formation.scale = "auto"`` and ``formation.time_scale = "auto"``: a scenario the robot can drive (design §21).

- ``s`` (``scale = "auto"``): the robot's half track over the paper robot's :data:`PAPER_HALF_TRACK`
  (the smallest of the team's robots);
- ``σ`` (``time_scale = "auto"``): the scenario at ``s`` (σ = 1) is run on the ideal plant with each
  robot's ``c_true`` (:func:`bioform_mj.run.demand.peaks`); under similarity its speeds scale by 1/σ and
  its accelerations by 1/σ², so ``σ = max(1, v_wheel / (m_v v_top), √(v̇ / (m_a v̇_lim)),
  √(ω̇ / (m_a ω̇_lim)))`` over the robots, with the margins :data:`SPEED_MARGIN` and
  :data:`ACCEL_MARGIN` (:mod:`bioform_mj.robots.limits` gives ``v_top``, ``v̇_lim``, ``ω̇_lim``).
  The reason (which limit of which robot set σ) is the summary's ``scale_note``. The demand is taken over
  at least :data:`AUTO_HORIZON_S` of the scenario (its own duration where longer): a run shortened by
  ``sim.duration`` gets the σ of the run it previews (design §21; TIAGo got σ 2.51 for a 0.3 s run, 2.64 for 20 s).

A robot whose limit is unknown (no top speed) is refused (ScenarioError, exit 2) saying what is
missing and how to give it.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from bioform_mj.scenario.loader import register_auto_scale

#: the paper robot's half track, m (Sec. IV: l = 0.2 m with a = 0.4, b = 10)
PAPER_HALF_TRACK = 0.2
#: share of the robot's top speed the scenario may ask (σ from speed)
SPEED_MARGIN = 0.8
#: share of the acceleration and yaw-acceleration limits the scenario may ask (σ from accelerations)
ACCEL_MARGIN = 0.5

#: s (unscaled): the least span of the scenario whose demand sets σ: the paper's duration (Sec. IV, 20 s)
AUTO_HORIZON_S = 20.0

_LIMITS: dict[str, tuple[Any, dict[str, Any]]] = {}


def robot_limits(ref: Any) -> tuple[Any, dict[str, Any]]:
    """``(params, limits)`` of one resolved robot (:func:`~bioform_mj.robots.limits.limits_of`, standing
    alone on the floor and settled 0.2 s); remembered per robot (:func:`bioform_mj.assess.prerun.robot_key`)."""
    import mujoco
    import numpy as np

    from bioform_mj.assess.check import tip_margins
    from bioform_mj.assess.prerun import robot_key
    from bioform_mj.plants.mujoco.plant import MujocoPlant
    from bioform_mj.robots.limits import limits_of

    key = robot_key(ref)
    if key not in _LIMITS:
        plant = MujocoPlant([ref], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
        scratch = mujoco.MjData(plant.model)
        mujoco.mj_kinematics(plant.model, scratch)
        tips = tip_margins(plant.model, scratch, "f1/")["tip_accel_mps2"]
        loads = plant.settled_wheel_loads()[0]
        _LIMITS[key] = (plant.params[0], limits_of(plant, 0, ref, loads, tips))
    return _LIMITS[key]


def resolve_auto(sc: Any) -> tuple[float, float, str]:
    """``(s, σ, note)`` for a scenario whose ``formation.scale`` or ``time_scale`` is ``"auto"``
    (the other one as given); raises ScenarioError for a robot whose limits are unknown."""
    from bioform_mj.core.errors import ScenarioError
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.scenario.loader import apply_scale
    from bioform_mj.scenario.similarity import check_factor

    f = sc.formation
    refs = list(dict.fromkeys(resolve_robot(r) for r in sc.plant.robots))
    robots = [(ref, *robot_limits(ref)) for ref in refs]
    notes = []
    if f.scale == "auto":
        ref, p, _lim = min(robots, key=lambda x: x[1].half_track)
        s = float(p.half_track) / PAPER_HALF_TRACK
        notes.append(
            f"formation.scale = {s:.4g} (auto: '{Path(ref.model).name}' half track {p.half_track:.4g} m / the paper's "
            f"{PAPER_HALF_TRACK:g} m)"
        )
    else:
        s = check_factor("formation.scale", f.scale)
    if f.time_scale != "auto":
        return s, check_factor("formation.time_scale", f.time_scale), "; ".join(notes)
    from bioform_mj.run.demand import peaks  # its twin runs on the loop registered with it (run/simulate.py)

    for ref, _p, lim in robots:
        if lim["top_speed_mps"] is None:
            raise ScenarioError(
                "formation.time_scale",
                f"\"auto\" needs robot '{Path(ref.model).name}''s top speed, which it does not give "
                f"({lim['top_speed_note']}); or give formation.time_scale a number",
            )

    horizon = max(float(sc.sim.duration), AUTO_HORIZON_S)  # a shortened run previews the full one (design §21)

    def need(sigma: float) -> tuple[float, str]:
        """The factor by which the demand at ``sigma`` exceeds the margins (≤ 1: it fits; speeds count
        as ratios, accelerations as their square roots: both then fall as 1/σ under similarity)."""
        at = apply_scale(
            dataclasses.replace(
                sc,
                formation=dataclasses.replace(f, scale=s, time_scale=sigma),
                sim=dataclasses.replace(sc.sim, duration=horizon),
            )
        )
        worst, why = 0.0, ""
        for ref, p, lim in robots:
            pk = peaks(at, (p.a_eff, p.b_eff), p.half_track)
            cand = {
                f"wheel speed {pk['wheel_speed_mps']:.3g} m/s against {SPEED_MARGIN:g} x top speed "
                f"{lim['top_speed_mps']:.3g} m/s ({lim['top_speed_source']})": pk["wheel_speed_mps"]
                / (SPEED_MARGIN * lim["top_speed_mps"]),
                f"acceleration {pk['accel_mps2']:.3g} m/s² against {ACCEL_MARGIN:g} x {lim['accel_mps2']:.3g} "
                f"m/s² ({lim['accel_limited_by']})": math.sqrt(pk["accel_mps2"] / (ACCEL_MARGIN * lim["accel_mps2"])),
                f"yaw acceleration {pk['yaw_accel_radps2']:.3g} rad/s² against {ACCEL_MARGIN:g} x "
                f"{lim['yaw_accel_radps2']:.3g} rad/s² ({lim['yaw_accel_limited_by']})": math.sqrt(
                    pk["yaw_accel_radps2"] / (ACCEL_MARGIN * lim["yaw_accel_radps2"])
                ),
            }
            k = max(cand, key=lambda c: cand[c])
            if cand[k] > worst:
                worst, why = cand[k], f"'{Path(ref.model).name}' {k}"
        return worst, why

    sigma, fit, why = _solve(need)
    sigma = check_factor("formation.time_scale", sigma)
    if horizon > float(sc.sim.duration):
        why += f"; over the scenario's first {horizon:g} s (unscaled), not only the run's {float(sc.sim.duration):g} s"
    if sigma == 1.0:
        notes.append(f"formation.time_scale = 1 (auto: the demand fits the margins as written, {fit:.2f}; {why})")
    else:
        notes.append(
            f"formation.time_scale = {sigma:.4g} (auto: set by the {why} at σ = {sigma:.4g}, {fit:.2f} of the "
            f"margin {SPEED_MARGIN:g} on speed, {ACCEL_MARGIN:g} on accelerations)"
        )
    return s, sigma, "; ".join(notes)


def _solve(need: Any, tries: int = 4) -> tuple[float, float, str]:
    """The least σ ≥ 1 found whose demand fits the margins (``need(σ) ≤ 1``), aiming at ``need(σ)``
    in [0.9, 1]: σ₁ = need(1) (similarity: demand ∝ σ⁻¹ in these units), then secant steps on
    ``log need`` against ``log σ`` (eq. 32's neuron is not similar when ``s σ ≠ 1``: the demand falls
    faster). ``(σ, need(σ), what sets it)``."""
    f0, why0 = need(1.0)
    if f0 <= 1.0:
        return 1.0, f0, why0
    pts = [(1.0, f0, why0)]
    sig = f0
    for _ in range(tries):
        fk, whyk = need(sig)
        pts.append((sig, fk, whyk))
        if 0.9 <= fk <= 1.0:
            break
        (sa, fa, _), (sb, fb, _) = pts[-2], pts[-1]
        q = math.log(fa / fb) / math.log(sb / sa) if fa > 0 and fb > 0 and sa != sb else 1.0
        q = min(max(q, 0.5), 3.0)
        sig = max(1.0, sb * fb ** (1.0 / q))
    fits = [p for p in pts if p[1] <= 1.0]
    if fits:
        return min(fits)
    sb, fb, whyb = max(pts)  # none fits yet: extrapolate with the slowest fall (demand ∝ σ^-0.5)
    return sb * fb**2, fb, whyb + " (extrapolated)"


register_auto_scale(resolve_auto)  # the loader resolves "auto" with it (design §21)
