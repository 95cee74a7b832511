"""Issue 27 item 7: verdicts that were wrong on published robots, each reproduced on a variant of the paper
robot written by the test, the expected numbers computed by hand from the file (design §14).

The paper robot: 24.5 kg, wheels r = 0.1 m at y = ±0.2 m on the axle through the centre of mass, two
spherical casters r = 0.025 m at x = ±0.13 m, 0.5 mm above the floor when level (``models/paper_robot.xml``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bioform_mj.assess.check import G, check
from bioform_mj.assess.feasibility import feasibility, run_refusals
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.level_support import statics_loads
from bioform_mj.robots.refs import models_dir
from bioform_mj.scenario.loader import load

PAPER = (models_dir() / "paper_robot.xml").read_text()
MASS = 24.5  # kg, the paper robot's (its header)


def _variant(tmp_path: Path, name: str, caster_z: str, mu: float | None = None) -> Path:
    """The paper robot with its casters at height ``caster_z`` (m, the file's −0.0745 is 0.5 mm above the
    floor; −0.075 is level with the wheels), and with sliding friction ``mu`` (condim 3) where given."""
    src = PAPER.replace('pos="0.13 0 -0.0745"', f'pos="0.13 0 {caster_z}"')
    src = src.replace('pos="-0.13 0 -0.0745"', f'pos="-0.13 0 {caster_z}"')
    if mu is not None:
        old = 'condim="1" priority="2" friction="0 0 0"'
        assert old in src
        src = src.replace(old, f'condim="3" priority="2" friction="{mu} 0 0"')
    out = tmp_path / f"{name}.xml"
    out.write_text(src)
    return out


def test_statics_of_a_stance_match_the_lever_rule():
    """Three supports are statically determinate: a caster at x = 0.13 m and wheels at y = ±0.2 m under a centre
    of mass at x = 0.03 m carry W·0.03/0.13 on the caster, the rest shared by the wheels; four level supports
    symmetric about the centre of mass carry W/4 each; a centre of mass outside the support leaves nothing."""
    w = 100.0
    f = statics_loads(np.array([[0.0, 0.2], [0.0, -0.2], [0.13, 0.0]]), np.array([0.03, 0.0]), w)
    caster = w * 0.03 / 0.13
    assert f == pytest.approx([(w - caster) / 2, (w - caster) / 2, caster], rel=1e-9)
    f4 = statics_loads(np.array([[0.0, 0.2], [0.0, -0.2], [0.13, 0.0], [-0.13, 0.0]]), np.zeros(2), w)
    assert f4 == pytest.approx([w / 4] * 4, rel=1e-9)
    # equal springs under a rigid plane: a centre of mass 0.05 m back leaves the front caster
    # W/4 − W·0.05·0.13/(2·0.13²) = 5.77 N; 0.1 m back it would pull (−13.5 N): dropped, and the rest is the
    # three-support lever rule, W·0.1/0.13 on the rear caster
    pts = np.array([[0.0, 0.2], [0.0, -0.2], [0.13, 0.0], [-0.13, 0.0]])
    assert statics_loads(pts, np.array([-0.05, 0]), w)[2] == pytest.approx(w / 4 - w * 0.05 / (2 * 0.13), rel=1e-9)
    f_back = statics_loads(pts, np.array([-0.1, 0]), w)
    assert f_back[2] == 0.0 and f_back[3] == pytest.approx(w * 0.1 / 0.13, rel=1e-9)
    assert f_back[0] == pytest.approx((w - w * 0.1 / 0.13) / 2, rel=1e-9)
    # outside every support (behind the rear caster): no stance carries it
    assert not statics_loads(pts, np.array([-0.2, 0]), w).any()


def test_casters_level_with_the_wheels_are_not_wheels_off_the_floor(tmp_path):
    """Casters level with the wheels, μ = 0.01: MuJoCo puts all the weight at rest on the casters (0 N on the
    wheels), which was a ``fail (structural)``: "the wheels do not stand on the floor". The statics of the four
    level supports give each W/4 (the centre of mass is on the axle, the casters symmetric), the drive test a
    within 3 % of the formula: the verdict is warn, naming the level stance; the traction limit is μ (W/4) r / f."""
    path = _variant(tmp_path, "level", "-0.075", mu=0.01)
    rep = check(str(path))
    assert rep["verdict"] == "warn", rep["reasons"]
    assert not any("do not stand on the floor" in r for r in rep["reasons"])
    level = rep["level_support"]
    assert level is not None and max(level["measured_n"]) < 0.02 * MASS * G  # what MuJoCo resolved at rest
    w = rep["weight_n"]
    assert level["statics_n"] == pytest.approx([w / 4, w / 4], rel=0.02)
    assert sorted(level["supports"]) == sorted(
        ["front_caster", "back_caster", "left_wheel_collision", "right_wheel_collision"]
    )
    assert any(r.startswith("level stance:") for r in rep["reasons"])
    assert rep["a_identified"] == pytest.approx(0.4, rel=0.03) and rep["b_identified"] == pytest.approx(10, rel=0.03)
    f = rep["floor_fraction"]["drive"]
    assert rep["traction_limit_nm"] == pytest.approx(1.0 * (w / 4) * 0.1 / f, rel=0.02)


def test_a_level_stance_is_not_refused_and_wheels_in_the_air_are(tmp_path, monkeypatch):
    """``bioform run``'s refusals: the level stance runs; casters 3 mm below the wheels' contact (the wheels
    in the air, r = 0.1 m) are refused — unless the robot check was told to skip: then a warning, the run goes
    ahead (design §14.2)."""
    sc = load(
        "paper",
        plant="mujoco",
        overrides=["formation.initial_poses=[[0,0,0]]", "formation.offsets=[[3,0]]", "graph.edges=[]"],
    )
    import mujoco

    level = MujocoPlant([str(_variant(tmp_path, "level", "-0.075", mu=0.01))], sc.initial_poses(), 0.001, 0.001)
    scratch = mujoco.MjData(level.model)
    mujoco.mj_kinematics(level.model, scratch)
    assert float(level.settled_wheel_loads().max()) < 0.02 * MASS * G  # the old evidence of "off the floor"
    assert run_refusals(level, scratch, level.settled_wheel_loads()) == []
    # nor do the pre-run warnings take MuJoCo's 0 N: no traction limit of 0 N·m, no caster that stops the robot
    # (the casters' μ N = 0.01 · 118 N = 1.2 N against min(2 τ_max f / r = 98 N, μ ΣN = μ W/2 = 120 N): 1 %)
    warned = feasibility(sc, level)
    assert not any("traction limit" in w for w in warned) and not any("cannot move" in w for w in warned), warned
    assert any("brakes the robot with μ N = 1.18 N, 1 % of what the wheels can push" in w for w in warned), warned
    air = MujocoPlant([str(_variant(tmp_path, "air", "-0.078"))], sc.initial_poses(), 0.001, 0.001)
    scratch = mujoco.MjData(air.model)
    mujoco.mj_kinematics(air.model, scratch)
    why = run_refusals(air, scratch, air.settled_wheel_loads())
    assert len(why) == 1 and "the wheels do not stand on the floor" in why[0]
    monkeypatch.delenv("BIOFORM_NO_ROBOT_CHECK", raising=False)
    from bioform_mj.core.errors import InputError

    with pytest.raises(InputError, match="do not stand on the floor"):
        feasibility(sc, air)
    monkeypatch.setenv("BIOFORM_NO_ROBOT_CHECK", "1")
    warned = feasibility(sc, air)
    assert any(w.startswith("robot check skipped (the run goes ahead); it would refuse") for w in warned), warned


def _cylinder_wheels(tmp_path: Path) -> Path:
    """The paper robot with cylinder tyres r = 0.1 m (a cylinder touches the floor at its rim edges: the scene
    replaces it by a single-contact proxy, design §8)."""
    src = PAPER
    for side in ("left", "right"):
        old = f'<geom name="{side}_wheel_collision"/>'
        assert old in src
        src = src.replace(old, f'<geom name="{side}_wheel_collision" type="cylinder" size="0.1 0.02" zaxis="0 1 0"/>')
    out = tmp_path / "cylinders.xml"
    out.write_text(src)
    return out


def test_a_mapped_radius_off_the_tyre_simulates_the_tyre_and_says_both(tmp_path):
    """Cylinder tyres r = 0.1 m, wheel_radius mapped 0.12 m (+20 %): the contact proxy was built at the mapped
    0.12 m, so the robot rolled as the mapping said while the notes said "the physics the model's". Now the
    proxy is the tyre's (0.1 m), the robot rolls at a = 1/(m r + 2 I_w/r) = 0.4 with r = 0.1, the formula of
    the mapping gives 1/(24.5·0.12 + 2·0.0025/0.12) = 0.3354 (a +19 % gap), and the check fails naming both radii."""
    import mujoco

    from bioform_mj.robots.prepare import prepare_robot
    from bioform_mj.robots.refs import RobotRef

    path = _cylinder_wheels(tmp_path)
    spec, lay, _, _ = prepare_robot(RobotRef(str(path), wheel_radius=0.12))
    model = spec.compile()
    for g in lay.wheel_geoms:
        gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g)
        assert int(model.geom_type[gid]) == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID)  # the proxy
        assert model.geom_size[gid, 0] == pytest.approx(0.1, rel=1e-6)  # the tyre's radius, not the mapped 0.12
    assert any("proxy of radius 0.1 m" in n for n in lay.notes)
    rep = check(RobotRef(str(path), wheel_radius=0.12))
    a_mapped = 1 / (24.5 * 0.12 + 2 * 0.0025 / 0.12)
    assert rep["a_eff"] == pytest.approx(a_mapped, rel=1e-3)
    assert rep["a_identified"] == pytest.approx(0.4, rel=0.03)  # the physics: the 0.1 m tyre
    assert rep["verdict"] == "fail"
    assert any("0.12 m" in r and "0.1 m" in r for r in rep["fail_reasons"]), rep["fail_reasons"]
    # unmapped, the proxy of the same tyre identifies as its formula
    plain = check(str(path))
    assert plain["a_identified"] == pytest.approx(plain["a_eff"], rel=0.03) and plain["a_eff"] == pytest.approx(0.4)


def _damped(tmp_path: Path, c: float, timestep: str = "0.002", mu: str = "1") -> Path:
    """The paper robot with wheel damping ``c`` N·m·s/rad (drag rates k_υ = 2 a c / r = 8 c, k_ω = 2 b c l / r
    = 40 c 1/s), its own step ``timestep`` s and wheel friction ``mu``."""
    src = PAPER.replace('damping="0" armature="0"', f'damping="{c}" armature="0"')
    src = src.replace('<option timestep="0.001"', f'<option timestep="{timestep}"')
    src = src.replace('friction="1 0.005 0.0001"', f'friction="{mu} 0.005 0.0001"')
    out = tmp_path / f"damped_{c}_{timestep}_{mu}.xml"
    out.write_text(src)
    return out


def test_a_robot_is_identified_at_the_step_the_run_simulates(tmp_path):
    """Wheel damping 13.9 N·m·s/rad (drag rates 111 and 556 1/s: a 9 ms time constant), the model's own step
    2 ms: identified at DRAG_STEP / 556 = 3.6e-5 s it is near the formula; at the run's 1 ms MuJoCo integrates the
    damping coarsely and the run meets another robot (a −91 % off). The check says it at both steps, a fail at the
    run's, with the drag rate and k dt = 556 × 0.001."""
    from bioform_mj.assess.identify import DRAG_STEP

    rep = check(str(_damped(tmp_path, 13.9)), run_step=0.001)
    k_turn = 2 * 10 * 13.9 * 0.2 / 0.1  # 2 b c l / r, 1/s
    rows = {r["at"]: r for r in rep["identification_steps"]}
    assert rows["identification"]["timestep_s"] == pytest.approx(DRAG_STEP / k_turn, rel=1e-6)
    assert rows["model"]["timestep_s"] == 0.002 and rows["run"]["timestep_s"] == 0.001
    run = rows["run"]
    assert run["identifiable"] is False or max(abs(v) for v in run["relative_error"].values()) > 0.10
    said = [r for r in rep["fail_reasons"] if r.startswith("at the run's step 0.001 s")]
    assert len(said) == 1 and f"k = {k_turn:.3g} 1/s" in said[0] and "k dt = 0.56" in said[0], rep["fail_reasons"]
    # the drag is beyond what the opt-in learner.drag can learn (its bound drag_max = 50 1/s): said as such
    assert any(
        f"drag rate {k_turn:.3g} 1/s is beyond the opt-in learner.drag's range [0, 50] 1/s" in r for r in rep["reasons"]
    )


def test_a_drag_beyond_learner_drag_range_is_said_and_a_tip_is_the_cause_after_a_tip(tmp_path):
    """c_hat_off's cause: a drag rate (111, 556 1/s) beyond learner.drag's bound (drag_max = 50 1/s) is said to be
    beyond its range, not recommended; one within (c = 0.1: 0.8, 4 1/s) is recommended. After a tip the cause is
    the tip, not the geoms the overturned robot lies on."""
    from bioform_mj.assess.outcomes import outcome_list, unmodelled_causes

    strong = MujocoPlant([str(_damped(tmp_path, 13.9, "0.001"))], np.zeros((1, 3)), 0.001, 0.001, slots=False)
    k = strong.params[0].unmodelled(0.0, 0.0)["drag_rate_per_s"]
    assert k == pytest.approx([2 * 0.4 * 13.9 / 0.1, 2 * 10 * 13.9 * 0.2 / 0.1], rel=1e-3)
    said = unmodelled_causes(strong.params[0], drag_max=50.0)[0]
    assert "beyond the range of the opt-in learner.drag [0, learner.drag_max = 50] 1/s" in said
    assert "would estimate" not in said
    weak = MujocoPlant([str(_damped(tmp_path, 0.1, "0.001"))], np.zeros((1, 3)), 0.001, 0.001, slots=False)
    assert "the opt-in learner.drag would estimate it" in unmodelled_causes(weak.params[0], drag_max=50.0)[0]
    common = dict(
        slip_t=None,
        spinning=False,
        final=0.0,
        fe0=1.0,
        t_end=20.0,
        learning=True,
        c_hat=np.array([0.1, 10.0]),
        lo=np.array([0.02, 0.5]),
        hi=np.array([2.0, 50.0]),
        c_true=np.array([0.4, 10.0]),
        causes=lambda: ["caster 'lidar_link' braking"],
    )
    tipped = outcome_list(tip_t=3.25, **common)
    off = [o for o in tipped if o["kind"] == "c_hat_off"][0]["detail"]
    assert "likely cause: the robot tipped at t = 3.250 s" in off and "lidar" not in off
    upright = [o for o in outcome_list(tip_t=None, **common) if o["kind"] == "c_hat_off"][0]["detail"]
    assert "caster 'lidar_link' braking" in upright


def _paper_wheel_speed(scale: float, half_track: float) -> float:
    """The paper leader's (x = t, y = 3 + 0.4 sin t, × ``scale``) largest wheel ground speed |υ| + l|ω| by hand:
    υ = scale √(1 + 0.16 cos² t), ω = −0.4 sin t / (1 + 0.16 cos² t) (the heading atan(0.4 cos t) differentiated),
    over 20 s on a 0.1 ms grid (world-frame slots move as the leader)."""
    t = np.arange(0.0, 20.0, 1e-4)
    c2 = 0.16 * np.cos(t) ** 2
    return float(np.max(scale * np.sqrt(1 + c2) + half_track * np.abs(0.4 * np.sin(t) / (1 + c2))))


def test_torque_the_wheels_damper_absorbs_is_the_motors_not_the_tyres(tmp_path):
    """Cruising at the paper leader's peak wheel ground speed (max |υ_r| + l|ω_r|, by hand; above the leader's
    sqrt(1 + 0.4²) = 1.077 m/s: the outer wheel of its turns, issue 27) against wheel damping c takes c υ / r per
    wheel. c = 0.3: ≈ 3.3 N·m, within the 5 N·m motor though beyond the traction limit of μ = 0.2
    (0.2 · 120 N · 0.1 m ≈ 2.4 N·m): the damper absorbs it before the tyre, no warning (it blamed traction).
    c = 0.6: ≈ 6.6 N·m, beyond the motor: a warning naming the damper, the motor limit and both speeds."""
    sc = load(
        "paper",
        plant="mujoco",
        overrides=["formation.initial_poses=[[0,0,0]]", "formation.offsets=[[3,0]]", "graph.edges=[]"],
    )
    low = MujocoPlant([str(_damped(tmp_path, 0.3, "0.001", "0.2"))], sc.initial_poses(), 0.001, 0.001)
    v_wheel = _paper_wheel_speed(1.0, low.params[0].half_track)
    assert v_wheel > float(np.hypot(1.0, 0.4))
    assert 0.3 * v_wheel / 0.1 > 0.2 * (MASS * G / 2) * 0.1  # beyond the tyre's traction μ N r (N: half the weight)
    warned = feasibility(sc, low)
    assert not any("cruising" in w for w in warned), warned
    high = MujocoPlant([str(_damped(tmp_path, 0.6, "0.001"))], sc.initial_poses(), 0.001, 0.001)
    said = [w for w in feasibility(sc, high) if "cruising" in w]
    assert len(said) == 1 and "damper (0.6 N·m·s/rad)" in said[0] and "beyond the motor limit 5 N·m" in said[0]
    assert f"absorb {0.6 * v_wheel / 0.1:.3g} N·m per wheel" in said[0]
    assert (
        f"peak wheel ground speed {v_wheel:.3g} m/s" in said[0] and f"leader's speed {np.hypot(1, 0.4):.3g}" in said[0]
    )


def test_a_compile_error_naming_a_compiler_option_names_the_key_that_sets_it(tmp_path, capsys):
    """A URDF diff drive whose chassis inertia ixx = 0.1 > iyy + izz = 0.012 + 0.02 breaks the triangle
    inequality: MuJoCo refuses it with "use 'balanceinertia' to fix", an option no bioform key set. The error now
    names the mapping key and the flag; with the flag the robot compiles and is checked."""
    from bioform_mj.cli import main as cli
    from test_assess_check_published import _urdf

    text = _urdf()
    assert 'ixx="0.01" iyy="0.012" izz="0.02"' in text
    path = tmp_path / "odd.urdf"
    path.write_text(text.replace('ixx="0.01" iyy="0.012" izz="0.02"', 'ixx="0.1" iyy="0.012" izz="0.02"'))
    assert cli.main(["robot", "check", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "A + B >= C" in err[0]
    assert "map balance_inertia = true in the robot's table, or pass --balance-inertia" in err[0]
    assert cli.main(["robot", "check", str(path), "--balance-inertia"]) in (0, 4)  # checked: pass, warn or fail
    out = capsys.readouterr()
    assert "does not compile" not in out.err and "a_eff = " in out.out
    # never silent: what balancing did, by the numbers (MuJoCo sets the three moments to their mean, 0.044 kg·m²)
    mean = (0.1 + 0.012 + 0.02) / 3
    assert "balance_inertia: MuJoCo balanced the inertia of '" in out.out
    assert f"(principal moments 0.012 0.02 0.1 -> {mean:.4g} {mean:.4g} {mean:.4g} kg·m²)" in out.out


def test_identify_names_a_skid_steer_base(tmp_path, capsys):
    """``bioform identify`` on a base with a fixed wheel off the driven axle (the menagerie Jackal's trait)
    exited 0 without a word of it; it now says it on stderr and in its JSON (``skid_steer``)."""
    import json

    from bioform_mj.cli import main as cli
    from test_robots_mapping import _REAR, _published

    ref = _published(tmp_path, _REAR)
    flags = ["--base", ref.base, "--left-wheel", ref.left_wheel, "--right-wheel", ref.right_wheel]
    cli.main(["identify", ref.model, *flags])
    out = capsys.readouterr()
    assert json.loads(out.out)["skid_steer"] and "other wheel 'rear_wheel'" in json.loads(out.out)["skid_steer"][0]
    assert any(line.startswith("warning: a 4-wheel / skid-steer base") for line in out.err.splitlines())


def test_run_told_to_skip_the_robot_check_is_not_refused_by_it(tmp_path, capsys):
    """Wheels r = 0.05 m on the paper robot (its casters carry it, the wheels 5 cm above the floor): ``bioform
    run`` refuses it (exit 2, nothing written); with ``--no-robot-check`` it runs (exit 0), saying what the check
    would refuse; and the flag holds for that command only (the next run is refused again)."""
    from bioform_mj.cli import main as cli

    off = tmp_path / "offfloor.xml"
    old = '<geom type="ellipsoid" size="0.1 0.02 0.1"'
    assert old in PAPER
    off.write_text(PAPER.replace(old, '<geom type="ellipsoid" size="0.05 0.02 0.05"'))

    def run(out: str, *flags: str) -> tuple[int, list[str]]:
        sets = ["--set", "plant.kind=mujoco", "--set", f'plant.robots=["{off}"]', "--set", "sim.duration=0.05"]
        code = cli.main(["run", "paper", *sets, "--quiet", "--out", str(tmp_path / out), *flags])
        return code, capsys.readouterr().err.strip().splitlines()

    capsys.readouterr()
    code, err = run("skipped", "--no-robot-check")
    assert code == 0 and (tmp_path / "skipped" / "summary.json").exists()
    said = [e for e in err if "robot check skipped (the run goes ahead); it would refuse" in e]
    assert len(said) == 1 and "do not stand on the floor" in said[0]
    code, err = run("refused")
    assert code == 2 and len(err) == 1 and "do not stand on the floor" in err[0]
    assert not (tmp_path / "refused").exists()


# ------------------------------------------------------------- issue 27 item 5: opt-in, the paper's defaults stay
def test_the_paper_defaults_stay_the_papers():
    """Nothing of item 5 is on unless asked: bounds c_bounds × ĉ(0) = [0.1, 10] × 0.5 c_true, c = (3, 3), kd = 0."""
    from bioform_mj.control.params import stack_params

    sc = load("paper")
    assert sc.learner.projection_band == () and sc.learner.kd_deadband == () and sc.torque.resistance_margin == 0
    p = stack_params(sc, np.tile([0.4, 10.0], (3, 1)))
    assert p.c_min[0] == pytest.approx([0.02, 0.5]) and p.c_max[0] == pytest.approx([2.0, 50.0])
    assert list(p.c_gain) == [3.0, 3.0] and list(p.kd) == [0.0, 0.0] and p.sizing is None


def test_projection_band_is_around_the_prior_and_bad_bands_exit_2(tmp_path, capsys):
    """``learner.projection_band = [0.5, 2]``: ĉ projected onto [0.5, 2] × c_true = [0.2, 0.8] × [5, 20] for the
    paper's c_true (0.4, 10), ĉ(0) = 0.5 c_true on its lower edge; a band without 1 inside, NaN or one number:
    exit 2, one error: line, nothing written."""
    from bioform_mj.cli import main as cli
    from bioform_mj.control.params import stack_params

    sc = load("paper", overrides=["learner.projection_band=[0.5, 2]"])
    p = stack_params(sc, np.tile([0.4, 10.0], (3, 1)))
    assert p.c_min[1] == pytest.approx([0.2, 5.0]) and p.c_max[1] == pytest.approx([0.8, 20.0])
    for bad in ("[2, 3]", "[0.5]", "[0, 2]", "[0.5, nan]"):
        out = tmp_path / "x"
        code = cli.main(["run", "paper", "--set", f"learner.projection_band={bad}", "--out", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "learner.projection_band" in err[0] and not out.exists(), (bad, err)


def test_sliding_gain_and_d_hat_sized_to_the_identified_dead_band(tmp_path, monkeypatch):
    """The paper robot with wheel frictionloss f = 0.05 N·m: robot check identifies a dead band 2 f = 0.1 N·m on
    τ_a and τ_b, a resistance a · 0.1 = 0.04 m/s² and b · 0.1 = 1 rad/s². ``torque.resistance_margin = 5``: c =
    max((3, 3), 5 × (0.04, 1)) = (3, 5); ``learner.kd_deadband = [25, 50]``: kd = (25, 50). Without frictionloss no
    dead band is identified: kd stays the scenario's 0."""
    from bioform_mj.control.params import stack_params
    from bioform_mj.run.simulate import make_plant

    monkeypatch.setenv("BIOFORM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("BIOFORM_NO_ROBOT_CHECK", raising=False)
    fl = tmp_path / "frictionloss.xml"
    fl.write_text(PAPER.replace('armature="0" frictionloss="0"', 'armature="0" frictionloss="0.05"'))
    ov = ["plant.kind=mujoco", "torque.resistance_margin=5", "learner.kd_deadband=[25.0, 50.0]"]
    sc = load("paper", overrides=[*ov, f'plant.robots=["{fl}"]'])
    plant = make_plant(sc)
    p = stack_params(sc, plant.c_true(), plant.tau_max, plant)
    (row,) = p.sizing["robots"]
    assert row["source"] == "identified" and row["followers"] == [1, 2, 3]
    assert row["deadband_torque_Nm"] == pytest.approx([0.1, 0.1], rel=0.05)
    assert row["resistance"] == pytest.approx([0.4 * 0.1, 10 * 0.1], rel=0.05)
    assert p.c_gain[0] == 3.0 and p.c_gain[1] == pytest.approx(5 * 10 * 0.1, rel=0.05)
    assert list(p.kd) == [25.0, 50.0]
    clean = load("paper", overrides=[*ov, 'plant.robots=["paper"]'])
    plant = make_plant(clean)
    p = stack_params(clean, plant.c_true(), plant.tau_max, plant)
    assert list(p.kd) == [0.0, 0.0] and "no dead band identified" in p.sizing["why"]
    assert list(p.c_gain) == [3.0, 3.0]
    # the ideal plant (or none, a gym environment) identifies nothing: the scenario's gains, said in the summary
    p = stack_params(load("paper", overrides=ov[1:]), np.tile([0.4, 10.0], (3, 1)))
    assert list(p.c_gain) == [3.0, 3.0] and list(p.kd) == [0.0, 0.0] and "ideal plant" in p.sizing["why"]


def test_an_unnamed_geom_has_one_name_in_the_check(tmp_path):
    """The paper robot's rear caster unnamed, with friction and loaded (the centre of mass 30 mm back, the caster
    1 mm lower): identify named it '#N' (its index in the scene), robot check's braking-caster line 'base#8' (the
    9th geom of body 'base'), both in one report. Now every reason says 'base#8'."""
    import re

    text = PAPER.replace('condim="1" priority="2" friction="0 0 0"', 'condim="3" friction="1 0.005 0.0001"')
    text = text.replace('pos="-0.13 0 -0.0745"', 'pos="-0.13 0 -0.0755"')
    text = text.replace('<inertial pos="0 0 0" mass="23.5"', '<inertial pos="-0.03 0 0" mass="23.5"')
    old = '<geom name="back_caster" class="caster"'
    assert old in text
    path = tmp_path / "unnamed.xml"
    path.write_text(text.replace(old, '<geom class="caster"'))
    rep = check(str(path))
    said = [r for r in rep["reasons"] if "base#8" in r]
    assert len(said) >= 2  # identify's braking finding and robot check's braking-caster line
    assert not any(re.search(r"'#\d+'", r) for r in rep["reasons"]), rep["reasons"]
    assert [f.get("geom") for f in rep["findings"] if f["kind"] == "braking_caster"] == ["base#8"]


def test_a_runs_files_hold_no_absolute_path_and_load_back(tmp_path):
    """A robot given by its absolute path: summary.json and resolved.toml held that path of the machine. They now
    name it relative to the run's folder, and each loads back to the same file and the same log."""
    import json

    from bioform_mj.cli import main as cli

    robot = tmp_path / "robots" / "mine.xml"
    robot.parent.mkdir()
    robot.write_text(PAPER)
    a = tmp_path / "runs" / "a"
    sets = ["--set", "plant.kind=mujoco", "--set", f'plant.robots=["{robot}"]', "--set", "sim.duration=0.05"]
    assert cli.main(["run", "paper", *sets, "--quiet", "--no-robot-check", "--out", str(a)]) == 0
    for name in ("summary.json", "resolved.toml"):
        assert str(tmp_path) not in (a / name).read_text(), name
    assert json.loads((a / "summary.json").read_text())["config"]["plant"]["robots"] == ["../../robots/mine.xml"]
    for i, record in enumerate(("summary.json", "resolved.toml")):
        b = tmp_path / "runs" / f"b{i}"
        assert cli.main(["run", str(a / record), "--quiet", "--no-robot-check", "--out", str(b)]) == 0
        la, lb = np.load(a / "log.npz"), np.load(b / "log.npz")
        assert all(np.array_equal(la[k], lb[k], equal_nan=True) for k in la.files), record


def test_the_batch_engine_refuses_the_sizing_it_cannot_do():
    """The sizing reads robot check's identification, which the batch engine does not make: refused by name
    (it would silently run the paper's c and kd); the projection band is only bounds, and runs there."""
    from bioform_mj.batch.support import unsupported

    ov = ["plant.kind=mujoco"]
    for extra in ("torque.resistance_margin=2", "learner.kd_deadband=[25.0, 50.0]"):
        assert "torque.resistance_margin / learner.kd_deadband" in unsupported(load("paper", overrides=[*ov, extra]))
    assert unsupported(load("paper", overrides=[*ov, "learner.projection_band=[0.5, 2]"])) is None


def test_a_mapped_radius_below_the_tyre_starts_the_robot_on_the_floor():
    """The paper robot's tyres r = 0.1 m mapped 0.09 m: the scene placed the axle at the mapped 0.09 m, 1 cm
    inside the floor; the robot jumped and was in the air at the end of the settle, and robot check failed it
    'the wheels do not stand on the floor' (0 N). It now starts on its tyres: the drive test identifies the
    tyre's a = 0.4, b = 10 against the mapped formula 1/(24.5·0.09 + 2·0.0025/0.09) = 0.4424 (a −9.6 % gap, a
    warning naming both radii)."""
    from bioform_mj.robots.refs import RobotRef

    rep = check(RobotRef("paper", wheel_radius=0.09))
    assert rep["a_eff"] == pytest.approx(1 / (24.5 * 0.09 + 2 * 0.0025 / 0.09), rel=1e-4)
    assert rep["a_identified"] == pytest.approx(0.4, rel=0.02) and rep["b_identified"] == pytest.approx(10, rel=0.02)
    assert not any("do not stand on the floor" in r for r in rep["reasons"])
    assert any("0.09 m" in r and "0.1 m" in r and r.startswith("identification differs") for r in rep["reasons"])
    assert rep["wheel_load_n"] == pytest.approx([rep["weight_n"] / 2] * 2, rel=0.02)
