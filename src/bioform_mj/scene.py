"""Compose a MuJoCo scene of ``n`` differential-drive followers with ``mujoco.MjSpec``.

A robot is an MJCF file plus a mapping (:class:`bioform_mj.robots.RobotRef`); see the README,
"What a robot needs". A URDF file is imported first (:mod:`bioform_mj.urdf`, design §12: free
root link, links kept as bodies, meshes found, every guess a note), then treated the same. An
MJCF robot's asset files are made absolute (:func:`absolute_asset_files`). :func:`prepare_robot`
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
- keyframes are dropped (the scene sets its own initial poses).

What was found is stored in the robot's spec as the custom text ``bioform_layout`` (JSON of
:class:`RobotLayout`), so a compiled scene carries it (``f1/bioform_layout``, …) and
:func:`layout_of` reads it back.

The scene adds a floor, lights, a skybox, the virtual leader as a mocap "ghost" body
``leader`` (no collisions), optional mocap slot markers ``slot_1 … slot_n``, a mocap body
``centroid`` carrying the cameras ``track`` (chase view) and ``top`` (top-down) that the
plant moves to the formation centroid, and the followers attached with prefixes
``f1/``, ``f2/``, … (1-based), each placed so that its axle midpoint is at the initial
pose and its wheels touch the floor. Nothing here edits XML strings.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.errors import InputError
from bioform_mj.robots import RobotRef, models_dir, resolve_robot, robot_names
from bioform_mj.urdf import import_urdf, is_urdf

log = logging.getLogger(__name__)

__all__ = [
    "ModelError",
    "RobotNames",
    "ROBOT",
    "RobotLayout",
    "layout_of",
    "prepare_robot",
    "model_path",
    "load_robot",
    "build_scene",
    "compile_scene",
    "follower_prefix",
    "yaw_quat",
    "payload_inertial",
    "MARKER_Z",
    "Markers",
    "PATCH_THICKNESS",
    "FRICTIONLESS",
    "CONTACT_PRIORITY",
    "SUPPORT_CLEARANCE",
    "subtree",
    "welded_to",
]


#: height of the leader ghost / slot markers above the floor, m
MARKER_Z = 0.002
#: a geom whose sliding friction is below this (or whose condim is 1) is frictionless as published
FRICTIONLESS = 1e-3
#: priority given to a robot's frictionless geoms and mapped casters (design §13): above the floor's
#: (0, or 1 with ``floor_friction``) and a friction patch's (1), so that MuJoCo takes their own
#: friction and condim for the pair instead of the larger of the two
CONTACT_PRIORITY = 2
#: a collision geom whose lowest point is within this of the floor (m, or 0.25 r if larger) supports the chassis
SUPPORT_CLEARANCE = 0.005
#: thickness of a low-friction floor patch, m: far above a wheel's contact penetration (~1 µm),
#: below the paper robot's caster clearance (0.5 mm), so only the wheels touch it
PATCH_THICKNESS = 0.0002


class ModelError(InputError):
    """A robot model file is missing, does not compile, or lacks what the plant needs.

    A ``ValueError`` (via :class:`~bioform_mj.errors.InputError`: the CLI exits 2).
    """


@dataclass(frozen=True)
class RobotNames:
    """Element names every robot model must define (before the scene prefix)."""

    base: str = "base"
    wheel_joints: tuple[str, str] = ("left_wheel", "right_wheel")
    motors: tuple[str, str] = ("left_motor", "right_motor")
    wheel_geoms: tuple[str, str] = ("left_wheel_collision", "right_wheel_collision")


ROBOT = RobotNames()


def follower_prefix(i: int) -> str:
    """Name prefix of follower ``i`` (0-based index → ``"f{i+1}/"``)."""
    return f"f{i + 1}/"


def model_path(name_or_path: str | Path) -> Path:
    """A shipped robot (``"paper"``, ``"paper_robot"`` or ``"paper_robot.xml"``) or a path.

    Paths are not checked here: :func:`load_robot` raises ``ModelError`` naming the file.
    """
    s = str(name_or_path)
    stem = s[: -len(".xml")] if s.endswith(".xml") else s
    stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
    if "/" not in s and "\\" not in s and stem in robot_names() and not Path(s).exists():
        return models_dir() / f"{stem}_robot.xml"
    return Path(s)


def yaw_quat(theta: float) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` of a rotation by ``theta`` rad about +z."""
    return np.array([np.cos(theta / 2), 0.0, 0.0, np.sin(theta / 2)])


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


_SINGLE_CONTACT = (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID))
_LAYOUT_TEXT = "bioform_layout"
_FREE, _HINGE = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_HINGE)
_ACT = mujoco.mjtObj.mjOBJ_ACTUATOR


@dataclass(frozen=True)
class RobotLayout:
    """What the plant needs of one robot, resolved once from its MJCF and mapping.

    Names are the robot file's (the scene adds its prefix). Lengths in m, in the base body's
    frame where a frame matters; ``tau_max`` in N·m.
    """

    file: str
    base: str
    wheel_joints: tuple[str, str]  # [left, right] hinge joints
    motors: tuple[str, str]  # the torque motors the plant writes (gear = wheel_sign)
    wheel_geoms: tuple[str, str]  # the geom that touches the floor, per wheel
    wheel_radius: float
    half_track: float
    axle: tuple[float, float, float]  # axle midpoint in the base body's frame
    wheel_sign: tuple[int, int]  # +1/−1: sign · joint velocity = forward wheel rate
    tau_max: float
    disabled_actuators: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    # design §13: the robot that runs and its contacts
    frozen_joints: tuple[str, ...] = ()  # removed from the scene: their bodies welded where the file puts them
    locked_joints: tuple[str, ...] = ()  # held at qpos0 by a joint equality (referenced elsewhere, not removable)
    held_joints: tuple[str, ...] = ()  # held by the model's own position actuators
    free_joints: tuple[str, ...] = ()  # left free (free_joints = true, or a ball joint that cannot be locked)
    rolling_joints: tuple[str, ...] = ()  # passive joints above a floor contact (caster swivel/wheel): free
    casters: tuple[str, ...] = ()  # geoms the mapping names as casters
    priority_geoms: tuple[str, ...] = ()  # geoms given CONTACT_PRIORITY so that their own friction/condim win
    published_contacts: tuple[tuple[str, float, int], ...] = ()  # (geom, friction, condim) as published, where changed
    #: the guesses of a format import (URDF, design §12), also at the head of ``notes``: runs warn them
    import_notes: tuple[str, ...] = ()

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> RobotLayout:
        d = json.loads(text)
        for k in ("wheel_joints", "motors", "wheel_geoms", "axle", "wheel_sign", "disabled_actuators", "notes"):
            d[k] = tuple(d[k])
        for k in ("frozen_joints", "locked_joints", "held_joints", "free_joints", "rolling_joints", "casters"):
            d[k] = tuple(d.get(k, ()))
        d["priority_geoms"] = tuple(d.get("priority_geoms", ()))
        d["published_contacts"] = tuple((str(g), float(f), int(c)) for g, f, c in d.get("published_contacts", ()))
        d["import_notes"] = tuple(d.get("import_notes", ()))
        return cls(**d)


def layout_of(model: mujoco.MjModel, prefix: str = "") -> RobotLayout:
    """The :class:`RobotLayout` of the robot named with ``prefix`` in a compiled model.

    Names in the returned layout carry ``prefix``. A model without the ``bioform_layout`` text
    (an MJCF compiled without :func:`prepare_robot`) gets the shipped convention, read directly.
    """
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, prefix + _LAYOUT_TEXT)
    if tid < 0:
        lay = _analyse(model, Path("<model>"), _convention_ref(), add_motors=False)[0]
    else:
        adr, size = model.text_adr[tid], model.text_size[tid]
        lay = RobotLayout.from_json(bytes(model.text_data[adr : adr + size - 1]).decode())
    if not prefix:
        return lay
    return replace(
        lay,
        base=prefix + lay.base,
        wheel_joints=tuple(prefix + j for j in lay.wheel_joints),
        motors=tuple(prefix + a for a in lay.motors),
        wheel_geoms=tuple(prefix + g for g in lay.wheel_geoms),
        disabled_actuators=tuple(prefix + a for a in lay.disabled_actuators),
        frozen_joints=tuple(prefix + j for j in lay.frozen_joints),
        locked_joints=tuple(prefix + j for j in lay.locked_joints),
        held_joints=tuple(prefix + j for j in lay.held_joints),
        free_joints=tuple(prefix + j for j in lay.free_joints),
        rolling_joints=tuple(prefix + j for j in lay.rolling_joints),
        casters=tuple(prefix + g for g in lay.casters),
        priority_geoms=tuple(prefix + g for g in lay.priority_geoms),
        published_contacts=tuple((prefix + g, f, c) for g, f, c in lay.published_contacts),
    )


def _convention_ref() -> RobotRef:
    return RobotRef(model="", base=ROBOT.base, left_wheel=ROBOT.wheel_joints[0], right_wheel=ROBOT.wheel_joints[1])


def _geom_support(model: mujoco.MjModel, data: mujoco.MjData, g: int, d: np.ndarray) -> float:
    """Extent of geom ``g`` from its centre along the world unit vector ``d``, m (support function)."""
    size = model.geom_size[g]
    rot = data.geom_xmat[g].reshape(3, 3)
    loc = rot.T @ d
    t = int(model.geom_type[g])
    if t == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return float(size[0])
    if t == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID):
        return float(np.sqrt(np.sum((size * loc) ** 2)))
    if t == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
        return float(abs(loc[2]) * size[1] + np.hypot(loc[0], loc[1]) * size[0])
    if t == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
        return float(abs(loc[2]) * size[1] + size[0])
    if t == int(mujoco.mjtGeom.mjGEOM_BOX):
        return float(np.sum(np.abs(loc) * size[:3]))
    if t == int(mujoco.mjtGeom.mjGEOM_MESH):
        mid = model.geom_dataid[g]
        va, vn = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        return float(np.max(model.mesh_vert[va : va + vn] @ loc))
    raise ValueError(f"geom type {mujoco.mjtGeom(t).name} cannot be a wheel")


def subtree(model: mujoco.MjModel, root: int) -> np.ndarray:
    """Ids of body ``root`` and all its descendants."""
    ids = np.arange(model.nbody)
    inside = ids == root
    for b in ids[root + 1 :]:  # children always come after their parents
        inside[b] = inside[model.body_parentid[b]]
    return ids[inside]


def welded_to(model: mujoco.MjModel, body: int) -> np.ndarray:
    """Ids of ``body`` and every body welded to it: its descendants reached through bodies without
    joints (a hubcap on a fixed joint below a wheel; a body the compiler fused is part of ``body``
    already). They move rigidly with ``body`` (design §13)."""
    ids = np.arange(model.nbody)
    inside = ids == body
    for b in ids[body + 1 :]:
        inside[b] = inside[model.body_parentid[b]] and model.body_jntnum[b] == 0
    return ids[inside]


def _collides(model: mujoco.MjModel, g: int) -> bool:
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


def _name(model: mujoco.MjModel, objtype: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, objtype, i) or f"#{i}"


# Published models leave many elements unnamed (menagerie wheels: ``<geom class="collision"
# type="cylinder" .../>``, ``<velocity joint=.../>``): look spec elements up by their compiled
# index, never by a name that may not exist.
def _spec_body(spec: mujoco.MjSpec, model: mujoco.MjModel, b: int) -> mujoco.MjsBody:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
    return spec.body(name) if name else spec.bodies[b]


def _spec_geom(spec: mujoco.MjSpec, model: mujoco.MjModel, g: int) -> mujoco.MjsGeom:
    b = int(model.geom_bodyid[g])
    return _spec_body(spec, model, b).geoms[g - int(model.body_geomadr[b])]


def _spec_joint(spec: mujoco.MjSpec, model: mujoco.MjModel, j: int) -> mujoco.MjsJoint:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    if name:
        return spec.joint(name)
    b = int(model.jnt_bodyid[j])
    return _spec_body(spec, model, b).joints[j - int(model.body_jntadr[b])]


def _spec_actuator(spec: mujoco.MjSpec, model: mujoco.MjModel, a: int) -> mujoco.MjsActuator:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
    return spec.actuator(name) if name else spec.actuators[a]


def _analyse(model: mujoco.MjModel, path: Path, ref: RobotRef, *, add_motors: bool = True):
    """Resolve ``ref``'s mapping on the compiled robot ``model``; returns ``(layout, plan)``.

    ``plan`` says what :func:`prepare_robot` must change in the spec. Raises ModelError naming
    the element and the file.
    """
    base_name = ref.base or ROBOT.base
    jl_name = ref.left_wheel or ROBOT.wheel_joints[0]
    jr_name = ref.right_wheel or ROBOT.wheel_joints[1]
    notes: list[str] = []

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

    joints = []
    for side, jname in (("left_wheel", jl_name), ("right_wheel", jr_name)):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, jname)
        if j < 0:
            raise ModelError(f"{path}: no joint '{jname}' ({side}; map it with {side} = \"JOINT\")")
        if model.jnt_type[j] != _HINGE:
            raise ModelError(
                f"{path}: joint '{jname}' ({side}) is not a hinge (type {mujoco.mjtJoint(model.jnt_type[j]).name})"
            )
        b = model.jnt_bodyid[j]
        while b not in (0, base):
            b = model.body_parentid[b]
        if b != base:
            raise ModelError(f"{path}: joint '{jname}' ({side}) is not on a body below '{base_name}'")
        joints.append(j)
    if joints[0] == joints[1]:
        raise ModelError(f"{path}: left_wheel and right_wheel are the same joint '{jl_name}'")

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    rot = data.xmat[base].reshape(3, 3)
    fwd, left, up = rot[:, 0], rot[:, 1], rot[:, 2]
    if up[2] < 0.999:
        raise ModelError(
            f"{path}: body '{base_name}' is not level in the model file (its z axis is "
            f"{np.round(up, 3).tolist()}); the base frame must be x forward, z up"
        )
    anchors = np.array([data.xanchor[j] for j in joints])
    axes = np.array([data.xaxis[j] for j in joints])
    signs = []
    for j, ax in zip(joints, axes):
        c = float(ax @ left)
        if abs(c) < 0.99:
            raise ModelError(
                f"{path}: joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' axis "
                f"{np.round(rot.T @ ax, 3).tolist()} (base frame) is not along the base's y axis"
            )
        signs.append(1 if c > 0 else -1)
    for j, sgn in zip(joints, signs):
        if sgn < 0:
            notes.append(
                f"joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' axis points right (−y): "
                "its motor gets gear −1 so that positive torque drives forward"
            )
    if (anchors[0] - anchors[1]) @ left <= 0:
        raise ModelError(
            f"{path}: left_wheel '{jl_name}' is not to the left of right_wheel '{jr_name}' "
            "(swapped mapping, or the base's x axis is not forward)"
        )
    mid = anchors.mean(axis=0)
    axle = rot.T @ (mid - data.xpos[base])
    if np.linalg.norm(axle) > 1e-6:
        notes.append(
            f"base origin is off the axle midpoint (axle midpoint at {np.round(axle, 4).tolist()} m in "
            f"'{base_name}'): pose and υ refer to the axle midpoint"
        )
    half_track = float(0.5 * np.linalg.norm(anchors[0] - anchors[1]))
    if ref.half_track > 0:
        if abs(ref.half_track / half_track - 1) > 0.01:
            notes.append(f"half_track {ref.half_track:g} m given; the joint anchors say {half_track:.4g} m")
        half_track = float(ref.half_track)

    # wheel contact geoms: collision geoms on each wheel's body; radius = extent below the anchor
    radii, geoms, proxies = [], [], []
    for j, anchor in zip(joints, anchors):
        wb = model.jnt_bodyid[j]
        jname = _name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
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
        ext = [float((data.geom_xpos[g] - anchor) @ -up + _geom_support(model, data, g, -up)) for g in cand]
        k = int(np.argmax(ext))
        g = cand[k]
        radii.append(ext[k])
        geoms.append(g)
        gtype = int(model.geom_type[g])
        if gtype not in _SINGLE_CONTACT or len(cand) > 1:
            proxies.append((j, cand))
            kind = mujoco.mjtGeom(gtype).name[len("mjGEOM_") :].lower()
            notes.append(
                f"wheel '{jname}': collision {kind} '{_name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}'"
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

    # actuators on the wheels: keep a plain motor, neutralise every other drive
    wheel_set = set(joints)

    def drives_wheel(a: int) -> bool:
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

    def plain_motor(a: int, j: int) -> bool:
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

    drives = [a for a in range(model.nu) if drives_wheel(a)]
    # <dcmotor> drives (design §8.2): used with the mapping's motor = "dc", removed otherwise
    dc_all = [a for a in drives if int(model.actuator_dyntype[a]) == int(mujoco.mjtDyn.mjDYN_DCMOTOR)]
    drives = [a for a in drives if a not in dc_all]
    keep = []
    for j in joints:
        mine = [a for a in drives if plain_motor(a, j)]
        keep.append(mine[0] if mine else -1)
    if min(keep) < 0 or len(drives) != 2:
        keep = [-1, -1]
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
                f"'{jl_name}'/'{jr_name}' has a forcerange and the joints have no actuatorfrcrange; "
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
                    f"joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' actuatorfrcrange {lim:g} N·m "
                    f"caps the motor limit {tau_max:g} N·m"
                )
                tau_max = lim
    if not tau_max > 0:
        raise ModelError(f"{path}: wheel torque limit is {tau_max:g} N·m; give tau_max in the robot's mapping")

    disabled = [a for a in drives if a not in keep]
    dc_keep: list[int] = []
    if ref.motor == "dc":
        tau_max = _dc_plan(model, path, ref, joints, dc_all, dc_keep, notes)
        disabled = list(drives)
        keep = dc_keep
    act_names = {_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu)}
    if min(keep) >= 0:  # an unnamed kept motor gets a name (prepare_robot sets it)
        motors = tuple(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
            or f"{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}_motor"
            for a, j in zip(keep, joints)
        )
    else:
        motors = tuple(n if n not in act_names else f"bioform_{n}" for n in ROBOT.motors)
        if add_motors:
            notes.append(f"torque motors '{motors[0]}', '{motors[1]}' (±{tau_max:g} N·m) attached to the wheel joints")
    if disabled:
        notes.append(
            "the model's own wheel drive "
            + ", ".join(f"'{_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)}'" for a in disabled)
            + " is left unused (zero gain and bias: no force)"
        )
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
                f"joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}': "
                + ", ".join(parts)
                + " (armature enters a_eff, b_eff; damping and frictionloss are a drag and a dead band "
                "the paper's model lacks)"
            )

        if model.jnt_stiffness[j]:
            notes.append(
                f"joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}': stiffness {model.jnt_stiffness[j]:g} N·m/rad, "
                "a spring on a wheel that turns without end: a torque k φ growing with the distance driven "
                f"(k s / r = {model.jnt_stiffness[j] / r:.3g} N·m per metre), which the paper's model lacks"
            )
    # other wheels: hinges below the base, axis along its y, touching the floor (a 4-wheel or skid-steer
    # base, e.g. the menagerie Jackal); a swivelling caster's wheel sits below a second joint and is fine
    floor_z = float(np.mean(anchors[:, 2])) - r
    for j in range(model.njnt):
        if j in joints or model.jnt_type[j] != _HINGE or abs(float(data.xaxis[j] @ left)) < 0.99:
            continue
        b = int(model.jnt_bodyid[j])
        if model.body_jntnum[b] != 1:
            continue
        p_ = int(model.body_parentid[b])
        while p_ not in (0, base) and model.body_jntnum[p_] == 0:
            p_ = int(model.body_parentid[p_])
        if p_ != base:
            continue
        touches = [
            g
            for g in range(model.ngeom)
            if model.geom_bodyid[g] == b
            and (model.geom_contype[g] or model.geom_conaffinity[g])
            and data.geom_xpos[g][2] - _geom_support(model, data, g, -up) - floor_z <= max(0.005, 0.25 * r)
        ]
        if touches:
            notes.append(
                f"other wheel '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' (a hinge along the axle direction, not "
                "mapped) touches the floor: with a fixed wheel off the driven axle the base turns only by "
                "scrubbing it sideways (skid steer), which the paper's differential-drive model lacks; "
                "its own actuators, if any, are left as they are"
            )
    cj = _contacts_and_joints(model, data, path, ref, base, joints, drives + dc_all, r, floor_z, up, notes)
    jn = tuple(_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints)
    gnames = []
    for j, g, pr in zip(jn, geoms, proxies):
        named = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) if pr is None else None
        gnames.append(named or f"{j}_contact")  # an unnamed wheel geom gets a name (prepare_robot)
    layout = RobotLayout(
        file=str(path),
        base=base_name,
        wheel_joints=jn,
        motors=motors,
        wheel_geoms=tuple(gnames),
        wheel_radius=r,
        half_track=half_track,
        axle=tuple(float(x) for x in axle),
        wheel_sign=tuple(signs),
        tau_max=float(tau_max),
        disabled_actuators=tuple(_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in disabled),
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
        axle_world=mid,
        base_yaw=float(np.arctan2(fwd[1], fwd[0])),
        **cj["plan"],
    )
    return layout, plan


def _geom_label(model: mujoco.MjModel, g: int) -> str:
    """A geom's name, or ``BODY_geomK`` for an unnamed one (prepare_robot gives it that name)."""
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    if name:
        return name
    b = int(model.geom_bodyid[g])
    return f"{_name(model, mujoco.mjtObj.mjOBJ_BODY, b)}_geom{g - int(model.body_geomadr[b])}"


def _joint_label(model: mujoco.MjModel, j: int) -> str:
    """A joint's name, or ``BODY_jointK`` for an unnamed one (prepare_robot gives it that name)."""
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    if name:
        return name
    b = int(model.jnt_bodyid[j])
    return f"{_name(model, mujoco.mjtObj.mjOBJ_BODY, b)}_joint{j - int(model.body_jntadr[b])}"


def _quoted(names) -> str:
    return ", ".join(f"'{n}'" for n in names)


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
        if data.geom_xpos[g] @ up - _geom_support(model, data, g, -up) - floor_z <= tol
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
        wb = _name(model, mujoco.mjtObj.mjOBJ_BODY, on_wheel[0])
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
    # frictionless as published: priority so that MuJoCo's max rule does not give them the floor's μ
    raise_prio = [
        g
        for g in robot_geoms
        if model.geom_bodyid[g] not in wheel_bodies
        and (model.geom_friction[g, 0] < FRICTIONLESS or model.geom_condim[g] == 1 or g in friction)
        and model.geom_priority[g] < CONTACT_PRIORITY
    ]
    fl = [g for g in raise_prio if g not in friction]
    if fl:
        notes.append(
            f"frictionless geom(s) {_quoted(_geom_label(model, g) for g in fl)} (friction < {FRICTIONLESS:g} or "
            f"condim 1 as published) get priority {CONTACT_PRIORITY}: they stay frictionless against the floor "
            "(MuJoCo would otherwise take the larger friction of the pair, the floor's)"
        )

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
    if frozen:
        notes.append(
            f"joint(s) {jl(frozen)} frozen (design §13: removed from the scene, their bodies welded where the file "
            "puts them; map free_joints = true to leave them free)"
            + (
                f"; their actuator(s) {_quoted(_name(model, _ACT, a) for a in frozen_acts)} removed"
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
        notes.append(
            f"joint(s) {jl(held)} held by the model's own position actuators at ctrl = 0"
            + (
                " (their target is 0, the file's configuration is "
                + ", ".join(f"{q:.3g}" for q in qs)
                + ": they move there)"
                if any(abs(q) > 1e-9 for q in qs)
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
        for g in set(raise_prio) | set(friction)
        if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    }
    name_joints = {
        j: _joint_label(model, j) for j in locked if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    }
    return {
        "layout": dict(
            frozen_joints=tuple(_joint_label(model, j) for j in frozen),
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


def dc_constants(model: mujoco.MjModel, a: int) -> tuple[float, float, float, float]:
    """``(R Ω, K V·s/rad, |gear|, V_max V)`` of a compiled ``<dcmotor>`` actuator ``a``
    (``gainprm[0:2]`` hold R and K; ``V_max`` from its voltage ``ctrlrange`` or, with the
    current driver, the controller's ``Vmax`` in ``gainprm[7]``)."""
    R, K = float(model.actuator_gainprm[a, 0]), float(model.actuator_gainprm[a, 1])
    g = abs(float(model.actuator_gear[a, 0]))
    if int(model.actuator_ctrlspec[a]) == DC_INPUT_FF:
        vmax = float(model.actuator_gainprm[a, 7])
    else:
        vmax = (
            float(min(-model.actuator_ctrlrange[a, 0], model.actuator_ctrlrange[a, 1]))
            if model.actuator_ctrllimited[a]
            else 0.0
        )
    return R, K, g, vmax


#: ``actuator_ctrlspec`` of a ``<dcmotor>`` with ``input="voltage"`` resp. ``input="ff"`` (MuJoCo 4.0)
DC_INPUT_VOLTAGE = 8
DC_INPUT_FF = 4


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
        jname = _name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if len(mine) != 1:
            raise ModelError(
                f"scenario key 'plant.robots.motor': \"dc\" needs one <dcmotor> on wheel joint "
                f"'{jname}' of {path}, found {len(mine)}"
            )
        a = mine[0]
        aname = _name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
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
        f"DC motors '{_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, dc_keep[0])}', "
        f"'{_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, dc_keep[1])}' ({drv} driver): stall torque "
        f"{stall:.4g} N·m at the wheel" + (f", limited to {tau:g} N·m" if tau < stall else "")
    )
    return tau


def _dc_driver(act, model, a: int, sgn: float, driver: str, tau: float) -> None:
    """Set the driver of a kept ``<dcmotor>`` (design §8.2). The plant writes ``ctrl = s · τ``
    with ``τ`` the commanded wheel torque (:func:`dc_ctrl_scale`):

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


def dc_ctrl_scale(model: mujoco.MjModel, a: int) -> float:
    """``ctrl`` per N·m of commanded wheel torque of actuator ``a``: 1 for a torque motor,
    ``R/(g K)`` for a ``<dcmotor>`` with the voltage driver, ``1/g`` with the current driver."""
    if int(model.actuator_dyntype[a]) != int(mujoco.mjtDyn.mjDYN_DCMOTOR):
        return 1.0
    R, K, g, _ = dc_constants(model, a)
    return R / (g * K) if int(model.actuator_ctrlspec[a]) == DC_INPUT_VOLTAGE else 1.0 / g


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
    imported: tuple[str, ...] = ()
    if is_urdf(path):  # design §12: a URDF stays a robot (free root, links kept, meshes found)
        try:
            imp = import_urdf(ref)
        except InputError as exc:
            raise ModelError(str(exc)) from None
        spec, model, ref, imported = imp.spec, imp.model, imp.ref, imp.notes
    else:
        try:
            spec = mujoco.MjSpec.from_file(str(path))
            model = spec.compile()
        except Exception as exc:  # mujoco raises ValueError; be robust to other types
            raise ModelError(f"{path}: does not compile: {_one_line(exc)}") from exc
        absolute_asset_files(spec)
    layout, plan = _analyse(model, path, ref)
    if imported:
        layout = replace(layout, notes=imported + layout.notes, import_notes=imported)

    # spec elements by compiled index, resolved before anything is deleted (unnamed ones included)
    acts = {a: _spec_actuator(spec, model, a) for a in range(model.nu)}
    sjoints = {j: _spec_joint(spec, model, j) for j in set(plan["freeze"]) | set(plan["lock"])}
    sgeoms = {g: _spec_geom(spec, model, g) for g in set(plan["priority"]) | set(plan["friction"])}
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
            _wheel_proxy(spec, model, j, pr[1] if isinstance(pr, tuple) else None, layout.wheel_radius, gname)
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
    for j, q0 in plan["lock"].items():
        data = np.zeros(mujoco.mjNEQDATA)
        data[0] = q0  # joint1 = polycoef[0] without a joint2: held at q0
        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_JOINT,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            name1=sjoints[j].name,
            data=data,
            solref=[2 * dt, 1.0],  # as stiff as the step allows (MuJoCo: timeconst >= 2 dt)
        )


def absolute_asset_files(spec: mujoco.MjSpec) -> None:
    """Make the spec's mesh, skin, height-field and texture file names absolute (resolved against
    the model file's folder and its ``meshdir``/``texturedir``), so that a scene composed of robots
    from many folders names each file once and wholly (design §12: a run's ``scene.xml`` copies
    them beside it, :func:`bioform_mj.outputs.scenexml.write_scene`). Files in the spec's own
    asset dictionary are left alone."""
    top = Path(spec.modelfiledir or ".")
    own = set(spec.assets) if spec.assets else set()

    def fix(name: str, folder: str) -> str:
        if not name or name in own or Path(name).is_absolute():
            return name
        return str((top / folder / name).resolve())

    for m in spec.meshes:
        m.file = fix(m.file, spec.meshdir)
    for sk in spec.skins:
        sk.file = fix(sk.file, spec.meshdir)
    for h in spec.hfields:
        h.file = fix(h.file, spec.meshdir)
    for t in spec.textures:
        t.file = fix(t.file, spec.texturedir)
        if any(t.cubefiles):
            t.cubefiles = [fix(c, spec.texturedir) for c in t.cubefiles]


def load_robot(entry: RobotRef | str | Path) -> mujoco.MjSpec:
    """Load one robot MJCF as a fresh, drivable ``MjSpec`` (see :func:`prepare_robot`; raises ``ModelError``)."""
    return prepare_robot(entry)[0]


def _add_payload_to_body(
    body: mujoco.MjsBody, mass_kg: float, inertia_kgm2: float, at: np.ndarray | None = None
) -> None:
    """Add a point-like payload (mass, yaw inertia about its own centre) at ``at`` (body frame, m;
    default the body origin)."""
    mass, ipos, iquat, inertia = payload_inertial(
        body.mass,
        np.asarray(body.ipos),
        np.asarray(body.iquat),
        np.asarray(body.inertia),
        mass_kg,
        inertia_kgm2,
        at,
    )
    body.mass, body.ipos, body.iquat, body.inertia = mass, ipos, iquat, inertia


def payload_inertial(
    mass: float,
    ipos: np.ndarray,
    iquat: np.ndarray,
    inertia: np.ndarray,
    payload_mass: float,
    payload_inertia: float,
    at: np.ndarray | None = None,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """New ``(mass, ipos, iquat, diag inertia)`` of a body after adding a payload.

    The payload sits at ``at`` (body frame, m; default the body origin; the plant puts it on
    the axle midpoint) and has yaw
    inertia ``payload_inertia`` kg·m² about the body z axis through its own centre. It is
    flat (a plate lying on the robot: roll and pitch inertia half the yaw inertia), which
    keeps the body's inertia physical (A + B >= C). Handles an off-origin centre of mass
    exactly (parallel-axis theorem, re-diagonalised).
    """
    if payload_mass < 0 or payload_inertia < 0:
        raise ValueError("payload mass and inertia must be >= 0")
    ipos = np.asarray(ipos, float)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(iquat, float))
    rot = rot.reshape(3, 3)
    # inertia tensor about the body origin, body frame
    i_origin = rot @ np.diag(inertia) @ rot.T + mass * (ipos @ ipos * np.eye(3) - np.outer(ipos, ipos))
    i_origin += np.diag([0.5, 0.5, 1.0]) * payload_inertia  # flat payload: Izz = Ixx + Iyy
    p = np.zeros(3) if at is None else np.asarray(at, float)
    i_origin += payload_mass * (p @ p * np.eye(3) - np.outer(p, p))
    new_mass = mass + payload_mass
    # a massless base (a URDF base_footprint, design §12) with a massless payload stays massless
    new_ipos = (mass * ipos + payload_mass * p) / new_mass if new_mass > 0 else ipos.copy()
    i_com = i_origin - new_mass * (new_ipos @ new_ipos * np.eye(3) - np.outer(new_ipos, new_ipos))
    evals, evecs = np.linalg.eigh(i_com)
    if np.allclose(i_com, np.diag(np.diag(i_com)), atol=1e-12):
        # already principal in the body frame: keep the axes (and the quaternion) as they are
        return new_mass, new_ipos, np.array([1.0, 0, 0, 0]), np.diag(i_com).copy()
    if np.linalg.det(evecs) < 0:
        evecs[:, 0] *= -1
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, evecs.ravel())
    return new_mass, new_ipos, quat, evals


def _add_assets(spec: mujoco.MjSpec) -> None:
    spec.add_texture(
        name="skybox",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.35, 0.5, 0.7],
        rgb2=[0.05, 0.05, 0.1],
        width=512,
        height=3072,
    )
    spec.add_texture(
        name="grid",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        mark=mujoco.mjtMark.mjMARK_EDGE,
        rgb1=[0.22, 0.25, 0.28],
        rgb2=[0.16, 0.18, 0.2],
        markrgb=[0.7, 0.7, 0.7],
        width=300,
        height=300,
    )
    grid = spec.add_material(name="grid", texrepeat=[1, 1], texuniform=True, reflectance=0.15)
    grid.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "grid"
    spec.add_material(name="ghost", rgba=[0.95, 0.55, 0.1, 0.35])
    spec.add_material(name="slot", rgba=[0.2, 0.9, 0.4, 0.35])


def _look_quat(offset: np.ndarray) -> np.ndarray:
    """Quaternion of a camera at ``offset`` from a target, looking at it, world z up."""
    back = offset / np.linalg.norm(offset)  # camera +z points away from the target
    right = np.cross([0.0, 0.0, 1.0], back)
    if np.linalg.norm(right) < 1e-9:  # looking straight down: image x = world x
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([right, up, back]).ravel())
    return quat


def build_scene(
    robot_files: Sequence[str | Path],
    initial_poses: np.ndarray,
    *,
    slots: bool = True,
    floor_friction: float | None = None,
    payloads: Sequence[tuple[float, float]] | None = None,
    timestep: float | None = None,
    friction_patch: Sequence[float] | None = None,
    sensors: bool = False,
    obstacles: Sequence = (),
) -> mujoco.MjSpec:
    """Compose the scene of ``n`` followers; returns an uncompiled ``MjSpec``.

    Parameters
    ----------
    robot_files : sequence of str, Path or RobotRef, length n
        One robot per follower (shipped name, MJCF path, or :class:`~bioform_mj.robots.RobotRef`
        with a mapping); robots may differ.
    initial_poses : array (n, 3)
        ``(x m, y m, θ rad)`` of each follower's axle midpoint, world frame; each robot is
        placed so that its axle midpoint is there, heading ``θ``, wheels on the floor.
    slots : bool
        Add mocap markers ``slot_1 … slot_n`` (visual only) for the formation slots.
    floor_friction : float, optional
        Sliding friction of every floor contact. Without it MuJoCo's rule applies
        (the larger of floor and wheel friction, i.e. the robot file decides).
    payloads : sequence of (mass kg, yaw inertia kg·m²), length n, optional
        Extra payload on each follower's base at its axle midpoint.
    timestep : float, optional
        Physics step, s. Default: the first robot file's ``<option timestep>``.
    friction_patch : (x0, y0, x1, y1, mu), optional
        A low-friction floor rectangle (m; sliding friction ``mu``): a box geom
        ``friction_patch`` :data:`PATCH_THICKNESS` thick on the floor whose friction decides
        the wheel contacts (priority 1; casters keep theirs with priority 2).
    sensors : bool
        Add each robot's odometry sensors (:func:`add_sensors`: wheel encoders, gyro,
        accelerometer; design §8.3). Off, the scene has no sensors of ours (no cost per step).
    obstacles : sequence of :class:`~bioform_mj.obstacles.Obstacle`
        Fixed obstacles standing on the floor: static box or cylinder geoms of the world body,
        named as the obstacles (``obstacle_k``), colliding with the robots (design §19).

    The scene's ``<option>`` (integrator, solver, …) is the first robot file's.
    """
    poses = np.asarray(initial_poses, dtype=float)
    n = len(robot_files)
    if n < 1:
        raise ValueError("need at least one robot")
    if poses.shape != (n, 3) or not np.all(np.isfinite(poses)):
        raise ValueError(f"initial_poses must be a finite ({n}, 3) array, got shape {poses.shape}")
    if payloads is not None and len(payloads) != n:
        raise ValueError(f"payloads must have {n} entries, got {len(payloads)}")
    if timestep is not None and not timestep > 0:
        raise ValueError(f"timestep must be > 0, got {timestep}")

    prepared = [prepare_robot(f) for f in robot_files]
    robots = [p[0] for p in prepared]

    spec = mujoco.MjSpec()
    spec.modelname = "bioform_scene"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option = robots[0].option  # copies the values
    if timestep is not None:
        spec.option.timestep = timestep
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    spec.visual.headlight.ambient = [0.25, 0.25, 0.25]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    spec.stat.extent = 5.0
    _add_assets(spec)

    world = spec.worldbody
    floor = world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        material="grid",
        condim=3,
    )
    if floor_friction is not None:
        if not floor_friction >= 0:
            raise ValueError(f"floor_friction must be >= 0, got {floor_friction}")
        floor.friction = [floor_friction, 0.005, 0.0001]
        floor.priority = 1  # floor decides the wheel contacts; casters use priority 2
    if friction_patch is not None:  # faults: wheel slip on a low-friction rectangle of floor
        x0, y0, x1, y1, mu = (float(v) for v in friction_patch)
        if not (x0 < x1 and y0 < y1 and mu >= 0):
            raise ValueError(
                f"friction_patch must be (x0, y0, x1, y1, mu) with x0 < x1, y0 < y1, mu >= 0, "
                f"got {tuple(friction_patch)}"
            )
        h = PATCH_THICKNESS / 2
        world.add_geom(
            name="friction_patch",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[(x0 + x1) / 2, (y0 + y1) / 2, h],
            size=[(x1 - x0) / 2, (y1 - y0) / 2, h],
            friction=[mu, 0.005, 0.0001],
            priority=1,
            condim=3,
            rgba=[0.55, 0.8, 1.0, 0.45],
        )
    for ob in obstacles:  # design §19: static geoms of the world body
        half_h = ob.size[2] if ob.shape == "box" else ob.size[1]
        world.add_geom(
            name=ob.name,
            type=mujoco.mjtGeom.mjGEOM_BOX if ob.shape == "box" else mujoco.mjtGeom.mjGEOM_CYLINDER,
            pos=[ob.x, ob.y, half_h],
            quat=yaw_quat(ob.yaw),
            size=list(ob.size) + [0.0] * (3 - len(ob.size)),
            condim=3,
            rgba=[0.45, 0.42, 0.38, 1.0],  # outputs.figures.OBSTACLE_RGB
        )
    world.add_light(
        name="sun",
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        pos=[0, 0, 10],
        dir=[-0.3, 0.2, -1.0],
        diffuse=[0.8, 0.8, 0.8],
        specular=[0.2, 0.2, 0.2],
        castshadow=False,  # a directional shadow map over a many-metre floor shows acne
    )
    world.add_light(
        name="fill",
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
        pos=[0, 0, 10],
        dir=[0.4, -0.3, -1.0],
        diffuse=[0.3, 0.3, 0.3],
        specular=[0, 0, 0],
        castshadow=False,
    )

    # cameras ride on a mocap body that whoever renders keeps on the formation centroid (Markers); the
    # cameras' distances and the markers' sizes are the paper robot's × u, the robots' size relative to it
    u = robot_unit([p[1].half_track for p in prepared])
    centre = poses[:, :2].mean(axis=0)
    centroid = world.add_body(name="centroid", mocap=True, pos=[centre[0], centre[1], 0.0])
    chase = np.array([-6.0, -6.0, 6.0]) * u
    centroid.add_camera(name="track", pos=chase, quat=_look_quat(chase), fovy=45)
    centroid.add_camera(name="top", pos=[0, 0, 14.0 * u], quat=_look_quat(np.array([0, 0, 1.0])), fovy=45)

    leader = world.add_body(name="leader", mocap=True, pos=[centre[0], centre[1], MARKER_Z])
    ghost = dict(contype=0, conaffinity=0, group=1, material="ghost", mass=0, density=0)
    leader.add_geom(
        name="leader_ghost",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.15 * u, 0.12 * u, 0.05 * u],
        pos=[0, 0, 0.05 * u],
        **ghost,
    )
    leader.add_geom(
        name="leader_heading",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.12 * u, 0.025 * u, 0.01 * u],
        pos=[0.2 * u, 0, 0.05 * u],
        **ghost,
    )
    if slots:
        for i in range(n):
            slot = world.add_body(name=f"slot_{i + 1}", mocap=True, pos=[poses[i, 0], poses[i, 1], MARKER_Z])
            slot.add_geom(
                name=f"slot_{i + 1}_marker",
                type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[0.12 * u, 0.002, 0],
                contype=0,
                conaffinity=0,
                group=1,
                material="slot",
                mass=0,
                density=0,
            )

    for i, ((robot, layout, axle_world, base_yaw), pose) in enumerate(zip(prepared, poses)):
        if payloads is not None:
            mass_kg, inertia_kgm2 = payloads[i]
            _add_payload_to_body(robot.body(layout.base), float(mass_kg), float(inertia_kgm2), np.array(layout.axle))
        if sensors:
            add_sensors(robot, layout)
        robot.option = spec.option  # avoid MuJoCo 4 attach-conflict warnings: the scene decides
        # the file's axle midpoint goes to (x, y), its wheels' lowest point to the floor, heading θ
        yaw = pose[2] - base_yaw
        c, s_ = np.cos(yaw), np.sin(yaw)
        mx, my = c * axle_world[0] - s_ * axle_world[1], s_ * axle_world[0] + c * axle_world[1]
        frame = world.add_frame(
            pos=[pose[0] - mx, pose[1] - my, layout.wheel_radius - axle_world[2]], quat=yaw_quat(yaw)
        )
        spec.attach(robot, prefix=follower_prefix(i), frame=frame)
    return spec


#: names of the sensors :func:`add_sensors` puts on a robot (the follower prefix is added on attach)
SENSORS = ("bioform_left_encoder", "bioform_right_encoder", "bioform_gyro", "bioform_accel")
IMU_SITE = "bioform_imu"


def add_sensors(spec: mujoco.MjSpec, layout: RobotLayout) -> None:
    """The odometry sensors of one robot (design §8.3), added to its prepared spec: an IMU site
    ``bioform_imu`` on the base at the axle midpoint (axes of the base), ``jointpos`` on the left and
    right wheel joints (the encoders' shafts; the plant quantises them), a ``gyro`` and an
    ``accelerometer`` on the site. MuJoCo computes them in the forward pass at the start of each
    ``mj_step`` (the values after a step are those of the state it started from) and adds no noise
    (MuJoCo 4.0's sensor ``noise`` attribute is metadata only): quantisation, bias and noise are the
    plant's (``plants/mujoco_kernels.py: sense``)."""
    site = spec.body(layout.base).add_site(name=IMU_SITE, pos=list(layout.axle), size=[0.005, 0, 0], group=4)
    del site
    for name, j in zip(SENSORS[:2], layout.wheel_joints):
        spec.add_sensor(name=name, type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=j)
    spec.add_sensor(
        name=SENSORS[2], type=mujoco.mjtSensor.mjSENS_GYRO, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE
    )
    spec.add_sensor(
        name=SENSORS[3], type=mujoco.mjtSensor.mjSENS_ACCELEROMETER, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=IMU_SITE
    )


#: half track of the paper's robot, m: the unit of the visual markers' and the cameras' sizes
PAPER_HALF_TRACK = 0.2


def robot_unit(half_tracks: Sequence[float]) -> float:
    """The robots' size relative to the paper's (median half track / :data:`PAPER_HALF_TRACK`): the
    scene's markers and cameras (:func:`build_scene`) and the video's halos, slot discs, camera margin
    and trail tolerance (``outputs/video.py``) are the paper-scale sizes × this, so a TurtleBot team
    (l = 0.08 m: 0.4) is drawn as the paper's robots are (design §9). 1 for the paper robot."""
    u = float(np.median(np.asarray(half_tracks, dtype=float))) / PAPER_HALF_TRACK
    return round(u, 9) if np.isfinite(u) and u > 0 else 1.0


def compile_scene(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Compile a scene spec; returns ``(model, data)`` with ``mj_forward`` done.

    Raises :class:`~bioform_mj.errors.InputError` first if the installed MuJoCo distributions
    are not one release (checked once per process, design §17)."""
    from .deps import check_mujoco_once

    check_mujoco_once()
    try:
        model = spec.compile()
    except Exception as exc:
        raise ModelError(f"scene does not compile: {_one_line(exc)}") from exc
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


class Markers:
    """The scene's visual mocap bodies: the leader's ghost, the slot markers and the camera
    carrier ``centroid``. Ids are looked up once; :meth:`place` moves them for a frame.

    They have no collisions and no mass, so moving them never changes the physics: only
    renderers need them, and they set them per rendered frame, not per control step.
    """

    def __init__(self, model: mujoco.MjModel, n: int) -> None:
        def mocap(name: str) -> int:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            return int(model.body_mocapid[bid]) if bid >= 0 else -1

        self.leader = mocap("leader")
        self.centroid = mocap("centroid")
        slots = [mocap(f"slot_{i + 1}") for i in range(n)]
        self.slots = np.array(slots) if min(slots, default=-1) >= 0 else None

    def place(
        self,
        data: mujoco.MjData,
        leader_pose: np.ndarray,
        slots: np.ndarray | None = None,
        centroid: np.ndarray | None = None,
    ) -> None:
        """Ghost at ``leader_pose`` ``[x, y, θ]``, slot markers at ``slots`` (n, 2), cameras over
        ``centroid`` (2,) (m, rad); ``None`` leaves that marker where it is."""
        if self.leader >= 0:
            data.mocap_pos[self.leader] = (leader_pose[0], leader_pose[1], MARKER_Z)
            data.mocap_quat[self.leader] = (np.cos(leader_pose[2] / 2), 0.0, 0.0, np.sin(leader_pose[2] / 2))
        if slots is not None and self.slots is not None:
            data.mocap_pos[self.slots, :2] = slots
        if centroid is not None and self.centroid >= 0:
            data.mocap_pos[self.centroid, :2] = centroid
