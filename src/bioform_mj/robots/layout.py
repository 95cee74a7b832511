"""What the plant needs of one robot (:class:`RobotLayout`), and what the robot's preparation
(:mod:`bioform_mj.robots.analysis`, :mod:`bioform_mj.robots.prepare`) and the project's readers of a
compiled robot share: the contact constants of design §13, the element names by convention
(:data:`ROBOT`), body trees (:func:`subtree`, :func:`welded_to`), element labels, spec elements by
compiled index, and a ``<dcmotor>``'s constants (design §8.2).

Imports nothing of the project above :mod:`bioform_mj.robots.refs`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import mujoco
import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.robots.refs import models_dir, robot_names

__all__ = [
    "ModelError",
    "RobotNames",
    "ROBOT",
    "RobotLayout",
    "model_path",
    "FRICTIONLESS",
    "frictionless",
    "frictionless_contacts",
    "contact_carries",
    "CONTACT_PRIORITY",
    "SUPPORT_CLEARANCE",
    "subtree",
    "welded_to",
    "dc_constants",
    "dc_ctrl_scale",
    "DC_INPUT_VOLTAGE",
    "DC_INPUT_FF",
]


#: a geom whose sliding friction is below this (or whose condim is 1) is frictionless as published
FRICTIONLESS = 1e-3


def frictionless(mu: float, condim: int) -> bool:
    """The one floor-contact classification (design §13): a geom of sliding friction ``mu`` (the first of
    MuJoCo's three) and contact dimension ``condim`` is frictionless as its maker published it when ``mu`` is
    below :data:`FRICTIONLESS` or ``condim`` is 1 (a Menagerie ``condim="1"`` caster, a URDF's ``<gazebo>``
    ``mu1 0``). The scene simulates such a non-wheel geom with ``condim 1`` (normal force only) at
    :data:`CONTACT_PRIORITY`; ``robot check``, ``bioform run``, the fit and the replay all take it from here."""
    return float(mu) < FRICTIONLESS or int(condim) == 1


def frictionless_contacts(model: mujoco.MjModel, geoms: list[int]) -> tuple[list[int], list[int], str]:
    """Of the non-wheel collision geoms ``geoms`` of a compiled robot, those :func:`frictionless` as published, those
    of them the scene turns to ``condim 1`` (published above 1), and ``robot check``'s note on them ("" for none;
    geoms named as :func:`_geom_label` does). A URDF's ``<gazebo>`` ``mu1 0`` imports as friction 0 at condim 3:
    MuJoCo's pyramidal cone at its smallest μ (1e-5) is ill-conditioned (a Kobuki's loads at rest summed to 26.13 N
    of its 23.95 N weight, and the fit's rollouts with wheel damping blew up). Design §13."""
    fl = [g for g in geoms if frictionless(model.geom_friction[g, 0], model.geom_condim[g])]
    names = {g: _geom_label(model, g) for g in fl}
    to1 = [g for g in fl if model.geom_condim[g] > 1]
    if not fl:
        return fl, to1, ""
    note = (
        f"frictionless geom(s) {_quoted(names[g] for g in fl)} (friction < {FRICTIONLESS:g} or condim 1 as "
        f"published) simulated with condim 1 (normal force only) at priority {CONTACT_PRIORITY}: they stay "
        "frictionless against the floor (MuJoCo would otherwise take the larger friction of the pair, the floor's)"
    )
    if to1:
        note += f"; published condim {'/'.join(str(int(model.geom_condim[g])) for g in to1)} of "
        note += _quoted(names[g] for g in to1)
    return fl, to1, note


#: what a contact of each ``condim`` transmits (MuJoCo: 1 normal, 3 + sliding, 4 + torsional, 6 + rolling)
_CARRIES = {1: "normal", 3: "normal+sliding", 4: "normal+sliding+torsion", 6: "normal+sliding+torsion+rolling"}


def contact_carries(condim: int) -> str:
    """What a floor contact of dimension ``condim`` transmits, in words (``robot check``'s ``carries``):
    ``normal`` (condim 1: a frictionless push), ``normal+sliding`` (3), ``+torsion`` (4), ``+rolling`` (6)."""
    return _CARRIES.get(int(condim), f"condim {int(condim)}")


#: priority given to a robot's frictionless geoms and mapped casters (design §13): above the floor's
#: (0, or 1 with ``floor_friction``) and a friction patch's (1), so that MuJoCo takes their own
#: friction and condim for the pair instead of the larger of the two (against a surface more slippery than
#: the geom, the smaller of the two: explicit pairs, design §13.3)
CONTACT_PRIORITY = 2


#: a collision geom whose lowest point is within this of the floor (m, or 0.25 r if larger) supports the chassis
SUPPORT_CLEARANCE = 0.005


class ModelError(InputError):
    """A robot model file is missing, does not compile, or lacks what the plant needs.

    A ``ValueError`` (via :class:`~bioform_mj.core.errors.InputError`: the CLI exits 2).
    """


@dataclass(frozen=True)
class RobotNames:
    """Element names every robot model must define (before the scene prefix)."""

    base: str = "base"
    wheel_joints: tuple[str, str] = ("left_wheel", "right_wheel")
    motors: tuple[str, str] = ("left_motor", "right_motor")
    wheel_geoms: tuple[str, str] = ("left_wheel_collision", "right_wheel_collision")


ROBOT = RobotNames()


def model_path(name_or_path: str | Path) -> Path:
    """A shipped robot (``"paper"``, ``"paper_robot"`` or ``"paper_robot.xml"``) or a path.

    Paths are not checked here: :func:`~bioform_mj.robots.prepare.load_robot` raises ``ModelError`` naming the file.
    """
    s = str(name_or_path)
    stem = s[: -len(".xml")] if s.endswith(".xml") else s
    stem = stem[: -len("_robot")] if stem.endswith("_robot") else stem
    if "/" not in s and "\\" not in s and stem in robot_names() and not Path(s).exists():
        return models_dir() / f"{stem}_robot.xml"
    return Path(s)


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
    #: (driven wheel joint, frozen joint it hangs below): a suspension the scene welds (design §13)
    suspended_wheels: tuple[tuple[str, str], ...] = ()
    locked_joints: tuple[str, ...] = ()  # held at qpos0 by a joint equality (referenced elsewhere, not removable)
    held_joints: tuple[str, ...] = ()  # held by the model's own position actuators
    free_joints: tuple[str, ...] = ()  # left free (free_joints = true, or a ball joint that cannot be locked)
    rolling_joints: tuple[str, ...] = ()  # passive joints above a floor contact (caster swivel/wheel): free
    casters: tuple[str, ...] = ()  # geoms the mapping names as casters
    priority_geoms: tuple[str, ...] = ()  # geoms given CONTACT_PRIORITY so that their own friction/condim win
    published_contacts: tuple[tuple[str, float, int], ...] = ()  # (geom, friction, condim) as published, where changed
    #: the guesses of a format import (URDF, design §12), also at the head of ``notes``: runs warn them
    import_notes: tuple[str, ...] = ()
    #: design §13.2: the keyframe the robot starts and is held in ("" none) and its joints' values there
    keyframe: str = ""
    keyframe_qpos: tuple[tuple[str, float], ...] = ()

    def with_prefix(self, prefix: str) -> RobotLayout:
        """This layout with ``prefix`` before every element name (a robot of a scene, ``layout_of``)."""
        return replace(
            self,
            base=prefix + self.base,
            wheel_joints=tuple(prefix + j for j in self.wheel_joints),
            motors=tuple(prefix + a for a in self.motors),
            wheel_geoms=tuple(prefix + g for g in self.wheel_geoms),
            disabled_actuators=tuple(prefix + a for a in self.disabled_actuators),
            frozen_joints=tuple(prefix + j for j in self.frozen_joints),
            suspended_wheels=tuple((prefix + w, prefix + j) for w, j in self.suspended_wheels),
            locked_joints=tuple(prefix + j for j in self.locked_joints),
            held_joints=tuple(prefix + j for j in self.held_joints),
            free_joints=tuple(prefix + j for j in self.free_joints),
            rolling_joints=tuple(prefix + j for j in self.rolling_joints),
            casters=tuple(prefix + g for g in self.casters),
            priority_geoms=tuple(prefix + g for g in self.priority_geoms),
            published_contacts=tuple((prefix + g, f, c) for g, f, c in self.published_contacts),
        )

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
        d["suspended_wheels"] = tuple((str(w), str(j)) for w, j in d.get("suspended_wheels", ()))
        d["published_contacts"] = tuple((str(g), float(f), int(c)) for g, f, c in d.get("published_contacts", ()))
        d["import_notes"] = tuple(d.get("import_notes", ()))
        d["keyframe_qpos"] = tuple((str(j), float(q)) for j, q in d.get("keyframe_qpos", ()))
        return cls(**d)


def geom_support(model: mujoco.MjModel, data: mujoco.MjData, g: int, d: np.ndarray) -> float:
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


def _later_in_tree(model: mujoco.MjModel, root: int) -> np.ndarray:
    """Ids after body ``root`` in its tree (the world's child it hangs from, ``body_rootid``): where its descendants
    can be, children always coming after their parents. Every body after it for the world (0). Looking only there
    keeps a scene of n robots from visiting every later robot's bodies for each robot (n²)."""
    ids = np.arange(model.nbody)
    if root == 0:
        return ids[1:]
    rid = model.body_rootid
    return ids[(rid == rid[root]) & (ids > root)]


def subtree(model: mujoco.MjModel, root: int) -> np.ndarray:
    """Ids of body ``root`` and all its descendants."""
    ids = np.arange(model.nbody)
    inside = ids == root
    for b in _later_in_tree(model, root):  # children always come after their parents
        inside[b] = inside[model.body_parentid[b]]
    return ids[inside]


def welded_to(model: mujoco.MjModel, body: int) -> np.ndarray:
    """Ids of ``body`` and every body welded to it: its descendants reached through bodies without
    joints (a hubcap on a fixed joint below a wheel; a body the compiler fused is part of ``body``
    already). They move rigidly with ``body`` (design §13)."""
    ids = np.arange(model.nbody)
    inside = ids == body
    for b in _later_in_tree(model, body):
        inside[b] = inside[model.body_parentid[b]] and model.body_jntnum[b] == 0
    return ids[inside]


def _collides(model: mujoco.MjModel, g: int) -> bool:
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


def element_name(model: mujoco.MjModel, objtype: mujoco.mjtObj, i: int) -> str:
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


def _label(model: mujoco.MjModel, objtype: mujoco.mjtObj, i: int, sep: str) -> str:
    """Element ``i``'s name (a geom or a joint), or ``BODY{sep}K`` for an unnamed one: the ``K``-th
    of its kind on its body ``BODY`` (named as :func:`element_name` does)."""
    name = mujoco.mj_id2name(model, objtype, i)
    if name:
        return name
    if objtype == mujoco.mjtObj.mjOBJ_GEOM:
        b, first = int(model.geom_bodyid[i]), int(model.body_geomadr[model.geom_bodyid[i]])
    else:
        b, first = int(model.jnt_bodyid[i]), int(model.body_jntadr[model.jnt_bodyid[i]])
    return f"{element_name(model, mujoco.mjtObj.mjOBJ_BODY, b)}{sep}{i - first}"


def _geom_label(model: mujoco.MjModel, g: int) -> str:
    """A geom's name, or ``BODY_geomK`` for an unnamed one (prepare_robot gives it that name)."""
    return _label(model, mujoco.mjtObj.mjOBJ_GEOM, g, "_geom")


def _joint_label(model: mujoco.MjModel, j: int) -> str:
    """A joint's name, or ``BODY_jointK`` for an unnamed one (prepare_robot gives it that name)."""
    return _label(model, mujoco.mjtObj.mjOBJ_JOINT, j, "_joint")


def _quoted(names) -> str:
    return ", ".join(f"'{n}'" for n in names)


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


def dc_ctrl_scale(model: mujoco.MjModel, a: int) -> float:
    """``ctrl`` per N·m of commanded wheel torque of actuator ``a``: 1 for a torque motor,
    ``R/(g K)`` for a ``<dcmotor>`` with the voltage driver, ``1/g`` with the current driver."""
    if int(model.actuator_dyntype[a]) != int(mujoco.mjtDyn.mjDYN_DCMOTOR):
        return 1.0
    R, K, g, _ = dc_constants(model, a)
    return R / (g * K) if int(model.actuator_ctrlspec[a]) == DC_INPUT_VOLTAGE else 1.0 / g
