"""Regressions found by judging ``robot check`` on published robots outside the zoo (issue 18, "the checks
will be judged on published robots you have not seen"): a MiR100 URDF (DFKI-NI/mir_robot), a Fetch Freight
URDF (ZebraDevs/fetch_ros), a Hello Robot Stretch MJCF (hello-robot/stretch_mujoco).

Every robot here is written by the test, small, with the one feature that went wrong on the published one;
the numbers the assertions use are computed by hand from the file.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from bioform_mj.assess.check import G, check, tip_margins
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef
from test_robots_urdf import box_stl  # a binary STL box, as the URDF tests write it

HALF_PI = repr(math.pi / 2)


def _urdf(tail: str = "", chassis: str = '<box size="0.3 0.2 0.05"/>') -> str:
    """A URDF diff drive: 2 kg chassis, wheels r = 0.05 m at y = ±0.12 m, a sphere caster front and back."""
    casters = ""
    for name, x in (("caster_front", 0.12), ("caster_back", -0.12)):
        casters += f"""
  <joint name="{name}_joint" type="fixed"><parent link="base_link"/><child link="{name}"/>
    <origin xyz="{x!r} 0 -0.035"/></joint>
  <link name="{name}"><inertial><mass value="0.05"/><inertia ixx="4e-6" iyy="4e-6" izz="4e-6" ixy="0" ixz="0"
    iyz="0"/></inertial><collision><geometry><sphere radius="0.015"/></geometry></collision></link>"""
    wheels = ""
    for side, y in (("left", 0.12), ("right", -0.12)):
        wheels += f"""
  <joint name="wheel_{side}_joint" type="continuous"><parent link="base_link"/><child link="wheel_{side}"/>
    <origin xyz="0 {y!r} 0" rpy="-{HALF_PI} 0 0"/><axis xyz="0 0 1"/><limit effort="2" velocity="10"/></joint>
  <link name="wheel_{side}"><inertial><mass value="0.2"/><inertia ixx="1.3e-4" iyy="1.3e-4" izz="2.5e-4"
    ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><cylinder radius="0.05" length="0.02"/></geometry></collision></link>"""
    return f"""<?xml version="1.0"?>
<robot name="dd">
  <link name="base_footprint"/>
  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>
    <origin xyz="0 0 0.05"/></joint>
  <link name="base_link"><inertial><mass value="2.0"/><inertia ixx="0.01" iyy="0.012" izz="0.02" ixy="0"
    ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.03"/><geometry>{chassis}</geometry></collision></link>
  {wheels}
  {casters}
  {tail}
</robot>
"""


def _geoms_of(model: mujoco.MjModel, body: str) -> list[int]:
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    assert b >= 0, body
    return [g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_contype[g]]


def test_gazebo_friction_in_the_value_attribute_form_is_read(tmp_path):
    """MiR's URDF writes ``<mu1 value="200"/>`` (Gazebo's URDF parser takes the ``value`` attribute before the
    text); it was dropped without a word, and the wheels and casters kept MuJoCo's default μ = 1."""
    tail = """
  <gazebo reference="caster_front"><mu1 value="0.0"/><mu2 value="0.0"/><kp value="1e7"/></gazebo>
  <gazebo reference="caster_back"><mu1 value="0.3"/><mu2 value="0.4"/></gazebo>"""
    path = tmp_path / "dd.urdf"
    path.write_text(_urdf(tail))
    spec, layout, _, _ = prepare_robot(RobotRef(str(path)))
    model = spec.compile()
    for link, mu in (("caster_front", 0.0), ("caster_back", 0.3)):
        geoms = _geoms_of(model, link)
        assert geoms and all(model.geom_friction[g, 0] == pytest.approx(mu) for g in geoms), link
    notes = " | ".join(layout.import_notes)
    assert "link 'caster_back': sliding friction 0.3 from <gazebo> mu1" in notes and "mu2 0.4 not used" in notes
    assert "reference 'caster_front': kp" in notes  # the rest of the block is still said to be ignored


def test_urdf_overlaps_that_do_not_collide_are_named_but_not_a_warning(tmp_path):
    """MiR's caster wheels sit 35–66 mm inside its chassis mesh: with URDF self-collision off (Gazebo's
    convention) that overlap exerts nothing, yet robot check warned that the bodies 'touch at rest' with
    kilonewtons and told the user to exclude a pair that is already excluded."""
    swivel = """
  <joint name="swivel_joint" type="continuous"><parent link="base_link"/><child link="swivel"/>
    <origin xyz="0.2 0 -0.02"/><axis xyz="0 0 1"/></joint>
  <link name="swivel"><inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0"
    iyz="0"/></inertial></link>
  <joint name="roller_joint" type="continuous"><parent link="swivel"/><child link="roller"/>
    <origin xyz="-0.02 0 -0.015"/><axis xyz="0 1 0"/></joint>
  <link name="roller"><inertial><mass value="0.01"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0"
    iyz="0"/></inertial><collision><geometry><sphere radius="0.015"/></geometry></collision></link>"""
    path = tmp_path / "dd.urdf"
    # the chassis' bottom 10 mm above the floor, the swivel caster's roller (0 to 30 mm) 20 mm inside it
    path.write_text(_urdf(swivel, chassis='<box size="0.4 0.2 0.14"/>'))
    rep = check(RobotRef(str(path)), identify_=False)
    pairs = {(c["body1"], c["body2"]): c for c in rep["self_contacts"]}
    assert set(pairs) == {("base_link", "roller")}
    assert all(c["simulated"] is False and c["depth_m"] == pytest.approx(0.02, abs=2e-3) for c in pairs.values())
    assert not any("touch at rest" in r for r in rep["reasons"])
    said = [n for n in rep["notes"] if "'base_link' and 'roller'" in n]
    assert len(said) == 1 and "not collided in the scene: self-collision off" in said[0], rep["notes"]


CHASSIS_HX, CHASSIS_HY, PAYLOAD_X = 0.2, 0.15, -0.05


def _flat_chassis_mjcf(chassis: str) -> str:
    """Wheels (spheres r = 0.05 m) at x = 0, y = ±0.17 m; a 2 kg chassis whose bottom is 5 mm above the floor
    and reaches x = ±0.2 m; a 1 kg payload (no collision) 5 cm behind the axle: the centre of mass is behind
    the axle, the chassis' rear edge is what it rests on (a Fetch Freight's base mesh, a skid plate)."""
    return f"""<mujoco><worldbody><body name="base" pos="0 0 0">
  {chassis}
  <geom type="sphere" size="0.01" pos="{PAYLOAD_X} 0 0.05" mass="1" contype="0" conaffinity="0"/>
  <body name="lw" pos="0 0.17 0.05"><joint name="left_wheel" type="hinge" axis="0 1 0"/>
    <geom type="sphere" size="0.05" mass="0.2"/></body>
  <body name="rw" pos="0 -0.17 0.05"><joint name="right_wheel" type="hinge" axis="0 1 0"/>
    <geom type="sphere" size="0.05" mass="0.2"/></body>
</body></worldbody>
<actuator><motor joint="left_wheel" ctrlrange="-1 1" gear="1"/><motor joint="right_wheel" ctrlrange="-1 1"/>
</actuator></mujoco>"""


@pytest.mark.parametrize("kind", ["box", "mesh"])
def test_a_chassis_near_the_floor_supports_at_its_edges_not_its_centre(tmp_path, kind):
    """The support of the tip-over margins took each near-floor geom's centre: a chassis (box or mesh)
    centred on the axle counted as a point at the axle, and a Freight whose centre of mass is 3 mm behind
    the axle came out 'statically unstable (forward)' while it rests on its chassis' rear edge."""
    z = 0.025  # chassis centre; half height 0.02: its bottom 5 mm above the floor (the wheels' bottom)
    if kind == "box":
        chassis = f'<geom type="box" size="{CHASSIS_HX} {CHASSIS_HY} 0.02" pos="0 0 {z}" mass="2"/>'
        assets = ""
    else:
        box_stl(tmp_path / "chassis.stl", CHASSIS_HX, CHASSIS_HY, 0.02)
        chassis = f'<geom type="mesh" mesh="chassis" pos="0 0 {z}" mass="2"/>'
        assets = '<asset><mesh name="chassis" file="chassis.stl"/></asset>'
    path = tmp_path / "flat.xml"
    path.write_text(_flat_chassis_mjcf(chassis).replace("<worldbody>", assets + "<worldbody>", 1))
    spec, _, _, _ = prepare_robot(RobotRef(str(path), tau_max=1.0))
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    prefix = model.body(1).name.split("/")[0] + "/" if "/" in model.body(1).name else ""
    tips = tip_margins(model, data, prefix)
    m = 2.0 + 1.0 + 0.4
    cx = PAYLOAD_X * 1.0 / m  # the chassis and the wheels are centred on the axle
    h = (2.0 * z + 1.0 * 0.05 + 0.4 * 0.05) / m  # above the floor (the wheels' bottom, z = 0)
    assert tips["support_m"]["x_rear"] == pytest.approx(-CHASSIS_HX, abs=1e-6)
    assert tips["support_m"]["x_front"] == pytest.approx(CHASSIS_HX, abs=1e-6)
    assert tips["tip_accel_mps2"]["forward"] == pytest.approx(G * (cx + CHASSIS_HX) / h, rel=1e-5)
    assert tips["tip_accel_mps2"]["backward"] == pytest.approx(G * (CHASSIS_HX - cx) / h, rel=1e-5)
    assert tips["tip_accel_mps2"]["lateral"] == pytest.approx(G * 0.17 / h, rel=1e-5)  # the wheels, wider


def test_a_robot_still_moving_after_the_settle_is_said(tmp_path):
    """Hello Robot's Stretch MJCF at qpos0 has its wrist inside the base: the self contact bounces it, and the
    'floor contacts at rest' were a snapshot (one wheel 342 N, the other and the caster 0 N, of 284 N) that
    nothing flagged. ``not_at_rest`` says so; a robot that stands still gets ''. Gravcomp bodies (the
    Stretch's lift and arm) weigh nothing on the floor."""
    from bioform_mj.plants.mujoco.plant import MujocoPlant
    from bioform_mj.robots.contacts import floor_contacts, not_at_rest

    path = tmp_path / "flat.xml"
    chassis = f'<geom type="box" size="{CHASSIS_HX} {CHASSIS_HY} 0.02" pos="0 0 0.025" mass="2"/>'
    path.write_text(_flat_chassis_mjcf(chassis))
    plant = MujocoPlant([RobotRef(str(path), tau_max=1.0)], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    model, data, lay = plant.model, plant.data, plant.layouts[0]
    for k in range(200):
        plant.step(np.zeros((1, 2)), k * 0.001)
    base = model.body(lay.base).id
    floor = floor_contacts(model, data, lay, "f1/")
    assert not_at_rest(model, data, base, floor, 0.2) == ""
    assert sum(c["load_n"] for c in floor) == pytest.approx(3.4 * G, rel=0.02)
    free = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    data.qvel[model.jnt_dofadr[free]] = 0.1  # the base sliding forward at 0.1 m/s
    mujoco.mj_forward(model, data)
    said = not_at_rest(model, data, base, floor, 0.2)
    assert "not at rest after the 0.2 s settle" in said and "0.1 m/s" in said
    data.qvel[model.jnt_dofadr[free]] = 0.0
    mujoco.mj_forward(model, data)
    assert model.body_mass[base] == pytest.approx(3.0)  # chassis 2 kg and payload 1 kg are the base's geoms
    model.body_gravcomp[base] = 1.0  # the 3 kg base held by gravcomp: the floor should carry the wheels' 0.4 kg
    said = not_at_rest(model, data, base, floor, 0.2)
    assert f"of the {0.4 * G:.4g} N it holds at rest" in said and "gravcomp holds" in said


@pytest.mark.parametrize("legacy", ["<legacyMode>true</legacyMode>", ""])
def test_gazebo_plugin_wheels_on_the_wrong_side_are_swapped_by_the_geometry(tmp_path, legacy):
    """A Pioneer 3-DX URDF (mario-serna/pioneer_p3dx_model) names ``leftJoint`` the right wheel: the ROS 1
    diff-drive plugin's legacyMode (its default when the tag is missing) drives leftJoint as the right
    wheel. The import took the names as sides and every check ended 'left_wheel … is not to the left'."""

    def plugin(left: str, right: str) -> str:
        return f"""
  <gazebo><plugin name="differential_drive_controller" filename="libgazebo_ros_diff_drive.so">
    <leftJoint>{left}</leftJoint><rightJoint>{right}</rightJoint>{legacy}<wheelTorque>5</wheelTorque>
  </plugin></gazebo>"""

    path = tmp_path / "dd.urdf"
    path.write_text(_urdf(plugin("wheel_right_joint", "wheel_left_joint")))
    rep = check(RobotRef(str(path)), identify_=False)
    assert rep["parts"]["wheel_joints"] == ["wheel_left_joint", "wheel_right_joint"]
    said = [n for n in rep["notes"] if "wheels from the Gazebo diff-drive plugin" in n]
    assert len(said) == 1 and "its leftJoint 'wheel_right_joint' is the right wheel" in said[0]
    path.write_text(_urdf(plugin("wheel_left_joint", "wheel_right_joint")))  # named as they are: kept
    rep = check(RobotRef(str(path)), identify_=False)
    assert rep["parts"]["wheel_joints"] == ["wheel_left_joint", "wheel_right_joint"]
    assert not any("is the right wheel" in n for n in rep["notes"])


class _Kicked:
    """A one-robot plant whose base is pushed sideways at 5 cm/s until ``until`` s (None: always)."""

    def __init__(self, plant, until: float | None):
        self.plant, self.until = plant, until
        self.model, self.data = plant.model, plant.data
        free = next(j for j in range(self.model.njnt) if self.model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
        self.dof = int(self.model.jnt_dofadr[free]) + 1  # world y

    def step(self, tau, t):
        if self.until is None or t < self.until:
            self.data.qvel[self.dof] = 0.05
        self.plant.step(tau, t)


def test_a_robot_moving_at_0_2_s_is_settled_longer_then_said(tmp_path):
    """robot check's settle: 0.2 s, then 0.1 s more at a time while the robot moves (a Pioneer 3-DX on its
    caster: 73 N of 55 N at 0.2 s, at rest at 0.3 s), up to 1 s; a robot still moving then is said."""
    from bioform_mj.plants.mujoco.plant import MujocoPlant
    from bioform_mj.robots.contacts import settle

    path = tmp_path / "flat.xml"
    path.write_text(_flat_chassis_mjcf(f'<geom type="box" size="{CHASSIS_HX} {CHASSIS_HY} 0.02" pos="0 0 0.025"/>'))
    ticks = []
    for until, steps, moving in ((None, 1000, True), (0.25, 300, False), (0.1, 200, False)):
        plant = MujocoPlant([RobotRef(str(path), tau_max=1.0)], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
        got, floor, why = settle(_Kicked(plant, until), plant.layouts[0], lambda: ticks.append(1))
        assert got == steps and bool(why) == moving, (until, got, why)
        if moving:
            assert "not at rest after the 1 s settle" in why and "the base moves at 0.05" in why
        else:
            assert sum(c["load_n"] for c in floor) == pytest.approx(float(plant.params[0].mass) * G, rel=0.05)
    assert len(ticks) == (1000 + 300 + 200) // 10


def test_placeholder_inertias_are_said_with_their_share(tmp_path):
    """The Pioneer 3-DX URDF gives a 10 g top plate and a 0.1 g sonar ``ixx = iyy = izz = 1`` kg·m² (radii of
    gyration 10 m and 100 m on a robot 0.5 m across): 2 of its 3.16 kg·m² yaw inertia, so b_eff is a third of
    the robot's, without a word. The same diff drive without them says nothing."""
    path = tmp_path / "dd.urdf"
    path.write_text(_urdf())
    assert not any("implausible inertias" in r for r in check(RobotRef(str(path)), identify_=False)["reasons"])
    sonar = """
  <joint name="sonar_joint" type="fixed"><parent link="base_link"/><child link="sonar"/>
    <origin xyz="0.15 0 0.06"/></joint>
  <link name="sonar"><inertial><mass value="0.0001"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0"
    iyz="0"/></inertial></link>"""
    path.write_text(_urdf(sonar))
    rep = check(RobotRef(str(path)), identify_=False)
    said = [r for r in rep["reasons"] if "implausible inertias" in r]
    assert len(said) == 1 and "'sonar' 0.0001 kg, 1 kg·m² (100 m)" in said[0], said
    # yaw inertia: 1 of the sonar + the rest (chassis 0.02, wheels 2 (1.3e-4 + 0.2 · 0.12²), casters 2 (4e-6 +
    # 0.05 · 0.12²), about the centre of mass on the axle midpoint by symmetry; the sonar's 0.1 g moves it 4 µm)
    rest = 0.02 + 2 * (1.3e-4 + 0.2 * 0.12**2) + 2 * (4e-6 + 0.05 * 0.12**2)
    assert f"({100 * 1 / (1 + rest):.0f} % of the yaw inertia, 0 % of the wheels' spin inertia I_w)" in said[0]
    assert rep["yaw_inertia_kgm2"] == pytest.approx(1 + rest, rel=1e-3)


def test_a_caster_mapped_on_a_driven_wheel_is_refused(tmp_path, capsys):
    """``--caster l_wheel_link`` on the Freight was taken: the wheel's published mesh (off for contacts, the
    scene rolls the wheel on its proxy) was made frictionless with a note, and the check ran as if nothing was
    wrong. A caster on a driven wheel's body is bad input: one error line, exit 2, nothing written."""
    from bioform_mj.cli import main as cli

    path = tmp_path / "dd.urdf"
    path.write_text(_urdf())
    out = tmp_path / "check.json"
    assert cli.main(["robot", "check", str(path), "--caster", "wheel_left", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "driven wheel body 'wheel_left'" in err[0], err
    assert str(path) in err[0] and not out.exists()
    assert cli.main(["robot", "check", str(path), "--caster", "caster_back", "--json", str(out)]) in (0, 4)
    assert out.exists()


def test_a_gazebo_mu_above_the_floors_is_the_floors(tmp_path):
    """MiR's URDF gives its driven wheels Gazebo ``mu1 200`` (ODE takes the smaller mu of a pair: the floor's).
    Applied with priority, 200 won every pair, beat the friction patches of a fault scenario, and in MuJoCo's
    pyramidal cone left the wheels of a base on four level supports with almost no normal load (MiR: 0 N of
    850 N; the check said 'the wheels do not stand on the floor'). Now the wheels keep the floor's μ 1 and
    no priority; a mu below the floor's (a caster's 0.3) still wins by priority."""
    from bioform_mj.robots.layout import CONTACT_PRIORITY

    tail = """
  <gazebo reference="wheel_left"><mu1>200</mu1><mu2>200</mu2></gazebo>
  <gazebo reference="wheel_right"><mu1 value="200"/><mu2 value="200"/></gazebo>
  <gazebo reference="caster_back"><mu1>0.3</mu1></gazebo>"""
    path = tmp_path / "dd.urdf"
    path.write_text(_urdf(tail))  # the casters' bottoms are level with the wheels': four supports
    spec, layout, _, _ = prepare_robot(RobotRef(str(path)))
    model = spec.compile()
    for link, mu, prio in (("wheel_left", 1.0, 0), ("wheel_right", 1.0, 0), ("caster_back", 0.3, CONTACT_PRIORITY)):
        geoms = _geoms_of(model, link)
        assert geoms and all(model.geom_friction[g, 0] == pytest.approx(mu) for g in geoms), link
        assert all(model.geom_priority[g] == prio for g in geoms), link
    notes = " | ".join(layout.import_notes)
    assert "link 'wheel_left': sliding friction 200 from <gazebo> mu1" in notes and "at or above the floor's 1" in notes
    rep = check(RobotRef(str(path)), identify_=False)
    weight = rep["mass_kg"] * G
    wheels = [c["load_n"] for c in rep["floor_contacts"] if c["role"] == "wheel"]
    assert len(wheels) == 2 and min(wheels) > 0.1 * weight, rep["floor_contacts"]  # 4.3 N each of 24.5 N (μ 200: ~0)
    assert sum(c["load_n"] for c in rep["floor_contacts"]) == pytest.approx(weight, rel=0.02)


def test_a_dropped_visual_mesh_leaves_no_machine_path_in_the_runs_scene(tmp_path, monkeypatch):
    """The Pioneer 3-DX and Freight copies have no visual meshes: the import drops them with a note, which a
    run's scene.xml keeps (the robot's layout text); it said 'no file /abs/path/…' (issue 18 item 7: no
    absolute path of the machine but the asset paths). The note gives the path from the URDF's folder."""
    from bioform_mj.cli import main as cli

    deco = """
  <joint name="deco_joint" type="fixed"><parent link="base_link"/><child link="deco"/></joint>
  <link name="deco"><visual><geometry><mesh filename="meshes/gone.stl"/></geometry></visual></link>"""
    (tmp_path / "robot").mkdir()
    path = tmp_path / "robot" / "dd.urdf"
    path.write_text(_urdf(deco))
    _, layout, _, _ = prepare_robot(RobotRef(str(path)))
    said = [n for n in layout.import_notes if "visual mesh(es) dropped" in n]
    assert len(said) == 1 and "'meshes/gone.stl' of link 'deco' (no file meshes/gone.stl)" in said[0], said
    assert str(tmp_path) not in " ".join(layout.import_notes)
    (tmp_path / "sc.toml").write_text(
        'name = "dd"\n[sim]\nduration = 0.05\n[plant]\nkind = "mujoco"\nrobots = ["robot/dd.urdf"]\n'
    )
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "sc.toml", "--quiet", "--out", str(tmp_path / "run")]) == 0
    assert str(tmp_path) not in (tmp_path / "run" / "scene.xml").read_text()
