"""Prepare one robot for the scene (:func:`prepare_robot`), as :func:`bioform_mj.robots.scene.build_scene` composes it.

A robot is an MJCF file plus a mapping (:class:`bioform_mj.robots.refs.RobotRef`); see the README,
"What a robot needs". A URDF file is imported first (:mod:`bioform_mj.robots.urdf`, design §12: free
root link, links kept as bodies, meshes found, every guess a note), then treated the same. An
MJCF robot's asset files are made absolute (:func:`bioform_mj.robots.mjcf.absolute_asset_files`); each format is
one entry of :mod:`bioform_mj.robots.formats`. :func:`prepare_robot`
resolves it once, from the compiled model:

- the base body (``base`` by convention) carrying a free joint (one is added to a top-level
  base that has none); it is taken as x forward, y left, z up;
- the two wheel hinges (``left_wheel``/``right_wheel`` by convention): the wheel radius from
  the wheels' collision geoms (their extent below the joint anchor), the half track from the
  joint anchors, the axle midpoint (the reference point of pose and ``υ``, wherever the base
  origin is), and each wheel's forward sign (a joint axis may point either way);
- torque motors on the two wheel joints with ``gear = ±1`` (so that positive ``ctrl`` drives
  forward, in N·m): a plain motor of the model on the joint is kept (its gear sign fixed),
  otherwise ``left_motor``/``right_motor`` are added and the model's own wheel drives (joint or
  tendon velocity/position/motor actuators) get zero gain and bias: they exert no force but stay
  in the model, so sensors that name them still compile;
- the robot that runs (design §13): joints other than the wheels and the root are held where the
  file puts them — by the model's own position servo, else frozen (deleted: their bodies welded,
  the actuators on them removed), else (a tendon, equality or sensor names them) locked by a joint
  equality — unless the mapping says ``free_joints``; a caster's swivel and wheel stay free. Other
  actuators are kept with ctrl = 0;
- contacts as the maker meant (design §13): a non-wheel geom published frictionless (friction
  below :data:`FRICTIONLESS` or condim 1) and the mapping's ``casters`` get
  :data:`CONTACT_PRIORITY`, so that MuJoCo uses their own friction and condim against the floor
  rather than the larger of the pair; ``caster_friction`` sets the casters' friction;
- a wheel collision shape that scrubs when turning (cylinder, capsule, box, mesh: several
  contact points across the tread) is switched off for contacts (kept for looks) and replaced
  by a single-contact ellipsoid proxy of the same radius (design §8 pitfall);
- a keyframe (the mapping's ``keyframe``, default ``home`` where the file has one) is baked in first
  (:mod:`bioform_mj.robots.keyframe`, design §13.2): its configuration becomes ``qpos0``, the position
  servos hold it; then keyframes are dropped (the scene sets its own initial poses).

What was found is stored in the robot's spec as the custom text ``bioform_layout`` (JSON of
:class:`RobotLayout`), so a compiled scene carries it (``f1/bioform_layout``, …) and
:func:`~bioform_mj.robots.analysis.layout_of` reads it back.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.analysis import _analyse
from bioform_mj.robots.entries import resolve_robot
from bioform_mj.robots.formats import format_of
from bioform_mj.robots.layout import (
    _LAYOUT_TEXT,
    CONTACT_PRIORITY,
    DC_INPUT_FF,
    DC_INPUT_VOLTAGE,
    ModelError,
    RobotLayout,
    _spec_actuator,
    _spec_body,
    _spec_geom,
    _spec_joint,
    dc_constants,
)
from bioform_mj.robots.refs import RobotRef

__all__ = ["prepare_robot", "prepare_robots", "load_robot"]


def _wheel_proxy(
    spec: mujoco.MjSpec, model: mujoco.MjModel, j: int, cand: list[int] | None, r: float, name: str
) -> None:
    """Switch the wheel's collision geoms ``cand`` off and add a single-contact ellipsoid ``name``
    of radius ``r`` centred on the joint anchor, its short axis along the joint axis (mass 0)."""
    body = _spec_body(spec, model, int(model.jnt_bodyid[j]))
    src = None
    width = 0.25 * r
    for g in cand or []:
        gs = _spec_geom(spec, model, g)
        if src is None:
            src = gs
        if int(model.geom_type[g]) in (int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_CAPSULE)):
            width = float(model.geom_size[g, 1])
        gs.contype, gs.conaffinity = 0, 0
    width = min(max(width, 0.05 * r), r)
    quat = np.zeros(4)
    axis = np.asarray(model.jnt_axis[j], float)
    mujoco.mju_quatZ2Vec(quat, axis / np.linalg.norm(axis))
    g = body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
        size=[r, r, width],
        pos=np.asarray(model.jnt_pos[j], float),
        quat=quat,
        mass=0,
        density=0,
        contype=1,
        conaffinity=1,
        group=3,
        rgba=[0.2, 0.6, 0.2, 0.3],
    )
    if src is not None:
        g.contype, g.conaffinity = int(model.geom_contype[cand[0]]) or 1, int(model.geom_conaffinity[cand[0]]) or 1
        g.condim = int(model.geom_condim[cand[0]])
        g.friction = np.array(model.geom_friction[cand[0]], float)
        g.solref = np.array(model.geom_solref[cand[0]], float)
        g.solimp = np.array(model.geom_solimp[cand[0]], float)
        g.solmix = float(model.geom_solmix[cand[0]])
        g.priority = int(model.geom_priority[cand[0]])
        g.margin, g.gap = float(model.geom_margin[cand[0]]), float(model.geom_gap[cand[0]])
    else:
        g.condim = 3
        g.friction = [1.0, 0.005, 0.0001]


def _dc_driver(act, model, a: int, sgn: float, driver: str, tau: float) -> None:
    """Set the driver of a kept ``<dcmotor>`` (design §8.2). The plant writes ``ctrl = s · τ``
    with ``τ`` the commanded wheel torque (:func:`~bioform_mj.robots.layout.dc_ctrl_scale`):

    - ``"voltage"``: ``ctrl`` is the terminal voltage ``V = R τ / (g K)``, clipped to ``±V_max``
      (the torque ``τ`` at stall; moving, back-EMF takes ``(gK)²/R · φ̇``: a drag);
    - ``"current"``: ``ctrl`` is the motor torque ``τ/g`` (``input="ff"``): the on-board driver
      applies ``v = (R/K) τ/g + K g φ̇`` (back-EMF compensated), clamped to ``V_max``, so ``τ`` is
      delivered exactly up to the torque–speed line; a current limit ``τ_max / (g K)``.
    """
    R, K, g, vmax = dc_constants(model, a)
    gear = np.array(act.gear, float)
    gear[0] = sgn * abs(gear[0])
    act.gear = gear
    gp = np.array(act.gainprm, float)
    if driver == "voltage":
        act.ctrlspec = DC_INPUT_VOLTAGE
        gp[7] = 0.0
        act.ctrlrange = [-vmax, vmax]
    else:
        act.ctrlspec = DC_INPUT_FF
        gp[7] = vmax
        act.ctrlrange = [-tau / g, tau / g]
        act.forcelimited = 1
        act.forcerange = [-tau / g, tau / g]
    act.gainprm = gp
    act.ctrllimited = 1


def prepare_robot(entry: RobotRef | str | Path) -> tuple[mujoco.MjSpec, RobotLayout, np.ndarray, float]:
    """Load one robot, resolve its mapping and make its spec drivable (see the module docstring).

    Returns ``(spec, layout, axle_world, base_yaw)``: a fresh ``MjSpec`` (motors attached, wheel
    drives neutralised, proxies added, the layout stored as text), the layout, and the axle
    midpoint (m) and base heading (rad) in the model file's world frame at ``qpos0`` (to place the
    robot). Raises :class:`ModelError` (exit 2) naming the element and the file.
    """
    try:
        ref = resolve_robot(entry)
    except ModelError:
        raise
    except InputError as exc:
        raise ModelError(str(exc)) from None
    path = Path(ref.model)
    # design §12: the file's format (robots/formats.py) loads it: compiled, with what its import guessed
    spec, model, ref, imported, key, key_q, key_notes = format_of(path).load(ref, path)
    from bioform_mj.robots.sanity import model_value_problem  # NaN or negative masses, axes, friction: refused

    if bad := model_value_problem(model):
        raise ModelError(f"{path}: {bad}")
    layout, plan = _analyse(model, path, ref)
    if imported:
        layout = replace(layout, notes=imported + layout.notes, import_notes=imported)
    elif key_notes or key:
        layout = replace(layout, notes=key_notes + layout.notes, keyframe=key, keyframe_qpos=key_q)

    # spec elements by compiled index, resolved before anything is deleted (unnamed ones included)
    acts = {a: _spec_actuator(spec, model, a) for a in range(model.nu)}
    sjoints = {j: _spec_joint(spec, model, j) for j in set(plan["freeze"]) | set(plan["lock"])}
    sgeoms = {
        g: _spec_geom(spec, model, g) for g in set(plan["priority"]) | set(plan["friction"]) | set(plan["condim1"])
    }
    for g, pr, gname in zip(plan["geoms"], plan["proxies"], layout.wheel_geoms):
        if pr is None and g >= 0 and not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g):
            _spec_geom(spec, model, g).name = gname
    base = spec.body(layout.base)
    if not plan["has_free"]:
        base.add_freejoint(name=f"{layout.base}_free")
    for key in list(spec.keys):
        spec.delete(key)
    for j, pr, gname in zip(plan["joints"], plan["proxies"], layout.wheel_geoms):
        if pr is not None:
            r_proxy = pr[2] if isinstance(pr, tuple) and len(pr) > 2 else layout.wheel_radius  # the tyre's own
            _wheel_proxy(spec, model, j, pr[1] if isinstance(pr, tuple) else None, r_proxy, gname)
    for a in plan["disabled"]:
        act = acts[a]
        act.gainprm = np.zeros(len(act.gainprm))
        act.biasprm = np.zeros(len(act.biasprm))
    for a in plan["dc_removed"]:  # motor = "ideal": the model's DC motors are not used
        spec.delete(acts[a])
    tau = layout.tau_max
    if plan["dc"]:
        for a, sgn, mname in zip(plan["keep"], layout.wheel_sign, layout.motors):
            if not acts[a].name:
                acts[a].name = mname
            _dc_driver(
                acts[a],
                model,
                a,
                sgn,
                ref.driver or "current",
                tau,
            )
    elif min(plan["keep"]) >= 0:
        for a, sgn, mname in zip(plan["keep"], layout.wheel_sign, layout.motors):
            act = acts[a]
            if not act.name:
                act.name = mname
            gear = np.array(act.gear, float)
            gear[0] = sgn * abs(gear[0])
            act.gear = gear
            if ref.tau_max > 0:  # the mapping's limit replaces the model's (gear ±1: ctrl is N·m)
                act.ctrlrange = [-tau, tau]
                act.forcelimited = 1
                act.forcerange = [-tau, tau]
    else:
        for name, j, sgn in zip(layout.motors, layout.wheel_joints, layout.wheel_sign):
            spec.add_actuator(
                name=name,
                target=j,
                trntype=mujoco.mjtTrn.mjTRN_JOINT,
                gear=[float(sgn), 0, 0, 0, 0, 0],
                ctrllimited=1,
                ctrlrange=[-tau, tau],
                forcelimited=1,
                forcerange=[-tau, tau],
            )
    _hold_and_contacts(spec, model, plan, acts, sjoints, sgeoms)
    spec.add_text(name=_LAYOUT_TEXT, data=layout.to_json())
    return spec, layout, np.asarray(plan["axle_world"], float), plan["base_yaw"]


def _hold_and_contacts(spec, model, plan, acts, sjoints, sgeoms) -> None:
    """design §13 in the spec: casters' friction and priority, frozen joints removed (with the
    actuators on them), locked joints held by a joint equality at their ``qpos0``."""
    for g, name in plan["name_geoms"].items():
        sgeoms[g].name = name
    for g in plan["priority"]:
        sgeoms[g].priority = CONTACT_PRIORITY
    for g, fr in plan["friction"].items():
        sgeoms[g].friction = fr
        sgeoms[g].priority = CONTACT_PRIORITY
    for g in plan["condim1"]:
        sgeoms[g].condim = 1
    for j, name in plan["name_joints"].items():
        sjoints[j].name = name
    for a in plan["freeze_acts"]:
        spec.delete(acts[a])
    for j in plan["freeze"]:
        spec.delete(sjoints[j])
    dt = float(model.opt.timestep)
    for j in plan["lock"]:
        data = np.zeros(mujoco.mjNEQDATA)  # joint1 − qpos0 = polycoef[0] = 0 without a joint2: held at qpos0
        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_JOINT,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            name1=sjoints[j].name,
            data=data,
            solref=[2 * dt, 1.0],  # as stiff as the step allows (MuJoCo: timeconst >= 2 dt)
        )


def prepare_robots(
    entries: Sequence[RobotRef | str | Path],
) -> list[tuple[mujoco.MjSpec, RobotLayout, np.ndarray, float]]:
    """:func:`prepare_robot` of each entry, each distinct entry prepared once: a repeat gets a copy of the first's
    spec (``MjSpec.copy``) and its own copy of the axle midpoint; the layout (frozen) is shared. A team of n copies of
    one robot reads, checks and analyses its file once, not n times (at n = 1024: 34 s of the build under cProfile;
    the scene is the same byte for byte, tests/test_scene_build.py). An entry that cannot be hashed is prepared each
    time."""
    done: dict = {}
    out = []
    for e in entries:
        try:
            first = done.get(e)
        except TypeError:  # not hashable: no reuse
            out.append(prepare_robot(e))
            continue
        if first is None:
            first = done[e] = prepare_robot(e)
            out.append(first)
        else:
            out.append((first[0].copy(), first[1], first[2].copy(), first[3]))
    return out


def load_robot(entry: RobotRef | str | Path) -> mujoco.MjSpec:
    """Load one robot MJCF as a fresh, drivable ``MjSpec`` (see :func:`prepare_robot`; raises ``ModelError``)."""
    return prepare_robot(entry)[0]
