"""Issue 18 item 3: the verdict is right on robots with swivel (castor) wheels (design §14.1).

A synthetic base written here: two driven wheels on the axle, the centre of mass on the axle midpoint,
and two swivel casters on the centreline (0.2 m ahead and behind), each a passive vertical hinge with
damping carrying a sphere on a roller hinge 30 mm behind the swivel axis. The file turns both swivels
by 90° or 180° at ``qpos0``: their wheels must swing round before the robot moves as the formula says.
``identify`` turns each swivel to its steady state under the coming test's motion first (driving:
behind its axis; turning in place: 8.6° beyond the tangent to its circle about the axle midpoint, so that
the wheel rolls along its heading), and then identifies the rigid-body formula; without that
pre-alignment the same tests read a 17 % high (90°) or b 47 % low (180°, the pattern of the menagerie
TIAGo). A sphere on a swivel alone (no roller) cannot roll: it is named as a
braking caster.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

import bioform_mj.assess.identify as identify_module
from bioform_mj.assess.check import check
from bioform_mj.assess.identify import identify
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.contacts import (
    SWIVEL_TILT_DEG,
    align_swivels,
    floor_contacts,
    robot_contacts,
    rolling_bodies,
    self_contacts,
    swivel_casters,
)
from bioform_mj.robots.layout import subtree
from bioform_mj.robots.refs import RobotRef

R, L, R_CASTER, X_CASTER = 0.05, 0.15, 0.02, 0.2


def _robot(
    turn_deg: float = 90.0, trail: float = 0.03, roller: bool = True, com_y: float = 0.0, fork: bool = False
) -> mujoco.MjSpec:
    """The base, built with MjSpec: swivels turned by ``turn_deg`` about the vertical at ``qpos0``, casters
    ``trail`` m behind their axes, each sphere on a roller hinge (``roller``) or straight on the swivel; the
    chassis's centre of mass ``com_y`` m beside the axle midpoint; ``fork``: a colliding fork geom on each
    swivel, on its axis and lower than the wheel's centre (as a caster mesh's frame may be), off the floor."""
    spec = mujoco.MjSpec()
    spec.modelname = "swivel_caster_base"
    spec.compiler.degree = False
    spec.option.timestep = 0.001
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    hinge, sphere = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtGeom.mjGEOM_SPHERE

    def body(parent, name: str, pos, mass: float, inertia, ipos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
        b = parent.add_body(name=name, pos=list(pos), quat=list(quat))
        b.mass, b.inertia, b.ipos, b.explicitinertial = mass, list(inertia), list(ipos), True
        return b

    base = body(spec.worldbody, "base", (0, 0, R), 8.0, (0.06, 0.1, 0.12), ipos=(0, com_y, 0.04))
    base.add_freejoint(name="root")
    base.add_geom(name="chassis", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, 0.09], size=[0.26, 0.12, 0.03],
                  contype=0, conaffinity=0)  # fmt: skip
    for side, y in (("left", L), ("right", -L)):
        wheel = body(base, f"{side}_wheel_link", (0, y, 0), 0.5, (4e-4, 6.25e-4, 4e-4))
        wheel.add_joint(name=f"{side}_wheel", type=hinge, axis=[0, 1, 0])
        wheel.add_geom(name=f"{side}_tire", type=sphere, size=[R, 0, 0], condim=3)
        spec.add_exclude(bodyname1="base", bodyname2=f"{side}_wheel_link")
        motor = spec.add_actuator(name=f"{side}_motor", target=f"{side}_wheel", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        motor.set_to_motor()
        motor.ctrlrange, motor.ctrllimited = [-2.0, 2.0], True
    half = math.radians(turn_deg) / 2
    for name, x in (("front", X_CASTER), ("back", -X_CASTER)):
        sw = body(base, f"{name}_swivel", (x, 0, 0), 0.05, (2e-5,) * 3, ipos=(-0.015, 0, -0.015),
                  quat=(math.cos(half), 0, 0, math.sin(half)))  # fmt: skip
        sw.add_joint(name=f"{name}_swivel_joint", type=hinge, axis=[0, 0, 1], damping=0.02)
        if fork:
            sw.add_geom(name=f"{name}_fork", type=sphere, size=[0.004, 0, 0], pos=[0, 0, -(R - R_CASTER) - 0.006])
        wheel = body(sw, f"{name}_wheel", (-trail, 0, -(R - R_CASTER)), 0.05, (8e-6,) * 3)
        if roller:
            wheel.add_joint(name=f"{name}_roller", type=hinge, axis=[0, 1, 0])
        wheel.add_geom(name=f"{name}_tire", type=sphere, size=[R_CASTER, 0, 0], condim=3, friction=[1, 0.005, 1e-4])
    return spec


def _write(tmp_path: Path, spec: mujoco.MjSpec) -> str:
    p = tmp_path / "swivel_base.xml"
    p.write_text(spec.to_xml())
    return str(p)


def _caster_state(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> tuple[np.ndarray, ...]:
    """Base frame, m: the swivel axis's position ``p``, the trail ``t`` (wheel centre − axis, horizontal) and
    the caster wheel's rolling direction (up × roller axis)."""
    base = model.body("f1/base").id
    rot, origin = data.xmat[base].reshape(3, 3), data.xpos[base]
    anchor = data.xanchor[model.joint(f"f1/{name}_swivel_joint").id]
    p = (rot.T @ (anchor - origin))[:2]
    t = (rot.T @ (data.geom_xpos[model.geom(f"f1/{name}_tire").id] - anchor))[:2]
    ax = rot.T @ data.xaxis[model.joint(f"f1/{name}_roller").id]
    return p, t, np.array([-ax[1], ax[0]])


def _velocity(x: np.ndarray, axle: np.ndarray, v: float, w: float) -> np.ndarray:
    """Base-frame velocity at ``x`` of the motion (υ, ω) about the axle midpoint ``axle``."""
    return np.array([v - w * (x[1] - axle[1]), w * (x[0] - axle[0])])


@pytest.mark.parametrize("trail,fork", [(0.03, False), (0.0, False), (0.03, True)])
def test_swivels_are_found_and_turned_to_their_steady_state_for_the_coming_motion(tmp_path, trail, fork):
    """Found from the layout's rolling joints (vertical hinges only, not the rollers); trail and heading
    at qpos0 as the file puts them (90° turned: the wheels sideways). Aligned for a drive and for a CCW turn
    in place, each caster is in its steady state: its wheel's velocity ``u(p + t)`` (``u`` the motion's
    velocity field about the axle midpoint) points along −t (it rolls along its heading, trailing the
    axis); turning, that is asin(d/ρ) = 8.6° beyond the tangent. Trailless, it rolls along ``u(p)``. A fork
    geom lower than the wheel's centre is not taken for the wheel (the wheel is the roller's)."""
    plant = MujocoPlant(
        [_write(tmp_path, _robot(90.0, trail, fork=fork))], np.zeros((1, 3)), 0.001, 0.001, None, slots=False
    )
    model, lay = plant.model, plant.layouts[0]
    sw = swivel_casters(model, lay)
    assert [s.joint for s in sw] == ["f1/front_swivel_joint", "f1/back_swivel_joint"]
    for s, x in zip(sw, (X_CASTER, -X_CASTER)):
        assert s.anchor == pytest.approx((x, 0.0), abs=1e-9) and s.sense == 1.0
        assert s.trail_m == pytest.approx(trail, abs=1e-9)
        # trail (-0.03, 0) turned +90°: towards −y; the rolling direction up × roller axis, (−1, 0) turned: −y
        assert s.angle0 == pytest.approx(-math.pi / 2, abs=1e-9)
    data = mujoco.MjData(model)
    axle = np.array(lay.axle[:2])
    for v, w in ((1.0, 0.0), (0.0, 1.0)):
        mujoco.mj_resetData(model, data)
        turned = align_swivels(data, sw, lay.axle, v, w)
        mujoco.mj_kinematics(model, data)
        for name, q in zip(("front", "back"), turned):
            p, t, roll = _caster_state(model, data, name)

            if trail:
                uw = _velocity(p + t, axle, v, w)
                assert np.linalg.norm(t) == pytest.approx(trail, rel=1e-9)
                assert uw[0] * t[1] - uw[1] * t[0] == pytest.approx(0.0, abs=1e-12) and uw @ t < 0, (name, v, w)
                if w:  # from −y (qpos0) to asin(d/ρ) = 8.6° beyond the tangent: front −8.6°, back 180° − 8.6°
                    lead = math.asin(trail / X_CASTER)
                    assert q == pytest.approx(math.pi - lead if name == "back" else -lead, abs=1e-9)
            else:
                ua = _velocity(p, axle, v, w)
                assert ua[0] * roll[1] - ua[1] * roll[0] == pytest.approx(0.0, abs=1e-12), (name, v, w)


def _rolling_by_scene_kinematics(model: mujoco.MjModel, lay) -> set[int]:
    """Ground truth for ``rolling_bodies``: the whole scene's ``mj_kinematics`` at qpos0 (the joint's world axis
    against the base's world vertical), as the code did before it looked at the robot's own bodies only."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    up = data.xmat[model.body(lay.base).id].reshape(3, 3)[:, 2]
    out: set[int] = set()
    for j in lay.rolling_joints:
        jid = model.joint(j).id
        swivel = abs(float(data.xaxis[jid] @ up)) >= math.cos(math.radians(SWIVEL_TILT_DEG))
        if model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_BALL or not swivel:
            out |= set(subtree(model, int(model.jnt_bodyid[jid])).tolist())
    return out


def test_a_team_s_rolling_bodies_and_contacts_are_each_robot_s_own(tmp_path):
    """A team of four swivel-caster robots (turned 90° and 180°, one with its swivels tilted 30° off the
    vertical, headings 0 to 2.5 rad), the second pushed into the first: ``rolling_bodies`` from the robot's own
    bodies equals the whole scene's kinematics (the rollers roll; the swivels only where tilted); the one-pass
    ``robot_contacts`` equals a per-robot scan of every contact (the robots' shared contacts in both lists), and
    ``floor_contacts``/``self_contacts`` given them equal the ones that scan (docs/findings/performance.md)."""
    tilted = _robot(90.0)
    for name in ("front", "back"):
        b = tilted.body(f"{name}_swivel")
        tilt = np.array([math.cos(math.radians(15)), math.sin(math.radians(15)), 0.0, 0.0])
        q = np.zeros(4)
        mujoco.mju_mulQuat(q, tilt, np.array(b.quat))
        b.quat = q.tolist()
    files = []
    for k, spec in enumerate((_robot(90.0), _robot(180.0), tilted, _robot(45.0, roller=False))):
        d = tmp_path / f"r{k}"
        d.mkdir()
        files.append(_write(d, spec))
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 1.0], [1.0, 0.0, 2.5], [1.0, 1.0, -0.7]])
    plant = MujocoPlant(files, poses, 0.001, 0.001, None, slots=False)
    model = plant.model
    rolls = [rolling_bodies(model, lay) for lay in plant.layouts]
    assert rolls == [_rolling_by_scene_kinematics(model, lay) for lay in plant.layouts]
    names = [{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b).split("/")[1] for b in r} for r in rolls]
    wheels = {"front_wheel", "back_wheel"}
    assert names == [wheels, wheels, wheels | {"front_swivel", "back_swivel"}, set()]
    data = mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    root = model.joint("f2/root").qposadr[0]
    data.qpos[root : root + 2] = [0.1, 0.28]  # robot 2's left tyre into robot 1's
    mujoco.mj_forward(model, data)
    found = robot_contacts(model, data, plant.layouts)
    g = data.contact.geom1[: data.ncon], data.contact.geom2[: data.ncon]
    scan = []
    for lay in plant.layouts:
        mine = set(subtree(model, model.body(lay.base).id).tolist())
        scan.append([k for k in range(data.ncon) if {model.geom_bodyid[g[0][k]], model.geom_bodyid[g[1][k]]} & mine])
    assert [list(f) for f in found] == scan
    shared = set(scan[0]) & set(scan[1])
    assert shared and all(set(s).isdisjoint(scan[0]) for s in scan[2:])  # robots 1 and 2 touch, no other pair
    for i, lay in enumerate(plant.layouts):
        prefix = f"f{i + 1}/"
        assert floor_contacts(model, data, lay, prefix, found[i]) == floor_contacts(model, data, lay, prefix)
        assert self_contacts(model, data, lay, prefix, found[i]) == self_contacts(model, data, lay, prefix)
    assert {c["geom"] for c in floor_contacts(model, data, plant.layouts[2], "f3/", found[2])} >= {"front_tire"}


@pytest.mark.parametrize(
    "turn_deg,off",
    [
        # slow: the 90° case (a) is what test_a_urdf_base_with_a_rear_swivel_caster_turned_sideways checks in half
        # the time (casters 90° off, found and aligned, a and b within 3 %, unaligned a off); it took 63 s beside
        # that test's 31 s and the 180° case's 60 s in one make-test run at load 5-8; make test-slow runs it
        pytest.param(90.0, "a", marks=pytest.mark.slow),
        (180.0, "b"),
    ],
)
def test_misaligned_swivel_casters_identify_as_the_rigid_body_formula(tmp_path, monkeypatch, turn_deg, off):
    """Casters 90° / 180° off at qpos0: identify within 2 % of the formula (measured a −0.08 %, b −0.49 %:
    the caster rollers' spin inertia, which the formula leaves out) and robot check passes; the same
    tests without the pre-alignment are >10 % off (measured a +17.6 % at 90°; b −46.9 % at 180°)."""
    path = _write(tmp_path, _robot(turn_deg))
    rep = identify(path)
    assert abs(rep["relative_error"]["a"]) < 0.02 and abs(rep["relative_error"]["b"]) < 0.02, rep["relative_error"]
    assert rep["test"]["caster_swivels"] == ["front_swivel_joint", "back_swivel_joint"]
    assert not [f for f in rep["findings"] if f["kind"] != "rocking"], rep["findings"]
    assert check(path)["verdict"] == "pass"
    monkeypatch.setattr(identify_module, "align_swivels", lambda *a, **k: [])
    unaligned = identify(path)
    assert abs(unaligned["relative_error"][off]) > 0.10, unaligned["relative_error"]


@pytest.mark.slow  # ≥ 7 s warm here (make test keeps to the fast set; make test-slow runs it)
def test_a_sphere_on_a_swivel_alone_slides_and_is_named_a_braking_caster(tmp_path):
    """No roller: the swivel turns the sphere about the vertical, but it cannot roll; it slides with μ 1
    (each carries 2.8 N): identify names both as braking casters and robot check fails with that cause."""
    path = _write(tmp_path, _robot(90.0, roller=False))
    rep = identify(path)
    braking = {f["geom"] for f in rep["findings"] if f["kind"] == "braking_caster"}
    assert braking == {"front_tire", "back_tire"}
    # one classification (design §0): identify's floor contacts are robot check's, casters that cannot roll
    assert {(c["role"], c["rolls"]) for c in rep["floor_contacts"] if c["geom"] in braking} == {("caster", False)}
    chk = check(path)
    assert chk["verdict"] == "fail" and chk["cause"]["kind"] == "braking_caster"
    rows = [c for c in chk["floor_contacts"] if c["geom"] in braking]
    assert rows and all(not c["rolls"] and c["role"] == "caster" for c in rows)


@pytest.mark.slow  # ≥ 7 s warm here (make test keeps to the fast set; make test-slow runs it)
def test_a_robot_that_turns_while_driving_straight_is_tested_at_a_lower_torque(tmp_path, monkeypatch):
    """The chassis's centre of mass 20 mm beside the axle (17 mm for the robot): equal wheel torques turn it
    (the υ·ω coupling of design §8.1). At the first torque the drive test turns 0.78 rad; rerun at a torque
    that turns about DRIVE_HEADING_MAX it identifies a +1.2 %, b +0.9 % (the coupling's own share) and robot
    check warns (centre of mass off the axle) with a note; without the rerun the robot spins round (3 rad),
    its drive fit does not hold and a reads −65 % (the fit's own rerun at a third of the torque: +1.5 %)."""
    path = _write(tmp_path, _robot(90.0, com_y=0.02))
    rep = identify(path)
    rerun = rep["test"]["drive_rerun"]
    assert rerun and rerun["first_heading_change_rad"] > identify_module.DRIVE_HEADING_MAX
    assert rep["test"]["torque_Nm"] < 0.5 * rerun["first_torque_Nm"]
    assert abs(rep["relative_error"]["a"]) < 0.02 and abs(rep["relative_error"]["b"]) < 0.02, rep["relative_error"]
    chk = check(path)
    assert chk["verdict"] == "warn" and any(n.startswith("drive tests at ") for n in chk["notes"])
    assert any("turned before each identification test" in n and "damping of up to 0.02" in n for n in chk["notes"])
    monkeypatch.setattr(identify_module, "DRIVE_HEADING_MAX", float("inf"))
    # without it, the drive fit does not hold and the lower-torque rerun of design §14.2 catches it (a +1.5 %)
    spun = identify(path)
    assert spun["test"]["fit_rerun"]["kept"] and abs(spun["relative_error"]["a"]) < 0.02, spun["test"]["fit_rerun"]
    monkeypatch.setattr(identify_module, "FIT_RERUN_SCALE", 1.0)  # and without both, a is far off
    assert identify(path)["relative_error"]["a"] < -0.3


PIONEER_LIKE_URDF = """<?xml version="1.0"?>
<robot name="pioneer_like">
  <link name="base_link">
    <inertial><mass value="9.0"/><origin xyz="-0.02 0 0.1"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.15" iyz="0" izz="0.2"/></inertial>
    <collision><origin xyz="-0.045 0 0.145"/><geometry><box size="0.35 0.25 0.14"/></geometry></collision>
  </link>
  SIDES
  <link name="swivel">
    <inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
  </link>
  <joint name="swivel_joint" type="continuous"><parent link="base_link"/><child link="swivel"/>
    <origin xyz="-0.185 0 0.055" rpy="0 0 1.5708"/><axis xyz="0 0 1"/><dynamics damping="0.05"/></joint>
  <link name="center_wheel">
    <inertial><mass value="0.2"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1.5e-4" iyz="0" izz="1e-4"/></inertial>
    <collision><origin rpy="-1.5708 0 0"/><geometry><cylinder length="0.01" radius="0.0375"/></geometry></collision>
  </link>
  <joint name="center_wheel_joint" type="continuous"><parent link="swivel"/><child link="center_wheel"/>
    <origin xyz="-0.026 0 -0.0175"/><axis xyz="0 1 0"/></joint>
</robot>
"""
_SIDE = """<link name="S_wheel">
    <inertial><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial>
    <collision><origin rpy="-1.5708 0 0"/><geometry><cylinder length="0.04" radius="0.09"/></geometry></collision>
  </link>
  <joint name="S_wheel_joint" type="continuous"><parent link="base_link"/><child link="S_wheel"/>
    <origin xyz="0 Y 0.09"/><axis xyz="0 1 0"/></joint>"""


def test_a_urdf_base_with_a_rear_swivel_caster_turned_sideways(tmp_path, monkeypatch):
    """A Pioneer-3-DX-like URDF: one rear caster, a continuous swivel (damping 0.05) whose joint origin turns
    it 90° (the wheel sideways) and a continuous wheel joint 26 mm behind it. Through the URDF import the
    swivel is found and aligned: a −0.8 %, b −2.1 % (measured; the caster wheel's spin inertia is outside the
    formula), not a fail; without the alignment the drive test reads a −66 %."""
    sides = "\n  ".join(_SIDE.replace("S", s).replace("Y", y) for s, y in (("left", "0.158"), ("right", "-0.158")))
    path = tmp_path / "pioneer_like.urdf"
    path.write_text(PIONEER_LIKE_URDF.replace("SIDES", sides))
    ref = RobotRef(
        model=str(path), base="base_link", left_wheel="left_wheel_joint", right_wheel="right_wheel_joint", tau_max=2.0
    )
    rep = identify(ref)
    assert rep["test"]["caster_swivels"] == ["swivel_joint"]
    assert abs(rep["relative_error"]["a"]) < 0.03 and abs(rep["relative_error"]["b"]) < 0.03, rep["relative_error"]
    # one classification (design §0): a loaded caster whose wheel rolls
    assert [(c["role"], c["rolls"]) for c in rep["floor_contacts"] if c["body"] == "center_wheel"] == [("caster", True)]
    assert check(ref)["verdict"] != "fail"
    monkeypatch.setattr(identify_module, "align_swivels", lambda *a, **k: [])
    assert identify(ref)["relative_error"]["a"] < -0.3
