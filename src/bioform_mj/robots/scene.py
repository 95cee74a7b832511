"""Compose a MuJoCo scene of ``n`` differential-drive followers with ``mujoco.MjSpec``.

Each robot is prepared once (:func:`~bioform_mj.robots.prepare.prepare_robot`: its mapping resolved
by :mod:`bioform_mj.robots.analysis`, what the plant needs stored as a
:class:`~bioform_mj.robots.layout.RobotLayout`); the names of those modules that the rest of the
project and the tests use are re-exported here.

The scene adds a floor, lights, a skybox, the virtual leader as a mocap "ghost" body
``leader`` (no collisions), optional mocap slot markers ``slot_1 … slot_n``, a mocap body
``centroid`` carrying the cameras ``track`` (chase view) and ``top`` (top-down) that the
plant moves to the formation centroid, and the followers attached with prefixes
``f1/``, ``f2/``, … (1-based), each placed so that its axle midpoint is at the initial
pose and its wheels touch the floor. Nothing here edits XML strings.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.analysis import layout_of
from bioform_mj.robots.layout import (
    CONTACT_PRIORITY,
    DC_INPUT_FF,
    DC_INPUT_VOLTAGE,
    FRICTIONLESS,
    ROBOT,
    SUPPORT_CLEARANCE,
    ModelError,
    RobotLayout,
    RobotNames,
    _one_line,
    dc_constants,
    dc_ctrl_scale,
    model_path,
    subtree,
    welded_to,
)
from bioform_mj.robots.mjcf import absolute_asset_files
from bioform_mj.robots.prepare import load_robot, prepare_robot, prepare_robots
from bioform_mj.robots.surfaces import add_min_friction_pairs

log = logging.getLogger(__name__)

__all__ = [
    # composed here
    "build_scene",
    "compile_scene",
    "follower_prefix",
    "yaw_quat",
    "payload_inertial",
    "add_sensors",
    "robot_unit",
    "MARKER_Z",
    "PATCH_THICKNESS",
    "SENSORS",
    "Markers",
    # re-exported from robot_layout, robot_analysis and robot_prepare (the public API and the tests use them)
    "CONTACT_PRIORITY",
    "DC_INPUT_FF",
    "DC_INPUT_VOLTAGE",
    "FRICTIONLESS",
    "ROBOT",
    "SUPPORT_CLEARANCE",
    "ModelError",
    "RobotLayout",
    "RobotNames",
    "absolute_asset_files",
    "dc_constants",
    "dc_ctrl_scale",
    "layout_of",
    "load_robot",
    "model_path",
    "prepare_robot",
    "subtree",
    "welded_to",
]


#: height of the leader ghost / slot markers above the floor, m
MARKER_Z = 0.002


#: thickness of a low-friction floor patch, m: far above a wheel's contact penetration (~1 µm),
#: below the paper robot's caster clearance (0.5 mm), so only the wheels touch it
PATCH_THICKNESS = 0.0002


def follower_prefix(i: int) -> str:
    """Name prefix of follower ``i`` (0-based index → ``"f{i+1}/"``)."""
    return f"f{i + 1}/"


def yaw_quat(theta: float) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` of a rotation by ``theta`` rad about +z."""
    return np.array([np.cos(theta / 2), 0.0, 0.0, np.sin(theta / 2)])


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
    prepared: Sequence[tuple] | None = None,
) -> mujoco.MjSpec:
    """Compose the scene of ``n`` followers; returns an uncompiled ``MjSpec``.

    Parameters
    ----------
    robot_files : sequence of str, Path or RobotRef, length n
        One robot per follower (shipped name, MJCF path, or :class:`~bioform_mj.robots.refs.RobotRef`
        with a mapping); robots may differ.
    initial_poses : array (n, 3)
        ``(x m, y m, θ rad)`` of each follower's axle midpoint, world frame; each robot is
        placed so that its axle midpoint is there, heading ``θ``, wheels on the floor.
    slots : bool
        Add mocap markers ``slot_1 … slot_n`` (visual only) for the formation slots.
    floor_friction : float, optional
        Sliding friction of every floor contact (priority 1; a robot geom of priority 2 gets the
        smaller of its own and this, design §13.3). Without it MuJoCo's rule applies
        (the larger of floor and wheel friction, i.e. the robot file decides).
    payloads : sequence of (mass kg, yaw inertia kg·m²), length n, optional
        Extra payload on each follower's base at its axle midpoint.
    timestep : float, optional
        Physics step, s. Default: the first robot file's ``<option timestep>``.
    friction_patch : (x0, y0, x1, y1, mu), optional
        A low-friction floor rectangle (m; sliding friction ``mu``): a box geom
        ``friction_patch`` :data:`PATCH_THICKNESS` thick on the floor whose friction decides
        the wheel contacts (priority 1); a robot geom of priority 2 (casters, Gazebo μ) gets the
        smaller of its own and the patch's friction (an explicit contact pair, design §13.3).
    sensors : bool
        Add each robot's odometry sensors (:func:`add_sensors`: wheel encoders, gyro,
        accelerometer; design §8.3). Off, the scene has no sensors of ours (no cost per step).
    obstacles : sequence of :class:`~bioform_mj.formation.obstacles.Obstacle`
        Fixed obstacles standing on the floor: static box or cylinder geoms of the world body,
        named as the obstacles (``obstacle_k``), colliding with the robots (design §19).
    prepared : sequence of :func:`prepare_robot` results, length n, optional
        The robots already prepared from ``robot_files`` (each used once: attaching consumes it);
        default: prepared here.

    The scene's ``<option>`` (integrator, solver, …) is the first robot file's.

    The steps: the arguments checked, the robots prepared, :func:`_new_spec`, :func:`_add_floor`,
    :func:`_add_obstacles`, :func:`_add_lights`, :func:`_add_markers`, :func:`_attach_robots`, the friction pairs.
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

    if prepared is not None and len(prepared) != n:
        raise ValueError(f"prepared must have {n} entries, got {len(prepared)}")
    prepared = list(prepared) if prepared is not None else prepare_robots(robot_files)
    spec = _new_spec(prepared[0][0], timestep)
    world = spec.worldbody
    _add_floor(world, floor_friction, friction_patch)
    _add_obstacles(world, obstacles)
    _add_lights(world)
    # the cameras' distances and the markers' sizes are the paper robot's × u, the robots' size relative to it
    _add_markers(world, poses, robot_unit([p[1].half_track for p in prepared]), slots)
    spec = _attach_robots(spec, prepared, poses, payloads, sensors)
    # design §13.3: on the scene's own slippery surfaces a robot's priority geom gets the smaller friction
    surfaces = (["floor"] if floor_friction is not None else []) + (["friction_patch"] if friction_patch else [])
    add_min_friction_pairs(spec, surfaces)
    return spec


def _new_spec(first: mujoco.MjSpec, timestep: float | None) -> mujoco.MjSpec:
    """The empty scene: the first robot's ``<option>`` (step ``timestep`` s where given), the view, the assets."""
    spec = mujoco.MjSpec()
    spec.modelname = "bioform_scene"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option = first.option  # copies the values
    if timestep is not None:
        spec.option.timestep = timestep
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    spec.visual.headlight.ambient = [0.25, 0.25, 0.25]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    spec.stat.extent = 5.0
    _add_assets(spec)
    return spec


def _add_floor(world: mujoco.MjsBody, floor_friction: float | None, friction_patch: Sequence[float] | None) -> None:
    """The floor plane (sliding friction ``floor_friction`` with priority 1 where given) and the optional
    low-friction patch ``(x0, y0, x1, y1, mu)`` (m, m, m, m, -); ValueError for a bad one (design §13.3)."""
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


def _add_obstacles(world: mujoco.MjsBody, obstacles: Sequence) -> None:
    """The obstacles as static box or cylinder geoms of the world body, standing on the floor (design §19)."""
    for ob in obstacles:
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


def _add_lights(world: mujoco.MjsBody) -> None:
    """Two directional lights, without shadows."""
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


def _add_markers(world: mujoco.MjsBody, poses: np.ndarray, u: float, slots: bool) -> None:
    """The mocap bodies: the centroid carrying the cameras (whoever renders keeps it on the formation's centroid,
    :class:`Markers`), the leader's ghost and, with ``slots``, one marker per follower's slot at ``poses`` (n, 3);
    sizes and distances scaled by the robot unit ``u`` (:func:`robot_unit`)."""
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
        for i in range(len(poses)):
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


#: robots attached one by one to a spec up to this many; above it, in groups (:func:`_attach_robots`)
GROUP_FROM = 16

#: at most this many groups per spec (:func:`_attach_tree`)
GROUP_FAN = 8

#: MuJoCo's warning for the group's attach with an empty prefix (the names already carry theirs: nothing is lost)
_EMPTY_PREFIX = "Attaching a spec with an empty prefix may prevent the model from being saved correctly."


def _attach_robots(
    spec: mujoco.MjSpec,
    prepared: Sequence[tuple],
    poses: np.ndarray,
    payloads: Sequence[tuple[float, float]] | None,
    sensors: bool,
) -> mujoco.MjSpec:
    """Attaches each prepared robot (with its payload and sensors) as ``f{i+1}/``: its axle midpoint at the pose's
    (x, y) m, its tyres' lowest point on the floor, heading θ rad. Returns the scene: ``spec`` itself, or above
    :data:`GROUP_FROM` robots a copy of it.

    Each ``MjSpec.attach`` rebuilds the whole parent's name lists (MuJoCo's ``ProcessLists``), so attaching n robots
    one by one to the scene costs n² (235 of 360 s at n = 1024, docs/findings/performance.md, "Building the scene").
    Above :data:`GROUP_FROM` robots they are attached in a tree (:func:`_attach_tree`): each robot to a small group
    spec under its own prefix, each group to its parent with an empty prefix; every attach then meets a parent of
    a bounded size but the last few. The scene is the same as one built robot by robot: the same bodies, names,
    classes and order, ``to_xml`` and the compiled model equal byte for byte (tests/test_scene_build.py). MuJoCo
    keeps a warning about the empty prefix and says it again at every compile and ``to_xml``; the copy returned
    (``MjSpec.copy``) does not carry it."""
    items = list(range(len(prepared)))
    if len(items) <= GROUP_FROM:
        for i in items:
            _attach_one(spec, prepared[i], poses[i], i, payloads, sensors)
        return spec
    _attach_tree(spec, items, prepared, poses, payloads, sensors)
    return spec.copy()


def _attach_tree(
    spec: mujoco.MjSpec,
    items: list[int],
    prepared: Sequence[tuple],
    poses: np.ndarray,
    payloads: Sequence[tuple[float, float]] | None,
    sensors: bool,
) -> None:
    """Attach robots ``items`` (indices, in order) to ``spec``: one by one up to :data:`GROUP_FROM`, else split in
    order into at most :data:`GROUP_FAN` groups, each built by this function in its own spec (the scene's
    ``<option>`` and compiler angle and limit settings: no attach conflict) and attached with an empty prefix."""
    if len(items) <= GROUP_FROM:
        for i in items:
            _attach_one(spec, prepared[i], poses[i], i, payloads, sensors)
        return
    size = max(GROUP_FROM, math.ceil(len(items) / GROUP_FAN))
    for start in range(0, len(items), size):
        group = mujoco.MjSpec()
        group.option = spec.option
        group.compiler.degree = spec.compiler.degree
        group.compiler.autolimits = spec.compiler.autolimits
        _attach_tree(group, items[start : start + size], prepared, poses, payloads, sensors)
        with _without_warning(_EMPTY_PREFIX):
            spec.attach(group, prefix="", frame=spec.worldbody.add_frame())


def _attach_one(
    spec: mujoco.MjSpec,
    entry: tuple,
    pose: np.ndarray,
    i: int,
    payloads: Sequence[tuple[float, float]] | None,
    sensors: bool,
) -> None:
    """Attach prepared robot ``i`` (``entry``: a :func:`prepare_robot` result) to ``spec`` at ``pose`` (x m, y m, θ rad)
    with its payload and sensors (see :func:`_attach_robots`)."""
    robot, layout, axle_world, base_yaw = entry
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
    # the tyre's own radius where a mapped wheel_radius differs from it (the physics is the tyre's: design §14.4;
    # at the mapped one a smaller radius starts the robot inside the floor and it jumps)
    r_floor = _tyre_radius(layout)
    frame = spec.worldbody.add_frame(pos=[pose[0] - mx, pose[1] - my, r_floor - axle_world[2]], quat=yaw_quat(yaw))
    spec.attach(robot, prefix=follower_prefix(i), frame=frame)


class _Dropped(threading.local):
    """The MuJoCo warnings this thread drops now (:func:`_without_warning`'s ``text``s)."""

    def __init__(self) -> None:
        self.texts: list[str] = []


_DROPPED = _Dropped()
_FILTER_LOCK = threading.Lock()
#: the filter's installation, shared by every thread: how many blocks are open, and the handler it replaced
_FILTER: dict[str, Any] = {"open": 0, "prev": None}


def _filtered(msg: str) -> None:
    """MuJoCo's warning handler while a :func:`_without_warning` block is open (in any thread): the text of a block
    open in the calling thread (MuJoCo calls its handler in the thread that warns) is dropped, any other goes where it
    went before (the handler replaced, else a Python ``RuntimeWarning`` ``"MuJoCo: …"`` as
    :func:`bioform_mj.outputs.mjlog.api_warnings` says them). Never raises: it is called from C."""
    try:
        if msg.strip() in _DROPPED.texts:
            return
        prev = _FILTER["prev"]
        if prev is not None:
            prev(msg)
        else:
            warnings.warn(f"MuJoCo: {msg}", RuntimeWarning, stacklevel=2)
    except Exception:  # noqa: BLE001
        pass


@contextlib.contextmanager
def _without_warning(text: str) -> Iterator[None]:
    """MuJoCo's warning ``text`` dropped while the block runs, in this thread only; any other warning, and this one
    from another thread, goes where it went (:func:`_filtered`).

    MuJoCo has one warning handler per process: the first block to open installs :func:`_filtered` and the last
    to close puts back the handler it found, under a lock, so that blocks overlapping in several threads (two
    scenes built at once) leave the handler as it was (swapping it per block left a closed block's filter
    installed when two overlapped). A handler someone installs while a block is open is theirs: it is kept, and it
    sees ``text`` in that time."""
    _DROPPED.texts.append(text)
    with _FILTER_LOCK:
        if _FILTER["open"] == 0:
            _FILTER["prev"] = mujoco.get_mju_user_warning()
            mujoco.set_mju_user_warning(_filtered)
        _FILTER["open"] += 1
    try:
        yield
    finally:
        _DROPPED.texts.pop()
        with _FILTER_LOCK:
            _FILTER["open"] -= 1
            if _FILTER["open"] == 0:
                if mujoco.get_mju_user_warning() is _filtered:
                    mujoco.set_mju_user_warning(_FILTER["prev"])
                _FILTER["prev"] = None


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
    plant's (``plants/mujoco/kernels.py: sense``)."""
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

    Raises :class:`~bioform_mj.core.errors.InputError` first if the installed MuJoCo distributions
    are not one release (checked once per process, design §17)."""
    from bioform_mj.core.deps import check_mujoco_once

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


def _tyre_radius(layout: RobotLayout) -> float:
    """The wheels' own radius, m: the collision geoms' where a mapped ``wheel_radius`` differs from them (the
    layout's note ``wheel_radius R m given; the collision geoms say G m``), else ``layout.wheel_radius``."""
    for n in layout.notes:
        if n.startswith("wheel_radius ") and "collision geoms say " in n:
            return float(n.rsplit("say ", 1)[1].split()[0])
    return float(layout.wheel_radius)
