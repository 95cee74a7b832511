"""Issue 18, items 2 and 4 (design §13): every floor contact named with the friction its maker meant,
and the ground truth of the robot that runs.

Small MJCF robots built here (explicit inertials, so every number below is computed by hand): a
differential drive (r = 0.05 m, l = 0.15 m, chassis 5 kg with its centre 5 cm behind the axle, wheels
0.5 kg with spin inertia 6.25e-4 kg·m²) standing on a rear caster 0.2 m behind the axle. Variants: a
frictionless caster as published menagerie-style (``friction="0.0001" condim="1"``, no priority), a
frictional one, an arm on a plain motor that drops when free, hubcaps welded below the wheels, and a
mudguard on its own servo overlapping a wheel. Accelerations are measured in raw MuJoCo on the composed
scene (``build_scene``), never with the project's identification code.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.assess.check import check
from bioform_mj.cli import main as cli
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.layout import CONTACT_PRIORITY, ModelError
from bioform_mj.robots.params import robot_truth
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef, as_ref
from bioform_mj.robots.scene import build_scene, compile_scene

R, L, G = 0.05, 0.15, 9.81
M_BASE, M_WHEEL, I_SPIN = 5.0, 0.5, 6.25e-4
X_COM, X_CASTER = -0.05, -0.2
I_BASE_YAW, I_WHEEL_YAW = 0.1, 4e-4


def _robot(caster: str = 'friction="0.0001" condim="1"', extra: str = "", wheel_extra: str = "", actuators: str = ""):
    return f"""
<mujoco model="t">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" integrator="implicitfast"/>
  <worldbody>
    <body name="base" pos="0 0 {R}">
      <freejoint name="root"/>
      <inertial pos="{X_COM} 0 0.05" mass="{M_BASE}" diaginertia="0.05 0.08 {I_BASE_YAW}"/>
      <geom name="chassis" type="box" pos="0 0 0.08" size="0.25 0.1 0.03"/>
      <geom name="caster" type="sphere" size="0.02" pos="{X_CASTER} 0 {-R + 0.02}" {caster}/>
      <body name="left_wheel_link" pos="0 {L} 0">
        <joint name="left_wheel" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="{M_WHEEL}" diaginertia="{I_WHEEL_YAW} {I_SPIN} {I_WHEEL_YAW}"/>
        <geom name="left_wheel_collision" type="sphere" size="{R}" condim="3"/>
        {wheel_extra.replace("SIDE", "left").replace("SGN", "")}
      </body>
      <body name="right_wheel_link" pos="0 {-L} 0">
        <joint name="right_wheel" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="{M_WHEEL}" diaginertia="{I_WHEEL_YAW} {I_SPIN} {I_WHEEL_YAW}"/>
        <geom name="right_wheel_collision" type="sphere" size="{R}" condim="3"/>
        {wheel_extra.replace("SIDE", "right").replace("SGN", "-")}
      </body>
      {extra}
    </body>
  </worldbody>
  <contact>
    <exclude body1="base" body2="left_wheel_link"/>
    <exclude body1="base" body2="right_wheel_link"/>
  </contact>
  <actuator>
    <motor name="left_motor" joint="left_wheel" ctrlrange="-3 3"/>
    <motor name="right_motor" joint="right_wheel" ctrlrange="-3 3"/>
    {actuators}
  </actuator>
</mujoco>
"""


def _write(tmp_path: Path, name: str, xml: str) -> str:
    p = tmp_path / name
    p.write_text(xml)
    return str(p)


def _a_formula(mass: float, i_w: float) -> float:
    return 1.0 / (mass * R + 2 * i_w / R)  # design §8


def _measured_accel(entry, tau: float, seconds: float = 0.3) -> float:
    """υ̇ (m/s²) of the composed scene's robot under constant wheel torque ``tau``, raw MuJoCo:
    0.3 s at rest, then a least-squares slope of the free joint's forward speed."""
    model, data = compile_scene(build_scene([entry], np.zeros((1, 3)), slots=False))
    acts = [model.actuator(f"f1/{n}").id for n in ("left_motor", "right_motor")]
    for _ in range(300):
        mujoco.mj_step(model, data)
    t, v = [], []
    data.ctrl[acts] = tau
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
        t.append(data.time)
        v.append(data.qvel[0])  # free joint: world-frame linear velocity, heading +x
    return float(np.polyfit(t, v, 1)[0])


def test_frictionless_caster_stays_frictionless_and_rolls_as_the_formula_says(tmp_path):
    f = _write(tmp_path, "fl.xml", _robot())
    spec = build_scene([f], np.zeros((1, 3)), slots=False)
    model = spec.compile()
    assert model.geom_priority[model.geom("f1/caster").id] == CONTACT_PRIORITY  # file: priority 0
    assert model.geom_priority[model.geom("floor").id] < CONTACT_PRIORITY
    mass = M_BASE + 2 * M_WHEEL
    a = _a_formula(mass, I_SPIN)
    tau = 0.5
    meas = _measured_accel(f, tau)
    assert meas == pytest.approx(2 * tau * a, rel=0.02)  # measured: +0.19 %
    # the same scene without the priority: MuJoCo takes the floor's μ = 1 for the caster, which brakes
    spec = build_scene([f], np.zeros((1, 3)), slots=False)
    spec.geom("f1/caster").priority = 0
    m2, d2 = compile_scene(spec)
    for _ in range(300):
        mujoco.mj_step(m2, d2)
    d2.ctrl[:2] = tau
    v0 = d2.qvel[0]
    for _ in range(300):
        mujoco.mj_step(m2, d2)
    assert (d2.qvel[0] - v0) / 0.3 < 0.7 * 2 * tau * a  # braked by the caster's μ N (measured: −73 %)


def test_floor_contacts_loads_roles_and_frictions(tmp_path):
    f = _write(tmp_path, "fl.xml", _robot())
    rep = check(f, identify_=False)
    mass = M_BASE + 2 * M_WHEEL
    assert rep["mass_kg"] == pytest.approx(mass, rel=1e-12)
    fc = {c["geom"]: c for c in rep["floor_contacts"]}
    assert set(fc) == {"left_wheel_collision", "right_wheel_collision", "caster"}
    assert fc["caster"]["role"] == "caster" and fc["left_wheel_collision"]["role"] == "wheel"
    assert sum(c["load_n"] for c in fc.values()) == pytest.approx(mass * G, rel=0.01)  # measured: 7e-6
    # statics about the axle: N_c x_c = m_base g x_com (wheels on the axle)
    n_c = M_BASE * G * X_COM / X_CASTER
    assert fc["caster"]["load_n"] == pytest.approx(n_c, rel=0.02)
    assert fc["left_wheel_collision"]["load_n"] == pytest.approx((mass * G - n_c) / 2, rel=0.02)
    assert fc["caster"]["condim"] == 1 and fc["caster"]["condim_published"] == 1
    assert fc["caster"]["friction_published"] == pytest.approx(1e-4) and fc["caster"]["friction"] < 1e-3
    assert fc["left_wheel_collision"]["friction"] == 1.0 and fc["left_wheel_collision"]["condim"] == 3
    assert not any("caster" in r and "brakes" in r for r in rep["reasons"])
    # traction limit with the real, least loaded wheel and the rotor's share
    f_drive = mass * R * _a_formula(mass, I_SPIN)
    assert rep["floor_fraction"]["drive"] == pytest.approx(f_drive, rel=1e-9)
    n_w = min(fc["left_wheel_collision"]["load_n"], fc["right_wheel_collision"]["load_n"])
    assert rep["traction_limit_nm"] == pytest.approx(n_w * R / max(rep["floor_fraction"].values()), rel=0.01)


def test_frictional_caster_is_a_warning_with_its_cost_and_the_mapping_can_fix_it(tmp_path, capsys):
    f = _write(tmp_path, "fr.xml", _robot(caster='friction="0.8" condim="3"'))
    rep = check(f, identify_=False)
    c = next(c for c in rep["floor_contacts"] if c["geom"] == "caster")
    assert c["role"] == "caster" and c["friction"] == pytest.approx(1.0)  # the pair's max: the floor's μ = 1
    assert c["friction_published"] == pytest.approx(0.8) and c["welded_to_base"] and not c["rolls"]
    brake = [r for r in rep["reasons"] if "caster 'caster'" in r]
    assert len(brake) == 1 and f"{c['load_n']:.3g} N" in brake[0] and f"μ N = {c['load_n']:.3g} N" in brake[0]
    # the mapping names it and makes it frictionless: priority wins, no warning, load unchanged
    ref = RobotRef(f, casters=("caster",), caster_friction=0.0)
    rep2 = check(ref, identify_=False)
    c2 = next(c for c in rep2["floor_contacts"] if c["geom"] == "caster")
    assert c2["friction"] < 1e-4 and c2["friction_published"] == pytest.approx(0.8)
    assert c2["load_n"] == pytest.approx(c["load_n"], rel=0.01)
    assert rep2["parts"]["casters"] == ["caster"] and rep2["parts"]["published_contacts"] == [["caster", 0.8, 3]]
    assert not any("caster 'caster'" in r for r in rep2["reasons"])
    a = _a_formula(M_BASE + 2 * M_WHEEL, I_SPIN)
    assert _measured_accel(ref, 0.5) == pytest.approx(2 * 0.5 * a, rel=0.02)  # measured: +0.19 %
    # a body name works too (all its collision geoms)
    assert prepare_robot(RobotRef(f, casters=("base",)))[1].casters == ("chassis", "caster")
    # a name not in the model: exit 2 naming it and the file
    with pytest.raises(ModelError, match=r"fr\.xml.*no geom or body 'nope'"):
        prepare_robot(RobotRef(f, casters=("nope",)))
    assert cli.main(["robot", "check", f, "--caster", "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "'nope'" in err[0] and "fr.xml" in err[0]


def test_mapping_keys_parse_and_are_refused_when_wrong():
    r = as_ref({"model": "x.xml", "casters": ["a", "b"], "caster_friction": 0.0, "free_joints": True})
    assert r.casters == ("a", "b") and r.caster_friction == 0.0 and r.free_joints and r.mapped
    assert r.to_table() == {"model": "x.xml", "casters": ["a", "b"], "caster_friction": 0.0, "free_joints": True}
    assert not RobotRef("x.xml").mapped
    for bad in ({"casters": "a"}, {"casters": [1]}, {"caster_friction": -1}, {"free_joints": 1}):
        with pytest.raises(ValueError, match="scenario key 'plant.robots"):
            as_ref({"model": "x.xml", **bad})


ARM = """
      <body name="arm" pos="0 0 0.1">
        <joint name="arm_joint" type="hinge" axis="0 1 0" damping="0.5"/>
        <inertial pos="-0.15 0 0" mass="2" diaginertia="0.001 0.015 0.015"/>
        <geom name="arm_geom" type="capsule" fromto="0 0 0 -0.3 0 0" size="0.02" contype="0" conaffinity="0"/>
      </body>"""


def _standing_arm_truth() -> tuple[float, float, float]:
    """(m, I, a, b) of the arm robot as it stands in the file (arm horizontal), by hand."""
    mass = M_BASE + 2 * M_WHEEL + 2.0
    yaw = (
        I_BASE_YAW
        + M_BASE * X_COM**2
        + 2 * (I_WHEEL_YAW + M_WHEEL * L**2)
        + 0.015
        + 2.0 * 0.15**2  # the arm's centre 0.15 m behind the axle (the caster carries it)
    )
    a = _a_formula(mass, I_SPIN)
    b = L / (yaw * R + 2 * I_SPIN * L**2 / R)
    return mass, yaw, a, b


def test_arm_on_a_plain_motor_is_frozen_by_default_and_drops_when_free(tmp_path):
    f = _write(tmp_path, "arm.xml", _robot(extra=ARM, actuators='<motor name="arm_motor" joint="arm_joint"/>'))
    spec, lay, *_ = prepare_robot(f)
    assert lay.frozen_joints == ("arm_joint",)
    assert any("frozen" in n and "'arm_motor'" in n for n in lay.notes)
    assert not any("position actuators hold 0" in n for n in lay.notes)
    model = spec.compile()
    assert model.njnt == 3 and model.nu == 2  # the arm is welded to the base, its motor gone
    mass, yaw, a, b = _standing_arm_truth()
    p = robot_truth(f)
    assert p.mass == pytest.approx(mass, rel=1e-12)
    assert p.yaw_inertia == pytest.approx(yaw, rel=1e-6)
    assert p.a_eff == pytest.approx(a, rel=1e-6) and p.b_eff == pytest.approx(b, rel=1e-6)
    plant = MujocoPlant([f], np.zeros((1, 3)), 0.001, 0.001, slots=False)
    np.testing.assert_allclose(plant.c_true()[0], [a, b], rtol=1e-6)
    rep = check(f, identify_=False)
    assert rep["moving_parts"] == []
    assert rep["c_true"]["b"] == pytest.approx(b, rel=1e-6)
    assert rep["yaw_inertia_kgm2"] == pytest.approx(yaw, rel=1e-6)
    # free joints: the arm drops (to hanging, yaw inertia falls), c_true is the settled robot's
    free = RobotRef(f, free_joints=True)
    assert prepare_robot(free)[1].free_joints == ("arm_joint",)
    rep = check(free, identify_=False)
    moving = {m["body"]: m for m in rep["moving_parts"]}
    assert set(moving) == {"arm"} and moving["arm"]["rotation_deg"] > 45
    assert rep["yaw_inertia_file_kgm2"] == pytest.approx(yaw, rel=1e-6)
    assert rep["yaw_inertia_kgm2"] < 0.9 * yaw  # the arm hangs: its 2 kg no longer 0.15 m out
    assert rep["c_true"]["b"] > 1.05 * b
    assert any("yaw inertia" in r and "settled" in r for r in rep["reasons"])
    assert any("move relative to the base" in r for r in rep["reasons"])


def test_arm_held_by_its_servo_or_locked_by_an_equality(tmp_path):
    _, yaw, a, b = _standing_arm_truth()

    def servo(kp: float) -> str:
        act = f'<position name="arm_servo" joint="arm_joint" kp="{kp}"/>'
        return _write(tmp_path, f"servo{kp}.xml", _robot(extra=ARM, actuators=act))

    lay = prepare_robot(servo(5000))[1]
    assert lay.held_joints == ("arm_joint",) and not lay.frozen_joints
    # a stiff servo holds the arm within the thresholds (static sag m g x / kp = 0.034°); c_true of the
    # settled robot = the formula of the standing one
    rep = check(servo(5000), identify_=False)
    assert rep["moving_parts"] == []
    assert rep["c_true"]["b"] == pytest.approx(b, rel=0.005)
    # a weak one lets it sag 2.94 N·m / 20 = 8.4°: a moving part
    rep = check(servo(20), identify_=False)
    assert [m["body"] for m in rep["moving_parts"]] == ["arm"] and rep["moving_parts"][0]["rotation_deg"] > 5
    # a sensor names the joint: it cannot be removed, an equality locks it
    sensed = _write(
        tmp_path,
        "sensed.xml",
        _robot(extra=ARM).replace("</mujoco>", '<sensor><jointpos name="arm_q" joint="arm_joint"/></sensor></mujoco>'),
    )
    lay = prepare_robot(sensed)[1]
    assert lay.locked_joints == ("arm_joint",)
    rep = check(sensed, identify_=False)
    assert rep["moving_parts"] == []
    assert rep["c_true"]["a"] == pytest.approx(a, rel=1e-3) and rep["c_true"]["b"] == pytest.approx(b, rel=0.005)


HUBCAP = """<body name="SIDE_hubcap" pos="0 SGN0.03 0">
          <inertial pos="0 0 0" mass="0.2" diaginertia="0.0011 0.002 0.0011"/>
          <geom type="cylinder" size="0.03 0.005" zaxis="0 1 0" contype="0" conaffinity="0"/>
        </body>"""


def test_welded_hubcap_is_in_the_wheel_spin_inertia(tmp_path):
    f = _write(tmp_path, "hub.xml", _robot(wheel_extra=HUBCAP))
    mass = M_BASE + 2 * M_WHEEL + 2 * 0.2
    i_w = I_SPIN + 0.002  # the wheel's spin inertia plus the hubcap's (on the axis: no parallel-axis term)
    p = robot_truth(f)
    assert p.wheel_inertia == pytest.approx(i_w, rel=1e-9)
    a = _a_formula(mass, i_w)
    assert p.a_eff == pytest.approx(a, rel=1e-9)
    meas = _measured_accel(f, 0.5)
    assert meas == pytest.approx(2 * 0.5 * a, rel=0.01)  # measured: +0.08 %
    assert abs(meas / (2 * 0.5 * _a_formula(mass, I_SPIN)) - 1) > 0.15  # the wheel alone: 19 % high
    # fused by the compiler (fusestatic): the hubcap is part of the wheel body, the same I_w
    fused = _write(
        tmp_path,
        "hub_fused.xml",
        _robot(wheel_extra=HUBCAP).replace('autolimits="true"', 'autolimits="true" fusestatic="true"'),
    )
    spec, *_ = prepare_robot(fused)
    assert mujoco.mj_name2id(spec.compile(), mujoco.mjtObj.mjOBJ_BODY, "left_hubcap") < 0  # fused away
    assert robot_truth(fused).wheel_inertia == pytest.approx(i_w, rel=1e-9)
    # off the axis: the parallel-axis term m d² about the joint axis
    off = _write(tmp_path, "hub_off.xml", _robot(wheel_extra=HUBCAP.replace('pos="0 0 0" mass', 'pos="0.01 0 0" mass')))
    assert robot_truth(off).wheel_inertia == pytest.approx(i_w + 0.2 * 0.01**2, rel=1e-9)


MUDGUARD = """
      <body name="mudguard" pos="0 {l} {z}">
        <joint name="mudguard_joint" type="hinge" axis="1 0 0"/>
        <inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
        <geom name="mudguard_geom" type="box" size="0.03 0.03 0.01"/>
      </body>"""


def test_self_contacts_name_overlapping_bodies(tmp_path):
    depth = 0.005  # the mudguard's underside 5 mm inside the left wheel's sphere
    z = R + 0.01 - depth
    f = _write(
        tmp_path,
        "mud.xml",
        _robot(
            extra=MUDGUARD.format(l=L, z=z),
            actuators='<position name="mudguard_servo" joint="mudguard_joint" kp="50"/>',
        ),
    )
    rep = check(f, identify_=False)
    sc = rep["self_contacts"]
    assert len(sc) == 1
    assert {sc[0]["body1"], sc[0]["body2"]} == {"left_wheel_link", "mudguard"}
    assert sc[0]["geoms"] in (
        [["left_wheel_collision", "mudguard_geom"]],
        [["mudguard_geom", "left_wheel_collision"]],
    )
    assert sc[0]["depth_m"] == pytest.approx(depth, abs=1.5e-3) and sc[0]["force_n"] > 1.0
    assert sc[0]["simulated"] is True
    assert any("'left_wheel_link'" in r and "'mudguard'" in r for r in rep["reasons"])
    # frozen (no servo), the mudguard is welded to the base and MuJoCo's weld-level parent filter drops
    # the pair in the scene: still named (the published geoms overlap at rest, design §13.1), but as not
    # simulated, with no force, and a note instead of a warning
    frozen = _write(tmp_path, "mud_frozen.xml", _robot(extra=MUDGUARD.format(l=L, z=z)))
    rep = check(frozen, identify_=False)
    (pair,) = rep["self_contacts"]
    assert {pair["body1"], pair["body2"]} == {"left_wheel_link", "mudguard"}
    assert pair["simulated"] is False and pair["force_n"] == 0.0 and pair["points"] == 0
    assert pair["depth_m"] == pytest.approx(depth, abs=1e-6)  # the published geoms at the file's configuration
    assert not any("'mudguard'" in r for r in rep["reasons"])
    assert any("'mudguard'" in n and "frozen" in n for n in rep["notes"])
    (free,) = check(RobotRef(frozen, free_joints=True), identify_=False)["self_contacts"]
    assert free["simulated"] is True and free["force_n"] > 1.0
    # without the overlap there is none
    clear = _write(
        tmp_path,
        "clear.xml",
        _robot(
            extra=MUDGUARD.format(l=L, z=R + 0.02),
            actuators='<position name="mudguard_servo" joint="mudguard_joint" kp="50"/>',
        ),
    )
    assert check(clear, identify_=False)["self_contacts"] == []


def test_robot_check_json_and_text_carry_contacts_mass_and_inertia(tmp_path, capsys):
    f = _write(tmp_path, "fl.xml", _robot())
    out = tmp_path / "r.json"
    assert cli.main(["robot", "check", f, "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    for key in ("floor_contacts", "self_contacts", "moving_parts", "mass_kg", "yaw_inertia_kgm2", "c_true"):
        assert key in rep
    for c in rep["floor_contacts"]:
        assert {
            "body",
            "geom",
            "role",
            "load_n",
            "friction",
            "friction_published",
            "condim",
            "condim_published",
        } <= set(c)
    text = capsys.readouterr().out
    assert text.count(f"mass {rep['mass_kg']:.4g} kg, yaw inertia {rep['yaw_inertia_kgm2']:.4g}") == 1  # once
    assert "floor contacts at rest: 3" in text and "caster" in text and "moving parts (first 2 s): none" in text


def test_heavy_rotor_passes_little_torque_to_the_floor(tmp_path):
    mass = M_BASE + 2 * M_WHEEL
    arm = 10 * mass * R**2  # armature 10 m r²: 1/21 of the drive torque reaches the floor
    f = _write(
        tmp_path,
        "rotor.xml",
        _robot().replace('type="hinge" axis="0 1 0"/>', f'type="hinge" axis="0 1 0" armature="{arm}"/>'),
    )
    p = robot_truth(f)
    f_drive = p.floor_fraction[0]
    assert f_drive == pytest.approx(mass * R**2 / (mass * R**2 + 2 * (I_SPIN + arm)), rel=1e-9)
    assert 0.04 < f_drive < 0.05
    # the floor force measured in raw MuJoCo: sum of the wheels' tangential contact forces = f τ_a / r
    model, data = compile_scene(build_scene([f], np.zeros((1, 3)), slots=False))
    for _ in range(300):
        mujoco.mj_step(model, data)
    tau = 1.0
    data.ctrl[:2] = tau
    for _ in range(50):
        mujoco.mj_step(model, data)
    wheel = {model.geom(f"f1/{s}_wheel_collision").id for s in ("left", "right")}
    fx, f6 = 0.0, np.zeros(6)
    for k in range(data.ncon):
        con = data.contact[k]
        if con.geom1 in wheel or con.geom2 in wheel:
            mujoco.mj_contactForce(model, data, k, f6)
            fx += abs((con.frame.reshape(3, 3).T @ f6[:3])[0])  # world x of the contact force
    assert fx == pytest.approx(f_drive * 2 * tau / R, rel=0.03)  # measured: +0.03 %
    # and the robot accelerates as a_eff with the rotor in I_w says (measured: −0.48 %)
    assert _measured_accel(f, 0.75) == pytest.approx(2 * 0.75 * _a_formula(mass, I_SPIN + arm), rel=0.01)


def test_scenario_robot_table_takes_the_keys_and_a_run_says_the_configuration_changed(tmp_path):
    from bioform_mj.assess.feasibility import feasibility
    from bioform_mj.scenario.loader import load

    _write(tmp_path, "arm.xml", _robot(extra=ARM, actuators='<motor name="arm_motor" joint="arm_joint"/>'))
    (tmp_path / "s.toml").write_text(
        '[plant]\nkind = "mujoco"\nrobots = [{model = "arm.xml", casters = ["caster"], caster_friction = 0.0, '
        "free_joints = true}]\n"
        "[formation]\ninitial_poses = [[0, 0, 0]]\noffsets = [[3, 0]]\n[graph]\nedges = []\n"
    )
    sc = load(str(tmp_path / "s.toml"))
    ref = sc.plant.robots[0]
    assert ref.casters == ("caster",) and ref.caster_friction == 0.0 and ref.free_joints
    assert sc.to_dict()["plant"]["robots"][0]["free_joints"] is True
    plant = MujocoPlant([ref], sc.initial_poses(), 0.001, 0.001)
    _, yaw, _, b = _standing_arm_truth()
    assert plant.params[0].yaw_inertia < 0.9 * yaw and plant.c_true()[0, 1] > 1.05 * b  # the arm hangs
    warn = [w for w in feasibility(sc, plant) if "yaw inertia" in w]
    assert len(warn) == 1 and f"{yaw:.4g}" in warn[0]
    # held (the default): no such warning, c_true of the standing robot
    held = MujocoPlant([str(tmp_path / "arm.xml")], sc.initial_poses(), 0.001, 0.001)
    assert held.c_true()[0, 1] == pytest.approx(b, rel=1e-6)
    assert not any("yaw inertia" in w for w in feasibility(sc, held))


def test_no_import_cycle_between_identify_and_the_plant():
    """STYLE item 8: the plant imports the ground truth from robot_params, not identify."""
    import subprocess
    import sys

    code = (
        "import sys, bioform_mj.plants.mujoco.plant, bioform_mj.assess.check; "
        "assert 'bioform_mj.assess.identify' not in sys.modules, 'the plant imports identify'"
    )
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


SWIVEL = f"""
      <body name="caster_swivel" pos="{X_CASTER} 0 -0.01">
        <joint name="caster_swivel_joint" type="hinge" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="0.005" diaginertia="1e-7 1e-7 1e-7"/>
        <body name="caster_wheel" pos="0 0 {-R + 0.03}">
          <joint name="caster_wheel_joint" type="hinge" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="0.005" diaginertia="1e-7 2e-7 1e-7"/>
          <geom name="caster_tire" type="sphere" size="0.02" condim="3" friction="1 0.005 0.0001"/>
        </body>
      </body>"""


def test_a_swivel_caster_wheel_rolls_free_and_does_not_brake(tmp_path):
    xml = _robot(extra=SWIVEL).replace(
        '<geom name="caster" type="sphere"', '<geom name="caster" contype="0" conaffinity="0" type="sphere"'
    )
    f = _write(tmp_path, "swivel.xml", xml)
    lay = prepare_robot(f)[1]
    assert set(lay.rolling_joints) == {"caster_swivel_joint", "caster_wheel_joint"} and not lay.frozen_joints
    rep = check(f, identify_=False)
    c = next(c for c in rep["floor_contacts"] if c["geom"] == "caster_tire")
    assert c["role"] == "caster" and c["rolls"] and not c["welded_to_base"] and c["friction"] == 1.0
    assert c["load_n"] == pytest.approx(M_BASE * G * X_COM / X_CASTER, rel=0.03)
    assert not any("brakes" in r for r in rep["reasons"]) and rep["moving_parts"] == []
    mass = M_BASE + 2 * M_WHEEL + 0.01
    # the caster wheel's spin inertia adds 2e-7 / 0.02² = 5e-4 kg: within the tolerance
    assert _measured_accel(f, 0.5) == pytest.approx(2 * 0.5 * _a_formula(mass, I_SPIN), rel=0.02)  # measured: +0.16 %


def test_a_run_warns_about_a_braking_caster_before_it_starts(tmp_path):
    from bioform_mj.assess.feasibility import feasibility
    from bioform_mj.scenario.loader import load

    fr = _write(tmp_path, "fr.xml", _robot(caster='friction="0.8" condim="3"'))
    sc = load(
        "paper",
        plant="mujoco",
        overrides=["formation.initial_poses=[[0,0,0]]", "formation.offsets=[[3,0]]", "graph.edges=[]"],
    )
    warn = [w for w in feasibility(sc, MujocoPlant([fr], sc.initial_poses(), 0.001, 0.001)) if "brakes" in w]
    n_c = M_BASE * G * X_COM / X_CASTER
    assert len(warn) == 1 and warn[0].startswith("follower 1: caster 'caster'")
    brake = float(re.search(r"μ N = ([\d.]+) N", warn[0])[1])
    assert brake == pytest.approx(1.0 * n_c, rel=0.02)  # μ = 1 (the pair's max) × the statics load
    fixed = RobotRef(fr, casters=("caster",), caster_friction=0.0)
    assert not any("brakes" in w for w in feasibility(sc, MujocoPlant([fixed], sc.initial_poses(), 0.001, 0.001)))
