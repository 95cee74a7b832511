"""``bioform robot check``: what the project finds in a robot model, and whether a scenario can ask it.

:func:`check` resolves a robot (MJCF + mapping, :func:`bioform_mj.robots.prepare.prepare_robot`), reads
the ground truth from the compiled model, identifies ``a, b`` (constant torques from rest,
:func:`bioform_mj.assess.identify.identify`), and measures what the paper's model leaves out:

- **traction limit** per wheel ``μ N r / f`` (N·m; ``N`` the wheel's load at rest, from the
  contact forces, ``= m g / 2`` when the wheels carry all the weight; μ of the wheel–floor
  contact as the scene composes it; ``f`` the share of the wheel torque that reaches the floor past
  the wheel's rotor, :attr:`~bioform_mj.robots.params.RobotParams.floor_fraction`, design §13)
  against the **motor limit** (N·m);
- **static tip-over margins**: the forward, backward and lateral accelerations (m/s²) at which
  the chassis tips, from the centre of mass (height ``h``, position ``c`` from the axle midpoint)
  and the support rectangle of every collision geom within :data:`~bioform_mj.robots.layout.SUPPORT_CLEARANCE` of the
  floor (wheels, casters): accelerating forward tips it backwards about the rearmost support
  ``x_rear`` once ``a > g (c_x − x_rear)/h``; braking tips it forwards once
  ``a > g (x_front − c_x)/h``; turning tips it sideways once ``υω > g min(y_left − c_y, c_y − y_right)/h``;
- the centre of mass's offset from the axle, and the wheel joints' damping, armature and
  frictionloss with how each enters the ground truth (:meth:`~bioform_mj.robots.params.RobotParams.unmodelled`).

Verdict: ``fail`` when the robot cannot do the paper's experiment at all (statically unstable,
identification more than 10 % off the formula, a dead band at least the motor limit); ``warn``
when it can, with a caveat (motor limit above the traction limit, full torque tips the chassis,
identification 3–10 % off, centre of mass more than 1 cm off the axle, damping time constant
under 5 s); else ``pass``. :func:`feasibility` is the pre-run estimate for a scenario.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from dataclasses import asdict
from typing import Any

import numpy as np

from bioform_mj.robots.refs import RobotRef

__all__ = [
    "check",
    "tip_margins",
    "feasibility",
    "add_parser",
    "mapping_args",
    "ref_from_args",
    "main",
    "EXIT_FAIL",
    "G",
]

#: exit code of ``bioform robot check`` for a ``fail`` verdict (0: pass or warn, 2: bad input)
EXIT_FAIL = 4
#: gravity, m/s²
G = 9.81
#: a mapped wheel_radius/half_track this far (relative) from what the model's geometry says is a
#: pre-run warning (scene.layout_of notes every difference over 1 %)
GIVEN_TOL = 0.05
_GIVEN = re.compile(
    r"(?P<what>wheel_radius|half_track) (?P<given>[-+.\deE]+) m given; the [a-z ]+ say (?P<model>[-+.\deE]+) m$"
)
#: identification vs formula: above WARN_ID the verdict is warn, above FAIL_ID fail (relative)
WARN_ID, FAIL_ID = 0.03, 0.10
#: the yaw inertia of the robot that runs differs from the file's (or changes while driving) by more: a warning
YAW_TOL = 0.01
#: a self contact at rest deeper than this (m), or pushing more than ``causes.SELF_CONTACT_LOAD`` of the weight
#: (identification's structural threshold, the one definition: design §0), is a warning
SELF_DEPTH = 1e-3


def tip_margins(model: Any, data: Any, prefix: str = "") -> dict[str, Any]:
    """Static tip-over margins of the robot ``prefix`` standing at ``qpos0`` on a floor at z = 0.

    Returns ``tip_accel_mps2`` ``{forward, backward, lateral}`` (m/s², ≤ 0: statically
    unstable that way), the support rectangle (m, base frame, from the axle midpoint),
    ``com_height_m`` and the supporting geoms. ``data`` must hold ``mj_kinematics`` at qpos0.
    """
    import mujoco

    from bioform_mj.robots.analysis import layout_of
    from bioform_mj.robots.contacts import floor_points
    from bioform_mj.robots.layout import SUPPORT_CLEARANCE, geom_support, subtree

    lay = layout_of(model, prefix)
    base = model.body(lay.base).id
    rot = data.xmat[base].reshape(3, 3)
    jl, jr = (model.joint(j).id for j in lay.wheel_joints)
    mid = 0.5 * (data.xanchor[jl] + data.xanchor[jr])
    bodies = subtree(model, base)
    masses = model.body_mass[bodies]
    com = (masses[:, None] * data.xipos[bodies]).sum(axis=0) / masses.sum()
    floor_z = mid[2] - lay.wheel_radius
    tol = max(SUPPORT_CLEARANCE, 0.25 * lay.wheel_radius)
    pts, names = [], []
    body_set = set(bodies.tolist())
    down = np.array([0.0, 0.0, -1.0])
    lows = {
        g: data.geom_xpos[g][2] - geom_support(model, data, g, down)
        for g in range(model.ngeom)
        if model.geom_bodyid[g] in body_set and (model.geom_contype[g] or model.geom_conaffinity[g])
    }
    if lows and min(lows.values()) - floor_z > tol:
        # nothing reaches the floor the mapped wheel_radius implies (a radius that disagrees with the
        # collision geoms: the scene notes it): the robot stands on its lowest geoms
        floor_z = min(lows.values())
    for g, low in lows.items():
        if low - floor_z <= tol:
            pts.extend(rot.T @ (q - mid) for q in floor_points(model, data, g, floor_z + tol))
            names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}")
    if not pts:
        from bioform_mj.core.errors import InputError

        raise InputError(f"robot '{prefix.rstrip('/') or lay.base}' ({lay.file}): no collision geom to stand on")
    pts = np.array(pts)
    c = rot.T @ (com - mid)
    h = float(com[2] - floor_z)
    x_front, x_rear = float(pts[:, 0].max()), float(pts[:, 0].min())
    y_left, y_right = float(pts[:, 1].max()), float(pts[:, 1].min())
    return {
        "tip_accel_mps2": {
            "forward": G * (c[0] - x_rear) / h,  # accelerating forward tips it backwards
            "backward": G * (x_front - c[0]) / h,  # braking tips it forwards
            "lateral": G * min(y_left - c[1], c[1] - y_right) / h,
        },
        "support_m": {"x_front": x_front, "x_rear": x_rear, "y_left": y_left, "y_right": y_right},
        "support_geoms": names,
        "com_height_m": h,
    }


def cause_of(findings: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The likeliest cause among :func:`~bioform_mj.assess.identify.identify`'s findings (its ``CAUSE_ORDER``;
    ``damping`` only as the last resort), or None."""
    from bioform_mj.assess.causes import CAUSE_ORDER

    for kind in CAUSE_ORDER:
        for fd in findings:
            if fd["kind"] == kind:
                return fd
    return None


def check(entry: Any, *, identify_: bool = True) -> dict[str, Any]:
    """Everything :mod:`bioform_mj.assess.check` reports about one robot, with the verdict.

    ``entry``: shipped name, MJCF path or :class:`~bioform_mj.robots.refs.RobotRef`. Raises
    :class:`~bioform_mj.core.errors.InputError` (exit 2) for a model that cannot be used at all.
    """
    import mujoco

    from bioform_mj.assess.causes import SELF_CONTACT_LOAD, check_radius, identify_notes
    from bioform_mj.assess.identify import DRAG_STEP, identify
    from bioform_mj.plants.mujoco.plant import MujocoPlant
    from bioform_mj.robots.contacts import (
        braking_casters,
        moving_parts,
        pose_change,
        relative_poses,
        self_contacts,
        settle,
        still_bodies,
    )
    from bioform_mj.robots.overlaps import self_contacts_at_rest
    from bioform_mj.robots.params import implausible_inertias, robot_parameters

    plant = MujocoPlant([entry], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    check_radius(plant)  # exit 2 before any work: a radius nothing can be measured with
    p, lay = plant.params[0], plant.layouts[0]  # p: the configuration that runs (robot_params.running_data)
    model = plant.model
    scratch = mujoco.MjData(model)
    mujoco.mj_kinematics(model, scratch)  # the file's configuration (qpos0)
    tips = tip_margins(model, scratch, "f1/")  # static margins as the file stands (a settled copy may have fallen)
    p_file = robot_parameters(model, "f1/", scratch)
    base = model.body(lay.base).id
    still = still_bodies(model, lay)
    ref_pose = relative_poses(model, scratch, base, still)
    worst = (np.zeros(len(still)), np.zeros(len(still)))

    def track() -> None:
        now = pose_change(ref_pose, relative_poses(model, plant.data, base, still))
        np.maximum(worst[0], now[0], out=worst[0])
        np.maximum(worst[1], now[1], out=worst[1])

    mu = plant._wheel_friction(0)
    settled, floor, moving_at_rest = settle(plant, lay, track)  # 0.2 s, up to 1 s while it moves
    loads = plant.wheel_loads()[0]
    # the scene's contacts at rest, and every pair whose published geoms overlap at qpos0 (design §13.1)
    selfc, self_notes = self_contacts_at_rest(
        entry, lay.base[len("f1/") :], model, "f1/", self_contacts(model, plant.data, lay, "f1/")
    )
    # μ N r / f per wheel (design §13: N the wheel's own load at rest, f the share of torque that
    # reaches the floor past the rotor; μ m g r / 2 for an even split and a light rotor)
    traction = p.traction_torque(mu, float(loads.min()))
    motor = float(min(p.tau_max))
    motor_accel = 2 * motor * p.a_eff  # υ̇ at full torque on both wheels, m/s²
    notes = list(lay.notes) + self_notes
    reasons_fail, reasons_warn = [], []

    # the first ~2 s under gravity and a drive (forward, then a turn): what moves relative to the base
    t_drive = 0.25 * min(motor, traction)
    for k in range(1800):
        tau = t_drive * (np.array([[1.0, 1.0]]) if k < 900 else np.array([[-1.0, 1.0]]))
        plant.step(tau, (settled + k) * 0.001)
        if k % 10 == 9:
            track()
    end = mujoco.MjData(model)
    end.qpos[:] = plant.data.qpos
    mujoco.mj_kinematics(model, end)
    p_end = robot_parameters(model, "f1/", end)
    moving = moving_parts(model, still, worst, "f1/")
    if moving:
        reasons_warn.append(
            f"{len(moving)} part(s) move relative to the base in the first 2 s under gravity and a drive "
            "(moving_parts: "
            + ", ".join(
                f"'{m['body']}' {1e3 * m['displacement_m']:.1f} mm / {m['rotation_deg']:.1f}°" for m in moving[:5]
            )
            + ("…" if len(moving) > 5 else "")
            + "); c_true is for the configuration after settling"
        )
    for what, other in (("the file's configuration", p_file), ("the end of the 2 s drive", p_end)):
        change = other.yaw_inertia / p.yaw_inertia - 1
        if abs(change) > YAW_TOL:
            reasons_warn.append(
                f"the yaw inertia of the robot that runs (after settling) is {p.yaw_inertia:.4g} kg·m², "
                f"{what} has {other.yaw_inertia:.4g} kg·m² ({100 * change:+.1f} % against the settled one): c_true = "
                f"({p.a_eff:.4g}, {p.b_eff:.4g}) is the settled one"
                + (", at the end b_eff = " + f"{p_end.b_eff:.4g}" if other is p_end else "")
            )
    weight = p.mass * G
    wheel_force = sum(c["load_n"] for c in floor if c["role"] == "wheel")
    drive_force = min(2 * motor * p.floor_fraction[0] / p.wheel_radius, mu * wheel_force)
    for _, brake, msg in braking_casters(floor, drive_force):
        (reasons_fail if brake >= drive_force else reasons_warn).append(msg)
    if settled > 200 and not moving_at_rest:
        notes.append(f"at rest after {settled * 0.001:g} s (still moving at 0.2 s): floor contacts and loads from then")
    if odd := implausible_inertias(model, "f1/", scratch):  # at the file's configuration
        reasons_warn.append(odd)
    if moving_at_rest:
        pushed = [f"'{c['body1']}'/'{c['body2']}'" for c in selfc if c["simulated"]]
        reasons_warn.append(moving_at_rest + (f"; its own bodies push it: {', '.join(pushed)}" if pushed else ""))
    for sc in selfc:  # a pair the scene does not collide is a note (self_notes), not a warning
        if sc["simulated"] and (sc["depth_m"] > SELF_DEPTH or sc["force_n"] > SELF_CONTACT_LOAD * weight):
            reasons_warn.append(
                f"the robot's own bodies '{sc['body1']}' and '{sc['body2']}' touch at rest "
                f"({1e3 * sc['depth_m']:.2g} mm deep, {sc['force_n']:.3g} N; self_contacts): MuJoCo collides all but "
                "parent-child pairs; exclude the pair (<contact><exclude body1=… body2=…/>) if the robot does not"
            )

    ident = identify(entry) if identify_ else None  # InputError (exit 2) for a mapping no test can use
    findings = ident["findings"] if ident else []
    notes += identify_notes(ident)  # design §14.1: what the identification set up, said
    if any("other wheel" in n for n in lay.notes):  # the cause, before what it makes the identification see
        skid = (
            "other fixed wheels touch the floor (see notes): a 4-wheel / skid-steer base, not the paper's "
            "differential drive; map one driven pair and make the others casters, or use another robot"
        )
        findings.insert(0, {"kind": "structural", "detail": skid})
        if not (ident and ident["identifiable"]):  # else said below, as the identification's cause
            reasons_fail.append(skid)
    # design §14.3: an identified value whose fit does not hold is not reported as the robot's
    holds = (ident or {}).get("fit_holds") or {}
    a_id = ident["identified"]["a"] if ident and holds.get("a", True) else None
    b_id = ident["identified"]["b"] if ident and holds.get("b", True) else None
    if ident and not ident["identifiable"]:
        c = cause_of(findings)
        reasons_fail.append(
            f"cannot identify a, b: {c['kind']}: {c['detail']}"
            if c
            else f"cannot identify a, b: {ident['not_identified']}"
        )
    elif ident:
        worst = max(abs(ident["relative_error"]["a"]), abs(ident["relative_error"]["b"]))
        c = cause_of(findings)
        why = (
            f"{c['kind']}: {c['detail']}"
            if c
            else "no cause found among the mapping, a braking caster, a dead band, slip, rocking and damping: "
            "the wheels do not roll as the model of design §8 assumes"
        )
        fr = ident["test"].get("fit_rerun") or {}
        if ident.get("fit_problem"):  # design §14.3: a fit that does not hold reports no a, b as measured
            reasons_fail.append(f"identification: {ident['fit_problem']}; cause {why}")
        elif fr.get("kept"):  # design §14.2: measured lower, but at the test torque the robot is not the model
            reasons_fail.append(
                f"identification: at {2 * fr['first_torque_Nm']:.3g} N·m (τ_a) the drive fit does not hold (residual "
                f"{fr['first_fit_residual']:.0%} of its torque term): the robot does not follow υ̇ = a τ_a there; at "
                f"{2 * fr['torque_Nm']:.3g} N·m a is {ident['relative_error']['a']:+.1%}, b "
                f"{ident['relative_error']['b']:+.1%} from the formula; cause {why}"
            )
        elif worst > FAIL_ID:
            reasons_fail.append(
                f"identification differs from the formula by {100 * worst:.1f} % (> {100 * FAIL_ID:g} %); cause {why}"
            )
        elif worst > WARN_ID:
            reasons_warn.append(f"identification differs from the formula by {100 * worst:.1f} %; cause {why}")
    for fd in findings:  # every cause found is said, whether the identification held or not (design §14)
        if fd["kind"] == "structural" and "self_contacts" in fd:  # a fail only as the cause of a wrong a, b
            msg = f"structural: {fd['detail']}"
            if all(fd["detail"] not in r for r in reasons_fail + reasons_warn):
                reasons_warn.append(msg)
        elif fd["kind"] == "structural" and ident and ident["identifiable"]:
            if all(fd["detail"] not in r for r in reasons_fail):  # once, also when it is the identification's cause
                reasons_fail.append(f"structural: {fd['detail']}")
        elif fd["kind"] in ("braking_caster", "caster_resistance", "rocking", "slip", "dead_band") or (
            fd["kind"] == "damping" and min(t for t in fd["time_constant_s"] if t is not None) < 5.0
        ):
            msg = f"{fd['kind'].replace('_', ' ')}: {fd['detail']}"
            if all(fd["detail"] not in r for r in reasons_fail + reasons_warn):
                reasons_warn.append(msg)
    ta = tips["tip_accel_mps2"]
    for way, acc in ta.items():
        if acc <= 0:
            reasons_fail.append(f"statically unstable: the centre of mass is outside the support ({way})")
    if motor > traction:
        reasons_warn.append(
            f"motor limit {motor:.3g} N·m exceeds the traction limit μ N r / f = {traction:.3g} N·m: "
            "the wheels can skid at full torque"
        )
    if motor_accel > min(ta["forward"], ta["backward"]) > 0:
        reasons_warn.append(
            f"full torque accelerates the robot at {motor_accel:.3g} m/s², more than tips it "
            f"(forward {ta['forward']:.3g}, backward {ta['backward']:.3g} m/s²): a start-up transient "
            "at the torque limit can overturn it"
        )
    if p.com_offset > 0.01:
        reasons_warn.append(
            f"centre of mass {1e3 * p.com_offset:.0f} mm off the axle midpoint: a_eff, b_eff hold from "
            "rest; moving, an unmodelled υ·ω coupling acts (design §8.1: b̂ biased)"
        )
    um = p.unmodelled(1.0, 1.0)
    if p.wheel_frictionloss and 2 * p.wheel_frictionloss >= motor:
        reasons_fail.append(
            f"wheel frictionloss {p.wheel_frictionloss:g} N·m per wheel: the dead band reaches the motor limit"
        )
    k_drag = max(um["drag_rate_per_s"])
    step = float(plant.model.opt.timestep)
    model_step = plant.file_timesteps[0]  # the robot file's own step, read when the plant prepared it
    if k_drag * model_step > 0.1:
        reasons_warn.append(
            f"wheel drag rate {k_drag:.3g} 1/s against the model's own step {model_step:g} s (k dt = "
            f"{k_drag * model_step:.2g}): MuJoCo integrates the wheel damping coarsely there (identified a, b "
            f"off by tens of %); run with sim.physics_dt <= {DRAG_STEP / k_drag:.2g} s (identification used "
            f"{ident['test']['timestep_s'] if ident else step:.2g} s)"
        )
    if any("stiffness" in n for n in lay.notes):
        reasons_warn.append("wheel joint stiffness: a spring torque that grows with the distance driven (see notes)")
    tcs = [t for t in um["drag_time_constant_s"] if t is not None]
    if tcs and min(tcs) < 5.0:
        reasons_warn.append(f"wheel damping: drag time constant {min(tcs):.2g} s (< 5 s), a large unmodelled term")
    verdict = "fail" if reasons_fail else "warn" if reasons_warn else "pass"
    from bioform_mj.robots.limits import limits_of  # design §21: the limits in one place

    ref0 = entry if isinstance(entry, RobotRef) else None
    limits = limits_of(plant, 0, ref0, loads, ta)
    layout = asdict(lay)
    layout["file"] = lay.file
    named = ("base", "wheel_joints", "motors", "wheel_geoms", "disabled_actuators", "frozen_joints", "locked_joints")
    named += ("held_joints", "free_joints", "rolling_joints", "casters", "priority_geoms")
    for k in named:  # without the scene prefix
        v = layout[k]
        layout[k] = [x[len("f1/") :] for x in v] if isinstance(v, (list, tuple)) else v[len("f1/") :]
    layout["published_contacts"] = [[g[len("f1/") :], f, c] for g, f, c in layout["published_contacts"]]
    return {
        "verdict": verdict,
        "reasons": reasons_fail + reasons_warn,
        "fail_reasons": reasons_fail,  # what makes the verdict fail (a run warns these: design §14.2)
        "model": lay.file,
        "parts": layout,
        "a_eff": p.a_eff,
        "b_eff": p.b_eff,
        "a_identified": a_id,
        "b_identified": b_id,
        "relative_error": ident["relative_error"] if ident else None,
        "c_true": {"a": p.a_eff, "b": p.b_eff},
        "c_true_after_drive": {"a": p_end.a_eff, "b": p_end.b_eff},
        "mass_kg": p.mass,
        "weight_n": weight,
        "yaw_inertia_kgm2": p.yaw_inertia,
        "yaw_inertia_file_kgm2": p_file.yaw_inertia,
        "yaw_inertia_after_drive_kgm2": p_end.yaw_inertia,
        "wheel_inertia_kgm2": p.wheel_inertia,
        "floor_fraction": {"drive": p.floor_fraction[0], "turn": p.floor_fraction[1]},
        "floor_contacts": floor,
        "floor_load_n": float(sum(c["load_n"] for c in floor)),
        "self_contacts": selfc,
        "moving_parts": moving,
        "joints": {
            k: [x[len("f1/") :] for x in getattr(lay, f"{k}_joints")]
            for k in ("frozen", "locked", "held", "free", "rolling")
        },
        "wheel_radius_m": p.wheel_radius,
        "half_track_m": p.half_track,
        "friction_mu": mu,
        "traction_limit_nm": traction,
        "motor_limit_nm": motor,
        "wheel_load_n": loads.tolist(),
        "weight_on_wheels": float(loads.sum() / (p.mass * G)),
        "motor_accel_mps2": motor_accel,
        "tip_accel_mps2": ta,
        "limits": limits,
        "support_m": tips["support_m"],
        "support_geoms": [g[len("f1/") :] for g in tips["support_geoms"]],
        "com_height_m": tips["com_height_m"],
        "com_offset_m": p.com_offset,
        "com_from_axle_m": list(p.com_xyz),
        "wheel_joints": {
            "damping_Nms_per_rad": p.wheel_damping,
            "armature_kgm2": p.wheel_armature,
            "frictionloss_Nm": p.wheel_frictionloss,
            "how_they_enter": {
                "armature": um["armature_in_c_true"],
                "damping": "a drag υ̇ = a τ_a − k_υ υ, ω̇ = b τ_b − k_ω ω with k_υ = 2 a c/r, k_ω = 2 b c l/r "
                f"(here {um['drag_rate_per_s'][0]:.3g}, {um['drag_rate_per_s'][1]:.3g} 1/s)",
                "frictionloss": f"a dead band of 2 f = {um['deadband_torque_Nm'][0]:.3g} N·m on τ_a and on τ_b",
                "c_hat": um["c_hat_converges_to"],
            },
            "identified": {
                "drag_rate_per_s": ident["drag_rate_per_s"]["identified"],
                "deadband_torque_Nm": ident["deadband_torque_Nm"]["identified"],
            }
            if ident
            else None,
        },
        "identification": None
        if ident is None
        else {
            k: ident.get(k)
            for k in (
                "identifiable",
                "identified",
                "identified_com",
                "relative_error",
                "drag_rate_per_s",
                "deadband_torque_Nm",
                "rocking",
                "slip_ratio",
                "test",
            )
        },
        "findings": findings,
        "cause": cause_of(findings) if reasons_fail else None,
        "notes": notes,
    }


def feasibility(scenario: Any, plant: Any) -> list[str]:
    """Pre-run estimate: ``warning`` lines for what the scenario asks beyond a robot's margins.

    ``scenario``: a :class:`~bioform_mj.scenario.config.Scenario`; ``plant``: its built
    :class:`~bioform_mj.plants.mujoco.plant.MujocoPlant`. Per follower, compares

    - the leader's largest acceleration ``max sqrt(υ̇_r² + (υ_r ω_r)²)`` over the run (with
      world-frame offsets every follower's slot moves with the leader) against the traction
      limit ``μ g`` (m/s²), its tangential part against the forward/backward tip margins and its
      centripetal part ``υ_r ω_r`` against the lateral tip margin;
    - the start-up transient: followers start at rest off their slots and the torque law meets
      the jump of the command at the motor limit, so full torque ``2 a_eff τ_max`` (m/s²) is
      compared with the tip margins, and ``τ_max`` with the traction limit ``μ N r / f`` (``N`` the
      least-loaded wheel's share of the weight at rest, measured on a settled copy of the scene:
      casters and gravity-compensated parts take weight off the wheels).

    Each follower's own slot path is used (design §14: in a leader-frame formation a slot off the
    leader's path turns on a wider or tighter circle than the leader). A loaded caster with friction
    is a warning naming it. Raises :class:`~bioform_mj.core.errors.InputError` (exit 2, before the run)
    for what ``robot check`` fails and no run survives (:func:`run_refusals`).

    Returns an empty list when nothing is at risk. The estimate is static (no pitch dynamics).
    """
    import mujoco

    from bioform_mj.assess.causes import SELF_CONTACT_LOAD
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.contacts import self_contacts

    t = np.linspace(0.0, scenario.sim.duration, max(200, int(scenario.sim.duration * 200)) + 1)
    _, vel, _ = scenario.build_leader().states(t)
    tangential, centripetal, total = slot_accelerations(scenario, t)
    scratch = mujoco.MjData(plant.model)
    mujoco.mj_kinematics(plant.model, scratch)
    out: list[str] = []
    settled = plant.settled_data()
    loads = plant.settled_wheel_loads(data=settled)
    refusals = run_refusals(plant, scratch, loads)
    if refusals:
        raise InputError("the robots cannot run this scenario (robot check fails them): " + "; ".join(refusals))
    pressed: dict[str, list[int]] = {}
    for i, p in enumerate(plant.params):  # braking casters: below, with contacts.braking_casters
        weight = p.mass * G
        mine = self_contacts(plant.model, settled, plant.layouts[i], f"f{i + 1}/")
        pressing = [c for c in mine if c["force_n"] > SELF_CONTACT_LOAD * weight]
        if pressing:
            note = (
                "the robot's own bodies press on each other at rest: "
                + ", ".join(f"'{c['body1']}'/'{c['body2']}' {c['force_n']:.3g} N" for c in pressing)
                + " (internal forces that brake or lock parts; exclude the pairs)"
            )
            pressed.setdefault(note, []).append(i + 1)
    for note, who in pressed.items():
        out.append(f"follower{'s' if len(who) > 1 else ''} {', '.join(map(str, who))}: self contact: {note}")
    given: dict[str, list[int]] = {}  # a mapped size far from the model's geometry (scene.layout_of's notes)
    for i, lay in enumerate(plant.layouts):
        for note in lay.notes:
            m = _GIVEN.match(note)
            if m and abs(float(m["given"]) / float(m["model"]) - 1) > GIVEN_TOL:
                given.setdefault(note, []).append(i + 1)
    for note, who in given.items():
        m = _GIVEN.match(note)
        out.append(
            f"follower{'s' if len(who) > 1 else ''} {', '.join(map(str, who))}: {note} "
            f"({float(m['given']) / float(m['model']) - 1:+.0%}): the controller and c_true use the given "
            "value, the physics the model's"
        )
    from bioform_mj.robots.contacts import braking_casters, floor_contacts
    from bioform_mj.robots.params import robot_parameters

    for i, p in enumerate(plant.params):
        p_file = robot_parameters(plant.model, f"f{i + 1}/", scratch)  # the file's configuration (qpos0)
        change = p.yaw_inertia / p_file.yaw_inertia - 1
        if abs(change) > YAW_TOL:  # design §13: c_true is the robot that runs (settled)
            out.append(
                f"follower {i + 1}: the robot that runs (settled at rest) has yaw inertia {p.yaw_inertia:.4g} kg·m², "
                f"the file's configuration {p_file.yaw_inertia:.4g} kg·m² ({100 * change:+.1f} %: parts held by weak "
                f"servos or left free moved); c_true = ({p.a_eff:.4g}, {p.b_eff:.4g}) is the settled robot's"
            )
        tips = tip_margins(plant.model, scratch, f"f{i + 1}/")["tip_accel_mps2"]
        mu = plant._wheel_friction(i)
        traction = p.traction_torque(mu, float(loads[i].min()))  # μ N r / f per wheel (design §13)
        who = f"follower {i + 1}"
        if total[i] > mu * G:
            out.append(
                f"{who}: its slot accelerates at up to {total[i]:.3g} m/s², beyond the traction limit "
                f"μ g = {mu * G:.3g} m/s²: the wheels will slip"
            )
        if tangential[i] > min(tips["forward"], tips["backward"]):
            out.append(
                f"{who}: its slot's tangential acceleration {tangential[i]:.3g} m/s² exceeds the tip-over margin "
                f"(forward {tips['forward']:.3g}, backward {tips['backward']:.3g} m/s²): the scenario overturns it"
            )
        if centripetal[i] > tips["lateral"]:
            out.append(
                f"{who}: its slot's turns need {centripetal[i]:.3g} m/s² sideways, beyond the lateral tip-over "
                f"margin {tips['lateral']:.3g} m/s²: the scenario overturns it"
            )
        motor = float(min(p.tau_max))
        # a caster that slides brakes the robot (design §13)
        floor = floor_contacts(plant.model, settled, plant.layouts[i], f"f{i + 1}/")
        wheel_force = sum(c["load_n"] for c in floor if c["role"] == "wheel")
        drive_force = min(2 * motor * p.floor_fraction[0] / p.wheel_radius, mu * wheel_force)
        for _, _, msg in braking_casters(floor, drive_force):
            out.append(f"{who}: {msg}")
        # cruising at the leader's top speed against the wheel damping c and frictionloss f takes
        # c v / r + f per wheel (menagerie Stretch 3: c = 30 N·m·s/rad, 151 N·m at 0.25 m/s)
        v_top = float(np.max(np.abs(vel[:, 0])))
        cruise = p.wheel_damping * v_top / p.wheel_radius + p.wheel_frictionloss
        if p.wheel_damping and cruise > min(motor, traction):
            out.append(
                f"{who}: cruising at the leader's {v_top:.3g} m/s against the wheel damping {p.wheel_damping:g} "
                f"N·m·s/rad and frictionloss {p.wheel_frictionloss:g} N·m takes {cruise:.3g} N·m per wheel, beyond "
                f"the {'motor' if motor < traction else 'traction'} limit "
                f"{min(motor, traction):.3g} N·m: the robot cannot keep up"
            )
        full = 2 * p.a_eff * motor
        if full > min(tips["forward"], tips["backward"]):
            out.append(
                f"{who}: a start-up transient at the torque limit accelerates at {full:.3g} m/s², beyond the "
                f"tip-over margin (forward {tips['forward']:.3g}, backward {tips['backward']:.3g} m/s²): "
                "the chassis can tip (scale the scenario, formation.scale, or lower the torque limit)"
            )
        if motor > traction:
            out.append(
                f"{who}: torque limit {motor:.3g} N·m exceeds the traction limit μ N r / f = "
                f"{traction:.3g} N·m (N = {loads[i].min():.3g} N on the least-loaded wheel at rest): "
                "the wheels can skid at full torque"
            )
    return out


def slot_accelerations(scenario: Any, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per follower (n,) the largest tangential, centripetal and total acceleration (m/s²) of its
    formation slot over the times ``t`` (s): the slot path ``p_r − R(θ_r) Δ_i`` (leader frame) or
    ``p_r − Δ_i`` differentiated twice; tangential along the slot's velocity, centripetal across it
    (where the slot moves slower than 1 mm/s, all of it counts as tangential)."""
    from bioform_mj.assess.outcomes import slots_of

    pose, _, _ = scenario.build_leader().states(t)
    slots = np.stack([slots_of(scenario, p) for p in pose])  # (T, n, 2)
    v = np.gradient(slots, t, axis=0)
    a = np.gradient(v, t, axis=0)
    speed = np.linalg.norm(v, axis=-1)
    moving = speed > 1e-3
    u = np.where(moving[..., None], v / np.maximum(speed, 1e-12)[..., None], 0.0)
    tan = np.where(moving, np.abs((a * u).sum(-1)), np.linalg.norm(a, axis=-1))
    cen = np.where(moving, np.abs(a[..., 0] * u[..., 1] - a[..., 1] * u[..., 0]), 0.0)
    tot = np.linalg.norm(a, axis=-1)
    # the ends of np.gradient are one-sided: drop the first and last two samples
    sl = slice(2, -2) if len(t) > 8 else slice(None)
    return tan[sl].max(axis=0), cen[sl].max(axis=0), tot[sl].max(axis=0)


def run_refusals(plant: Any, scratch: Any, loads: np.ndarray) -> list[str]:
    """What ``robot check`` fails that no run survives, per robot of a built plant (cheap: the
    layout, the static tip margins, the settled wheel loads ``loads`` (n, 2) N): a skid-steer base
    (other fixed wheels on the floor), a robot statically unstable, wheels that carry no weight, a
    dead band at the motor limit. ``bioform run`` refuses these with exit 2 (design §14)."""
    from bioform_mj.assess.causes import WHEEL_LOAD_MIN

    found: dict[str, list[int]] = {}
    for i, (p, lay) in enumerate(zip(plant.params, plant.layouts)):
        why = []
        if any("other wheel" in n for n in lay.notes):
            why.append(
                "other fixed wheels touch the floor: a 4-wheel / skid-steer base, not a differential drive "
                "(robot check: map one driven pair and make the others casters)"
            )
        try:
            tips = tip_margins(plant.model, scratch, f"f{i + 1}/")["tip_accel_mps2"]
            why += [f"statically unstable ({way})" for way, acc in tips.items() if acc <= 0]
        except ValueError as exc:
            why.append(str(exc))
        if float(loads[i].min()) < WHEEL_LOAD_MIN * p.mass * G:
            why.append(
                f"the wheels do not stand on the floor ({loads[i, 0]:.3g} N, {loads[i, 1]:.3g} N of "
                f"{p.mass * G:.3g} N at rest)"
            )
        if p.wheel_frictionloss and 2 * p.wheel_frictionloss >= min(p.tau_max):
            why.append(f"wheel frictionloss {p.wheel_frictionloss:g} N·m: the dead band reaches the motor limit")
        for w in why:
            found.setdefault(f"{lay.file}: {w}", []).append(i + 1)
    return [f"follower{'s' if len(who) > 1 else ''} {', '.join(map(str, who))}: {w}" for w, who in found.items()]


# ------------------------------------------------------------------ command line
def mapping_args(p: argparse.ArgumentParser) -> None:
    """The mapping flags shared by ``robot check`` and ``identify``."""
    p.add_argument("--base", help="the chassis body (default: 'base')")
    p.add_argument("--left-wheel", help="left wheel hinge joint (default: 'left_wheel')")
    p.add_argument("--right-wheel", help="right wheel hinge joint (default: 'right_wheel')")
    p.add_argument("--wheel-radius", type=float, help="wheel radius in m (default: from the wheels' collision geoms)")
    p.add_argument("--half-track", type=float, help="half the track in m (default: from the wheel joint anchors)")
    p.add_argument("--tau-max", type=float, help="wheel torque limit in N·m (default: the model's own drive limit)")
    p.add_argument(
        "--top-speed",
        type=float,
        help="top speed in m/s at the tyre, the maker's figure (default: the URDF's wheel <limit velocity> or "
        "the <dcmotor>'s no-load speed; design §21)",
    )
    p.add_argument(
        "--caster",
        action="append",
        metavar="NAME",
        help="a geom or body that is a caster (repeat for several; design §13)",
    )
    p.add_argument(
        "--caster-friction",
        type=float,
        metavar="MU",
        help="sliding friction of the casters against the floor (default: as published; frictionless "
        "geoms stay frictionless)",
    )
    p.add_argument(
        "--free-joints",
        action="store_true",
        help="leave the joints other than the wheels free (default: held at the file's configuration)",
    )
    p.add_argument(
        "--keyframe",
        metavar="NAME",
        help="MJCF: start and hold the robot in this keyframe (default: 'home' where the file has one; "
        "'none': qpos0; design §13.2)",
    )
    p.add_argument(
        "--package-path",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="URDF: where package://NAME/... points (repeatable; before $BIOFORM_PACKAGE_PATH, $ROS_PACKAGE_PATH)",
    )
    p.add_argument(
        "--self-collide",
        action="store_true",
        help="URDF: keep contacts between the robot's own links (default off, as in Gazebo)",
    )
    __import__("bioform_mj.robots.xacro_sandbox", fromlist=["add_flags"]).add_flags(p)  # --xacro (design §12)


def ref_from_args(model: str, args: argparse.Namespace) -> RobotRef:
    """A :class:`RobotRef` from a model argument and the :func:`mapping_args` flags."""
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.refs import package_path_from_args, resolve_robot

    for flag in ("wheel_radius", "half_track", "tau_max", "top_speed"):
        v = getattr(args, flag, None)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(f"--{flag.replace('_', '-')} must be a number > 0, got {v}")
    cf = getattr(args, "caster_friction", None)
    if cf is not None and not (math.isfinite(cf) and cf >= 0):
        raise InputError(f"--caster-friction must be a number >= 0, got {cf}")
    return resolve_robot(
        RobotRef(
            model=model,
            base=args.base or "",
            left_wheel=args.left_wheel or "",
            right_wheel=args.right_wheel or "",
            wheel_radius=args.wheel_radius or 0.0,
            half_track=args.half_track or 0.0,
            tau_max=args.tau_max or 0.0,
            casters=tuple(getattr(args, "caster", None) or ()),
            caster_friction=-1.0 if cf is None else float(cf),
            free_joints=bool(getattr(args, "free_joints", False)),
            self_collide=bool(getattr(args, "self_collide", False)),
            package_path=package_path_from_args(getattr(args, "package_path", None)),
            keyframe=getattr(args, "keyframe", None) or "",
            top_speed=getattr(args, "top_speed", None) or 0.0,
        )
    )


def add_parser(sub: Any) -> None:
    """Add ``bioform robot check`` to the CLI's subparsers."""
    robot = sub.add_parser("robot", help="robot models: check what the project finds in one")
    rsub = robot.add_subparsers(dest="robot_command", required=True, parser_class=type(robot))
    chk = rsub.add_parser(
        "check",
        help="parts, a_eff/b_eff (formula and identified), traction and tip-over "
        "margins, damping/armature/frictionloss; verdict pass/warn/fail "
        "(exit 0 pass or warn: a warn says its reasons in one warning: line on stderr; "
        f"2 bad input, {EXIT_FAIL} fail)",
    )
    chk.add_argument("model", help="shipped robot name or path to an MJCF or URDF file")
    mapping_args(chk)
    chk.add_argument("--json", type=str, metavar="FILE", help="write the report as JSON to FILE")


def _num(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.5g}"


def main(args: argparse.Namespace) -> int:
    """Run ``bioform robot check``; prints a short report, returns the exit code."""
    from bioform_mj.outputs.files import check_out_file, write_json
    from bioform_mj.robots.contacts import floor_table

    if args.json:  # before any work (exit 2): a directory, /proc/x, a read-only folder
        args.json = check_out_file(args.json, "--json")
    report = check(ref_from_args(args.model, args))
    if args.json:
        write_json(args.json, report)
    ta = report["tip_accel_mps2"]
    lines = [
        f"{report['verdict']}: {report['model']}",
        f"  parts: base '{report['parts']['base']}', wheels '{report['parts']['wheel_joints'][0]}' / "
        f"'{report['parts']['wheel_joints'][1]}' (sign {report['parts']['wheel_sign'][0]:+d}/"
        f"{report['parts']['wheel_sign'][1]:+d}), r = {report['wheel_radius_m']:.4g} m, "
        f"l = {report['half_track_m']:.4g} m",
        f"  a_eff = {report['a_eff']:.5g} (identified {_num(report['a_identified'])}), "
        f"b_eff = {report['b_eff']:.5g} (identified {_num(report['b_identified'])})",
        f"  motor limit {report['motor_limit_nm']:.3g} N·m, traction limit {report['traction_limit_nm']:.3g} N·m "
        f"(μ = {report['friction_mu']:g})",
        f"  tips at forward {ta['forward']:.3g}, backward {ta['backward']:.3g}, lateral {ta['lateral']:.3g} m/s² "
        f"(full torque: {report['motor_accel_mps2']:.3g} m/s²); "
        f"CoM {1e3 * report['com_offset_m']:.1f} mm off the axle, "
        f"{report['com_height_m']:.3g} m high",
    ]
    from bioform_mj.robots.limits import block

    lines += block(report["limits"])
    lines.append(
        f"  mass {report['mass_kg']:.4g} kg, yaw inertia {report['yaw_inertia_kgm2']:.4g} kg·m² "
        f"(the file's configuration: {report['yaw_inertia_file_kgm2']:.4g}), c_true = "
        f"({report['c_true']['a']:.5g}, {report['c_true']['b']:.5g}); torque reaching the floor "
        f"{100 * report['floor_fraction']['drive']:.3g} % driving, "
        f"{100 * report['floor_fraction']['turn']:.3g} % turning"
    )
    lines += floor_table(report)
    for sc in report["self_contacts"]:
        lines.append(
            f"  self contact: '{sc['body1']}' / '{sc['body2']}' "
            f"{1e3 * sc['depth_m']:.3g} mm deep, {sc['force_n']:.3g} N"
            + ("" if sc["simulated"] else " (not collided in the scene)")
        )
    moving = report["moving_parts"]
    lines.append(
        "  moving parts (first 2 s): "
        + (
            ", ".join(f"'{m['body']}' {1e3 * m['displacement_m']:.1f} mm / {m['rotation_deg']:.1f}°" for m in moving)
            if moving
            else "none"
        )
    )
    lines += [f"  {r}" for r in report["reasons"]]
    lines += [f"  note: {n}" for n in report["notes"]]
    print("\n".join(lines))
    if report["verdict"] == "fail":
        print(f"error: robot check failed: {'; '.join(report['reasons'])}", file=sys.stderr)
        return EXIT_FAIL
    if report["verdict"] == "warn":  # never silent: a warn's reasons on stderr too, not only in the report
        print(f"warning: robot check warns: {'; '.join(report['reasons'])}", file=sys.stderr)
    return 0
