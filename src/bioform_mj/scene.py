"""Compose a MuJoCo scene of ``n`` differential-drive followers with ``mujoco.MjSpec``.

A robot model (MJCF, see ``models/``) must provide, by name:

- body ``base`` with a free joint, its origin on the axle midpoint (x forward, z up);
- hinge joints ``left_wheel`` / ``right_wheel`` (positive rotation drives forward);
- torque actuators ``left_motor`` / ``right_motor`` on those joints (gear 1: ctrl is N·m);
- geoms ``left_wheel_collision`` / ``right_wheel_collision`` (single-contact sphere or
  ellipsoid; design §8 pitfall: a cylinder scrubs and biases ``b``).

The scene adds a floor, lights, a skybox, the virtual leader as a mocap "ghost" body
``leader`` (no collisions), optional mocap slot markers ``slot_1 … slot_n``, a mocap body
``centroid`` carrying the cameras ``track`` (chase view) and ``top`` (top-down) that the
plant moves to the formation centroid, and the followers attached with prefixes
``f1/``, ``f2/``, … (1-based). Nothing here edits XML strings.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.errors import InputError
from bioform_mj.robots import models_dir, robot_names

log = logging.getLogger(__name__)

__all__ = [
    "ModelError",
    "RobotNames",
    "ROBOT",
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
]


#: height of the leader ghost / slot markers above the floor, m
MARKER_Z = 0.002
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


_WHEEL_GEOM_TYPES = (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID))


def _check_compiled(path: Path, model: mujoco.MjModel) -> None:
    """Raise ModelError naming ``path`` unless ``model`` has what the plant needs."""

    def need(objtype: mujoco.mjtObj, name: str, what: str) -> int:
        i = mujoco.mj_name2id(model, objtype, name)
        if i < 0:
            raise ModelError(f"{path}: missing {what} '{name}'")
        return i

    base = need(mujoco.mjtObj.mjOBJ_BODY, ROBOT.base, "body")
    jnt_adr, jnt_num = model.body_jntadr[base], model.body_jntnum[base]
    if jnt_num != 1 or model.jnt_type[jnt_adr] != int(mujoco.mjtJoint.mjJNT_FREE):
        raise ModelError(f"{path}: body '{ROBOT.base}' needs exactly one free joint")
    for jname, aname, gname in zip(ROBOT.wheel_joints, ROBOT.motors, ROBOT.wheel_geoms):
        j = need(mujoco.mjtObj.mjOBJ_JOINT, jname, "joint")
        if model.jnt_type[j] != int(mujoco.mjtJoint.mjJNT_HINGE):
            raise ModelError(f"{path}: joint '{jname}' must be a hinge")
        a = need(mujoco.mjtObj.mjOBJ_ACTUATOR, aname, "actuator")
        if (
            model.actuator_trntype[a] != int(mujoco.mjtTrn.mjTRN_JOINT)
            or model.actuator_trnid[a, 0] != j
        ):
            raise ModelError(f"{path}: actuator '{aname}' must drive joint '{jname}'")
        if model.actuator_dyntype[a] != int(mujoco.mjtDyn.mjDYN_NONE) or model.actuator_gear[a, 0] != 1:
            raise ModelError(f"{path}: actuator '{aname}' must be a torque motor with gear 1")
        if not model.actuator_ctrllimited[a]:
            raise ModelError(f"{path}: actuator '{aname}' needs a ctrlrange (torque limit)")
        g = need(mujoco.mjtObj.mjOBJ_GEOM, gname, "geom")
        if model.geom_bodyid[g] != model.jnt_bodyid[j]:
            raise ModelError(f"{path}: geom '{gname}' must belong to the body of joint '{jname}'")
        if int(model.geom_type[g]) not in _WHEEL_GEOM_TYPES:
            raise ModelError(
                f"{path}: geom '{gname}' must be a sphere or ellipsoid (single contact; "
                "a cylinder scrubs when turning)"
            )
    # the plant observes the base origin: it must be the axle midpoint
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    jl, jr = (model.joint(n).id for n in ROBOT.wheel_joints)
    mid = 0.5 * (data.xanchor[jl] + data.xanchor[jr])
    mid_local = data.xmat[base].reshape(3, 3).T @ (mid - data.xpos[base])
    if np.linalg.norm(mid_local) > 1e-6:
        raise ModelError(
            f"{path}: the origin of body '{ROBOT.base}' must be the axle midpoint "
            f"(offset {np.round(mid_local, 6).tolist()} m)"
        )


def load_robot(path: str | Path) -> mujoco.MjSpec:
    """Load one robot MJCF as a fresh ``MjSpec`` and check it (raises ``ModelError``)."""
    path = model_path(path)
    if not path.is_file():
        raise ModelError(f"{path}: no such model file")
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        model = spec.compile()
    except Exception as exc:  # mujoco raises ValueError; be robust to other types
        raise ModelError(f"{path}: does not compile: {_one_line(exc)}") from exc
    _check_compiled(path, model)
    return spec


def _add_payload_to_body(body: mujoco.MjsBody, mass_kg: float, inertia_kgm2: float) -> None:
    """Add a point-like payload (mass, yaw inertia about its own centre) at the body origin."""
    mass, ipos, iquat, inertia = payload_inertial(
        body.mass, np.asarray(body.ipos), np.asarray(body.iquat), np.asarray(body.inertia),
        mass_kg, inertia_kgm2,
    )
    body.mass, body.ipos, body.iquat, body.inertia = mass, ipos, iquat, inertia


def payload_inertial(
    mass: float,
    ipos: np.ndarray,
    iquat: np.ndarray,
    inertia: np.ndarray,
    payload_mass: float,
    payload_inertia: float,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """New ``(mass, ipos, iquat, diag inertia)`` of a body after adding a payload.

    The payload sits at the body origin (the axle midpoint for ``base``) and has yaw
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
    new_mass = mass + payload_mass
    new_ipos = mass * ipos / new_mass
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
        name="skybox", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
        rgb1=[0.35, 0.5, 0.7], rgb2=[0.05, 0.05, 0.1], width=512, height=3072,
    )
    spec.add_texture(
        name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, mark=mujoco.mjtMark.mjMARK_EDGE,
        rgb1=[0.22, 0.25, 0.28], rgb2=[0.16, 0.18, 0.2], markrgb=[0.7, 0.7, 0.7],
        width=300, height=300,
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
) -> mujoco.MjSpec:
    """Compose the scene of ``n`` followers; returns an uncompiled ``MjSpec``.

    Parameters
    ----------
    robot_files : sequence of str or Path, length n
        One MJCF file (or shipped model name) per follower; robots may differ.
    initial_poses : array (n, 3)
        ``(x m, y m, θ rad)`` of each follower's axle midpoint, world frame.
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

    robots = [load_robot(f) for f in robot_files]

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
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05], material="grid",
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
            raise ValueError(f"friction_patch must be (x0, y0, x1, y1, mu) with x0 < x1, y0 < y1, mu >= 0, "
                             f"got {tuple(friction_patch)}")
        h = PATCH_THICKNESS / 2
        world.add_geom(
            name="friction_patch", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[(x0 + x1) / 2, (y0 + y1) / 2, h],
            size=[(x1 - x0) / 2, (y1 - y0) / 2, h], friction=[mu, 0.005, 0.0001], priority=1, condim=3,
            rgba=[0.55, 0.8, 1.0, 0.45],
        )
    world.add_light(
        name="sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, pos=[0, 0, 10],
        dir=[-0.3, 0.2, -1.0], diffuse=[0.8, 0.8, 0.8], specular=[0.2, 0.2, 0.2],
        castshadow=False,  # a directional shadow map over a many-metre floor shows acne
    )
    world.add_light(
        name="fill", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, pos=[0, 0, 10],
        dir=[0.4, -0.3, -1.0], diffuse=[0.3, 0.3, 0.3], specular=[0, 0, 0], castshadow=False,
    )

    # cameras ride on a mocap body that whoever renders keeps on the formation centroid (Markers)
    centre = poses[:, :2].mean(axis=0)
    centroid = world.add_body(name="centroid", mocap=True, pos=[centre[0], centre[1], 0.0])
    chase = np.array([-6.0, -6.0, 6.0])
    centroid.add_camera(name="track", pos=chase, quat=_look_quat(chase), fovy=45)
    centroid.add_camera(name="top", pos=[0, 0, 14.0], quat=_look_quat(np.array([0, 0, 1.0])), fovy=45)

    leader = world.add_body(name="leader", mocap=True, pos=[centre[0], centre[1], MARKER_Z])
    ghost = dict(contype=0, conaffinity=0, group=1, material="ghost", mass=0, density=0)
    leader.add_geom(name="leader_ghost", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.15, 0.12, 0.05],
                    pos=[0, 0, 0.05], **ghost)
    leader.add_geom(name="leader_heading", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.12, 0.025, 0.01],
                    pos=[0.2, 0, 0.05], **ghost)
    if slots:
        for i in range(n):
            slot = world.add_body(name=f"slot_{i + 1}", mocap=True,
                                  pos=[poses[i, 0], poses[i, 1], MARKER_Z])
            slot.add_geom(name=f"slot_{i + 1}_marker", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                          size=[0.12, 0.002, 0], contype=0, conaffinity=0, group=1,
                          material="slot", mass=0, density=0)

    for i, (robot, pose) in enumerate(zip(robots, poses)):
        if payloads is not None:
            mass_kg, inertia_kgm2 = payloads[i]
            _add_payload_to_body(robot.body(ROBOT.base), float(mass_kg), float(inertia_kgm2))
        robot.option = spec.option  # avoid MuJoCo 4 attach-conflict warnings: the scene decides
        frame = world.add_frame(pos=[pose[0], pose[1], 0.0], quat=yaw_quat(pose[2]))
        spec.attach(robot, prefix=follower_prefix(i), frame=frame)
    return spec


def compile_scene(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Compile a scene spec; returns ``(model, data)`` with ``mj_forward`` done."""
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

    def place(self, data: mujoco.MjData, leader_pose: np.ndarray, slots: np.ndarray | None = None,
              centroid: np.ndarray | None = None) -> None:
        """Ghost at ``leader_pose`` ``[x, y, θ]``, slot markers at ``slots`` (n, 2), cameras over
        ``centroid`` (2,) (m, rad); ``None`` leaves that marker where it is."""
        if self.leader >= 0:
            data.mocap_pos[self.leader] = (leader_pose[0], leader_pose[1], MARKER_Z)
            data.mocap_quat[self.leader] = (np.cos(leader_pose[2] / 2), 0.0, 0.0, np.sin(leader_pose[2] / 2))
        if slots is not None and self.slots is not None:
            data.mocap_pos[self.slots, :2] = slots
        if centroid is not None and self.centroid >= 0:
            data.mocap_pos[self.centroid, :2] = centroid
