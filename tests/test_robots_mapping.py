"""Issue 10: any differential-drive robot as it is published (an MJCF file plus a mapping).

Numbers, not smoke: flipped wheel axes identify the same ``a_eff, b_eff``; damping and
armature: formula and identification within 3 %; a base origin off the axle: pose and ``υ``
are the axle midpoint's (checked against a MuJoCo site there); bad mappings exit 2 naming
the element and the file, writing nothing.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.assess.check import EXIT_FAIL, check
from bioform_mj.assess.feasibility import feasibility
from bioform_mj.assess.identify import identify
from bioform_mj.cli import main as cli
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.params import robot_truth
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef, models_dir
from bioform_mj.scenario.loader import load

DATA = Path(__file__).parent / "data"
TP_FILE = DATA / "thirdparty_base.xml"
TP = RobotRef(str(TP_FILE), base="base_link", left_wheel="joint_left_wheel", right_wheel="joint_right_wheel")
TP_FLAGS = ["--base", "base_link", "--left-wheel", "joint_left_wheel", "--right-wheel", "joint_right_wheel"]


def _flipped_paper(tmp_path: Path) -> Path:
    src = (models_dir() / "paper_robot.xml").read_text()
    assert '<joint type="hinge" axis="0 1 0"' in src
    out = tmp_path / "flipped.xml"
    out.write_text(src.replace('<joint type="hinge" axis="0 1 0"', '<joint type="hinge" axis="0 -1 0"'))
    return out


def test_flipped_wheel_axes_identify_the_same_a_b(tmp_path):
    flipped = _flipped_paper(tmp_path)
    lay = prepare_robot(flipped)[1]
    assert lay.wheel_sign == (-1, -1) and any("gear −1" in n for n in lay.notes)
    orig, flip = identify("paper"), identify(str(flipped))
    for k in ("a", "b"):
        assert flip["formula"][k] == pytest.approx(orig["formula"][k], rel=1e-12)
        assert flip["identified"][k] == pytest.approx(orig["identified"][k], rel=1e-9)  # measured: equal to 1e-15
        assert flip["identified"][k] > 0
    # positive torque drives forward on both
    plant = MujocoPlant(["paper", str(flipped)], np.array([[0.0, 0, 0], [0, 2, 0]]), 0.001, 0.001)
    for k in range(200):
        plant.step(np.full((2, 2), 1.0), k * 0.001)
    _, vel = plant.observe()
    assert vel[0, 0] > 0.07 and vel[1, 0] == pytest.approx(vel[0, 0], rel=1e-9)
    assert np.all(plant._wheel_sign[1] == -1) and np.all(plant._wheel_sign[0] == 1)
    # the wheel rate contract: sign · qvel · r = forward speed while rolling
    rate = plant.data.qvel[plant._wheel_dof] * plant._wheel_sign * plant._wheel_radius[:, None]
    np.testing.assert_allclose(rate, vel[:, :1].repeat(2, axis=1), rtol=1e-3)


def test_third_party_mapping_found_as_published():
    spec, lay, axle_world, _ = prepare_robot(TP)
    assert lay.base == "base_link" and lay.wheel_joints == ("joint_left_wheel", "joint_right_wheel")
    assert lay.wheel_radius == pytest.approx(0.05, abs=1e-12)
    assert lay.half_track == pytest.approx(0.16, abs=1e-12)
    np.testing.assert_allclose(lay.axle, [0.1, 0.0, 0.05], atol=1e-12)
    assert lay.wheel_sign == (-1, -1)
    assert lay.tau_max == 4.0  # the joints' actuatorfrcrange
    assert set(lay.disabled_actuators) == {"drive_forward", "drive_turn"}
    model = spec.compile()
    for name in ("drive_forward", "drive_turn"):  # kept (a sensor names one) but without force
        assert np.all(model.actuator(name).gainprm == 0) and np.all(model.actuator(name).biasprm == 0)
    assert model.actuator("head_pan").gainprm[0] == 5  # other actuators as published
    assert model.nkey == 0
    assert model.geom("left_tire").contype[0] == 0 and model.geom("joint_left_wheel_contact").contype[0] == 1


def test_damping_and_armature_formula_vs_identification_within_3_percent():
    p = robot_truth(TP)
    # armature is in I_w: I_w = 0.001 (spin) + 0.0005 (armature)
    assert p.wheel_inertia == pytest.approx(0.0015, rel=1e-9)
    m, r, l = 12 + 2 * 0.8 + 0.3, 0.05, 0.16  # chassis, wheels, head
    assert p.a_eff == pytest.approx(1 / (m * r + 2 * 0.0015 / r), rel=1e-9)
    rep = identify(TP)
    assert abs(rep["relative_error"]["a"]) < 0.03 and abs(rep["relative_error"]["b"]) < 0.03
    # measured: a −0.9 %, b +0.2 %; the drag (joint damping 0.02 N·m·s/rad) within 5 %
    k_formula, k_id = rep["drag_rate_per_s"]["formula"], rep["drag_rate_per_s"]["identified"]
    np.testing.assert_allclose(k_id, k_formula, rtol=0.05)
    assert k_formula[0] == pytest.approx(2 * p.a_eff * 0.02 / r, rel=1e-12)
    assert k_formula[1] == pytest.approx(2 * p.b_eff * 0.02 * l / r, rel=1e-12)
    um = p.unmodelled(0.5, 1.0)
    assert um["drag_accel_at_speed"][0] == pytest.approx(k_formula[0] * 0.5)
    assert um["deadband_torque_Nm"] == [0.02, 0.02]


def test_base_origin_off_axle_pose_and_velocity_are_the_axle_midpoint():
    pose0 = np.array([[1.0, -2.0, 0.7]])
    plant = MujocoPlant([TP], pose0, 0.002, 0.002)
    m, d = plant.model, plant.data
    site = m.site("f1/axle_mid").id
    pose, vel = plant.observe()
    np.testing.assert_allclose(pose, pose0, atol=1e-9)  # placed by its axle midpoint
    np.testing.assert_allclose(d.site_xpos[site][:2], pose0[0, :2], atol=1e-9)
    rng = np.random.default_rng(5)
    worst_p = worst_v = 0.0
    for k in range(600):
        plant.step(rng.uniform(-0.2, 1.0, (1, 2)) * 1.5, k * 0.002)
        if k % 50 == 49:
            mujoco.mj_forward(m, d)
            pose, vel = plant.observe()
            sv = np.zeros(6)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, site, sv, 0)  # world frame [ang, lin]
            h = np.array([np.cos(pose[0, 2]), np.sin(pose[0, 2])])
            worst_p = max(worst_p, float(np.max(np.abs(pose[0, :2] - d.site_xpos[site][:2]))))
            worst_v = max(worst_v, abs(float(vel[0, 0] - sv[3:5] @ h)))
            assert vel[0, 1] == pytest.approx(sv[2], abs=1e-9)
    assert worst_p < 1e-9 and worst_v < 1e-9  # measured ~1e-16
    _, vel = plant.observe()
    assert vel[0, 0] > 0.1  # it did move


@pytest.mark.parametrize(
    "flags,what",
    [
        (["--base", "chassis"], "no body 'chassis'"),
        (["--left-wheel", "joint_head_pan"], "joint 'joint_head_pan' .*is not on a body below|not along"),
        (["--right-wheel", "no_such_joint"], "no joint 'no_such_joint'"),
        (["--left-wheel", "joint_right_wheel"], "same joint 'joint_right_wheel'"),
        (["--left-wheel", "base_free"], "joint 'base_free' .*is not a hinge"),
    ],
)
def test_bad_mapping_exits_2_naming_element_and_file(tmp_path, capsys, flags, what):
    base = dict(zip(TP_FLAGS[::2], TP_FLAGS[1::2]))
    base.update(dict(zip(flags[::2], flags[1::2])))
    argv = ["robot", "check", str(TP_FILE), *[x for kv in base.items() for x in kv], "--json", str(tmp_path / "r.json")]
    rc = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("error:") and "thirdparty_base.xml" in err[0]
    import re

    assert re.search(what, err[0]), err[0]
    assert not (tmp_path / "r.json").exists()


def test_no_collision_geom_and_no_radius_and_not_compiling_exit_2(tmp_path, capsys):
    src = TP_FILE.read_text()
    bare = tmp_path / "bare.xml"
    bare.write_text(src.replace('<geom name="left_tire" class="drive_wheel"/>', ""))
    assert cli.main(["robot", "check", str(bare), *TP_FLAGS]) == 2
    err = capsys.readouterr().err
    assert "bare.xml" in err and "joint_left_wheel" in err and "give --wheel-radius" in err  # the CLI's terms
    with pytest.raises(ValueError, match="give wheel_radius"):  # the Python API's: the key
        check(RobotRef(str(bare), "base_link", "joint_left_wheel", "joint_right_wheel"), identify_=False)
    # with a radius given, a proxy is added and the robot works
    rep = check(
        RobotRef(str(bare), "base_link", "joint_left_wheel", "joint_right_wheel", wheel_radius=0.05), identify_=False
    )
    assert rep["wheel_radius_m"] == pytest.approx(0.05)
    broken = tmp_path / "broken.xml"
    broken.write_text(src.replace("</worldbody>", ""))
    assert cli.main(["robot", "check", str(broken), *TP_FLAGS]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken.xml" in err[0] and "does not compile" in err[0]


def test_robot_check_json_and_verdicts(tmp_path, capsys):
    out = tmp_path / "check.json"
    assert cli.main(["robot", "check", str(TP_FILE), *TP_FLAGS, "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    for key in (
        "verdict",
        "a_eff",
        "b_eff",
        "a_identified",
        "b_identified",
        "traction_limit_nm",
        "motor_limit_nm",
        "tip_accel_mps2",
        "notes",
        "parts",
        "com_offset_m",
        "wheel_joints",
    ):
        assert key in rep
    assert rep["verdict"] == "warn"  # skids and tips at full torque, 2 cm CoM offset, damping
    assert rep["tip_accel_mps2"]["backward"] == pytest.approx(9.81 * 0.0205 / 0.1024, rel=0.02)
    # the caster carries part of the weight: traction μ N r / f with N the lighter wheel's load at rest and
    # f the share of torque past the rotor (design §13; here 0.92: armature 0.0005 + spin 0.001 kg·m²)
    f = max(rep["floor_fraction"].values())
    assert 0.85 < f < 0.95
    assert rep["traction_limit_nm"] == pytest.approx(min(rep["wheel_load_n"]) * 0.05 / f, rel=1e-9)
    assert 0.5 < rep["weight_on_wheels"] < 1.0  # statics: (0.25 - 0.0205) / 0.25 = 0.92 of 13.9 kg
    assert rep["weight_on_wheels"] == pytest.approx(0.92, abs=0.02)
    assert rep["motor_limit_nm"] == 4.0
    assert cli.main(["robot", "check", "paper"]) == 0
    assert "pass:" in capsys.readouterr().out
    # no rear caster: the centre of mass (2 cm behind the axle) has no support behind it
    tipsy = tmp_path / "tipsy.xml"
    tipsy.write_text(
        TP_FILE.read_text().replace('<geom name="rear_caster" class="caster_tp" pos="-0.15 0 0.025"/>', "")
    )
    assert cli.main(["robot", "check", str(tipsy), *TP_FLAGS]) == EXIT_FAIL
    assert "statically unstable" in capsys.readouterr().err


def test_identify_cli_takes_the_mapping(capsys):
    assert cli.main(["identify", str(TP_FILE), *TP_FLAGS]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["identified"]["a"] > 0 and rep["identified"]["b"] > 0


def test_toml_paths_are_relative_to_the_file(tmp_path, monkeypatch):
    sub = tmp_path / "cfg"
    sub.mkdir()
    (sub / "robot.xml").write_text((models_dir() / "lab_robot.xml").read_text())
    (sub / "s.toml").write_text(
        '[plant]\nkind = "mujoco"\nrobots = ["robot.xml", {model = "robot.xml", base = "base"}, "lab"]\n'
    )
    monkeypatch.chdir(tmp_path)  # not the file's directory
    sc = load(str(sub / "s.toml"))
    assert [Path(r.model) for r in sc.plant.robots[:2]] == [(sub / "robot.xml").resolve()] * 2
    assert sc.plant.robots[2].model == "lab"
    cfg = sc.to_dict()["plant"]["robots"]
    assert cfg[0] == str((sub / "robot.xml").resolve()) and cfg[1]["base"] == "base" and cfg[2] == "lab"


def test_robots_on_the_ideal_plant_give_c_true():
    sc = load("paper", overrides=["plant.robots=['lab']"])
    lab = robot_truth("lab")
    np.testing.assert_allclose(sc.plant.c_true, lab.c, rtol=1e-12)
    assert sc.plant.mass == pytest.approx(lab.mass_eff) and sc.plant.inertia == pytest.approx(lab.inertia_eff)
    assert load("paper").plant.c_true == (0.4, 10.0)  # the paper robot: as given
    assert load("paper", overrides=["plant.c_true=[1.0, 5.0]"]).plant.c_true == (1.0, 5.0)
    from bioform_mj.core.errors import ScenarioError

    with pytest.raises(ScenarioError, match="one c_true"):
        load("hetero", plant="ideal")
    with pytest.raises(ScenarioError, match="disagrees with plant.robots"):
        load("paper", overrides=["plant.robots=['lab']", "plant.c_true=[1.0, 5.0]"])


def test_feasibility_warns_about_a_robot_that_tips():
    sc = load(
        "paper",
        plant="mujoco",
        overrides=["formation.initial_poses=[[0,0,0]]", "formation.offsets=[[3,0]]", "graph.edges=[]"],
    )
    plant = MujocoPlant([TP], sc.initial_poses(), 0.002, 0.002)
    warn = feasibility(sc, plant)
    assert any("start-up transient" in w and "tip" in w for w in warn)
    assert any("traction limit" in w for w in warn)
    assert feasibility(sc, MujocoPlant(["paper"], sc.initial_poses(), 0.001, 0.001)) == []


def test_a_mapped_size_far_from_the_geometry_is_said_not_a_crash():
    """wheel_radius mapped 40 % above the paper robot's wheels: the run used to crash in the tip-over
    estimate (no geom reached the floor that radius implies). Now: a pre-run warning naming both
    values, and the run reports the wheels as slipping (their rate × the given radius is not the
    chassis speed), never silently."""
    from bioform_mj.run.simulate import make_plant, simulate

    ov = ["plant.kind=mujoco", "sim.duration=0.6", 'plant.robots=[{model="paper", wheel_radius=0.14}]']
    res = simulate(load("paper", overrides=ov))
    feas = res.summary["feasibility_warnings"]
    assert any("wheel_radius 0.14 m given; the collision geoms say 0.1 m (+40%)" in w for w in feas), feas
    assert [f["outcome"] for f in res.summary["followers"]] == ["slipping"] * 3
    # within 5 %: the mapping is taken as a correction, no warning
    ov[-1] = 'plant.robots=[{model="paper", wheel_radius=0.103}]'
    sc = load("paper", overrides=ov)
    assert not any("given" in w for w in feasibility(sc, make_plant(sc)))


@pytest.mark.parametrize("preset,robot", [("tb3", "tb3"), ("stretch", "stretch")])
def test_shipped_robot_scaled_paper_scenario_holds_formation(preset, robot):
    """Each shipped robot's scaled paper scenario holds its formation within 0.1 m in MuJoCo, upright.

    Measured (20 s): tb3 final errors 3.8-4.6 mm, c_hat within 7 %; stretch 6-7.5 mm, b_hat 13-15 % low
    (centre of mass 4 cm behind the axle, design §8.1)."""
    from bioform_mj.run.simulate import simulate

    sc = load(preset, overrides=["sim.duration=12"])
    assert sc.plant.kind == "mujoco" and sc.formation.scale < 1
    res = simulate(sc)
    assert res.diverged is None
    assert feasibility(sc, res.plant) == []
    final = [f["final_formation_error_m"] for f in res.summary["followers"]]
    assert max(final) < 0.1, final  # measured < 1 cm
    assert np.min(res.plant.upright()) > np.cos(res.plant.TIP_ANGLE)
    np.testing.assert_allclose(
        res.plant.c_true()[0], robot_truth(robot if preset != "tb3" else RobotRef("tb3", tau_max=0.05)).c, rtol=1e-6
    )


def test_scale_maps_lengths_and_keeps_times():
    p, s = load("paper"), load("paper", overrides=["formation.scale=0.1"])
    assert s.leader.speed == pytest.approx(0.1 * p.leader.speed) and s.leader.frequency == p.leader.frequency
    np.testing.assert_allclose(s.formation.offsets, 0.1 * np.array(p.formation.offsets))
    np.testing.assert_allclose(
        np.array(s.formation.initial_poses)[:, :2], 0.1 * np.array(p.formation.initial_poses)[:, :2]
    )
    assert s.kinematic.k2 == pytest.approx(p.kinematic.k2 / 0.01) and s.kinematic.k1 == p.kinematic.k1
    assert s.disturbance.bias[0] == pytest.approx(0.1 * p.disturbance.bias[0])
    from bioform_mj.core.errors import ScenarioError

    with pytest.raises(ScenarioError, match="formation.scale"):
        load("paper", overrides=["formation.scale=-1"])


def test_a_robot_the_scenario_overturns_is_reported_tipped_at_the_moment_it_tips():
    """tb3 in the unscaled paper scenario: the start-up transient at its motor limit tips it.
    The outcome names the time; it lies within 0.1 s of the first control step at which the
    chassis tilt (measured every step by an observer of the step-by-step loop) crossed 30°."""
    import math

    from bioform_mj.core.thresholds import TIP_ANGLE_DEG
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    sc = load("paper", plant="mujoco", overrides=['plant.robots=["tb3"]', "sim.duration=0.5"])

    class Tilt:
        period = sc.sim.control_dt

        def __init__(self):
            self.rows = []

        def start(self, run):
            pass

        def sample(self, run):
            self.rows.append((run.t, run.plant._up.copy()))

        def finish(self, run):
            pass

    probe = Tilt()
    ref = simulate(sc, [probe], engine="stepwise")
    fast = simulate(sc)
    cos_lim = math.cos(math.radians(TIP_ANGLE_DEG))
    for i, f in enumerate(fast.summary["followers"]):
        crossed = [t for t, up in probe.rows if up[i] < cos_lim]
        assert crossed, "the scenario must overturn every tb3 (measured: 0.15-0.2 s)"
        assert f["outcome"] == "tipped"
        t_reported = float(f["outcome_detail"].split("t = ")[1].split(" s")[0])
        assert abs(t_reported - crossed[0]) <= 0.1
        assert ref.summary["followers"][i]["outcome_detail"] == f["outcome_detail"]  # both loops agree


# ---------------------------------------------------------------- published-model traits (menagerie)
# Written for these tests (not a copy of any published file): the traits met when taking
# mujoco_menagerie's Hello Robot Stretch 3 and Clearpath Jackal as published: unnamed wheel
# collision geoms and unnamed wheel drives, wheel damping 30 N·m·s/rad with frictionloss 1 N·m and
# stiffness 0.02 N·m/rad at the model's 2 ms step, and (Jackal) a second pair of fixed wheels.
_PUBLISHED = """
<mujoco model="published_traits">
  <compiler angle="radian" autolimits="true"/>
  <option integrator="implicitfast" timestep="0.002"/>
  <default>
    <geom solref="0.005 1"/>
    <default class="wheel">
      <joint axis="0 0 1" damping="30" frictionloss="1" armature="0.1" stiffness="0.02"/>
      <velocity gear="3" kv="100" ctrlrange="-6 6" forcerange="-100 100"/>
    </default>
  </default>
  <worldbody>
    <body name="base_link">
      <freejoint/>
      <geom type="box" size="0.15 0.15 0.06" pos="-0.02 0 0.12" mass="20"/>
      <geom type="sphere" size="0.02" pos="-0.2 0 0.02" condim="1" priority="1"/>
      <body name="link_right_wheel" pos="0 -0.17 0.05" quat="1 -1 0 0">
        <joint name="joint_right_wheel" class="wheel"/>
        <geom type="cylinder" size="0.05 0.0125" mass="0.5"/>
      </body>
      <body name="link_left_wheel" pos="0 0.17 0.05" quat="1 -1 0 0">
        <joint name="joint_left_wheel" class="wheel"/>
        <geom type="cylinder" size="0.05 0.0125" mass="0.5"/>
      </body>
      EXTRA
    </body>
  </worldbody>
  <actuator>
    <velocity joint="joint_left_wheel" class="wheel"/>
    <velocity joint="joint_right_wheel" class="wheel"/>
  </actuator>
</mujoco>
"""
_REAR = """
      <body name="rear_wheel_link" pos="-0.2 0.17 0.05">
        <joint name="rear_wheel" axis="0 1 0"/>
        <geom type="sphere" size="0.05" mass="0.5"/>
      </body>"""


def _published(tmp_path, extra=""):
    path = tmp_path / "published_traits.xml"
    text = _PUBLISHED.replace("EXTRA", extra)
    if extra:  # the rear wheel replaces the rear caster
        text = text.replace('<geom type="sphere" size="0.02" pos="-0.2 0 0.02" condim="1" priority="1"/>', "")
    path.write_text(text)
    return RobotRef(model=str(path), base="base_link", left_wheel="joint_left_wheel", right_wheel="joint_right_wheel")


def test_published_traits_unnamed_parts_and_strong_damping(tmp_path):
    """Unnamed wheel geoms and drives no longer crash (was: AttributeError, exit 1); identification
    clears the dead band and integrates the damping finely (was: a = 3.9e-6, then +86 % at the
    model's own 2 ms step); check and feasibility say what the paper's model lacks."""
    ref = _published(tmp_path)
    spec, lay, _, _ = prepare_robot(ref)
    model = spec.compile()
    assert lay.wheel_geoms == ("joint_left_wheel_contact", "joint_right_wheel_contact")
    assert len(lay.disabled_actuators) == 2 and all(n.startswith("#") for n in lay.disabled_actuators)
    assert model.actuator("left_motor").id >= 0
    d = identify(ref)
    # both torque levels clear the dead band (was: a = 3.9e-6 on the menagerie Stretch 3) and the
    # damping is integrated at k dt = 0.02; the dead band is found exactly. OPEN: on this fixture a, b
    # still come out 25 % / 16 % low (the stripped menagerie Stretch 3 itself: +0.9 %, +3.5 %): the
    # 4 ms drag against the soft contact is not the first-order model the fit assumes
    assert 0.6 < d["identified"]["a"] / d["formula"]["a"] < 1.1
    assert d["deadband_torque_Nm"]["identified"][0] == pytest.approx(2.0, rel=0.03)
    assert d["test"]["timestep_s"] < 0.002
    rep = check(ref)
    assert rep["verdict"] != "pass"  # fail here: identification 25 % off (see OPEN above)
    assert any("k dt" in r for r in rep["reasons"]) and any("stiffness" in r for r in rep["reasons"])
    # cruising at the stretch preset leader's peak wheel ground speed (0.25 × the paper leader, its turn rate kept:
    # max 0.25 √(1 + 0.16 cos² t) + l 0.4 |sin t| / (1 + 0.16 cos² t) by hand, above its 0.269 m/s) the wheels' own
    # dampers absorb 30 v / 0.05 + 1 N·m per wheel: within the 300 N·m motors (it blamed the 22.5 N·m traction
    # limit, which that torque never reaches: issue 27), beyond a 100 N·m one
    from test_assess_verdict_stance import _paper_wheel_speed

    plant = MujocoPlant([ref], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    assert not any("cannot keep up" in w for w in feasibility(load("stretch"), plant))
    weak = MujocoPlant([replace(ref, tau_max=100.0)], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    said = [w for w in feasibility(load("stretch"), weak) if "cannot keep up" in w]
    v_wheel = _paper_wheel_speed(0.25, weak.params[0].half_track)
    assert v_wheel > 0.25 * np.hypot(1, 0.4)
    assert (
        len(said) == 1
        and f"absorb {30 * v_wheel / 0.05 + 1:.3g} N·m per wheel, beyond the motor limit 100 N·m" in said[0]
    ), said


def test_published_traits_second_fixed_axle_fails_check(tmp_path):
    """A fixed wheel off the driven axle (4-wheel / skid-steer, the menagerie Jackal) is named and fails
    the check (was: fail only for 'identification 71 % off', with no word of the rear wheels)."""
    rep = check(_published(tmp_path, _REAR))
    assert rep["verdict"] == "fail"
    assert any("skid-steer" in r for r in rep["reasons"])
    assert any("other wheel 'rear_wheel'" in n for n in rep["notes"])
