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
under 5 s); else ``pass``. :func:`bioform_mj.assess.feasibility.feasibility` is the pre-run estimate for a
scenario.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from bioform_mj.robots.refs import RobotRef

__all__ = [
    "check",
    "tip_margins",
    "EXIT_FAIL",
    "G",
]

#: exit code of ``bioform robot check`` for a ``fail`` verdict (0: pass or warn, 2: bad input)
EXIT_FAIL = 4
#: gravity, m/s²
G = 9.81
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
    down = np.array([0.0, 0.0, -1.0])
    # the robot's collision geoms, in geom order, found at once (a test per geom of the whole scene was n² in a team)
    mine = np.isin(model.geom_bodyid, bodies) & ((model.geom_contype != 0) | (model.geom_conaffinity != 0))
    lows = {g: data.geom_xpos[g][2] - geom_support(model, data, g, down) for g in np.flatnonzero(mine).tolist()}
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


@dataclass
class _Said:
    """What :func:`check` says so far: the reasons that fail the robot, those that warn, the notes."""

    fail: list[str] = field(default_factory=list)
    warn: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


class _Tracker:
    """Each still body's largest displacement (m), rotation (rad) from the file's pose, relative to the base."""

    def __init__(self, plant: Any, scratch: Any, base: int, still: Any) -> None:
        from bioform_mj.robots.contacts import relative_poses

        self.plant, self.base, self.still = plant, base, still
        self.ref_pose = relative_poses(plant.model, scratch, base, still)
        self.worst = (np.zeros(len(still)), np.zeros(len(still)))

    def __call__(self) -> None:
        from bioform_mj.robots.contacts import pose_change, relative_poses

        now = pose_change(self.ref_pose, relative_poses(self.plant.model, self.plant.data, self.base, self.still))
        np.maximum(self.worst[0], now[0], out=self.worst[0])
        np.maximum(self.worst[1], now[1], out=self.worst[1])


@dataclass
class _AtRest:
    """The robot as :func:`check` finds it at rest (design §13, §14)."""

    plant: Any  # the MujocoPlant holding it (scene prefix "f1/")
    p: Any  # RobotParams of the configuration that runs (after settling)
    lay: Any  # its RobotLayout
    scratch: Any  # MjData at the file's configuration (qpos0)
    tips: dict[str, Any]  # tip_margins as the file stands
    p_file: Any  # RobotParams at the file's configuration
    tracker: _Tracker
    mu: float  # wheel–floor friction
    settled: int  # steps (1 ms) it took to come to rest
    floor: list[dict[str, Any]]  # floor contacts at rest
    moving_at_rest: str  # why it still moves at rest, or ""
    loads: np.ndarray  # (2,) wheel loads, N (the statics' where the stance is level)
    level: dict[str, Any] | None  # level_support's reading
    selfc: list[dict[str, Any]]  # self contacts at rest
    traction: float  # μ N r / f of the least-loaded wheel, N·m
    motor: float  # the lower wheel torque limit, N·m
    motor_accel: float  # υ̇ at full torque on both wheels, m/s²


def _at_rest(entry: Any, said: _Said) -> _AtRest:
    """``entry`` in a plant, settled: what touches the floor, with what load (notes to ``said.notes``)."""
    import mujoco

    from bioform_mj.assess.causes import WHEEL_LOAD_MIN, check_radius
    from bioform_mj.assess.identify import ID_DURATION, ID_LEVELS
    from bioform_mj.plants.mujoco.plant import MujocoPlant
    from bioform_mj.robots.contacts import self_contacts, settle, still_bodies
    from bioform_mj.robots.level_support import level_support
    from bioform_mj.robots.overlaps import self_contacts_at_rest
    from bioform_mj.robots.params import robot_parameters
    from bioform_mj.robots.sanity import StepPace

    plant = MujocoPlant([entry], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    check_radius(plant)  # exit 2 before any work: a radius nothing can be measured with
    p, lay = plant.params[0], plant.layouts[0]  # p: the configuration that runs (robot_params.running_data)
    model = plant.model
    scratch = mujoco.MjData(model)
    mujoco.mj_kinematics(model, scratch)  # the file's configuration (qpos0)
    tips = tip_margins(model, scratch, "f1/")  # static margins as the file stands (a settled copy may have fallen)
    p_file = robot_parameters(model, "f1/", scratch)
    tracker = _Tracker(plant, scratch, model.body(lay.base).id, still_bodies(model, lay))
    mu = plant._wheel_friction(0)
    pace = StepPace(  # the check's steps at 1 ms: settle (<= 1 s), the 2 s drive, the identification's tests
        1000 + 2000 + (0.2 + 2 * len(ID_LEVELS) * (0.2 + ID_DURATION)) / 0.001,
        f"{getattr(entry, 'model', entry)}: robot check",
        "a robot whose geoms touch each other in many pairs steps slowly: exclude the pairs "
        "(<contact><exclude>) or give fewer collision geoms",
        plant.data,
    )
    settled, floor, moving_at_rest = settle(plant, lay, tracker, pace=pace)  # 0.2 s, up to 1 s while it moves
    loads = plant.wheel_loads()[0]
    level = level_support(model, plant.data, lay, p.mass * G, WHEEL_LOAD_MIN)  # design §14: a level stance
    if level is not None:
        loads = np.array(level["statics_n"])
    # the scene's contacts at rest, and every pair whose published geoms overlap at qpos0 (design §13.1)
    selfc, self_notes = self_contacts_at_rest(
        entry, lay.base[len("f1/") :], model, "f1/", self_contacts(model, plant.data, lay, "f1/")
    )
    # μ N r / f per wheel (design §13: N the wheel's own load at rest, f the share of torque that
    # reaches the floor past the rotor; μ m g r / 2 for an even split and a light rotor)
    traction = p.traction_torque(mu, float(loads.min()))
    motor = float(min(p.tau_max))
    said.notes += list(lay.notes) + self_notes
    from ..robots.realdata.calibrated import calibration_note

    said.notes += calibration_note(model)  # a calibrated robot (robot fit's) says where its numbers came from
    return _AtRest(
        plant, p, lay, scratch, tips, p_file, tracker, mu, settled, floor, moving_at_rest, loads, level, selfc,
        traction, motor, 2 * motor * p.a_eff,
    )  # fmt: skip


def _drive(r: _AtRest) -> tuple[Any, list[dict[str, Any]]]:
    """The first ~2 s under gravity and a drive (forward, a turn): (RobotParams at its end, the moving parts)."""
    import mujoco

    from bioform_mj.robots.contacts import moving_parts
    from bioform_mj.robots.params import robot_parameters

    plant, model = r.plant, r.plant.model
    t_drive = 0.25 * min(r.motor, r.traction)
    for k in range(1800):
        tau = t_drive * (np.array([[1.0, 1.0]]) if k < 900 else np.array([[-1.0, 1.0]]))
        plant.step(tau, (r.settled + k) * 0.001)
        if k % 10 == 9:
            r.tracker()
    end = mujoco.MjData(model)
    end.qpos[:] = plant.data.qpos
    mujoco.mj_kinematics(model, end)
    p_end = robot_parameters(model, "f1/", end)
    return p_end, moving_parts(model, r.tracker.still, r.tracker.worst, "f1/")


def _rest_reasons(r: _AtRest, p_end: Any, moving: list[dict[str, Any]], said: _Said) -> None:
    """What the robot at rest and in its first 2 s says: moving parts, a yaw inertia that changes, a level stance,
    braking casters, implausible inertias, a robot that does not come to rest, self contacts."""
    from bioform_mj.assess.causes import SELF_CONTACT_LOAD
    from bioform_mj.robots.contacts import braking_casters
    from bioform_mj.robots.params import implausible_inertias

    p, level, loads, floor = r.p, r.level, r.loads, r.floor
    if moving:
        said.warn.append(
            f"{len(moving)} part(s) move relative to the base in the first 2 s under gravity and a drive "
            "(moving_parts: "
            + ", ".join(
                f"'{m['body']}' {1e3 * m['displacement_m']:.1f} mm / {m['rotation_deg']:.1f}°" for m in moving[:5]
            )
            + ("…" if len(moving) > 5 else "")
            + "); c_true is for the configuration after settling"
        )
    for what, other in (("the file's configuration", r.p_file), ("the end of the 2 s drive", p_end)):
        change = other.yaw_inertia / p.yaw_inertia - 1
        if abs(change) > YAW_TOL:
            said.warn.append(
                f"the yaw inertia of the robot that runs (after settling) is {p.yaw_inertia:.4g} kg·m², "
                f"{what} has {other.yaw_inertia:.4g} kg·m² ({100 * change:+.1f} % against the settled one): c_true = "
                f"({p.a_eff:.4g}, {p.b_eff:.4g}) is the settled one"
                + (", at the end b_eff = " + f"{p_end.b_eff:.4g}" if other is p_end else "")
            )
    weight = p.mass * G
    wheel_force = float(loads.sum()) if level else sum(c["load_n"] for c in floor if c["role"] == "wheel")
    drive_force = min(2 * r.motor * p.floor_fraction[0] / p.wheel_radius, r.mu * wheel_force)
    if level is not None:
        said.warn.append(f"level stance: {level['detail']}")
    for _, brake, msg in braking_casters(floor, drive_force):
        (said.fail if brake >= drive_force else said.warn).append(msg)
    if r.settled > 200 and not r.moving_at_rest:
        said.notes.append(
            f"at rest after {r.settled * 0.001:g} s (still moving at 0.2 s): floor contacts and loads from then"
        )
    if odd := implausible_inertias(r.plant.model, "f1/", r.scratch):  # at the file's configuration
        said.warn.append(odd)
    if r.moving_at_rest:
        pushed = [f"'{c['body1']}'/'{c['body2']}'" for c in r.selfc if c["simulated"]]
        said.warn.append(r.moving_at_rest + (f"; its own bodies push it: {', '.join(pushed)}" if pushed else ""))
    for sc in r.selfc:  # a pair the scene does not collide is a note (self_notes), not a warning
        if sc["simulated"] and (sc["depth_m"] > SELF_DEPTH or sc["force_n"] > SELF_CONTACT_LOAD * weight):
            said.warn.append(
                f"the robot's own bodies '{sc['body1']}' and '{sc['body2']}' touch at rest "
                f"({1e3 * sc['depth_m']:.2g} mm deep, {sc['force_n']:.3g} N; self_contacts): MuJoCo collides all but "
                "parent-child pairs; exclude the pair (<contact><exclude body1=… body2=…/>) if the robot does not"
            )


def _identification(
    entry: Any, r: _AtRest, identify_: bool, run_step: float | None, said: _Said
) -> tuple[dict[str, Any] | None, Any, list[dict[str, Any]]]:
    """The identification (design §14) and what it says: (its result or None, its repetition at the simulated steps
    or None, the findings). InputError (exit 2) for a mapping no test can use."""
    from bioform_mj.assess.causes import identify_notes
    from bioform_mj.assess.identify import identify

    p, lay = r.p, r.lay
    ident = identify(entry) if identify_ else None  # InputError (exit 2) for a mapping no test can use
    steps = None
    if ident is not None:  # design §14.2: the robot as simulated, at the model's own step and the run's
        from bioform_mj.assess.identify_steps import identify_at_steps, step_reasons

        steps = identify_at_steps(entry, ident, r.plant.file_timesteps[0], run_step)
        s_fail, s_warn = step_reasons(
            steps,
            max(p.unmodelled(0.0, 0.0)["drag_rate_per_s"]),
            WARN_ID,
            FAIL_ID,
            "run" if run_step is not None else "model",
        )
        said.fail += s_fail
        said.warn += s_warn
    findings = ident["findings"] if ident else []
    said.notes += identify_notes(ident)  # design §14.1: what the identification set up, said
    if any("other wheel" in n for n in lay.notes):  # the cause, before what it makes the identification see
        skid = (
            "other fixed wheels touch the floor (see notes): a 4-wheel / skid-steer base, not the paper's "
            "differential drive; map one driven pair and make the others casters, or use another robot"
        )
        findings.insert(0, {"kind": "structural", "detail": skid})
        if not (ident and ident["identifiable"]):  # else said below, as the identification's cause
            said.fail.append(skid)
    return ident, steps, findings


def _identification_reasons(ident: dict[str, Any] | None, findings: list[dict[str, Any]], said: _Said) -> None:
    """Whether the identification agrees with the formula (design §14.2–14.3), and every cause found."""
    reasons_fail, reasons_warn = said.fail, said.warn  # appended to
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


def _limit_reasons(r: _AtRest, ident: dict[str, Any] | None, said: _Said) -> None:
    """What the robot's limits say: static stability, traction, tip-over at full torque, the centre of mass off
    the axle, the dead band, a drag the model's step integrates coarsely, stiffness, damping (design §13–14)."""
    from bioform_mj.assess.identify import DRAG_STEP

    p, lay, motor, traction, ta = r.p, r.lay, r.motor, r.traction, r.tips["tip_accel_mps2"]
    for way, acc in ta.items():
        if acc <= 0:
            said.fail.append(f"statically unstable: the centre of mass is outside the support ({way})")
    if motor > traction:
        said.warn.append(
            f"motor limit {motor:.3g} N·m exceeds the traction limit μ N r / f = {traction:.3g} N·m: "
            "the wheels can skid at full torque"
        )
    if r.motor_accel > min(ta["forward"], ta["backward"]) > 0:
        said.warn.append(
            f"full torque accelerates the robot at {r.motor_accel:.3g} m/s², more than tips it "
            f"(forward {ta['forward']:.3g}, backward {ta['backward']:.3g} m/s²): a start-up transient "
            "at the torque limit can overturn it"
        )
    if p.com_offset > 0.01:
        said.warn.append(
            f"centre of mass {1e3 * p.com_offset:.0f} mm off the axle midpoint: a_eff, b_eff hold from "
            "rest; moving, an unmodelled υ·ω coupling acts (design §8.1: b̂ biased)"
        )
    um = p.unmodelled(1.0, 1.0)
    if p.wheel_frictionloss and 2 * p.wheel_frictionloss >= motor:
        said.fail.append(
            f"wheel frictionloss {p.wheel_frictionloss:g} N·m per wheel: the dead band reaches the motor limit"
        )
    k_drag, step = max(um["drag_rate_per_s"]), float(r.plant.model.opt.timestep)
    model_step = r.plant.file_timesteps[0]  # the robot file's own step, read when the plant prepared it
    if k_drag * model_step > 0.1:
        said.warn.append(
            f"wheel drag rate {k_drag:.3g} 1/s against the model's own step {model_step:g} s (k dt = "
            f"{k_drag * model_step:.2g}): MuJoCo integrates the wheel damping coarsely there (identified a, b "
            f"off by tens of %); run with sim.physics_dt <= {DRAG_STEP / k_drag:.2g} s (identification used "
            f"{ident['test']['timestep_s'] if ident else step:.2g} s)"
        )
    if any("stiffness" in n for n in lay.notes):
        said.warn.append("wheel joint stiffness: a spring torque that grows with the distance driven (see notes)")
    tcs = [t for t in um["drag_time_constant_s"] if t is not None]
    if tcs and min(tcs) < 5.0:
        from bioform_mj.scenario.config import LearnerCfg

        k_top = LearnerCfg().drag_max  # the opt-in learner.drag's default bound, 1/s (design §14)
        said.warn.append(
            f"wheel damping: drag time constant {min(tcs):.2g} s (< 5 s), a large unmodelled term"
            + (
                f"; its drag rate {k_drag:.3g} 1/s is beyond the opt-in learner.drag's range [0, {k_top:g}] 1/s "
                "(learner.drag_max)"
                if k_drag > k_top
                else "; the opt-in learner.drag can learn it"
            )
        )


def _parts(lay: Any) -> dict[str, Any]:
    """The layout as the report gives it: its names without the scene prefix ``f1/``."""
    layout = asdict(lay)
    layout["file"] = lay.file
    named = ("base", "wheel_joints", "motors", "wheel_geoms", "disabled_actuators", "frozen_joints", "locked_joints")
    named += ("held_joints", "free_joints", "rolling_joints", "casters", "priority_geoms")
    for k in named:  # without the scene prefix
        v = layout[k]
        layout[k] = [x[len("f1/") :] for x in v] if isinstance(v, (list, tuple)) else v[len("f1/") :]
    layout["published_contacts"] = [[g[len("f1/") :], f, c] for g, f, c in layout["published_contacts"]]
    layout["suspended_wheels"] = [[w[len("f1/") :], j[len("f1/") :]] for w, j in layout["suspended_wheels"]]
    return layout


def check(entry: Any, *, identify_: bool = True, run_step: float | None = None) -> dict[str, Any]:
    """Everything :mod:`bioform_mj.assess.check` reports about one robot, with the verdict.

    ``entry``: shipped name, MJCF path or :class:`~bioform_mj.robots.refs.RobotRef`. ``run_step``: the run's
    ``sim.physics_dt`` (s) where a run asks; the identification is repeated at it and at the model's own step
    where they differ from the step it measured at (``identification_steps``; design §14.2). Raises
    :class:`~bioform_mj.core.errors.InputError` (exit 2) for a model that cannot be used at all.

    The steps: :func:`_at_rest`, :func:`_drive` (the first 2 s), :func:`_rest_reasons`, :func:`_identification`
    and :func:`_identification_reasons`, :func:`_limit_reasons`, the verdict and the report.
    """
    said = _Said()
    r = _at_rest(entry, said)
    p_end, moving = _drive(r)
    _rest_reasons(r, p_end, moving, said)
    ident, steps, findings = _identification(entry, r, identify_, run_step, said)
    # design §14.3: an identified value whose fit does not hold is not reported as the robot's
    holds = (ident or {}).get("fit_holds") or {}
    a_id = ident["identified"]["a"] if ident and holds.get("a", True) else None
    b_id = ident["identified"]["b"] if ident and holds.get("b", True) else None
    _identification_reasons(ident, findings, said)
    _limit_reasons(r, ident, said)
    reasons_fail, reasons_warn = said.fail, said.warn
    verdict = "fail" if reasons_fail else "warn" if reasons_warn else "pass"
    from bioform_mj.robots.limits import limits_of  # design §21: the limits in one place

    p, lay, loads, floor, tips, ta = r.p, r.lay, r.loads, r.floor, r.tips, r.tips["tip_accel_mps2"]
    limits, um = (
        limits_of(r.plant, 0, entry if isinstance(entry, RobotRef) else None, loads, ta),
        p.unmodelled(1.0, 1.0),
    )
    return {
        "verdict": verdict,
        "reasons": reasons_fail + reasons_warn,
        "fail_reasons": reasons_fail,  # what makes the verdict fail (a run warns these: design §14.2)
        "model": lay.file,
        "parts": _parts(lay),
        "a_eff": p.a_eff,
        "b_eff": p.b_eff,
        "a_identified": a_id,
        "b_identified": b_id,
        "relative_error": ident["relative_error"] if ident else None,
        "c_true": {"a": p.a_eff, "b": p.b_eff},
        "c_true_after_drive": {"a": p_end.a_eff, "b": p_end.b_eff},
        "mass_kg": p.mass,
        "weight_n": p.mass * G,
        "yaw_inertia_kgm2": p.yaw_inertia,
        "yaw_inertia_file_kgm2": r.p_file.yaw_inertia,
        "yaw_inertia_after_drive_kgm2": p_end.yaw_inertia,
        "wheel_inertia_kgm2": p.wheel_inertia,
        "floor_fraction": {"drive": p.floor_fraction[0], "turn": p.floor_fraction[1]},
        "floor_contacts": floor,
        "floor_load_n": float(sum(c["load_n"] for c in floor)),
        "self_contacts": r.selfc,
        "moving_parts": moving,
        "joints": {
            k: [x[len("f1/") :] for x in getattr(lay, f"{k}_joints")]
            for k in ("frozen", "locked", "held", "free", "rolling")
        },
        "wheel_radius_m": p.wheel_radius,
        "half_track_m": p.half_track,
        "friction_mu": r.mu,
        "traction_limit_nm": r.traction,
        "motor_limit_nm": r.motor,
        "wheel_load_n": loads.tolist(),
        "level_support": r.level,  # design §14: wheels level with other supports (loads above: the statics')
        "weight_on_wheels": float(loads.sum() / (p.mass * G)),
        "motor_accel_mps2": r.motor_accel,
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
        "identification_steps": steps,  # design §14.2: at the model's own step and the run's
        "findings": findings,
        "cause": cause_of(findings) if reasons_fail else None,
        "notes": said.notes,
    }
