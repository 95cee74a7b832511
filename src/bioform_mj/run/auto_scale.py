"""``formation.scale = "auto"`` and ``formation.time_scale = "auto"``: a scenario the robot can drive (design §21).

- ``s`` (``scale = "auto"``): the robot's half track over the paper robot's :data:`PAPER_HALF_TRACK`
  (the smallest of the team's robots);
- ``σ`` (``time_scale = "auto"``): the scenario at ``s`` (σ = 1) is run on the ideal plant with each
  robot's ``c_true`` (:func:`bioform_mj.run.demand.peaks`); under similarity its speeds scale by 1/σ and
  its accelerations by 1/σ², so ``σ = max(1, v_wheel / (m_v v_top), √(v̇ / (m_a v̇_lim)),
  √(ω̇ / (m_a ω̇_lim)), (τ_w − f) / (m_τ τ_max − f))`` over the robots, with the margins :data:`SPEED_MARGIN`,
  :data:`ACCEL_MARGIN` and :data:`TORQUE_MARGIN` (:mod:`bioform_mj.robots.limits` gives ``v_top``, ``v̇_lim``,
  ``ω̇_lim``, ``τ_max``; ``τ_w`` the peak wheel torque with the wheel's own damping and frictionloss ``f``,
  :func:`_torque_need` says why it counts so).
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
#: share of the torque limit τ_max the peak wheel torque (the motion's and the wheel's own damping and
#: frictionloss) may ask (σ from ``wheel_torque``, design §21): the resistance takes its share first, so the
#: margin is the speed's, not the accelerations' (which already count all of τ_max as available)
TORQUE_MARGIN = 0.8

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
            pk = peaks(at, (p.a_eff, p.b_eff), p.half_track, wheel=_wheel(p))
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
            torque = _torque_need(pk, p, lim)
            if torque is not None:
                cand[torque[1]] = torque[0]
            k = max(cand, key=lambda c: cand[c])
            if cand[k] > worst:
                worst, why = cand[k], f"'{Path(ref.model).name}' {k}"
        return worst, why

    sigma, fit, why = _solve(need)
    stuck = []
    for ref, p, lim in robots:  # a frictionloss that alone takes the torque margin: no σ makes room (_torque_need)
        if float(p.wheel_frictionloss) >= TORQUE_MARGIN * float(lim["torque_nm"]):
            stuck.append(
                f"wheel torque of '{Path(ref.model).name}' not counted in σ: its wheels' frictionloss "
                f"{float(p.wheel_frictionloss):.3g} N·m alone is at least {TORQUE_MARGIN:g} x τ_max "
                f"{float(lim['torque_nm']):.3g} N·m and does not fall with σ (the demand check warns, design §21)"
            )
    sigma = check_factor("formation.time_scale", sigma)
    if horizon > float(sc.sim.duration):
        why += f"; over the scenario's first {horizon:g} s (unscaled), not only the run's {float(sc.sim.duration):g} s"
    if sigma == 1.0:
        notes.append(f"formation.time_scale = 1 (auto: the demand fits the margins as written, {fit:.2f}; {why})")
    else:
        notes.append(
            f"formation.time_scale = {sigma:.4g} (auto: set by the {why} at σ = {sigma:.4g}, {fit:.2f} of the "
            f"margin {SPEED_MARGIN:g} on speed, {ACCEL_MARGIN:g} on accelerations, {TORQUE_MARGIN:g} on wheel torque)"
        )
    return s, sigma, "; ".join(notes + stuck)


def _wheel(p: Any) -> dict[str, float]:
    """The wheel :func:`bioform_mj.run.demand.wheel_need` takes of robot parameters ``p``: radius m, joint plus
    back-EMF damping N·m·s/rad, frictionloss N·m (a braking caster, which only robot check finds, is not counted
    here: the demand check before the run counts it, design §21)."""
    return {
        "radius_m": float(p.wheel_radius),
        "damping_nms": float(p.wheel_damping + p.motor_damping),
        "frictionloss_nm": float(p.wheel_frictionloss),
    }


def _torque_need(pk: dict[str, Any], p: Any, lim: dict[str, Any]) -> tuple[float, str] | None:
    """σ's candidate from the peak wheel torque ``pk["wheel_torque_nm"]`` against :data:`TORQUE_MARGIN` × τ_max,
    with its reason; None where no σ can bring it under the margin.

    The torque does not scale as one power of σ: per wheel it is the motion's inertial part (× σ⁻² under
    similarity), the damping ``c φ̇`` (× σ⁻¹) and the frictionloss ``f`` (× σ⁰). So the factor counted is
    ``(τ − f) / (m τ_max − f)``: ≤ 1 exactly where ``τ ≤ m τ_max``, and, as ``τ − f ≤ I σ⁻² + D σ⁻¹``, it falls at
    least as 1/σ — as fast as the other candidates, whose accelerations count by their square roots. Where
    ``f ≥ m τ_max`` slowing the scenario cannot make room (the frictionloss alone takes the margin): not a
    candidate; the demand check before the run warns about ``wheel_torque`` (design §21)."""
    f = float(p.wheel_frictionloss)
    room = TORQUE_MARGIN * float(lim["torque_nm"]) - f
    if "wheel_torque_nm" not in pk or room <= 0:
        return None
    tau = float(pk["wheel_torque_nm"])
    return (
        max(tau - f, 0.0) / room,
        f"wheel torque {tau:.3g} N·m (motion {pk['wheel_inertial_nm']:.3g}, the wheel's damping and frictionloss up "
        f"to {pk['wheel_resistance_nm']:.3g}) against {TORQUE_MARGIN:g} x τ_max {float(lim['torque_nm']):.3g} N·m",
    )


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
