"""Robot errors in the CLI's terms (issue 28): ``robot check``/``identify`` name the flags (``--left-wheel``,
``--tau-max``), the Python API and scenario files the keys (``left_wheel``, ``tau_max``); a robot whose wheels
cannot be told lists the continuous/revolute joints it found with their links, checked against the file read
independently with ElementTree."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import pytest

from bioform_mj.cli import main as cli
from bioform_mj.cli.robot import cli_terms
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import RobotRef, models_dir
from test_robots_urdf import L_HALF, diff_drive, wheel, write


def _err(code: int, capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error:"), err
    return err[0]


def _urdf_candidates(path) -> str:
    """``'joint' (on 'child', child of 'parent')`` for every continuous/revolute joint, in file order."""
    root = ET.parse(path).getroot()
    return ", ".join(
        f"'{j.get('name')}' (on '{j.find('child').get('link')}', child of '{j.find('parent').get('link')}')"
        for j in root.iter("joint")
        if j.get("type") in ("continuous", "revolute")
    )


def test_ambiguous_wheels_cli_names_flags_and_lists_candidates(tmp_path, capsys):
    path = write(tmp_path / "dd.urdf", diff_drive(tail=wheel("left2", L_HALF)))  # two wheels on the left
    cands = _urdf_candidates(path)
    assert cands.count("(on '") == 3
    line = _err(cli.main(["robot", "check", str(path)]), capsys)
    assert "cannot tell the driven wheels (left: 'wheel_left_joint', 'wheel_left2_joint'; right: " in line, line
    assert line.endswith(
        f"map them: --left-wheel JOINT --right-wheel JOINT (continuous/revolute joints found: {cands})"
    ), line
    assert "left_wheel" not in line.replace("'wheel_left", "")
    with pytest.raises(ValueError) as api:  # the Python API: the keys
        prepare_robot(RobotRef(model=str(path)))
    assert f"map left_wheel and right_wheel (continuous/revolute joints found: {cands})" in str(api.value)


def test_unknown_wheel_joint_lists_the_hinges(capsys):
    model = mujoco.MjModel.from_xml_path(str(models_dir() / "paper_robot.xml"))
    hinges = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    expected = ", ".join(
        f"'{model.joint(j).name}' (on '{model.body(model.jnt_bodyid[j]).name}', child of "
        f"'{model.body(model.body_parentid[model.jnt_bodyid[j]]).name}')"
        for j in hinges
    )
    assert len(hinges) == 2
    line = _err(cli.main(["robot", "check", "paper", "--left-wheel", "nope"]), capsys)
    assert line.endswith(
        f"no joint 'nope' (--left-wheel; map it with --left-wheel JOINT; hinge joints found: {expected})"
    )
    with pytest.raises(ValueError, match='map it with left_wheel = "JOINT"; hinge joints found'):
        prepare_robot(RobotRef(model="paper", left_wheel="nope"))


def test_missing_torque_limit_names_tau_max_flag(tmp_path, capsys):
    path = write(tmp_path / "dd.urdf", diff_drive(effort=False))
    line = _err(cli.main(["identify", str(path)]), capsys)
    assert "give --tau-max (N·m) (a URDF: <limit effort> on the wheel joints)" in line and "tau_max" not in line
    with pytest.raises(ValueError, match=r"give tau_max \(N·m\) in the robot's mapping"):
        prepare_robot(RobotRef(model=str(path)))


@pytest.mark.parametrize(
    "text,expected",
    [
        ("map left_wheel/right_wheel to choose others", "map --left-wheel/--right-wheel to choose others"),
        (
            "no body 'base' (the base; map it with base = \"BODY\")",
            "no body 'base' (the base; map it with --base BODY)",
        ),
        ("caster 'c' (mapping casters) is not a geom", "caster 'c' (--caster) is not a geom"),
        ("the robot mapping's top_speed (m/s)", "--top-speed (m/s)"),
        ("mesh '/m/left_wheel.stl' of joint 'tau_max'", "mesh '/m/left_wheel.stl' of joint 'tau_max'"),  # names kept
        ('xacro_args = {NAME = "VALUE"}', 'xacro_args = {NAME = "VALUE"}'),  # not a mapping flag: kept
    ],
)
def test_cli_terms(text, expected):
    assert cli_terms(text) == expected
