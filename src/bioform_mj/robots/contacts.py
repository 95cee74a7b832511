"""What a robot touches at rest and what of it moves: floor contacts, self contacts, moving parts (design §13).

Read from MuJoCo's own contact list of a compiled scene (``data.contact``, forces from
``mj_contactForce``), for the robot named with ``prefix``:

- :func:`floor_contacts`: every geom of the robot touching a geom of the world body (the floor, a
  friction patch), with its role (``wheel``: a driven wheel or a body welded to it; ``caster``: a
  geom the mapping names, or any other geom that carries load; ``other``: touching, carrying
  nothing), its load (normal force, N), and friction and condim as published and as MuJoCo mixes
  them for the pair (the contact's own ``friction``/``dim``);
- :func:`self_contacts`: pairs of the robot's own bodies in contact (penetration depth, force);
- :func:`relative_poses` / :func:`moving_parts`: how far each body moves relative to the base;
- :func:`swivel_casters` / :func:`align_swivels`: the casters that swivel about a vertical axis, and
  their swivels turned to trail a coming motion (design §14.1).

Imports nothing of the project above :mod:`bioform_mj.robots.layout`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.layout import (
    RobotLayout,
    _label,
    contact_carries,
    element_name,
    frictionless,
    subtree,
    welded_to,
)

__all__ = [
    "CASTER_LOAD",
    "is_caster",
    "MOVE_M",
    "MOVE_DEG",
    "floor_contacts",
    "self_contacts",
    "relative_poses",
    "moving_parts",
    "pose_change",
    "still_bodies",
    "braking_casters",
    "brakes",
    "Swivel",
    "swivel_casters",
    "rolling_bodies",
    "robot_contacts",
    "align_swivels",
]

#: a non-wheel geom carrying more than this fraction of the robot's weight is a caster (:func:`is_caster`); the
#: one load rule of ``robot check``, a run's outcomes and identification (design §0, §14.2)
CASTER_LOAD = 0.005
#: a body whose position relative to the base changes by more than this (m) or whose orientation
#: by more than :data:`MOVE_DEG` (deg) is a moving part
MOVE_M, MOVE_DEG = 5e-3, 1.0
#: a passive hinge above a floor contact whose axis is within this angle of the base's vertical is a
#: caster swivel (deg; design §14.1)
SWIVEL_TILT_DEG = 20.0
#: a caster wheel whose centre sits less than this behind its swivel axis has no trail (m): its rolling
#: direction is aligned with the motion instead of its trail behind it
TRAIL_MIN_M = 1e-3


def _gname(model: mujoco.MjModel, g: int) -> str:
    return _label(model, mujoco.mjtObj.mjOBJ_GEOM, g, "#")


def _bname(model: mujoco.MjModel, b: int) -> str:
    return element_name(model, mujoco.mjtObj.mjOBJ_BODY, b)


def strip_prefix(name: str, prefix: str) -> str:
    return name[len(prefix) :] if prefix and name.startswith(prefix) else name


def _wheel_bodies(model: mujoco.MjModel, lay: RobotLayout) -> set[int]:
    out: set[int] = set()
    for j in lay.wheel_joints:
        out |= set(welded_to(model, int(model.jnt_bodyid[model.joint(j).id])).tolist())
    return out


def _rolling_bodies(model: mujoco.MjModel, lay: RobotLayout) -> set[int]:
    out: set[int] = set()
    for j in lay.rolling_joints:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if jid >= 0:
            out |= set(subtree(model, int(model.jnt_bodyid[jid])).tolist())
    return out


def rolling_bodies(model: mujoco.MjModel, lay: RobotLayout) -> set[int]:
    """Bodies that can roll on the floor: below one of the layout's ``rolling_joints`` that is a ball
    joint or a hinge that is not a swivel (its axis more than :data:`SWIVEL_TILT_DEG` from the base's
    vertical at ``qpos0``). A geom on a swivel alone turns about the vertical but slides on the floor
    (design §14.1): it brakes like a fixed caster."""
    if not lay.rolling_joints:  # nothing to roll
        return set()
    base = model.body(lay.base).id
    ball, hinge = int(mujoco.mjtJoint.mjJNT_BALL), int(mujoco.mjtJoint.mjJNT_HINGE)
    cos_tilt = math.cos(math.radians(SWIVEL_TILT_DEG))
    out: set[int] = set()
    for j in lay.rolling_joints:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if jid < 0:
            continue
        kind = int(model.jnt_type[jid])
        if kind == ball or (kind == hinge and abs(_axis_up(model, base, jid)) < cos_tilt):
            out |= set(subtree(model, int(model.jnt_bodyid[jid])).tolist())
    return out


def _axis_up(model: mujoco.MjModel, base: int, jid: int) -> float:
    """The cosine between joint ``jid``'s axis and body ``base``'s vertical at ``qpos0``, m/m.

    From the robot's own bodies between ``base`` and the joint (``body_quat``, and the joints before ``jid`` at
    ``qpos0``: hinges and slides turn nothing there, a ball joint by its ``qpos0`` quaternion), as
    ``mj_kinematics`` composes them; the whole scene's kinematics per robot was n² in a team
    (docs/findings/performance.md). A joint outside ``base``'s tree: the scene's kinematics."""
    chain, b = [], int(model.jnt_bodyid[jid])
    while b not in (base, 0):
        chain.append(b)
        b = int(model.body_parentid[b])
    if b != base:  # not below the base: the world's frame and the base's from the kinematics of the scene
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        return float(data.xaxis[jid] @ data.xmat[base].reshape(3, 3)[:, 2])
    ball = int(mujoco.mjtJoint.mjJNT_BALL)
    q, tmp = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(4)
    for b in reversed(chain):
        mujoco.mju_mulQuat(tmp, q, model.body_quat[b])
        q[:] = tmp
        for k in range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b])):
            if k == jid:
                break
            if int(model.jnt_type[k]) == ball:
                adr = int(model.jnt_qposadr[k])
                mujoco.mju_mulQuat(tmp, q, model.qpos0[adr : adr + 4])
                q[:] = tmp
        mujoco.mju_normalize4(q)
    axis = np.zeros(3)
    mujoco.mju_rotVecQuat(axis, model.jnt_axis[jid], q)
    return float(axis[2])


def _contact_bodies(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """Bodies of the two geoms of each of the ``ncon`` contacts, (ncon,) each."""
    n = int(data.ncon)
    g1 = np.asarray(data.contact.geom1[:n], dtype=int)
    g2 = np.asarray(data.contact.geom2[:n], dtype=int)
    return model.geom_bodyid[g1], model.geom_bodyid[g2]


def robot_contacts(model: mujoco.MjModel, data: mujoco.MjData, layouts: Sequence[RobotLayout]) -> list[np.ndarray]:
    """Per robot (``layouts[i]``: its base and every body below it) the indices of its contacts in ``data.contact``
    now, ascending: a contact with a geom on one of its bodies (one between two robots is in both lists). One pass
    over the contacts for a whole team, for :func:`floor_contacts` and :func:`self_contacts`' ``contacts`` (each
    looking through every contact for its own robot was n² in a team: docs/findings/performance.md)."""
    owner = np.full(model.nbody, -1, dtype=np.int64)
    for i, lay in enumerate(layouts):
        owner[subtree(model, model.body(lay.base).id)] = i
    b1s, b2s = _contact_bodies(model, data)
    o1, o2 = owner[b1s], owner[b2s]
    k = np.arange(len(b1s))
    other = o2 != o1
    ks, who = np.concatenate([k, k[other]]), np.concatenate([o1, o2[other]])
    keep = who >= 0
    ks, who = ks[keep], who[keep]
    order = np.lexsort((ks, who))  # by robot, then contact
    ks, who = ks[order], who[order]
    cut = np.searchsorted(who, np.arange(len(layouts) + 1))
    return [ks[cut[i] : cut[i + 1]] for i in range(len(layouts))]


def _mine(b1s: np.ndarray, b2s: np.ndarray, bodies: list[int], contacts: np.ndarray | None) -> np.ndarray:
    """Indices of the contacts with a body of ``bodies`` (ascending): ``contacts`` (:func:`robot_contacts`'s)
    when given, else found among all."""
    if contacts is not None:
        return np.asarray(contacts, dtype=np.int64)
    return np.flatnonzero(np.isin(b1s, bodies) | np.isin(b2s, bodies))


def is_caster(load_n: float, weight: float, named: bool = False) -> bool:
    """Whether a non-wheel geom on the floor is a caster: the mapping ``named`` it, or it carries more than
    :data:`CASTER_LOAD` of the robot's ``weight`` (``load_n``, N: at rest, or a drive test's mean). The one
    caster rule (design §0, §13)."""
    return named or load_n > CASTER_LOAD * weight


def floor_contacts(
    model: mujoco.MjModel, data: mujoco.MjData, lay: RobotLayout, prefix: str = "", contacts: np.ndarray | None = None
) -> list[dict]:
    """Every geom of the robot (layout ``lay``, names with ``prefix``) that touches the floor now.

    One dict per geom: ``body``, ``geom`` (names without ``prefix``), ``role``, ``load_n`` (sum of
    the normal forces of its contacts, N), ``friction`` (sliding friction MuJoCo uses for the pair),
    ``condim`` (the pair's), ``friction_published``, ``condim_published`` (the geom's own, as the file
    says), ``priority``, ``points`` (number of contacts), ``welded_to_base`` (no joint between its
    body and the base: a caster that cannot roll slides), ``rolls`` (below a free caster joint that
    rolls: :func:`rolling_bodies`; a swivel alone does not), ``mass_share`` (its body's share of the robot's mass:
    a link welded to the base that carries most of it is the chassis) and ``lever_m`` (m: the horizontal distance of its
    contacts' load-weighted mean point from the axle midpoint, the lever of its drag about the turning centre).
    Call it on a robot at rest (settled) for the load at rest. ``contacts``: the robot's contacts
    (:func:`robot_contacts`, for a team), else found here.
    """
    base = model.body(lay.base).id
    bodies = set(subtree(model, base).tolist())
    wheels = _wheel_bodies(model, lay)
    rolling = rolling_bodies(model, lay)
    welded = set(welded_to(model, base).tolist())
    weight = float(model.body_mass[list(bodies)].sum() * np.linalg.norm(model.opt.gravity))
    published = {g: (f, c) for g, f, c in lay.published_contacts}
    casters = set(lay.casters)
    per: dict[int, dict[str, Any]] = {}
    f6 = np.zeros(6)
    b1s, b2s = _contact_bodies(model, data)
    mine = _mine(b1s, b2s, list(bodies), contacts)
    for k in mine[(b1s[mine] == 0) | (b2s[mine] == 0)]:
        con = data.contact[int(k)]
        g = int(con.geom2) if b1s[k] == 0 else int(con.geom1)
        mujoco.mj_contactForce(model, data, int(k), f6)
        row = per.get(g)
        if row is None:
            name = _gname(model, g)
            pub = published.get(name, (float(model.geom_friction[g, 0]), int(model.geom_condim[g])))
            b = int(model.geom_bodyid[g])
            row = per[g] = {
                "body": strip_prefix(_bname(model, b), prefix),
                "geom": strip_prefix(name, prefix),
                "role": "",
                "load_n": 0.0,
                "friction": float(con.friction[0]),
                "condim": int(con.dim),
                "carries": contact_carries(int(con.dim)),
                "friction_published": float(pub[0]),
                "condim_published": int(pub[1]),
                "priority": int(model.geom_priority[g]),
                "points": 0,
                "welded_to_base": b in welded,
                "rolls": b in rolling,
                "mass_share": float(model.body_mass[b]) * float(np.linalg.norm(model.opt.gravity)) / max(weight, 1e-12),
                "_named": name in casters,
                "_wheel": b in wheels,
            }
        row["load_n"] += float(f6[0])
        row["points"] += 1
        row["_at"] = row.get("_at", np.zeros(4)) + np.append(np.asarray(con.pos) * max(float(f6[0]), 1e-12), f6[0])
    axle = data.xpos[base] + data.xmat[base].reshape(3, 3) @ np.asarray(lay.axle, dtype=float)
    out = []
    for row in per.values():
        at = row.pop("_at")
        row["lever_m"] = float(np.hypot(*(at[:2] / max(float(at[3]), 1e-12 * row["points"]) - axle[:2])))
        named, wheel = row.pop("_named"), row.pop("_wheel")
        if wheel:
            row["role"] = "wheel"
        elif is_caster(row["load_n"], weight, named):
            row["role"] = "caster"
        else:
            row["role"] = "other"
        out.append(row)
    order = {"wheel": 0, "caster": 1, "other": 2}
    return sorted(out, key=lambda r: (order[r["role"]], r["body"], r["geom"]))


def self_contacts(
    model: mujoco.MjModel, data: mujoco.MjData, lay: RobotLayout, prefix: str = "", contacts: np.ndarray | None = None
) -> list[dict]:
    """Pairs of the robot's own bodies in contact now: ``body1``, ``body2``, ``geoms`` (pairs of geom
    names), ``depth_m`` (deepest penetration, m, ≥ 0), ``force_n`` (sum of normal forces, N),
    ``points``. Names without ``prefix``. ``contacts``: the robot's contacts (:func:`robot_contacts`), else found
    here."""
    bodies = set(subtree(model, model.body(lay.base).id).tolist())
    per: dict[tuple[int, int], dict[str, Any]] = {}
    f6 = np.zeros(6)
    b1s, b2s = _contact_bodies(model, data)
    mine = _mine(b1s, b2s, list(bodies), contacts)
    for k in mine[np.isin(b1s[mine], list(bodies)) & np.isin(b2s[mine], list(bodies))]:
        k = int(k)
        con = data.contact[k]
        g1, g2 = int(con.geom1), int(con.geom2)
        b1, b2 = int(b1s[k]), int(b2s[k])
        if b1 > b2:
            b1, b2, g1, g2 = b2, b1, g2, g1
        mujoco.mj_contactForce(model, data, k, f6)
        row = per.setdefault(
            (b1, b2),
            {
                "body1": strip_prefix(_bname(model, b1), prefix),
                "body2": strip_prefix(_bname(model, b2), prefix),
                "geoms": [],
                "depth_m": 0.0,
                "force_n": 0.0,
                "points": 0,
            },
        )
        pair = [strip_prefix(_gname(model, g1), prefix), strip_prefix(_gname(model, g2), prefix)]
        if pair not in row["geoms"]:
            row["geoms"].append(pair)
        row["depth_m"] = max(row["depth_m"], float(-con.dist))
        row["force_n"] += float(f6[0])
        row["points"] += 1
    return list(per.values())


def still_bodies(model: mujoco.MjModel, lay: RobotLayout) -> np.ndarray:
    """Bodies of the robot that should not move relative to its base: all but the base, the
    wheels (and what is welded to them) and the casters' swivels and wheels."""
    base = model.body(lay.base).id
    skip = _wheel_bodies(model, lay) | _rolling_bodies(model, lay) | {base}
    return np.array([b for b in subtree(model, base) if b not in skip], dtype=int)


def relative_poses(model: mujoco.MjModel, data: mujoco.MjData, base: int, bodies: np.ndarray):
    """``(pos (k, 3) m, rot (k, 3, 3))`` of ``bodies`` in the frame of body ``base``: each body's
    centre of mass (``data.xipos``: an arm turning about its own origin moves it) and orientation."""
    rb = data.xmat[base].reshape(3, 3)
    pos = (data.xipos[bodies] - data.xpos[base]) @ rb
    rot = np.einsum("ji,kjl->kil", rb, data.xmat[bodies].reshape(-1, 3, 3))
    return pos, rot


def moving_parts(
    model: mujoco.MjModel,
    bodies: np.ndarray,
    worst: tuple[np.ndarray, np.ndarray],
    prefix: str = "",
) -> list[dict]:
    """``bodies`` whose largest displacement ``worst = (metres (k,), degrees (k,))`` (:func:`pose_change`)
    exceeds :data:`MOVE_M` or :data:`MOVE_DEG`: ``body``, ``displacement_m``, ``rotation_deg``."""
    out = []
    for b, dm, dd in zip(bodies, *worst):
        if dm > MOVE_M or dd > MOVE_DEG:
            out.append(
                {
                    "body": strip_prefix(_bname(model, int(b)), prefix),
                    "displacement_m": float(dm),
                    "rotation_deg": float(dd),
                }
            )
    return out


def pose_change(
    ref: tuple[np.ndarray, np.ndarray], now: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Per body: distance (m) and rotation angle (deg) between two :func:`relative_poses`."""
    dm = np.linalg.norm(now[0] - ref[0], axis=1)
    rel = np.einsum("kji,kjl->kil", ref[1], now[1])  # R_ref^T R_now
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    return dm, np.degrees(np.arccos(cos))


def floor_points(model: Any, data: Any, g: int, z_top: float) -> list[np.ndarray]:
    """World points of geom ``g`` that stand on the floor: below ``z_top`` (m). A box's corners and a mesh's
    vertices there (a chassis or skid plate resting on its rear edge supports it there, not at its centre);
    for a round geom (sphere, ellipsoid, capsule, cylinder: wheels, casters) its centre, straight above the
    point it touches the floor with."""
    t = int(model.geom_type[g])
    pos, rot = data.geom_xpos[g], data.geom_xmat[g].reshape(3, 3)
    if t == int(mujoco.mjtGeom.mjGEOM_BOX):
        loc = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * model.geom_size[g]
    elif t == int(mujoco.mjtGeom.mjGEOM_MESH):
        mid = model.geom_dataid[g]
        va, vn = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        loc = model.mesh_vert[va : va + vn].astype(float)
    else:
        return [pos.copy()]
    world = pos + loc @ rot.T
    low = world[world[:, 2] <= z_top]
    return list(low if len(low) else world[np.argmin(world[:, 2])][None, :])


#: after the settle a robot at rest moves its base slower than these (m/s, rad/s), and the floor carries its
#: weight (less what gravcomp holds) within this fraction
REST_SPEED, REST_RATE, REST_LOAD = 0.01, 0.05, 0.1


def not_at_rest(model: Any, data: Any, base: int, floor: list[dict], settle_s: float) -> str:
    """Why the robot is not at rest after ``settle_s`` s at zero torque ('' when it is): the base still moving,
    or the floor contacts (:func:`floor_contacts`) not carrying its weight (a robot bouncing off its own
    bodies, tipping, falling). Then the floor contacts and wheel loads are a snapshot, and it is said."""
    v6 = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, base, v6, 0)
    rate, speed = float(np.linalg.norm(v6[:3])), float(np.linalg.norm(v6[3:]))
    bodies = subtree(model, base)
    g = float(np.linalg.norm(model.opt.gravity))
    weight = float(np.sum(model.body_mass[bodies])) * g
    held = float(np.sum(model.body_mass[bodies] * (1.0 - model.body_gravcomp[bodies]))) * g
    load = float(sum(c["load_n"] for c in floor))
    if speed < REST_SPEED and rate < REST_RATE and abs(load - held) <= REST_LOAD * held:
        return ""
    comp = f" (gravcomp holds {weight - held:.3g} N of its weight)" if held < 0.999 * weight else ""
    return (
        f"not at rest after the {settle_s:g} s settle: the base moves at {speed:.3g} m/s and {rate:.3g} rad/s, the "
        f"floor carries {load:.4g} N of the {held:.4g} N it holds at rest{comp}: the floor contacts, wheel loads "
        "and traction limit are a snapshot of a moving robot"
    )


def settle(
    plant: Any, lay: RobotLayout, track: Any, prefix: str = "f1/", cap: int = 1000, pace: Any = None
) -> tuple[int, list, str]:
    """Step a one-robot ``plant`` (time step 1 ms) at zero torque for 0.2 s, then 0.1 s at a time while
    :func:`not_at_rest` says it still moves, up to ``cap`` steps; ``track()`` and ``pace(steps)`` (a
    :class:`~bioform_mj.robots.sanity.StepPace`, which may raise) every 10 steps. Returns the
    steps taken, the :func:`floor_contacts` then, and :func:`not_at_rest`'s text ('' at rest)."""
    base = plant.model.body(lay.base).id
    k, why, floor = 0, "", []
    while k < 200 or (why and k < cap):
        for _ in range(200 if k < 200 else 100):
            plant.step(np.zeros((1, 2)), k * 0.001)
            k += 1
            if k % 10 == 0:
                track()
                if pace is not None:
                    pace(k)
        floor = floor_contacts(plant.model, plant.data, lay, prefix)
        why = not_at_rest(plant.model, plant.data, base, floor, k * 0.001)
    return k, floor, why


def brakes(c: dict) -> bool:
    """Whether a contact of :func:`floor_contacts` brakes the robot: a caster (:func:`is_caster`: a non-wheel
    geom with more than :data:`CASTER_LOAD` of the weight, or one the mapping names) that cannot roll, with
    friction (μ ≥ ``FRICTIONLESS`` and condim > 1). The one test ``robot check``, a run's outcomes and
    identification's ``braking_caster`` findings use (design §0, §14.2)."""
    return c["role"] == "caster" and not c["rolls"] and not frictionless(c["friction"], c["condim"])


def braking_casters(floor: list[dict], drive_force: float) -> list[tuple[dict, float, str]]:
    """The casters of :func:`floor_contacts` that brake: loaded, with friction (μ ≥ 1e-3 and condim > 1)
    and unable to roll (no joint between them and the base). ``drive_force``: what the wheels can
    push, N. Returns ``(contact, μ N in N, message)`` per braking caster."""
    out = []
    for c in floor:
        if not brakes(c):
            continue
        brake = c["friction"] * c["load_n"]
        msg = (
            f"caster '{c['geom']}' on body '{c['body']}' carries {c['load_n']:.3g} N with friction μ = "
            f"{c['friction']:g}, condim {c['condim']} as simulated (published μ = {c['friction_published']:g}, "
            f"condim {c['condim_published']}) and cannot roll: sliding, it brakes the robot with μ N = {brake:.3g} N, "
            f"{100 * brake / drive_force if drive_force > 0 else float('inf'):.0f} % of what the wheels can push "
            "(min of the motor limit 2 f τ_max / r "
            f"and their traction μ ΣN: {drive_force:.3g} N); if the real caster rolls, map caster_friction = 0"
            + (": the robot cannot move" if brake >= drive_force else "")
        )
        out.append((c, brake, msg))
    return out


@dataclass(frozen=True)
class Swivel:
    """One caster swivel (:func:`swivel_casters`): a passive hinge about the base's vertical carrying
    a wheel (or sphere) that touches the floor. Angles in rad, lengths in m, in the base body's frame."""

    joint: str  # joint name (with the scene's prefix)
    qpos: int  # qpos address
    dof: int  # qvel address
    q0: float  # the joint's qpos0, rad
    sense: float  # +1 / −1: the swivel axis along / against the base's up (a positive angle turns the caster CCW / CW)
    anchor: tuple[float, float]  # the swivel axis's horizontal position in the base frame, m
    angle0: float  # at q0: the heading of the trail (the wheel centre from the axis), or of the rolling direction
    trail_m: float  # horizontal distance of the wheel centre behind the axis (0: no trail)
    limits: tuple[float, float] | None  # the joint range, rad, where it is limited
    damping: float = 0.0  # N·m·s/rad: the swivel's joint damping (resists turning the caster round)
    frictionloss: float = 0.0  # N·m: the swivel's dry friction (the same)

    def resistance(self) -> dict[str, Any]:
        """``{"joint" (without the scene's prefix), "damping_Nms_per_rad", "frictionloss_Nm"}``."""
        return {
            "joint": self.joint.split("/", 1)[-1],
            "damping_Nms_per_rad": self.damping,
            "frictionloss_Nm": self.frictionloss,
        }


def swivel_casters(model: mujoco.MjModel, lay: RobotLayout) -> list[Swivel]:
    """The robot's caster swivels (design §14.1): each of the layout's ``rolling_joints`` (passive joints
    above a floor contact, design §13) that is a hinge within :data:`SWIVEL_TILT_DEG` of the base's
    vertical at ``qpos0``, with the lowest collision geom below it (the caster's wheel). Its direction is
    the trail (the wheel centre's horizontal offset from the axis) where that exceeds :data:`TRAIL_MIN_M`,
    else the rolling direction of the horizontal hinge that carries the wheel; a trailless swivel with no
    such hinge (a ball on a swivel) has no direction and is left out."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    base = model.body(lay.base).id
    rot = data.xmat[base].reshape(3, 3)
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    out: list[Swivel] = []
    for name in lay.rolling_joints:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0 or int(model.jnt_type[j]) != hinge:
            continue
        ax = rot.T @ data.xaxis[j]
        if abs(ax[2]) < math.cos(math.radians(SWIVEL_TILT_DEG)):
            continue
        below = set(subtree(model, int(model.jnt_bodyid[j])).tolist())
        # the caster's wheel: on the roller (a horizontal hinge below the swivel) where there is one, so
        # that a fork's own collision geom (a MiR caster's mesh) is not taken for it; the lowest centre
        rollers = [
            k
            for k in range(model.njnt)
            if k != j
            and int(model.jnt_type[k]) == hinge
            and int(model.jnt_bodyid[k]) in below
            and abs((rot.T @ data.xaxis[k])[2]) < 0.5
        ]
        carried = set(subtree(model, int(model.jnt_bodyid[rollers[0]])).tolist()) if rollers else below
        geoms = [
            g
            for g in range(model.ngeom)
            if model.geom_bodyid[g] in carried and (model.geom_contype[g] or model.geom_conaffinity[g])
        ]
        if not geoms:
            continue
        g = min(geoms, key=lambda g: float(data.geom_xpos[g] @ rot[:, 2]))
        trail = rot.T @ (data.geom_xpos[g] - data.xanchor[j])
        dist = math.hypot(trail[0], trail[1])
        if dist >= TRAIL_MIN_M:
            angle = math.atan2(trail[1], trail[0])
        elif rollers:  # no trail: the wheel's rolling direction, up × its hinge axis
            ra = rot.T @ data.xaxis[rollers[0]]
            angle, dist = math.atan2(ra[0], -ra[1]), 0.0
        else:
            continue
        anchor = rot.T @ (data.xanchor[j] - data.xpos[base])
        out.append(
            Swivel(
                joint=name,
                qpos=int(model.jnt_qposadr[j]),
                dof=int(model.jnt_dofadr[j]),
                q0=float(model.qpos0[model.jnt_qposadr[j]]),
                sense=1.0 if ax[2] > 0 else -1.0,
                anchor=(float(anchor[0]), float(anchor[1])),
                angle0=angle,
                trail_m=dist,
                limits=(float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1])) if model.jnt_limited[j] else None,
                damping=float(model.dof_damping[model.jnt_dofadr[j]]),
                frictionloss=float(model.dof_frictionloss[model.jnt_dofadr[j]]),
            )
        )
    return out


def align_swivels(
    data: mujoco.MjData, swivels: list[Swivel], axle: tuple[float, float, float], v: float, w: float
) -> list[float]:
    """Turn each swivel to its caster's steady state under the motion ``(υ, ω)`` (m/s, rad/s) of the axle
    midpoint ``axle`` (base frame, m): the wheel rolls along its own heading without slipping sideways,
    trailing its axis (design §14.1). With ``u(p) = υ x̂ + ω ẑ × (p − axle)`` the velocity field and the
    trail ``t`` (length ``d``), the wheel's velocity ``u(p + t) = u(p) + ω ẑ × t`` must point along
    ``−t``: the trail's heading is ``ψ − π − asin(ω d / |u(p)|)``, ``ψ`` the heading of ``u(p)``. Driving
    that is straight behind the axis; turning in place nearly tangent to the axis's circle about the axle
    midpoint, ``asin(d/ρ)`` further round (8.6° for a 30 mm trail 0.2 m out). A trailless caster's rolling
    direction is laid along ``u(p)`` (the nearer way round). Only the ratio of ``υ`` and ``ω`` counts.
    Sets ``data.qpos`` and zeroes the swivels' ``qvel``; call ``mj_forward`` after. A caster on the axis
    of a turn in place stays as it is. Returns the angle each swivel turned, rad."""
    turned = []
    for s in swivels:
        ux, uy = v - w * (s.anchor[1] - axle[1]), w * (s.anchor[0] - axle[0])
        speed = math.hypot(ux, uy)
        if speed < 1e-9 * max(1.0, abs(v), abs(w)):
            turned.append(0.0)
            continue
        psi = math.atan2(uy, ux)
        if s.trail_m > 0:
            lead = math.asin(max(-1.0, min(1.0, w * s.trail_m / speed)))
            delta = math.remainder(psi - math.pi - lead - s.angle0, 2 * math.pi)
        else:  # rolling either way along the motion: the nearer
            delta = math.remainder(psi - s.angle0, math.pi)
        q = s.q0 + s.sense * delta
        if s.limits is not None:
            q = min(max(q, s.limits[0]), s.limits[1])
        data.qpos[s.qpos] = q
        data.qvel[s.dof] = 0.0
        turned.append(q - s.q0)
    return turned


def floor_table(report: dict[str, Any]) -> list[str]:
    """The floor contacts of a report as a small text table."""
    rows = [("body", "geom", "role", "load N", "μ sim", "μ pub", "condim sim/pub", "carries")]
    for c in report["floor_contacts"]:
        rows.append(
            (
                c["body"],
                c["geom"],
                c["role"] + (" (rolls)" if c["rolls"] else ""),
                f"{c['load_n']:.4g}",
                f"{c['friction']:g}",
                f"{c['friction_published']:g}",
                f"{c['condim']}/{c['condim_published']}",
                c["carries"],
            )
        )
    width = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    out = [
        f"  floor contacts at rest: {len(report['floor_contacts'])}, {report['floor_load_n']:.4g} N of "
        f"{report['weight_n']:.4g} N weight"
    ]
    out += ["    " + "  ".join(v.ljust(w) for v, w in zip(r, width)).rstrip() for r in rows]
    return out
