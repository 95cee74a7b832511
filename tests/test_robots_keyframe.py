"""A robot starts and is held in its file's keyframe (design §13.2, issue 18 item 4).

A synthetic MJCF robot: a differential-drive base with an arm on position servos (a shoulder, and a
wrist with two hinges on one body), a frozen head (a hinge without actuator) and a ``home`` keyframe.
The ground truth is computed here from MuJoCo alone: the original file put in its keyframe by
``mj_resetDataKeyframe`` / ``mj_forward``, the yaw inertia summed over the robot's bodies about the
vertical through the wheel anchors' midpoint.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.cli import main as cli
from bioform_mj.robots.analysis import layout_of
from bioform_mj.robots.params import robot_parameters, running_data
from bioform_mj.robots.refs import RobotRef
from bioform_mj.robots.scene import build_scene, compile_scene

HOME_Q = {"shoulder": 0.9, "wrist_a": 0.5, "wrist_b": -0.7, "head": 1.2, "flap_a": 0.2, "flap_b": 0.5}
STOW_CTRL = {"shoulder": -0.4, "wrist_a": 0.3, "wrist_b": 0.6}

ROBOT = """
<mujoco model="kf_robot">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" integrator="implicitfast"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="10" diaginertia="0.05 0.05 0.08"/>
      <geom type="box" size="0.1 0.1 0.04" contype="0" conaffinity="0"/>
      <geom name="caster_f" type="sphere" pos="0.08 0 -0.075" size="0.025" condim="1" priority="2" friction="0 0 0"/>
      <geom name="caster_b" type="sphere" pos="-0.08 0 -0.075" size="0.025" condim="1" priority="2" friction="0 0 0"/>
      <body name="left" pos="0 0.15 0">
        <joint name="left_wheel" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="0.5" diaginertia="0.0013 0.0025 0.0013"/>
        <geom type="ellipsoid" size="0.1 0.02 0.1"/>
      </body>
      <body name="right" pos="0 -0.15 0">
        <joint name="right_wheel" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="0.5" diaginertia="0.0013 0.0025 0.0013"/>
        <geom type="ellipsoid" size="0.1 0.02 0.1"/>
      </body>
      <body name="upper" pos="0.05 0 0.05">
        <joint name="shoulder" type="hinge" axis="0 0 1" damping="2"/>
        <inertial pos="0.15 0 0" mass="0.8" diaginertia="0.0005 0.006 0.006"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" contype="0" conaffinity="0"/>
        <body name="hand" pos="0.3 0 0">
          <joint name="wrist_a" type="hinge" axis="0 0 1" pos="0.02 0 0" damping="1"/>
          <joint name="wrist_b" type="hinge" axis="0 1 0" pos="0 0 0.01" damping="1"/>
          <inertial pos="0.1 0.02 0" mass="0.4" diaginertia="0.0002 0.001 0.0012"/>
          <geom type="box" pos="0.1 0 0" size="0.1 0.02 0.02" contype="0" conaffinity="0"/>
        </body>
      </body>
      <body name="head" pos="-0.05 0 0.08">
        <joint name="head" type="hinge" axis="0 0 1"/>
        <inertial pos="0.12 0 0" mass="0.6" diaginertia="0.0003 0.003 0.003"/>
        <geom type="box" pos="0.12 0 0" size="0.12 0.02 0.02" contype="0" conaffinity="0"/>
      </body>
      <body name="flap_a" pos="0 0.05 0.1">
        <joint name="flap_a" type="hinge" axis="1 0 0"/>
        <inertial pos="0 0.05 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
      </body>
      <body name="flap_b" pos="0 -0.05 0.1">
        <joint name="flap_b" type="hinge" axis="1 0 0"/>
        <inertial pos="0 -0.05 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="lm" joint="left_wheel" ctrlrange="-5 5"/>
    <motor name="rm" joint="right_wheel" ctrlrange="-5 5"/>
    <position name="shoulder_servo" joint="shoulder" kp="3000" kv="20" ctrlrange="-3 3"/>
    <position name="wrist_a_servo" joint="wrist_a" kp="2000" kv="5" ctrlrange="-3 3"/>
    <position name="wrist_b_servo" joint="wrist_b" kp="2000" kv="5" ctrlrange="-3 3"/>
  </actuator>
  <equality>
    <joint joint1="flap_b" joint2="flap_a" polycoef="0.1 2 0 0 0"/>
  </equality>
  <keyframe>
    KEYS
  </keyframe>
</mujoco>
"""


def _qpos_key() -> str:
    # qpos order: root (7), left_wheel, right_wheel, shoulder, wrist_a, wrist_b, head, flap_a, flap_b
    q = [0, 0, 0.1, 1, 0, 0, 0, 0, 0] + [
        HOME_Q[n] for n in ("shoulder", "wrist_a", "wrist_b", "head", "flap_a", "flap_b")
    ]
    ctrl = [0, 0, HOME_Q["shoulder"], HOME_Q["wrist_a"], HOME_Q["wrist_b"]]
    return (
        f'<key name="home" qpos="{" ".join(map(str, q))}" ctrl="{" ".join(map(str, ctrl))}"/>\n'
        f'<key name="bare" qpos="{" ".join(map(str, q))}"/>\n'
        f'<key name="stow" ctrl="0 0 {STOW_CTRL["shoulder"]} {STOW_CTRL["wrist_a"]} {STOW_CTRL["wrist_b"]}"/>'
    )


@pytest.fixture()
def robot_file(tmp_path):
    p = tmp_path / "kf_robot.xml"
    p.write_text(ROBOT.replace("KEYS", _qpos_key()))
    return p


def _scene(entry):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return compile_scene(build_scene([entry], np.zeros((1, 3)), slots=False))[0]


def _joint_q(model, data, name):
    return float(data.qpos[model.jnt_qposadr[model.joint(name).id]])


def _independent_yaw(path, qpos: dict[str, float] | None, key: str | None = None) -> float:
    """Yaw inertia of the original file's robot in a configuration, about the vertical through the
    midpoint of the wheel anchors: MuJoCo kinematics, no project code."""
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    if key is not None:
        mujoco.mj_resetDataKeyframe(m, d, m.key(key).id)
    for n, q in (qpos or {}).items():
        d.qpos[m.jnt_qposadr[m.joint(n).id]] = q
    mujoco.mj_forward(m, d)
    mid = 0.5 * (d.xanchor[m.joint("left_wheel").id] + d.xanchor[m.joint("right_wheel").id])
    yaw = 0.0
    for b in range(1, m.nbody):
        R = d.ximat[b].reshape(3, 3)
        inertia_world = R @ np.diag(m.body_inertia[b]) @ R.T
        rel = d.xipos[b] - mid
        yaw += inertia_world[2, 2] + m.body_mass[b] * (rel[0] ** 2 + rel[1] ** 2)
    return float(yaw)


def test_home_keyframe_is_the_configuration_that_runs_and_its_yaw_inertia(robot_file):
    model = _scene(str(robot_file))
    lay = layout_of(model, "f1/")
    assert lay.keyframe == "home"
    assert any("keyframe 'home'" in n and "used by default" in n for n in lay.notes), lay.notes
    # yaw inertia of the composed robot at its rest configuration = the keyframe's, computed independently
    yaw_key = _independent_yaw(robot_file, None, key="home")
    yaw_q0 = _independent_yaw(robot_file, None)
    assert abs(yaw_key - yaw_q0) > 0.05 * yaw_q0  # the keyframe matters
    p = robot_parameters(model, "f1/")
    assert p.yaw_inertia == pytest.approx(yaw_key, abs=1e-6)
    # after the settle the arm is where the keyframe puts it (the servos hold it), the head frozen there
    data = running_data(model, 1, seconds=1.0)
    for n in ("shoulder", "wrist_a", "wrist_b"):
        assert _joint_q(model, data, "f1/" + n) == pytest.approx(HOME_Q[n], abs=1e-3)
    assert "head" in lay.frozen_joints[0]
    assert set(j.removeprefix("f1/") for j in lay.held_joints) == {"shoulder", "wrist_a", "wrist_b"}
    head = model.body("f1/head").id
    ref = mujoco.MjModel.from_xml_path(str(robot_file))
    rd = mujoco.MjData(ref)
    mujoco.mj_resetDataKeyframe(ref, rd, ref.key("home").id)
    mujoco.mj_forward(ref, rd)
    mujoco.mj_kinematics(model, data)
    base = model.body("f1/base").id
    rel_scene = data.xmat[base].reshape(3, 3).T @ data.xmat[head].reshape(3, 3)
    rel_ref = rd.xmat[1].reshape(3, 3).T @ rd.xmat[ref.body("head").id].reshape(3, 3)
    assert np.abs(rel_scene - rel_ref).max() < 1e-9
    running = robot_parameters(model, "f1/", data)
    assert running.yaw_inertia == pytest.approx(yaw_key, rel=1e-3)


def test_two_joints_on_one_body_move_as_in_the_file(robot_file):
    """Baked, the wrist's joints keep their meaning: displaced by δ from the keyframe, the hand is where
    the file puts it at keyframe + δ (a joint's anchor and axis carried through the joints after it)."""
    model = _scene(str(robot_file))
    data = mujoco.MjData(model)
    ref = mujoco.MjModel.from_xml_path(str(robot_file))
    rd = mujoco.MjData(ref)
    mujoco.mj_resetDataKeyframe(ref, rd, ref.key("home").id)
    for n, dq in (("wrist_a", 0.4), ("wrist_b", -0.3), ("shoulder", 0.2)):
        data.qpos[model.jnt_qposadr[model.joint("f1/" + n).id]] += dq
        rd.qpos[ref.jnt_qposadr[ref.joint(n).id]] += dq
    mujoco.mj_kinematics(model, data)
    mujoco.mj_kinematics(ref, rd)

    def rel(m, d, base, body):
        Rb, pb = d.xmat[base].reshape(3, 3), d.xpos[base]
        return Rb.T @ d.xmat[body].reshape(3, 3), Rb.T @ (d.xpos[body] - pb)

    Rs, ps = rel(model, data, model.body("f1/base").id, model.body("f1/hand").id)
    Rr, pr = rel(ref, rd, ref.body("base").id, ref.body("hand").id)
    assert np.abs(Rs - Rr).max() < 1e-9 and np.abs(ps - pr).max() < 1e-9


def test_a_coupling_equality_keeps_the_files_relation(robot_file):
    """flap_b = 0.1 + 2 flap_a (relative to the file's qpos0 = 0): the keyframe (0.2, 0.5) satisfies it;
    baked, qpos0 is the keyframe and the equality is rewritten about it, so the flaps stay there (an
    unshifted one would pull flap_b to 0.6). Both are locked (an equality names them) at the keyframe."""
    model = _scene(str(robot_file))
    lay = layout_of(model, "f1/")
    assert {"f1/flap_a", "f1/flap_b"} <= set(lay.locked_joints)
    data = running_data(model, 1, seconds=1.0)
    assert _joint_q(model, data, "f1/flap_a") == pytest.approx(0.2, abs=1e-4)
    assert _joint_q(model, data, "f1/flap_b") == pytest.approx(0.5, abs=1e-4)


def test_robot_table_keyframe_key_is_checked():
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.refs import as_ref

    assert as_ref({"model": "x.xml", "keyframe": "home"}).keyframe == "home"
    assert as_ref({"model": "x.xml"}).keyframe == ""
    assert as_ref({"model": "x.xml", "keyframe": "none"}).to_table() == {"model": "x.xml", "keyframe": "none"}
    with pytest.raises(InputError, match="keyframe"):
        as_ref({"model": "x.xml", "keyframe": 3})


def test_ctrl_only_keyframe_settles_to_the_servo_targets(robot_file):
    model = _scene(RobotRef(model=str(robot_file), keyframe="stow"))
    lay = layout_of(model, "f1/")
    assert lay.keyframe == "stow"
    q = dict(lay.keyframe_qpos)
    for n, target in STOW_CTRL.items():
        assert q[n] == pytest.approx(target, abs=1e-3)  # the configuration the servos settle at, reported
    assert abs(q.get("flap_a", 0.0)) < 1e-3  # no servo on it: the scene locks it, the settle holds it at qpos0
    assert any("ctrl only" in n for n in lay.notes)
    data = running_data(model, 1, seconds=1.0)
    for n, target in STOW_CTRL.items():
        assert _joint_q(model, data, "f1/" + n) == pytest.approx(target, abs=1e-3)
    # flap_a is not in keyframe_qpos (the .get above passes on its default): the running joint, locked, stays
    # at qpos0 but for the soft lock giving way to the equality flap_b = 0.1 + 2 flap_a (measured -1.0e-3 rad)
    assert "f1/flap_a" in lay.locked_joints and abs(_joint_q(model, data, "f1/flap_a")) < 2e-3
    yaw = _independent_yaw(robot_file, STOW_CTRL)
    assert robot_parameters(model, "f1/").yaw_inertia == pytest.approx(yaw, rel=1e-3)


def test_qpos_only_keyframe_servos_hold_it(robot_file):
    """A keyframe without ctrl: the servos' targets are set where they push nothing at the keyframe."""
    model = _scene(RobotRef(model=str(robot_file), keyframe="bare"))
    data = running_data(model, 1, seconds=1.0)
    for n in ("shoulder", "wrist_a", "wrist_b"):
        assert _joint_q(model, data, "f1/" + n) == pytest.approx(HOME_Q[n], abs=1e-3)


@pytest.mark.parametrize("off", ["none", "None"])
def test_keyframe_none_starts_at_qpos0_and_says_so(robot_file, off):
    model = _scene(RobotRef(model=str(robot_file), keyframe=off))
    lay = layout_of(model, "f1/")
    assert lay.keyframe == "" and lay.keyframe_qpos == ()
    assert any("'home' not used" in n for n in lay.notes)
    assert robot_parameters(model, "f1/").yaw_inertia == pytest.approx(_independent_yaw(robot_file, None), abs=1e-6)


def test_unknown_keyframe_exits_2_naming_the_files_keyframes(robot_file, capsys):
    rc = cli.main(["robot", "check", str(robot_file), "--keyframe", "parked"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    errors = [line for line in err if line.startswith("error:")]
    assert len(errors) == 1 and "'parked'" in errors[0] and "'home', 'bare', 'stow'" in errors[0], err


def test_a_urdf_with_a_keyframe_is_refused_naming_it():
    from bioform_mj.robots.layout import ModelError
    from bioform_mj.robots.prepare import prepare_robot

    urdf = Path(__file__).resolve().parent / "zoo" / "diffbot_urdf" / "diffbot.urdf"
    with pytest.raises(ModelError, match="keyframe 'home': a URDF has no keyframes"):
        prepare_robot(RobotRef(model=str(urdf), keyframe="home"))
    assert prepare_robot(RobotRef(model=str(urdf), keyframe="none"))[1].keyframe == ""


def test_scenario_robot_table_takes_the_keyframe_and_a_run_refuses_an_unknown_one(robot_file, tmp_path, capsys):
    from bioform_mj.scenario.loader import load

    (tmp_path / "s.toml").write_text(
        f'[plant]\nkind = "mujoco"\nrobots = [{{model = "{robot_file.name}", keyframe = "stow"}}]\n'
    )
    sc = load(str(tmp_path / "s.toml"))
    assert sc.plant.robots[0].keyframe == "stow"
    assert sc.to_dict()["plant"]["robots"][0]["keyframe"] == "stow"  # written back as given
    (tmp_path / "bad.toml").write_text(
        f'[plant]\nkind = "mujoco"\nrobots = [{{model = "{robot_file.name}", keyframe = "parked"}}]\n'
    )
    rc = cli.main(["run", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "out")])
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert rc == 2 and len(err) == 1 and "no keyframe 'parked'" in err[0], err
    assert not (tmp_path / "out").exists()


def test_tendon_coupling_and_spring_keep_the_files_meaning():
    """Tendon equalities are relative to length0 (at qpos0), which the keyframe moves: baked, the keyframe
    (0.3, 0.1), which satisfies t1 = 0.1 + 2 t2, stays (an unshifted relation would pull s1 to 0.4); the
    tendon spring (default rest length, at springref) pushes as in the file at the keyframe (−10 · 0.4 N)."""
    path = Path(__file__).resolve().parent / "data" / "keyframe_tendons.xml"
    model = _scene(str(path))
    data = running_data(model, 1, seconds=1.0)
    assert _joint_q(model, data, "f1/s1") == pytest.approx(0.3, abs=1e-4)
    assert _joint_q(model, data, "f1/s2") == pytest.approx(0.1, abs=1e-4)
    d0 = mujoco.MjData(model)
    mujoco.mj_forward(model, d0)
    ref = mujoco.MjModel.from_xml_path(str(path))
    rd = mujoco.MjData(ref)
    mujoco.mj_resetDataKeyframe(ref, rd, 0)
    mujoco.mj_forward(ref, rd)
    for n in ("s1", "s2"):
        got = d0.qfrc_passive[model.jnt_dofadr[model.joint("f1/" + n).id]]
        assert got == pytest.approx(rd.qfrc_passive[ref.jnt_dofadr[ref.joint(n).id]], abs=1e-9)
        assert got == pytest.approx(-4.0, abs=1e-9)
