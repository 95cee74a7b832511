"""Issue 27: a run's ``c_hat_off`` names the resistance ``robot check`` identified, with its numbers (design §14.2).

Was: at the fair scale the TurtleBot3 URDFs and the Create 3 said "none the plant knows" although ``robot check``
had named their braking caster (the end-of-run contact test missed it). Now the run's cached check carries its
``resistances`` (a braking caster's drag N and wheel torque N·m, a viscous drag as rates 1/s, a dead band N·m) and
both engines name them. Synthetic robots from the shipped paper robot (r = 0.1 m, l = 0.2 m, chassis 23.5 kg, wheels
0.5 kg with I_w = 0.0025 kg·m², yaw inertia 0.18 kg·m²); the numbers are checked against closed forms computed here.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bioform_mj.assess import prerun
from bioform_mj.assess.outcomes import robot_check_resistances, unmodelled_causes
from bioform_mj.robots.refs import models_dir
from bioform_mj.scenario.loader import load

PAPER = (models_dir() / "paper_robot.xml").read_text()
G = 9.81  # m/s², MuJoCo's default gravity
MU = 0.1  # the braking caster's friction (priority over the floor's μ = 1)


def _braking(tmp_path: Path) -> Path:
    """The paper robot with its rear caster (x = −0.13 m) lowered onto the floor at μ = 0.1 and the chassis' 23.5 kg
    centre of mass 3 cm behind the axle: the lever rule about the axle puts 23.5 g · 0.03 / 0.13 = 53.2 N on the
    caster, a drag of μ × that = 5.32 N, 0.532 N·m of wheel torque at r = 0.1 m."""
    text = PAPER
    for old, new in (
        ('pos="-0.13 0 -0.0745"', 'pos="-0.13 0 -0.0755"'),
        ('<inertial pos="0 0 0" mass="23.5"', '<inertial pos="-0.03 0 0" mass="23.5"'),
        (
            '<geom name="back_caster" class="caster"',
            f'<geom name="back_caster" class="caster" condim="3" priority="2" friction="{MU} 0.005 0.0001"',
        ),
    ):
        assert old in text, old
        text = text.replace(old, new)
    p = tmp_path / "braking.xml"
    p.write_text(text)
    return p


def _damped(tmp_path: Path, c: float) -> Path:
    """The paper robot with wheel damping ``c`` N·m·s/rad per wheel."""
    p = tmp_path / "damped.xml"
    p.write_text(PAPER.replace('damping="0" armature="0"', f'damping="{c}" armature="0"'))
    return p


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(prerun.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(prerun.SKIP_ENV, raising=False)
    monkeypatch.setattr(prerun, "_MEMO", {})


def _number(pattern: str, text: str) -> float:
    m = re.search(pattern, text)
    assert m, (pattern, text)
    return float(m.group(1))


def test_identified_resistances_are_named_with_their_numbers_and_nothing_else_is_invented():
    """The phrases, from a robot check's resistances; none known: the paper robot says nothing (the caller then
    says "none the plant knows"); the model's damping is replaced by the identified rates, not said twice."""
    found = [
        {"kind": "braking_caster", "geom": "back", "braking_force_n": 5.3, "torque_nm": 0.53, "while_driving": False},
        {"kind": "drag", "drag_rate_per_s": [0.0, 0.34]},
        {"kind": "dead_band", "deadband_torque_Nm": [0.6, 0.34]},
    ]
    said = unmodelled_causes(None, casters=["back", "front"], identified=found)
    assert said == [
        "caster 'back' braking (robot check: 5.3 N of drag, 0.53 N·m of wheel torque)",
        "wheel drag (identified by robot check: drag rate k_ω = 0.34 1/s, time constants 2.94 s; the opt-in "
        "learner.drag would estimate it)",
        "a dead band of 0.6 N·m on τ_a, 0.34 N·m on τ_b (robot check)",
        "caster 'front' braking",  # braking at the run's end, not named by the check: said without numbers
    ]
    assert unmodelled_causes(None) == []
    rc = {"robots": [{"followers": [1, 3], "resistances": found[:1]}, {"followers": [2], "resistances": []}]}
    assert robot_check_resistances(rc, 3) == [found[:1], [], found[:1]]
    assert robot_check_resistances(None, 2) == [[], []]  # skipped, or not a MuJoCo run


def _c_hat_off(summary: dict) -> list[str]:
    out = []
    for f in summary["followers"]:
        (o,) = [o for o in f["outcomes"] if o["kind"] == "c_hat_off"]  # ĉ(0) = c/5, learning slowed: off by design
        out.append(o["detail"])
    return out


@pytest.mark.slow
def test_a_run_names_the_braking_caster_robot_check_found(tmp_path, fresh_cache):
    """0.3 s from ĉ(0) = 0.2 c, learning slowed (k4 = 0.01) so ĉ stays off, on the CPU engine (and on the batch
    engine where Warp is installed): every follower's ``c_hat_off`` names 'back_caster' with the drag robot check
    measured, within 2 % of the lever rule's μ · 23.5 g · 0.03/0.13."""
    from bioform_mj.run.simulate import simulate

    drag = MU * 23.5 * G * 0.03 / 0.13  # N, independent of MuJoCo
    ov = [
        "plant.kind=mujoco",
        "sim.duration=0.3",
        "learner.c_hat0_scale=[0.2, 0.2]",
        "learner.k4=[0.01, 0.01]",
        f'plant.robots=[{{model="{_braking(tmp_path)}"}}]',
    ]
    sc = load("paper", overrides=ov)
    with pytest.warns(Warning):
        summaries = [simulate(sc).summary]
    try:
        import mujoco_warp  # noqa: F401
        import warp  # noqa: F401

        from bioform_mj.batch.runner import run_batch

        with pytest.warns(Warning):
            summaries.append(run_batch([sc])[0])
    except ImportError:
        pass
    for s in summaries:
        for d in _c_hat_off(s):
            assert "none the plant knows" not in d
            # a geom of the base body: robot check's "the chassis 'base' drags on the floor (geom 'back_caster')"
            f = _number(r"'back_caster' of the chassis braking \(robot check: ([0-9.]+) N of drag", d)
            tau = _number(r"N of drag, ([0-9.]+) N·m of wheel torque", d)
            assert f == pytest.approx(drag, rel=0.02) and tau == pytest.approx(drag * 0.1, rel=0.02), d


@pytest.mark.slow
def test_a_run_names_the_wheel_damping_as_drag_rates(tmp_path, fresh_cache):
    """Wheel damping c = 0.1 N·m·s/rad: k_υ = 2c/(m r² + 2 I_w) = 0.2/0.25 = 0.8 1/s and k_ω = 2 c l²/(I r² + 2 I_w l²)
    = 0.008/0.002 = 4 1/s (m = 24.5 kg, I = 0.18 kg·m²), named as robot check identified them, within 3 %."""
    from bioform_mj.run.simulate import simulate

    c, m, r, i_w, l, yaw = 0.1, 24.5, 0.1, 0.0025, 0.2, 0.18
    k_v, k_w = 2 * c / (m * r**2 + 2 * i_w), 2 * c * l**2 / (yaw * r**2 + 2 * i_w * l**2)
    ov = [
        "plant.kind=mujoco",
        "sim.duration=0.3",
        "learner.c_hat0_scale=[0.2, 0.2]",
        "learner.k4=[0.01, 0.01]",
        f'plant.robots=[{{model="{_damped(tmp_path, c)}"}}]',
    ]
    res = simulate(load("paper", overrides=ov))
    for d in _c_hat_off(res.summary):
        assert "identified by robot check" in d, d
        assert _number(r"k_υ = ([0-9.]+) 1/s", d) == pytest.approx(k_v, rel=0.03), d
        assert _number(r"k_ω = ([0-9.]+) 1/s", d) == pytest.approx(k_w, rel=0.03), d
        assert "the wheels' damping/back-EMF: 0.8, 4 1/s" in d  # the model's own figure beside it


def test_a_braking_casters_lever_is_measured_and_its_moment_counts_on_omega(tmp_path):
    """The braking caster of :func:`_braking` touches the floor 0.13 m behind the axle midpoint, on the centre line:
    robot check reports that lever (from its contact point, within 1 mm), and the demand puts the caster's moment
    ``F d`` on ω as ``b F r d / l`` rad/s² (b = 10, l = 0.2 m of the paper robot) in ``sliding_gain_w``."""
    from bioform_mj.assess.check import check
    from bioform_mj.assess.outcomes import identified_resistances
    from bioform_mj.run.demand import brake_yaw_torques, compare

    rep = check(str(_braking(tmp_path)))
    (brake,) = [x for x in identified_resistances(rep) if x["kind"] == "braking_caster"]
    assert brake["lever_m"] == pytest.approx(0.13, abs=1e-3)
    rc = {"robots": [{"followers": [1], "resistances": [brake]}]}
    (yaw,) = brake_yaw_torques(rc, [0.2])
    assert yaw == pytest.approx(brake["torque_nm"] * brake["lever_m"] / 0.2, rel=1e-12)
    assert brake_yaw_torques({"robots": [{"followers": [1], "resistances": [{**brake, "lever_m": None}]}]}, [0.2]) == [
        None
    ]
    sc = load("paper", ["formation.scale=0.4", "formation.time_scale=4"])
    pk = {"wheel_speed_mps": 0.1, "accel_mps2": 0.1, "yaw_accel_radps2": 0.1, "lateral_accel_mps2": 0.0}
    pk |= {"c_hat_min": [0.4, 10.0], "speed_mps": 0.2, "yaw_rate_radps": 1.0}
    lim = {"top_speed_mps": 1.0, "top_speed_source": "mapping", "accel_mps2": 1.0, "accel_limited_by": "torque"}
    lim |= {"yaw_accel_radps2": 10.0, "yaw_accel_limited_by": "torque", "lateral_accel_mps2": 5.0}
    lim |= {"torque_nm": 5.0, "traction_torque_nm": 10.0}
    items = compare(sc, pk, lim, None, (0.4, 10.0), brake["torque_nm"], yaw)
    want = 10.0 * brake["braking_force_n"] * 0.1 * 0.13 / 0.2  # b F r d / l, by hand (r = 0.1 m)
    assert items["sliding_gain_w"]["value"] == pytest.approx(want, rel=1e-2)
    assert "braking_caster_note" not in items["sliding_gain_w"]
    unknown = compare(sc, pk, lim, None, (0.4, 10.0), brake["torque_nm"], None)
    assert "sliding_gain_w" not in unknown  # no lever, no other resistance on ω: nothing to say there


def test_a_link_welded_to_the_base_that_carries_the_mass_is_the_chassis_not_a_caster():
    """A URDF's ``base_link`` below a massless ``base_footprint`` (the iRobot Create 2's description): its dragging
    collision cylinder is the chassis (robot check) and the run says so, where it said "caster 'base_link#1'"; a
    light link welded to the base (Clearpath Dingo-D's 0.1 kg rear ball caster, 1 % of the mass) stays a caster."""
    from bioform_mj.assess.causes import _contact_kind

    chassis = {"body": "base_link", "welded_to_base": True, "mass_share": 0.96}
    ball = {"body": "rear_caster", "welded_to_base": True, "mass_share": 0.0097}
    assert _contact_kind(chassis, "base_footprint") == "chassis" and _contact_kind(ball, "base_link") == "caster"
    assert _contact_kind({**chassis, "welded_to_base": False}, "base_footprint") == "caster"  # on a joint of its own
    found = [
        {"kind": "braking_caster", "geom": "base_link#1", "braking_force_n": 1.98, "torque_nm": 0.0712}
        | {"while_driving": True, "contact": "chassis"},
        {"kind": "braking_caster", "geom": "rear_caster#1", "braking_force_n": 5.86, "torque_nm": 0.287},
    ]
    said = unmodelled_causes(None, identified=found)
    drag = "(robot check: 1.98 N of drag while it drives, 0.0712 N·m of wheel torque)"
    assert said[0] == f"'base_link#1' of the chassis braking {drag}"
    assert said[1] == "caster 'rear_caster#1' braking (robot check: 5.86 N of drag, 0.287 N·m of wheel torque)"
