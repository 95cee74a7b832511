"""A URDF's casters its maker made frictionless for Gazebo (``<gazebo reference="caster…"><mu1>0</mu1>``) are
frictionless ``condim 1`` contacts wherever the project simulates the robot: ``bioform run``'s scene, ``robot
check`` and the fit (one floor-contact classification, ``robots.layout.frictionless``; design §13).

The URDF below is built here, Kobuki-like (r = 35 mm, half track 115 mm, chassis 2.4 kg on ``base_link`` under a
massless ``base_footprint``, two fixed cylinder casters tagged ``mu1 0``). Before the fix the import's friction-0
casters kept ``condim 3``: MuJoCo's pyramidal cone at its smallest μ (1e-5) is ill-conditioned, the loads at rest
did not add up to the weight (this robot at 0.3 s: 20.71 N of 23.94 N, rocking; the Kobuki in ``robot check``:
26.13 N of 23.95 N), the drag under a straight drive jumped by 2.4× the drive torque at times, and the fit's
damped rollouts blew up (wheels at 320 rad/s). Every number asserted is computed
here from the URDF's masses with plain MuJoCo reading the composed scene.
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.cli.main import main as cli
from bioform_mj.robots.refs import RobotRef
from bioform_mj.robots.scene import build_scene, compile_scene

R, L, G = 0.035, 0.115, 9.81
M_BASE, M_WHEEL, I_SPIN, M_CASTER = 2.4, 0.01, 0.001, 0.01
DAMPING = 0.002  # N·m·s/rad on each wheel joint
_I = 'ixy="0" ixz="0" iyz="0"'


def _wheel(side: str, y: float) -> str:
    return f"""
 <joint name="wheel_{side}_joint" type="continuous"><parent link="base_link"/><child link="wheel_{side}_link"/>
  <origin rpy="-1.5707963267948966 0 0" xyz="0 {y} 0.025"/><axis xyz="0 0 1"/>
  <limit effort="1" velocity="10"/><dynamics damping="{DAMPING}"/></joint>
 <link name="wheel_{side}_link"><collision><geometry><cylinder length="0.0206" radius="{R}"/></geometry></collision>
  <inertial><mass value="{M_WHEEL}"/><inertia ixx="{I_SPIN}" iyy="{I_SPIN}" izz="{I_SPIN}" {_I}/></inertial></link>
 <gazebo reference="wheel_{side}_link"><mu1>1.0</mu1><mu2>1.0</mu2></gazebo>"""


def _caster(name: str, x: float, z: float) -> str:
    return f"""
 <joint name="{name}_joint" type="fixed"><parent link="base_link"/><child link="{name}_link"/>
  <origin rpy="-1.5707963267948966 0 0" xyz="{x} 0 {z}"/></joint>
 <link name="{name}_link"><collision><geometry><cylinder length="0.0176" radius="0.017"/></geometry></collision>
  <inertial><mass value="{M_CASTER}"/><inertia ixx="0.001" iyy="0.001" izz="0.001" {_I}/></inertial></link>
 <gazebo reference="{name}_link"><mu1>0.0</mu1><mu2>0.0</mu2><kp>1000000.0</kp><kd>100.0</kd></gazebo>"""


URDF = f"""<?xml version="1.0"?>
<robot name="gazebo_casters">
 <link name="base_footprint"/>
 <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>
  <origin xyz="0 0 0.0102"/></joint>
 <link name="base_link">
  <inertial><mass value="{M_BASE}"/><origin xyz="0.01 0 0"/>
   <inertia ixx="0.02" iyy="0.02" izz="0.03675" {_I}/></inertial>
  <collision><origin xyz="0 0 0.05"/><geometry><cylinder length="0.08" radius="0.17"/></geometry></collision>
 </link>{_wheel("left", L)}{_wheel("right", -L)}
 {_caster("caster_front", 0.115, 0.007)}{_caster("caster_back", -0.135, 0.009)}
</robot>
"""
MASS = M_BASE + 2 * M_WHEEL + 2 * M_CASTER


def _ref(tmp_path: Path) -> RobotRef:
    p = tmp_path / "gazebo_casters.urdf"
    p.write_text(URDF)
    return RobotRef(model=str(p), base="base_footprint", left_wheel="wheel_left_joint", right_wheel="wheel_right_joint")


def _floor_loads(model: mujoco.MjModel, data: mujoco.MjData) -> dict[str, tuple[float, int]]:
    """Per robot body touching the floor: summed normal force (N) and the contacts' dim (plain MuJoCo)."""
    f6 = np.zeros(6)
    out: dict[str, tuple[float, int]] = {}
    for k in range(data.ncon):
        c = data.contact[k]
        g = c.geom2 if model.geom_bodyid[c.geom1] == 0 else c.geom1
        mujoco.mj_contactForce(model, data, k, f6)
        name = model.body(model.geom_bodyid[g]).name
        out[name] = (out.get(name, (0.0, 0))[0] + float(f6[0]), int(c.dim))
    return out


def test_run_scene_simulates_gazebo_frictionless_casters_with_condim_1(tmp_path):
    model, data = compile_scene(build_scene([_ref(tmp_path)], np.zeros((1, 3)), slots=False))
    for _ in range(round(0.3 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    loads = _floor_loads(model, data)
    assert loads["f1/caster_front_link"][1] == 1  # the pair's dim: was 3 (friction 0 in a pyramidal cone)
    assert loads["f1/wheel_left_link"][1] == 3 and loads["f1/wheel_right_link"][1] == 3
    # statics at rest: the loads add up to the weight (was 20.71 N of 23.94 N: rocking)
    assert sum(v[0] for v in loads.values()) == pytest.approx(MASS * G, rel=1e-3)  # measured: < 1e-6
    # driving straight, the only drag is the wheels' damping: v̇ = a (2τ − 2 d v / r), a = 1/(m r + 2 I_w / r)
    a = 1.0 / (MASS * R + 2 * I_SPIN / R)
    tau = 0.05
    acts = [model.actuator(f"f1/{n}").id for n in ("left_motor", "right_motor")]
    data.ctrl[acts] = tau
    t, v = [], []
    for _ in range(round(1.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
        t.append(data.time)
        v.append(float(np.hypot(data.qvel[0], data.qvel[1])))
    t, v = np.asarray(t), np.asarray(v)
    dv = np.gradient(v, t)[20:-20]
    drag = 2 * tau - dv / a  # N·m of both wheels that does not accelerate the robot
    wheels = 2 * DAMPING * v[20:-20] / R
    assert v[-1] > 0.4  # it rolled (0.48 m/s measured)
    assert np.mean(drag) == pytest.approx(np.mean(wheels), rel=0.02)  # measured: 0.6 % (was 1.4 %)
    assert np.abs(drag - wheels).max() < 0.03 * 2 * tau  # at every instant: measured 0.28 % (was 237 %)


def test_robot_check_says_what_each_floor_contact_carries(tmp_path, capsys):
    ref = _ref(tmp_path)
    out = tmp_path / "check.json"
    rc = cli(
        [
            "robot",
            "check",
            ref.model,
            "--base",
            "base_footprint",
            "--left-wheel",
            "wheel_left_joint",
            "--right-wheel",
            "wheel_right_joint",
            "--json",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert rc in (0, 1)  # ok or warn (placeholder inertias), never fail
    rep = json.loads(out.read_text())
    fc = {c["body"]: c for c in rep["floor_contacts"]}
    front = fc["caster_front_link"]
    assert front["condim"] == 1 and front["condim_published"] == 3 and front["carries"] == "normal"
    assert front["friction"] < 1e-3 and front["friction_published"] == 0.0
    assert fc["wheel_left_link"]["carries"] == "normal+sliding" and fc["wheel_left_link"]["condim"] == 3
    assert rep["floor_load_n"] == pytest.approx(MASS * G, rel=1e-3)  # the Kobuki's was 26.13 N of 23.95 N
    # statics about the axle (wheels at x = 0; the base's CoM 10 mm ahead, the front caster at 115 mm)
    n_front = (M_BASE * 0.01 + M_CASTER * 0.115 - M_CASTER * 0.135) * G / 0.115
    assert front["load_n"] == pytest.approx(n_front, rel=0.02)
    row = next(line for line in text.splitlines() if "caster_front_link" in line and "caster" in line.split())
    assert row.split()[-2:] == ["1/3", "normal"]
    assert "carries" in text
    assert "simulated with condim 1" in text and "caster_front_link" in text


def test_fit_and_run_classify_the_casters_alike(tmp_path):
    from bioform_mj.robots.realdata.simmodel import sim_spec

    ref = _ref(tmp_path)
    robot = sim_spec(ref)
    fit_model = robot.spec.compile()
    run_model = compile_scene(build_scene([ref], np.zeros((1, 3)), slots=False))[0]
    for b in ("caster_front_link", "caster_back_link"):
        (g_fit,) = [g for g in range(fit_model.ngeom) if fit_model.body(fit_model.geom_bodyid[g]).name == b]
        (g_run,) = [g for g in range(run_model.ngeom) if run_model.body(run_model.geom_bodyid[g]).name == "f1/" + b]
        assert fit_model.geom_condim[g_fit] == run_model.geom_condim[g_run] == 1
        assert fit_model.geom_priority[g_fit] == run_model.geom_priority[g_run]
    assert any("condim 1" in n and "caster_front_link" in n for n in robot.notes)
