"""Resolve a robot's mapping on its compiled model (design §13): the base, the wheels (radius,
half track, axle midpoint, forward signs), the wheel contact geoms and their proxies, the motors and
the torque limit, the other wheels, the casters and frictionless geoms, and what holds every other
joint. :func:`_analyse` returns the :class:`~bioform_mj.robots.layout.RobotLayout` and the ``plan``
that :func:`bioform_mj.robots.prepare.prepare_robot` carries out in the spec; :func:`layout_of`
reads a compiled model's layout back.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np

from bioform_mj.robots.layout import (
    _ACT,
    _FREE,
    _HINGE,
    _LAYOUT_TEXT,
    _SINGLE_CONTACT,
    CONTACT_PRIORITY,
    FRICTIONLESS,
    ROBOT,
    SUPPORT_CLEARANCE,
    ModelError,
    RobotLayout,
    _collides,
    _geom_label,
    _joint_label,
    _quoted,
    dc_constants,
    element_name,
    frictionless_contacts,
    geom_support,
    subtree,
    welded_to,
)
from bioform_mj.robots.refs import RobotRef

__all__ = ["layout_of"]


#: largest wheel torque limit a robot file may give, N·m (a 1e308 URDF effort overflowed the check's numbers)
MAX_WHEEL_TORQUE = 1e6


def layout_of(model: mujoco.MjModel, prefix: str = "") -> RobotLayout:
    """The :class:`RobotLayout` of the robot named with ``prefix`` in a compiled model.

    Names in the returned layout carry ``prefix``. A model without the ``bioform_layout`` text (an
    MJCF compiled without :func:`~bioform_mj.robots.prepare.prepare_robot`) gets the shipped
    convention, read directly.
    """
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, prefix + _LAYOUT_TEXT)
    if tid < 0:
        lay = _analyse(model, Path("<model>"), _convention_ref(), add_motors=False)[0]
    else:
        adr, size = model.text_adr[tid], model.text_size[tid]
        lay = RobotLayout.from_json(bytes(model.text_data[adr : adr + size - 1]).decode())
    return lay.with_prefix(prefix) if prefix else lay


def _convention_ref() -> RobotRef:
    return RobotRef(model="", base=ROBOT.base, left_wheel=ROBOT.wheel_joints[0], right_wheel=ROBOT.wheel_joints[1])


def _analyse(model: mujoco.MjModel, path: Path, ref: RobotRef, *, add_motors: bool = True):
    """Resolve ``ref``'s mapping on the compiled robot ``model``; returns ``(layout, plan)``.

    ``plan`` says what :func:`~bioform_mj.robots.prepare.prepare_robot` must change in the spec.
    Raises ModelError naming the element and the file. The steps, in order (each adds its notes):
    the base, the wheel joints, the axle, the wheels' contact geoms and radius, the wheel drives
    and the torque limit, the motors, notes on the wheel joints and on other wheels, the casters
    and the other joints (:func:`_contacts_and_joints`).
    """
    names = _Mapped(
        ref.base or ROBOT.base, ref.left_wheel or ROBOT.wheel_joints[0], ref.right_wheel or ROBOT.wheel_joints[1]
    )
    notes: list[str] = []
    base, has_free = _find_base(model, path, names.base, notes)
    joints = _wheel_joints(model, path, names, base)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    ax = _axle(model, data, path, ref, names, base, joints, notes)
    r, geoms, proxies = _wheel_contacts(model, data, path, ref, joints, ax.anchors, ax.up, notes)
    drives, dc_all, keep = _wheel_drives(model, joints)
    tau_max = _torque_limit(model, path, ref, names, joints, drives, keep, notes)
    motors, keep, disabled, dc_keep, tau_max = _motors(
        model, path, ref, joints, drives, dc_all, keep, tau_max, add_motors, notes
    )
    _note_wheel_joints(model, joints, r, notes)
    # other wheels: hinges below the base, axis along its y, touching the floor (a 4-wheel or skid-steer
    # base, e.g. the menagerie Jackal); a swivelling caster's wheel sits below a second joint and is fine
    floor_z = float(np.mean(ax.anchors[:, 2])) - r
    _note_other_wheels(model, data, base, joints, ax.left, ax.up, r, floor_z, notes)
    cj = _contacts_and_joints(model, data, path, ref, base, joints, drives + dc_all, r, floor_z, ax.up, notes)
    jn = tuple(element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints)
    layout = RobotLayout(
        file=str(path),
        base=names.base,
        wheel_joints=jn,
        motors=motors,
        wheel_geoms=_wheel_geom_names(model, jn, geoms, proxies),
        wheel_radius=r,
        half_track=ax.half_track,
        axle=tuple(float(x) for x in ax.axle),
        wheel_sign=tuple(ax.signs),
        tau_max=float(tau_max),
        disabled_actuators=tuple(element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in disabled),
        notes=tuple(notes),
        **cj["layout"],
    )
    plan = dict(
        has_free=has_free,
        keep=keep,
        disabled=disabled,
        dc=bool(dc_keep),
        dc_removed=[] if dc_keep else dc_all,
        proxies=proxies,
        geoms=geoms,
        radius=r,
        joints=joints,
        axle_world=ax.mid,
        base_yaw=float(np.arctan2(ax.fwd[1], ax.fwd[0])),
        **cj["plan"],
    )
    return layout, plan


class _Mapped(NamedTuple):
    """The mapping's names of the base body and the wheel joints (the convention's where not given)."""

    base: str
    left: str
    right: str


class _Axle(NamedTuple):
    """The wheels' axle in the model file's world frame at ``qpos0`` (m), and the base's axes."""

    fwd: np.ndarray  # base x axis, world frame
    left: np.ndarray  # base y axis
    up: np.ndarray  # base z axis
    anchors: np.ndarray  # (2, 3) the wheel joints' anchors, [left, right]
    signs: list[int]  # +1/−1 per wheel: sign · joint velocity = forward wheel rate
    mid: np.ndarray  # axle midpoint, world frame
    axle: np.ndarray  # axle midpoint in the base body's frame
    half_track: float


def _find_base(model: mujoco.MjModel, path: Path, base_name: str, notes: list[str]) -> tuple[int, bool]:
    """The base body's id and whether it has a free joint (one is added otherwise: noted)."""
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, base_name)
    if base < 0:
        raise ModelError(f"{path}: no body '{base_name}' (the base; map it with base = \"BODY\")")
    if base == 0:  # design §17: MuJoCo's world body cannot be a chassis (it failed later, naming no file)
        raise ModelError(
            f"{path}: base '{base_name}' is MuJoCo's world body, which is fixed and cannot be a robot's "
            f'chassis; name the chassis body (map it with base = "BODY")'
        )
    jnt_adr, jnt_num = model.body_jntadr[base], model.body_jntnum[base]
    has_free = jnt_num >= 1 and model.jnt_type[jnt_adr] == _FREE
    if jnt_num > (1 if has_free else 0):
        raise ModelError(
            f"{path}: body '{base_name}' has joints other than a free joint; the base must be one rigid chassis"
        )
    if not has_free and model.body_parentid[base] != 0:
        raise ModelError(f"{path}: body '{base_name}' has no free joint and is not a child of the world body")
    if not has_free:
        notes.append(f"body '{base_name}' had no free joint: one was added")
    return base, has_free


def _wheel_joints(model: mujoco.MjModel, path: Path, names: _Mapped, base: int) -> list[int]:
    """The ids of the left and right wheel joints: two different hinges on bodies below the base."""
    joints = []
    below = set(subtree(model, base).tolist())
    for side, jname in (("left_wheel", names.left), ("right_wheel", names.right)):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, jname)
        if j < 0:
            from bioform_mj.robots.urdf_wheels import hinge_candidates

            raise ModelError(
                f"{path}: no joint '{jname}' ({side}; map it with {side} = \"JOINT\"; hinge joints found: "
                f"{hinge_candidates(model)})"
            )
        if model.jnt_type[j] != _HINGE:
            raise ModelError(
                f"{path}: joint '{jname}' ({side}) is not a hinge (type {mujoco.mjtJoint(model.jnt_type[j]).name})"
            )
        if int(model.jnt_bodyid[j]) not in below:
            raise ModelError(f"{path}: joint '{jname}' ({side}) is not on a body below '{names.base}'")
        joints.append(j)
    if joints[0] == joints[1]:
        raise ModelError(f"{path}: left_wheel and right_wheel are the same joint '{names.left}'")
    return joints


def _axle(model, data, path: Path, ref: RobotRef, names: _Mapped, base: int, joints, notes) -> _Axle:
    """The level base's axes, the wheel axes along its y (their forward signs), the axle midpoint and
    the half track (the mapping's, if given)."""
    rot = data.xmat[base].reshape(3, 3)
    fwd, left, up = rot[:, 0], rot[:, 1], rot[:, 2]
    if up[2] < 0.999:
        raise ModelError(
            f"{path}: body '{names.base}' is not level in the model file (its z axis is "
            f"{np.round(up, 3).tolist()}); the base frame must be x forward, z up"
        )
    anchors = np.array([data.xanchor[j] for j in joints])
    axes = np.array([data.xaxis[j] for j in joints])
    signs = []
    for j, ax in zip(joints, axes):
        c = float(ax @ left)
        if abs(c) < 0.99:
            raise ModelError(
                f"{path}: joint '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' axis "
                f"{np.round(rot.T @ ax, 3).tolist()} (base frame) is not along the base's y axis"
            )
        signs.append(1 if c > 0 else -1)
    for j, sgn in zip(joints, signs):
        if sgn < 0:
            notes.append(
                f"joint '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' axis points right (−y): "
                "its motor gets gear −1 so that positive torque drives forward"
            )
    if (anchors[0] - anchors[1]) @ left <= 0:
        raise ModelError(
            f"{path}: left_wheel '{names.left}' is not to the left of right_wheel '{names.right}' "
            "(swapped mapping, or the base's x axis is not forward)"
        )
    mid = anchors.mean(axis=0)
    axle = rot.T @ (mid - data.xpos[base])
    if np.linalg.norm(axle) > 1e-6:
        notes.append(
            f"base origin is off the axle midpoint (axle midpoint at {np.round(axle, 4).tolist()} m in "
            f"'{names.base}'): pose and υ refer to the axle midpoint"
        )
    half_track = float(0.5 * np.linalg.norm(anchors[0] - anchors[1]))
    if ref.half_track > 0:
        if abs(ref.half_track / half_track - 1) > 0.01:
            notes.append(f"half_track {ref.half_track:g} m given; the joint anchors say {half_track:.4g} m")
        half_track = float(ref.half_track)
    return _Axle(fwd, left, up, anchors, signs, mid, axle, half_track)


def _wheel_contacts(model, data, path: Path, ref: RobotRef, joints, anchors, up, notes):
    """Each wheel's contact geom and the wheel radius, m: ``(r, geoms, proxies)``.

    The collision geoms on each wheel's body; the radius is their extent below the joint anchor
    (the mapping's ``wheel_radius`` if given). ``geoms[i]``: the lowest one (−1: none);
    ``proxies[i]``: ``None`` (the geom is single-contact and alone), ``(joint, candidates, radius)`` (they
    are replaced by a single-contact proxy of their own radius, m) or ``(joint, None)`` (no geom: a proxy of
    the mapped radius is added)."""
    radii, geoms, proxies = [], [], []
    for j, anchor in zip(joints, anchors):
        wb = model.jnt_bodyid[j]
        jname = element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        cand = [
            g
            for g in range(model.ngeom)
            if model.geom_bodyid[g] == wb and (model.geom_contype[g] or model.geom_conaffinity[g])
        ]
        if not cand:
            if ref.wheel_radius <= 0:
                raise ModelError(
                    f"{path}: the body of wheel joint '{jname}' has no collision geom; "
                    "give wheel_radius in the robot's mapping"
                )
            radii.append(float(ref.wheel_radius))
            geoms.append(-1)
            proxies.append((j, None))
            notes.append(
                f"wheel '{jname}' has no collision geom: a single-contact proxy of radius "
                f"{ref.wheel_radius:g} m was added"
            )
            continue
        ext = [float((data.geom_xpos[g] - anchor) @ -up + geom_support(model, data, g, -up)) for g in cand]
        k = int(np.argmax(ext))
        g = cand[k]
        radii.append(ext[k])
        geoms.append(g)
        gtype = int(model.geom_type[g])
        if gtype not in _SINGLE_CONTACT or len(cand) > 1:
            # the proxy has the tyre's own radius, as a single-contact wheel keeps its geom: a mapped wheel_radius
            # changes the formula, never the physics (design §14, ``mapping``)
            proxies.append((j, cand, ext[k]))
            kind = mujoco.mjtGeom(gtype).name[len("mjGEOM_") :].lower()
            notes.append(
                f"wheel '{jname}': collision {kind} '{element_name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}'"
                f"{f' (+{len(cand) - 1} more)' if len(cand) > 1 else ''} replaced by a single-contact "
                f"ellipsoid proxy of radius {ext[k]:.4g} m (a {kind} touches the floor at several "
                "points whose scrub resists turning; the original is kept for looks)"
            )
        else:
            proxies.append(None)
    if ref.wheel_radius > 0:
        if abs(ref.wheel_radius / max(radii) - 1) > 0.01:
            notes.append(f"wheel_radius {ref.wheel_radius:g} m given; the collision geoms say {max(radii):.4g} m")
        radii = [float(ref.wheel_radius)] * 2
    if abs(radii[0] - radii[1]) > 1e-6 * max(radii):
        notes.append(f"left and right wheel radii differ ({radii[0]:.5g}, {radii[1]:.5g} m): using their mean")
    r = float(np.mean(radii))
    if not r > 0:
        raise ModelError(
            f"{path}: wheel radius from the collision geoms is {r:g} m (are the wheel geoms centred on their joints?)"
        )
    return r, geoms, proxies


def _drives_wheel(model: mujoco.MjModel, a: int, wheel_set: set) -> bool:
    """Actuator ``a`` acts on a wheel joint (directly, or through a tendon)."""
    trn, tid = int(model.actuator_trntype[a]), int(model.actuator_trnid[a, 0])
    if trn in (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT)):
        return tid in wheel_set
    if trn == int(mujoco.mjtTrn.mjTRN_TENDON):
        adr, num = model.tendon_adr[tid], model.tendon_num[tid]
        return any(
            model.wrap_type[w] == int(mujoco.mjtWrap.mjWRAP_JOINT) and model.wrap_objid[w] in wheel_set
            for w in range(adr, adr + num)
        )
    return False


def _plain_motor(model: mujoco.MjModel, a: int, j: int) -> bool:
    """Actuator ``a`` is a plain torque motor on joint ``j`` (gain 1, no bias or dynamics, gear ±1, ctrl limited)."""
    return (
        int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
        and model.actuator_trnid[a, 0] == j
        and model.actuator_dyntype[a] == int(mujoco.mjtDyn.mjDYN_NONE)
        and model.actuator_gaintype[a] == int(mujoco.mjtGain.mjGAIN_FIXED)
        and model.actuator_gainprm[a, 0] == 1
        and model.actuator_biastype[a] == int(mujoco.mjtBias.mjBIAS_NONE)
        and abs(abs(model.actuator_gear[a, 0]) - 1) < 1e-12
        and bool(model.actuator_ctrllimited[a])
    )


def _wheel_drives(model: mujoco.MjModel, joints) -> tuple[list[int], list[int], list[int]]:
    """The actuators on the wheels: ``(drives, dc_all, keep)``: the drives other than ``<dcmotor>``, the
    ``<dcmotor>`` ones (design §8.2: used with the mapping's motor = "dc", removed otherwise), and the
    plain motor kept per wheel (``[-1, -1]`` unless there are exactly two drives, one plain motor each)."""
    # actuators on the wheels: keep a plain motor, neutralise every other drive
    wheel_set = set(joints)
    drives = [a for a in range(model.nu) if _drives_wheel(model, a, wheel_set)]
    # <dcmotor> drives (design §8.2): used with the mapping's motor = "dc", removed otherwise
    dc_all = [a for a in drives if int(model.actuator_dyntype[a]) == int(mujoco.mjtDyn.mjDYN_DCMOTOR)]
    drives = [a for a in drives if a not in dc_all]
    keep = []
    for j in joints:
        mine = [a for a in drives if _plain_motor(model, a, j)]
        keep.append(mine[0] if mine else -1)
    if min(keep) < 0 or len(drives) != 2:
        keep = [-1, -1]
    return drives, dc_all, keep


def _torque_limit(model, path: Path, ref: RobotRef, names: _Mapped, joints, drives, keep, notes) -> float:
    """The wheel torque limit, N·m: the mapping's ``tau_max``, else the kept motors' ctrl/force range,
    else the model's own drives' force range × gear or the joints' ``actuatorfrcrange``; a joint's
    ``actuatorfrcrange`` caps it."""
    limits = []
    if ref.tau_max > 0:
        tau_max = float(ref.tau_max)
    elif min(keep) >= 0:
        for a in keep:
            lim = float(min(abs(model.actuator_ctrlrange[a, 0]), abs(model.actuator_ctrlrange[a, 1])))
            if model.actuator_forcelimited[a]:
                lim = min(lim, float(min(-model.actuator_forcerange[a, 0], model.actuator_forcerange[a, 1])))
            limits.append(lim)
        tau_max = min(limits)
    else:
        for a in drives:
            if model.actuator_forcelimited[a]:
                lim = float(min(-model.actuator_forcerange[a, 0], model.actuator_forcerange[a, 1]))
                limits.append(lim * abs(float(model.actuator_gear[a, 0])))
        for j in joints:
            if model.jnt_actfrclimited[j]:
                limits.append(float(min(-model.jnt_actfrcrange[j, 0], model.jnt_actfrcrange[j, 1])))
        if not limits:
            raise ModelError(
                f"{path}: cannot tell the wheel torque limit: no drive actuator on "
                f"'{names.left}'/'{names.right}' has a forcerange and the joints have no actuatorfrcrange; "
                "give tau_max (N·m) in the robot's mapping (a URDF: <limit effort> on the wheel joints)"
            )
        tau_max = min(limits)
        notes.append(
            f"wheel torque limit {tau_max:g} N·m taken from the model's own drive "
            "(forcerange × gear, or the joints' actuatorfrcrange)"
        )
    for j in joints:
        if model.jnt_actfrclimited[j]:
            lim = float(min(-model.jnt_actfrcrange[j, 0], model.jnt_actfrcrange[j, 1]))
            if lim < tau_max:
                notes.append(
                    f"joint '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' actuatorfrcrange {lim:g} N·m "
                    f"caps the motor limit {tau_max:g} N·m"
                )
                tau_max = lim
    if not tau_max > 0:
        raise ModelError(f"{path}: wheel torque limit is {tau_max:g} N·m; give tau_max in the robot's mapping")
    if tau_max > MAX_WHEEL_TORQUE:  # effort="1e308": the check then said "accelerates the robot at inf m/s²"
        raise ModelError(
            f"{path}: wheel torque limit is {tau_max:g} N·m, above the {MAX_WHEEL_TORQUE:g} N·m of any wheel motor; "
            "give tau_max in the robot's mapping"
        )
    return tau_max


def _motors(model, path: Path, ref: RobotRef, joints, drives, dc_all, keep, tau_max, add_motors, notes):
    """The motors the plant writes: ``(motors, keep, disabled, dc_keep, tau_max)``: their names (the
    kept plain motors, the ``<dcmotor>`` ones with motor = "dc" (:func:`_dc_plan`, which also sets
    ``tau_max``), else torque motors to add), the actuators kept per wheel, the model's wheel drives
    left unused and the kept ``<dcmotor>`` ones."""
    disabled = [a for a in drives if a not in keep]
    dc_keep: list[int] = []
    if ref.motor == "dc":
        tau_max = _dc_plan(model, path, ref, joints, dc_all, dc_keep, notes)
        disabled = list(drives)
        keep = dc_keep
    act_names = {element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu)}
    if min(keep) >= 0:  # an unnamed kept motor gets a name (prepare_robot sets it)
        motors = tuple(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
            or f"{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}_motor"
            for a, j in zip(keep, joints)
        )
    else:
        motors = tuple(n if n not in act_names else f"bioform_{n}" for n in ROBOT.motors)
        if add_motors:
            notes.append(f"torque motors '{motors[0]}', '{motors[1]}' (±{tau_max:g} N·m) attached to the wheel joints")
    if disabled:
        notes.append(
            "the model's own wheel drive "
            + ", ".join(f"'{element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)}'" for a in disabled)
            + " is left unused (zero gain and bias: no force)"
        )
    return motors, keep, disabled, dc_keep, tau_max


def _note_wheel_joints(model: mujoco.MjModel, joints, r: float, notes: list[str]) -> None:
    """Notes on what the wheel joints carry that the paper's model lacks: damping, armature,
    frictionloss, stiffness."""
    for j in joints:
        dof = model.jnt_dofadr[j]
        parts = [
            f"{k} {v:g}"
            for k, v in (
                ("damping", model.dof_damping[dof]),
                ("armature", model.dof_armature[dof]),
                ("frictionloss", model.dof_frictionloss[dof]),
            )
            if v
        ]
        if parts:
            notes.append(
                f"joint '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}': "
                + ", ".join(parts)
                + " (armature enters a_eff, b_eff; damping and frictionloss are a drag and a dead band "
                "the paper's model lacks)"
            )

        if model.jnt_stiffness[j]:
            notes.append(
                f"joint '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}': "
                f"stiffness {model.jnt_stiffness[j]:g} N·m/rad, "
                "a spring on a wheel that turns without end: a torque k φ growing with the distance driven "
                f"(k s / r = {model.jnt_stiffness[j] / r:.3g} N·m per metre), which the paper's model lacks"
            )


def _note_other_wheels(model, data, base: int, joints, left, up, r: float, floor_z: float, notes) -> None:
    """A note per other fixed wheel touching the floor: a hinge along the axle direction, the only
    joint of its body, below the base through bodies without joints (skid steer)."""
    welded = set(welded_to(model, base).tolist())
    for j in range(model.njnt):
        if j in joints or model.jnt_type[j] != _HINGE or abs(float(data.xaxis[j] @ left)) < 0.99:
            continue
        b = int(model.jnt_bodyid[j])
        if model.body_jntnum[b] != 1:
            continue
        if int(model.body_parentid[b]) not in welded:
            continue
        touches = [
            g
            for g in range(model.ngeom)
            if model.geom_bodyid[g] == b
            and _collides(model, g)
            and data.geom_xpos[g][2] - geom_support(model, data, g, -up) - floor_z <= max(0.005, 0.25 * r)
        ]
        if touches:
            notes.append(
                f"other wheel '{element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' "
                f"(a hinge along the axle direction, not "
                "mapped) touches the floor: with a fixed wheel off the driven axle the base turns only by "
                "scrubbing it sideways (skid steer), which the paper's differential-drive model lacks; "
                "its own actuators, if any, are left as they are"
            )


def _wheel_geom_names(model: mujoco.MjModel, jn, geoms, proxies) -> tuple[str, ...]:
    """The geom that touches the floor, per wheel: its name, or ``JOINT_contact`` for a proxy or an
    unnamed wheel geom (prepare_robot gives it that name)."""
    gnames = []
    for j, g, pr in zip(jn, geoms, proxies):
        named = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) if pr is None else None
        gnames.append(named or f"{j}_contact")  # an unnamed wheel geom gets a name (prepare_robot)
    return tuple(gnames)


def _contacts_and_joints(model, data, path, ref: RobotRef, base: int, joints, drives, r, floor_z, up, notes) -> dict:
    """design §13: the casters and frictionless geoms (priority), and what holds each joint that is
    not a wheel. Returns ``{"layout": RobotLayout fields, "plan": what prepare_robot changes}``."""
    bodies = subtree(model, base)
    body_set = set(bodies.tolist())
    wheel_bodies = set()
    for j in joints:
        wheel_bodies |= set(welded_to(model, int(model.jnt_bodyid[j])).tolist())
    robot_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] in body_set and _collides(model, g)]
    tol = max(SUPPORT_CLEARANCE, 0.25 * r)
    support = [
        g
        for g in robot_geoms
        if data.geom_xpos[g] @ up - geom_support(model, data, g, -up) - floor_z <= tol
        and model.geom_bodyid[g] not in wheel_bodies
    ]

    # casters named by the mapping: geoms, or every collision geom of a body
    named: list[int] = []
    for nm in ref.casters:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, nm)
        if g >= 0:
            if model.geom_bodyid[g] not in body_set:
                raise ModelError(f"{path}: caster '{nm}' (mapping casters) is not a geom of the robot")
            named.append(g)
            continue
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, nm)
        if b < 0:
            raise ModelError(f"{path}: no geom or body '{nm}' (mapping casters)")
        mine = [g for g in robot_geoms if model.geom_bodyid[g] == b]
        if not mine:
            raise ModelError(f"{path}: body '{nm}' (mapping casters) has no collision geom")
        named += mine
    if on_wheel := [int(model.geom_bodyid[g]) for g in named if model.geom_bodyid[g] in wheel_bodies]:
        wb = element_name(model, mujoco.mjtObj.mjOBJ_BODY, on_wheel[0])
        raise ModelError(f"{path}: a caster (mapping casters) is on the driven wheel body '{wb}', not a caster")
    published: list[tuple[str, float, int]] = []
    friction: dict[int, list[float]] = {}
    condim1: list[int] = []
    if ref.caster_friction >= 0:
        targets = named or support
        if not targets:
            notes.append(
                f"caster_friction {ref.caster_friction:g} given, but no caster is named and no geom other than the "
                "wheels reaches the floor: ignored"
            )
        for g in targets:
            fr = np.array(model.geom_friction[g], float)
            published.append((_geom_label(model, g), float(fr[0]), int(model.geom_condim[g])))
            fr[0] = ref.caster_friction
            friction[g] = fr.tolist()
            if ref.caster_friction < FRICTIONLESS:  # frictionless: condim 1 (a pyramidal cone with μ ≈ 0 is
                condim1.append(g)  # ill-conditioned: the contact rocks ~10x longer before it settles)
        if targets:
            notes.append(
                f"caster(s) {_quoted(_geom_label(model, g) for g in targets)}: sliding friction "
                f"{ref.caster_friction:g} (mapping caster_friction; published "
                + ", ".join(f"{f:g}" for _, f, _ in published)
                + f"), priority {CONTACT_PRIORITY} so that it decides the floor contact"
                + (", condim 1" if condim1 else "")
            )
    # frictionless as published (layout.frictionless_contacts, the one floor-contact classification, design §13):
    # priority so that MuJoCo's max rule does not give them the floor's μ, and condim 1 (normal force only)
    others = [g for g in robot_geoms if model.geom_bodyid[g] not in wheel_bodies]
    pub_fl, to_condim1, note = frictionless_contacts(model, [g for g in others if g not in friction])
    raise_prio = [g for g in others if (g in pub_fl or g in friction) and model.geom_priority[g] < CONTACT_PRIORITY]
    published += [
        (_geom_label(model, g), float(model.geom_friction[g, 0]), int(model.geom_condim[g])) for g in to_condim1
    ]
    condim1 += to_condim1
    notes += [note] if note else []

    # joints that are not the wheels or the root (design §13)
    wheel_set = set(int(j) for j in joints)
    root = int(model.body_jntadr[base]) if model.body_jntnum[base] else -1
    sensed_acts = {
        int(model.sensor_objid[k])
        for k in range(model.nsensor)
        if model.sensor_objtype[k] == int(mujoco.mjtObj.mjOBJ_ACTUATOR)
    }
    joint_trn = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
    frozen, locked, held, free, rolling = [], [], [], [], []
    frozen_acts: list[int] = []
    lock_q: dict[int, float] = {}
    for j in range(model.njnt):
        b = int(model.jnt_bodyid[j])
        if j in wheel_set or j == root or b not in body_set:
            continue
        below = set(subtree(model, b).tolist())
        if any(model.geom_bodyid[g] in below for g in support) or b in wheel_bodies:
            rolling.append(j)  # a caster's swivel or wheel (or a joint on a wheel): passive, free
            continue
        acts = [
            a for a in range(model.nu) if model.actuator_trntype[a] in joint_trn and model.actuator_trnid[a, 0] == j
        ]
        servo = [
            a
            for a in acts
            if model.actuator_biastype[a] == int(mujoco.mjtBias.mjBIAS_AFFINE)
            and model.actuator_biasprm[a, 1] < 0
            and model.actuator_gainprm[a, 0] > 0
        ]
        if ref.free_joints:
            free.append(j)
            continue
        if servo:
            held.append(j)
            continue
        referenced = (
            any(
                model.wrap_type[w] == int(mujoco.mjtWrap.mjWRAP_JOINT) and model.wrap_objid[w] == j
                for w in range(model.nwrap)
            )
            or any(
                model.eq_type[e] == int(mujoco.mjtEq.mjEQ_JOINT) and j in (model.eq_obj1id[e], model.eq_obj2id[e])
                for e in range(model.neq)
            )
            or any(
                model.sensor_objtype[k] == int(mujoco.mjtObj.mjOBJ_JOINT) and model.sensor_objid[k] == j
                for k in range(model.nsensor)
            )
            or any(a in sensed_acts for a in acts)
        )
        if not referenced:
            frozen.append(j)
            frozen_acts += acts
        elif int(model.jnt_type[j]) in (_HINGE, int(mujoco.mjtJoint.mjJNT_SLIDE)):
            locked.append(j)
            lock_q[j] = float(model.qpos0[model.jnt_qposadr[j]])
        else:
            free.append(j)
    jl = lambda js: _quoted(_joint_label(model, j) for j in js)  # noqa: E731
    suspended: list[tuple[str, str]] = []
    if frozen:
        # a driven wheel below a frozen joint: a suspension (PMB-2: its wheels' ±5 mm sliders, frozen, biased its
        # fitted wheel damping 3x against a recording where they rode to their limit)
        below = {j: set(subtree(model, int(model.jnt_bodyid[j])).tolist()) for j in frozen}
        pairs = [(w, j) for w in joints for j in frozen if int(model.jnt_bodyid[w]) in below[j]]
        hung = [j for j in frozen if any(j == k for _, k in pairs)]
        # each driven wheel below a frozen joint, and that joint (the fit's suspension rule)
        suspended = [(_joint_label(model, w), _joint_label(model, j)) for w, j in pairs]
        notes.append(
            f"joint(s) {jl(frozen)} frozen (design §13: removed from the scene, their bodies welded where the file "
            "puts them; map free_joints = true to leave them free)"
            + (
                f"; a driven wheel hangs below {jl(hung)} (a suspension?): free it if it moves on the robot"
                if hung
                else ""
            )
            + (
                f"; their actuator(s) {_quoted(element_name(model, _ACT, a) for a in frozen_acts)} removed"
                if frozen_acts
                else ""
            )
        )
    if locked:
        notes.append(
            f"joint(s) {jl(locked)} locked at the file's configuration by a joint equality (a tendon, equality or "
            "sensor names them, so they cannot be removed)"
        )
    if held:
        qs = [float(model.qpos0[model.jnt_qposadr[j]]) for j in held]
        hold = [_servo_hold(model, j, joint_trn) for j in held]  # 0 unless a keyframe moved it (design §13.2)
        notes.append(
            f"joint(s) {jl(held)} held by the model's own position actuators at ctrl = 0"
            + (
                f" (their target is {', '.join(f'{h:.3g}' for h in hold)}, the file's configuration is "
                + ", ".join(f"{q:.3g}" for q in qs)
                + ": they move there)"
                if any(abs(q - h) > 1e-9 for q, h in zip(qs, hold))
                else ""
            )
        )
    if free:
        notes.append(
            f"joint(s) {jl(free)} left free"
            + (" (free_joints = true)" if ref.free_joints else " (a ball or free joint that an equality cannot lock)")
            + ": gravity and the drive move them; robot check reports moving_parts"
        )
    if rolling:
        notes.append(
            f"joint(s) {jl(rolling)} left free: a caster's swivel or wheel (a geom below them touches the floor)"
        )
    frozen_set = set(frozen_acts)
    others = [a for a in range(model.nu) if a not in drives and a not in frozen_set]
    if others:
        notes.append(
            f"{len(others)} other actuator(s) kept with ctrl = 0 (a position actuator holds its target 0, a motor "
            "or velocity actuator pushes nothing or damps)"
        )
    name_geoms = {
        g: _geom_label(model, g)
        for g in set(raise_prio) | set(friction) | set(condim1)
        if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    }
    name_joints = {
        j: _joint_label(model, j) for j in locked if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    }
    return {
        "layout": dict(
            frozen_joints=tuple(_joint_label(model, j) for j in frozen),
            suspended_wheels=tuple(suspended),
            locked_joints=tuple(_joint_label(model, j) for j in locked),
            held_joints=tuple(_joint_label(model, j) for j in held),
            free_joints=tuple(_joint_label(model, j) for j in free),
            rolling_joints=tuple(_joint_label(model, j) for j in rolling),
            casters=tuple(dict.fromkeys(_geom_label(model, g) for g in named)),
            priority_geoms=tuple(_geom_label(model, g) for g in raise_prio),
            published_contacts=tuple(published),
        ),
        "plan": dict(
            freeze=frozen,
            freeze_acts=frozen_acts,
            lock=lock_q,
            priority=raise_prio,
            friction=friction,
            condim1=condim1,
            name_geoms=name_geoms,
            name_joints=name_joints,
        ),
    }


def _servo_hold(model: mujoco.MjModel, j: int, joint_trn) -> float:
    """Where joint ``j``'s first position servo holds it at ``ctrl = 0``: ``−b0 / (b1 · gear)`` (0 for a
    servo as published, ``b0 = 0``; a keyframe's target where one moved it into the bias, design §13.2)."""
    for a in range(model.nu):
        if (
            model.actuator_trntype[a] in joint_trn
            and model.actuator_trnid[a, 0] == j
            and model.actuator_biasprm[a, 1] < 0
        ):
            return float(-model.actuator_biasprm[a, 0] / (model.actuator_biasprm[a, 1] * model.actuator_gear[a, 0]))
    return 0.0


def _dc_plan(model, path, ref, joints, dc_all, dc_keep, notes) -> float:
    """motor = "dc": the ``<dcmotor>`` on each wheel joint (appended to ``dc_keep``), checked; the
    wheel torque limit (stall torque ``g K V_max / R``, or the mapping's ``tau_max`` if lower)."""
    limits = []
    for j in joints:
        mine = [
            a
            for a in dc_all
            if int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT) and model.actuator_trnid[a, 0] == j
        ]
        jname = element_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if len(mine) != 1:
            raise ModelError(
                f"scenario key 'plant.robots.motor': \"dc\" needs one <dcmotor> on wheel joint "
                f"'{jname}' of {path}, found {len(mine)}"
            )
        a = mine[0]
        aname = element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        R, K, g, vmax = dc_constants(model, a)
        for val, what in ((R, "resistance"), (K, "motorconst"), (g, "gear"), (vmax, "ctrlrange (supply voltage)")):
            if not val > 0:
                raise ModelError(
                    f"scenario key 'plant.robots.motor': <dcmotor> '{aname}' in {path}: {what} must be > 0, got {val:g}"
                )
        dc_keep.append(a)
        limits.append(g * K * vmax / R)
    stall = min(limits)
    tau = min(stall, ref.tau_max) if ref.tau_max > 0 else stall
    drv = ref.driver or "current"
    notes.append(
        f"DC motors '{element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, dc_keep[0])}', "
        f"'{element_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, dc_keep[1])}' ({drv} driver): stall torque "
        f"{stall:.4g} N·m at the wheel" + (f", limited to {tau:g} N·m" if tau < stall else "")
    )
    return tau
