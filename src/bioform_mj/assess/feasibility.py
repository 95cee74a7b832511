"""What a scenario asks of its MuJoCo robots beyond their margins, before a run (design §13, §14).

:func:`feasibility` is the pre-run estimate (warnings) and :func:`run_refusals` what ``robot check``
(:mod:`bioform_mj.assess.check`) fails and no run survives (exit 2 before the run).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from bioform_mj.assess.check import YAW_TOL, G, tip_margins

__all__ = ["feasibility", "run_refusals", "slot_accelerations", "slot_wheel_speeds", "GIVEN_TOL"]

#: a mapped wheel_radius/half_track this far (relative) from what the model's geometry says is a
#: pre-run warning (scene.layout_of notes every difference over 1 %)
GIVEN_TOL = 0.05
_GIVEN = re.compile(
    r"(?P<what>wheel_radius|half_track) (?P<given>[-+.\deE]+) m given; the [a-z ]+ say (?P<model>[-+.\deE]+) m$"
)


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
    from bioform_mj.robots.contacts import robot_contacts, self_contacts

    t = np.linspace(0.0, scenario.sim.duration, max(200, int(scenario.sim.duration * 200)) + 1)
    _, vel, _ = scenario.build_leader().states(t)
    tangential, centripetal, total = slot_accelerations(scenario, t)
    scratch = mujoco.MjData(plant.model)
    mujoco.mj_kinematics(plant.model, scratch)
    out: list[str] = []
    settled = plant.settled_data()
    loads = plant.settled_wheel_loads(data=settled)
    refusals = run_refusals(plant, scratch, loads)
    level = _levels(plant, settled)  # design §14.4: a level stance's wheel loads are its statics', not MuJoCo's
    for i in level:
        loads[i] = level[i]
    if refusals:
        from bioform_mj.assess.skip import skipped

        if not skipped():
            raise InputError("the robots cannot run this scenario (robot check fails them): " + "; ".join(refusals))
        # design §14.2: a run told to skip the robot check is never refused by it; what it would refuse is said
        out += [f"robot check skipped (the run goes ahead); it would refuse {r}" for r in refusals]
    pressed: dict[str, list[int]] = {}
    contacts = robot_contacts(plant.model, settled, plant.layouts)  # each robot's, in one pass over the team's
    for i, p in enumerate(plant.params):  # braking casters: below, with contacts.braking_casters
        weight = p.mass * G
        mine = self_contacts(plant.model, settled, plant.layouts[i], f"f{i + 1}/", contacts[i])
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

    wheel_v = slot_wheel_speeds(scenario, t, [p.half_track for p in plant.params])

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
        floor = floor_contacts(plant.model, settled, plant.layouts[i], f"f{i + 1}/", contacts[i])
        wheel_force = float(loads[i].sum()) if i in level else sum(c["load_n"] for c in floor if c["role"] == "wheel")
        drive_force = min(2 * motor * p.floor_fraction[0] / p.wheel_radius, mu * wheel_force)
        for _, _, msg in braking_casters(floor, drive_force):
            out.append(f"{who}: {msg}")
        # cruising at the peak wheel ground speed against the wheel damping c and frictionloss f takes
        # c v / r + f per wheel (menagerie Stretch 3: c = 30 N·m·s/rad, 151 N·m at 0.25 m/s); the wheel's own
        # damper absorbs that torque between motor and tyre, so it is the motor's to give, never the tyre's
        # traction (design §14: at a steady cruise the tyre pushes nothing). The outer wheel of a turn runs
        # at |υ| + l|ω|, faster than the leader (issue 27: the leader's speed missed PMB-2's 1.1x)
        v_lead = float(np.max(np.abs(vel[:, 0])))
        v_wheel = max(float(wheel_v[i]), float(np.max(np.abs(vel[:, 0]) + p.half_track * np.abs(vel[:, 1]))))
        cruise = p.wheel_damping * v_wheel / p.wheel_radius + p.wheel_frictionloss
        if p.wheel_damping and cruise > motor:
            out.append(
                f"{who}: cruising at the peak wheel ground speed {v_wheel:.3g} m/s (|υ| + l|ω| of its slot; the "
                f"leader's speed {v_lead:.3g} m/s), the wheel's own damper ({p.wheel_damping:g} N·m·s/rad) and "
                f"frictionloss ({p.wheel_frictionloss:g} N·m) absorb {cruise:.3g} N·m per wheel, beyond the motor "
                f"limit {motor:.3g} N·m: the robot cannot keep up"
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
    v, a, speed, moving, sl = _slot_motion(scenario, t)
    u = np.where(moving[..., None], v / np.maximum(speed, 1e-12)[..., None], 0.0)
    tan = np.where(moving, np.abs((a * u).sum(-1)), np.linalg.norm(a, axis=-1))
    cen = np.where(moving, np.abs(a[..., 0] * u[..., 1] - a[..., 1] * u[..., 0]), 0.0)
    tot = np.linalg.norm(a, axis=-1)
    return tan[sl].max(axis=0), cen[sl].max(axis=0), tot[sl].max(axis=0)


def _slot_motion(scenario: Any, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, slice]:
    """Every follower's formation slot over the times ``t`` (s), differentiated twice: velocity ``v`` and
    acceleration ``a`` (T, n, 2; m/s, m/s²), speed (T, n), where it moves faster than 1 mm/s (T, n), and the
    samples to use (``np.gradient``'s one-sided ends dropped: the first and last two)."""
    from bioform_mj.assess.outcomes import slots_of

    pose, _, _ = scenario.build_leader().states(t)
    slots = np.stack([slots_of(scenario, p) for p in pose])  # (T, n, 2)
    v = np.gradient(slots, t, axis=0)
    a = np.gradient(v, t, axis=0)
    speed = np.linalg.norm(v, axis=-1)
    return v, a, speed, speed > 1e-3, slice(2, -2) if len(t) > 8 else slice(None)


def slot_wheel_speeds(scenario: Any, t: np.ndarray, half_tracks: Any) -> np.ndarray:
    """Per follower (n,) the largest wheel ground speed ``|v| + l |ω|`` (m/s) of its formation slot over the
    times ``t`` (s): ``v`` the slot's speed, ``ω = (v × v̇) / |v|²`` its path's turn rate (0 where the slot moves
    slower than 1 mm/s), ``l`` the follower's half track (``half_tracks``, m)."""
    v, a, speed, moving, sl = _slot_motion(scenario, t)
    turn = np.where(moving, (v[..., 0] * a[..., 1] - v[..., 1] * a[..., 0]) / np.maximum(speed, 1e-12) ** 2, 0.0)
    wheel = speed + np.asarray(half_tracks, dtype=float)[None, :] * np.abs(turn)
    return wheel[sl].max(axis=0)


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
        if float(loads[i].min()) < WHEEL_LOAD_MIN * p.mass * G and not _level(plant, i):
            why.append(
                f"the wheels do not stand on the floor ({loads[i, 0]:.3g} N, {loads[i, 1]:.3g} N of "
                f"{p.mass * G:.3g} N at rest)"
            )
        if p.wheel_frictionloss and 2 * p.wheel_frictionloss >= min(p.tau_max):
            why.append(f"wheel frictionloss {p.wheel_frictionloss:g} N·m: the dead band reaches the motor limit")
        for w in why:
            found.setdefault(f"{lay.file}: {w}", []).append(i + 1)
    return [f"follower{'s' if len(who) > 1 else ''} {', '.join(map(str, who))}: {w}" for w, who in found.items()]


def _levels(plant: Any, settled: Any) -> dict[int, np.ndarray]:
    """Per robot of a built plant whose wheels stand level with other supports on the settled state ``settled``
    (:func:`~bioform_mj.robots.level_support.level_support`): its wheel loads by the stance's statics, (2,) N."""
    from bioform_mj.assess.causes import WHEEL_LOAD_MIN
    from bioform_mj.robots.level_support import level_support

    out = {}
    for i, (p, lay) in enumerate(zip(plant.params, plant.layouts)):
        lv = level_support(plant.model, settled, lay, p.mass * G, WHEEL_LOAD_MIN)
        if lv is not None:
            out[i] = np.array(lv["statics_n"])
    return out


def _level(plant: Any, i: int) -> bool:
    """Whether robot ``i``'s wheels stand level with other supports on a settled copy of the scene
    (:func:`~bioform_mj.robots.level_support.level_support`): unloaded there by MuJoCo's choice, not off the floor."""
    from bioform_mj.assess.causes import WHEEL_LOAD_MIN
    from bioform_mj.robots.level_support import level_support

    return (
        level_support(plant.model, plant.settled_data(), plant.layouts[i], plant.params[i].mass * G, WHEEL_LOAD_MIN)
        is not None
    )


# ------------------------------------------------------------------ command line
