"""identify's cause attribution (design §14.2): casters that resist a turn are named as the casters, not as
wheel damping; a chassis edge dragging on the floor is named as a braking contact and never gives a negative
dead band. Synthetic bases built with MjSpec / URDF text (no published file)."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import mujoco
import pytest

import bioform_mj.assess.identify as identify_module
from bioform_mj.assess.causes import FIT_RESIDUAL_MAX
from bioform_mj.assess.check import check
from bioform_mj.assess.identify import identify


def _caster_base(tmp_path: Path, damping: float) -> str:
    """A 40 kg base, wheels r 0.1 m at ±0.2 m, four trailing swivel casters at (±0.3, ±0.2) m with cylinder
    wheels (r 0.05 m, 1 kg) on rollers, swivel ``damping`` N·m·s/rad; the wheel joints have no damping."""
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = 0.001
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    hinge = mujoco.mjtJoint.mjJNT_HINGE

    def body(parent, name, pos, mass, inertia, quat=(1.0, 0.0, 0.0, 0.0)):
        b = parent.add_body(name=name, pos=list(pos), quat=list(quat))
        b.mass, b.inertia, b.ipos, b.explicitinertial = mass, list(inertia), [0.0, 0.0, 0.0], True
        return b

    base = body(spec.worldbody, "base", (0, 0, 0.1), 40.0, (1.0, 1.2, 1.6))
    base.add_freejoint(name="root")
    base.add_geom(name="chassis", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, 0.1], size=[0.35, 0.25, 0.03],
                  contype=0, conaffinity=0)  # fmt: skip
    for side, y in (("left", 0.2), ("right", -0.2)):
        w = body(base, f"{side}_wheel_link", (0, y, 0), 1.0, (0.003, 0.005, 0.003))
        w.add_joint(name=f"{side}_wheel", type=hinge, axis=[0, 1, 0])
        w.add_geom(name=f"{side}_tire", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.1, 0, 0], condim=3)
        spec.add_exclude(bodyname1="base", bodyname2=f"{side}_wheel_link")
        m = spec.add_actuator(name=f"{side}_motor", target=f"{side}_wheel", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        m.set_to_motor()
        m.ctrlrange, m.ctrllimited = [-20.0, 20.0], True
    for name, x, y in (("fl", 0.3, 0.2), ("fr", 0.3, -0.2), ("bl", -0.3, 0.2), ("br", -0.3, -0.2)):
        sw = body(base, f"{name}_swivel", (x, y, 0), 0.5, (1e-3,) * 3)
        sw.add_joint(name=f"{name}_swivel_joint", type=hinge, axis=[0, 0, 1], damping=damping)
        cw = body(sw, f"{name}_caster", (-0.04, 0, -0.05), 1.0, (7e-4, 1.25e-3, 7e-4))
        cw.add_joint(name=f"{name}_roller", type=hinge, axis=[0, 1, 0])
        cw.add_geom(name=f"{name}_tire", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.05, 0.02, 0],
                    quat=[math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0], condim=3)  # fmt: skip
    p = tmp_path / "four_casters.xml"
    p.write_text(spec.to_xml())
    return str(p)


def test_four_swivel_casters_that_resist_the_turn_are_named_not_wheel_damping(tmp_path):
    """Four loaded swivel casters (15 % of the weight each) with swivel damping: the turn test is off by
    more than 5 % (measured b −22.4 %); the cause is ``caster_resistance`` naming the caster joints, no
    ``damping`` finding (the wheel joints have none), and with ideal casters (the counterfactual's last step)
    b is within 2 % of the formula (measured +0.7 %). Its steps, measured: swivel damping −0.1 % (the
    swivels start aligned, so they hardly turn), the casters' inertia −7.4 %, their scrub −15.6 %."""
    rep = identify(_caster_base(tmp_path, damping=0.5))
    gap = rep["relative_error"]["b"]
    assert gap < -0.05, rep["relative_error"]
    kinds = [f["kind"] for f in rep["findings"]]
    assert "damping" not in kinds, rep["findings"]
    cf = next(f for f in rep["findings"] if f["kind"] == "caster_resistance")
    assert {"fl_swivel_joint", "br_swivel_joint", "fl_roller"} <= set(cf["caster_joints"])
    assert abs(cf["b"]["without_casters"]) < 0.02, cf["b"]
    assert cf["b"]["gap"] == gap
    # the steps add up to the gap: joints + inertia + scrub + what remains with ideal casters
    assert abs(sum(cf["b"]["by_step"].values()) + cf["b"]["without_casters"] - gap) < 1e-12
    steps = cf["b"]["by_step"]
    assert steps["joints"] < 0 and steps["inertia"] < -0.03 and steps["scrub"] < -0.05, steps
    assert "swivel" in cf["detail"] and "damping up to 0.5" in cf["detail"]
    free = next(
        f for f in identify(_caster_base(tmp_path, damping=0.0))["findings"] if f["kind"] == "caster_resistance"
    )
    assert free["b"]["by_step"]["joints"] == 0.0  # no swivel damping: that step removes nothing
    assert abs(free["b"]["by_step"]["inertia"] - steps["inertia"]) < 1e-3


FREIGHT_LIKE = """<robot name="dragging_base">
  <link name="base_link">
    <inertial><origin xyz="-0.004 0 0.0015"/><mass value="70"/>
      <inertia ixx="1.2" ixy="0" ixz="0" iyy="1.3" iyz="0" izz="1.0"/></inertial>
    <collision><origin xyz="0 0 {z}"/><geometry><box size="0.5 0.5 0.3"/></geometry></collision>
  </link>
  <link name="r_wheel_link">
    <inertial><mass value="4.4"/><inertia ixx="0.0045" ixy="0" ixz="0" iyy="0.005" iyz="0" izz="0.0045"/></inertial>
    <collision><origin rpy="1.5708 0 0"/><geometry><cylinder radius="0.0613" length="0.04"/></geometry></collision>
  </link>
  <joint name="r_wheel_joint" type="continuous"><origin xyz="0 -0.1875 0.0553"/><parent link="base_link"/>
    <child link="r_wheel_link"/><axis xyz="0 1 0"/><limit effort="8.85" velocity="34.8"/></joint>
  <link name="l_wheel_link">
    <inertial><mass value="4.4"/><inertia ixx="0.0045" ixy="0" ixz="0" iyy="0.005" iyz="0" izz="0.0045"/></inertial>
    <collision><origin rpy="1.5708 0 0"/><geometry><cylinder radius="0.0613" length="0.04"/></geometry></collision>
  </link>
  <joint name="l_wheel_joint" type="continuous"><origin xyz="0 0.1875 0.0553"/><parent link="base_link"/>
    <child link="l_wheel_link"/><axis xyz="0 1 0"/><limit effort="8.85" velocity="34.8"/></joint>
</robot>
"""


def _reference_a(path: Path) -> float:
    """The zoo's independent reference (tests/zoo/reference.py: mujoco + numpy, no bioform_mj): identified a."""
    ref = sys.modules.get("zoo_reference")  # test_zoo's, where it ran first (dataclasses look it up there)
    if ref is None:
        spec = importlib.util.spec_from_file_location("zoo_reference", Path(__file__).parent / "zoo" / "reference.py")
        ref = sys.modules["zoo_reference"] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(ref)
    robot = ref.Robot(
        name="dragging", file=str(path), format="urdf", maker="-", collection="-", source="-", license="MIT",
        base="base_link", left="l_wheel_joint", right="r_wheel_joint", tau_max=8.85,
    )  # fmt: skip
    loaded = ref.load(robot)
    return float(ref.identify(loaded, ref.formula(loaded))["a_identified"])


@pytest.mark.parametrize("z, at_rest", [(0.150, False), (0.152, True)])
def test_a_chassis_edge_dragging_on_the_floor_is_a_braking_contact_and_no_negative_dead_band(
    tmp_path, monkeypatch, z, at_rest
):
    """No casters (a Fetch Freight-like base): the base box, its bottom 6.0 / 8.0 mm above the wheels' contact
    plane, tilts back onto its rear edge at rest (CoM 4 mm behind the axle and below it) and drags on the floor;
    the drive torque pitches it harder onto it and it bounces (z 0.150: 4.3 N at rest, 0.56 % of the weight:
    over the 0.5 % a caster needs (``contacts.CASTER_LOAD``, the one rule, design §0), so it is named at rest;
    with the 1 % identification had before, set here, it is named while driving, 16 N on average;
    z 0.152: 30 N at rest). identify names the
    chassis as a braking contact (at rest or while driving); the first drive fit does not hold (residual 86 % /
    9 % of its torque term, intercepts -15.6 / -5.3 N·m: a push at zero torque, which was printed as a dead
    band; a -69 % / -86 %), so the drive tests rerun at a third of the torque, where the fit holds (residual
    0.5 % / 0.2 %) and a is within 5 % of the independent reference's (measured a -7.8 % / -6.9 % from the
    formula, the reference -4.8 % / -5.1 %). No dead band is negative; robot check fails (the robot does not
    follow the model at the test torque) with that a and the chassis as the cause."""
    if not at_rest:  # the edge's 4.3 N under the caster load: only the drive test's mean names it
        from bioform_mj.robots import contacts

        monkeypatch.setattr(contacts, "CASTER_LOAD", 0.01)
    p = tmp_path / "dragging.urdf"
    p.write_text(FREIGHT_LIKE.format(z=z))
    rep = identify(str(p))
    brakes = [f for f in rep["findings"] if f["kind"] == "braking_caster"]
    assert brakes and brakes[0]["body"] == "base_link" and brakes[0]["contact"] == "chassis", rep["findings"]
    assert brakes[0]["load_n"] > 0.01 * 78.8 * 9.81
    assert brakes[0].get("while_driving", False) is not at_rest
    assert "the chassis 'base_link' drags on the floor" in brakes[0]["detail"]
    rerun = rep["test"]["fit_rerun"]
    assert rerun["kept"] and rerun["first_fit_residual"] > FIT_RESIDUAL_MAX and rerun["first_intercept_Nm"] < -1.0
    assert rerun["torque_Nm"] == pytest.approx(rerun["first_torque_Nm"] / 3)
    assert rep["fit_holds"] == {"a": True, "b": True} and rep["fit_residual"]["a"] < 0.01
    assert rep["identified"]["a"] == pytest.approx(_reference_a(p), rel=0.05)
    assert all(x >= 0 for x in rep["deadband_torque_Nm"]["identified"])
    for f in rep["findings"]:
        assert all(x >= 0 for x in f.get("deadband_torque_Nm", []) or []), f
        assert "dead band of -" not in f["detail"], f
    chk = check(str(p))  # fail: at the test torque the robot does not follow the model; the cause, the chassis
    assert chk["verdict"] == "fail" and chk["cause"]["kind"] == "braking_caster" and chk["cause"]["body"] == "base_link"
    assert chk["reasons"][0].startswith("identification: at 8.85 N·m (τ_a) the drive fit does not hold"), chk["reasons"]
    assert f"a is {rep['relative_error']['a']:+.1%}" in chk["reasons"][0]
    assert any("fit did not hold" in n for n in chk["notes"]), chk["notes"]


def test_a_drive_fit_that_does_not_hold_reports_no_measurement(tmp_path, monkeypatch):
    """The same base (z 0.150) with the lower-torque rerun off: the drive fit does not hold (residual 86 %
    of its torque term, intercept -15.6 N·m); identify says so (``fit_holds``, ``fit_problem``), reports no
    negative dead band, the rocking finding names the edge the chassis strikes (peaks of 1.4 kN) and gives no
    percentage for a; robot check fails with the fit's problem and the chassis as the cause, a null
    ``a_identified`` and no "differs by" percentage."""
    monkeypatch.setattr(identify_module, "FIT_RERUN_SCALE", 1.0)
    p = tmp_path / "dragging.urdf"
    p.write_text(FREIGHT_LIKE.format(z=0.150))
    rep = identify(str(p))
    assert rep["test"]["fit_rerun"] is None
    assert rep["fit_holds"] == {"a": False, "b": True}
    assert rep["fit_residual"]["a"] > FIT_RESIDUAL_MAX > 2 * rep["fit_residual"]["b"]
    assert min(rep["fit_intercept_Nm"]) < -1.0 and all(x >= 0 for x in rep["deadband_torque_Nm"]["identified"])
    assert "the identified a is not the robot's" in rep["fit_problem"]
    rock = next(f for f in rep["findings"] if f["kind"] == "rocking")
    assert [c["body"] for c in rock["strikes"]] == ["base_link"] and rock["strikes"][0]["peak_n"] > 100.0
    assert "from the formula" not in rock["detail"]
    chk = check(str(p))
    assert chk["verdict"] == "fail" and chk["cause"]["kind"] == "braking_caster"
    assert chk["a_identified"] is None and chk["b_identified"] == rep["identified"]["b"]
    assert not any("differs from the formula" in r for r in chk["reasons"]), chk["reasons"]
    assert any(r.startswith("identification: the fit of υ̇ = a τ_a") for r in chk["reasons"]), chk["reasons"]


def test_bioform_identify_warns_where_a_fit_does_not_hold(tmp_path, capsys, monkeypatch):
    """``bioform identify`` on the dragging base: the JSON has ``fit_problem`` and stderr one ``warning:`` line
    saying the drive fit does not hold (exit 0: it identified, and says what its a is not), the rerun off."""
    import json

    from bioform_mj.cli.main import main

    monkeypatch.setattr(identify_module, "FIT_RERUN_SCALE", 1.0)
    p = tmp_path / "dragging.urdf"
    p.write_text(FREIGHT_LIKE.format(z=0.150))
    assert main(["identify", str(p)]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["fit_holds"] == {"a": False, "b": True}
    warns = [ln for ln in err.splitlines() if ln.startswith("warning: the fit of υ̇ = a τ_a")]
    assert len(warns) == 1, err
