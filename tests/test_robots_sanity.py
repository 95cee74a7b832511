"""Bounded answers to hostile inputs (issue 28 item 2, :mod:`bioform_mj.robots.sanity`): each one ``error:`` line,
exit 2, promptly: FIFOs and devices never opened, archives never unpacked past their declared sizes, a
timestep that would step for hours refused with the estimate, bad numbers refused naming the element."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from bioform_mj.cli import main as cli
from bioform_mj.core.errors import InputError
from bioform_mj.robots import sanity as limits
from test_robots_urdf import diff_drive, write

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _cli(args: list[str], capsys) -> tuple[int, list[str]]:
    code = cli.main(args)
    return code, capsys.readouterr().err.strip().splitlines()


def _one_error(code: int, err: list[str], *needles: str) -> None:
    """Exit 2, one ``error:`` line (MuJoCo's own ``warning:`` about a NaN in the XML may precede it), no traceback."""
    assert code == 2, err
    errors = [e for e in err if e.startswith("error:")]
    assert len(errors) == 1 and all(e.startswith(("error:", "warning: MuJoCo")) for e in err), err
    for n in needles:
        assert n in errors[0], err


def _in_subprocess(args: list[str], env: dict, timeout: float = 120) -> subprocess.CompletedProcess:
    """``bioform ARGS`` in a process of its own: a read that blocks would hang the test run, not fail it."""
    return subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", *args],
        env={**os.environ, **env, "PYTHONPATH": SRC},
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# ------------------------------------------------------------------ reads that could block
def test_fifo_package_xml_on_ros_package_path_is_not_read(tmp_path):
    ws = tmp_path / "ws" / "src" / "pkg"
    ws.mkdir(parents=True)
    os.mkfifo(ws / "package.xml")
    os.mkfifo(tmp_path / "ws" / "package.xml")
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="package://nopkg/c.stl"/>'))
    t0 = time.monotonic()
    res = _in_subprocess(["robot", "check", str(path)], {"ROS_PACKAGE_PATH": str(tmp_path / "ws")}, timeout=90)
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1 and "package 'nopkg' is on no search path" in err[0], err
    assert time.monotonic() - t0 < 60


@pytest.mark.parametrize("where", ["robot", "mesh", "device"])
def test_fifo_or_device_refused_naming_it(where, tmp_path, capsys):
    if where == "robot":
        path = tmp_path / "r.urdf"
        os.mkfifo(path)
        needle = "is a FIFO"
    else:
        mesh = "/dev/zero" if where == "device" else str(tmp_path / "m.stl")
        if where == "mesh":
            os.mkfifo(mesh)
        path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision=f'<mesh filename="{mesh}"/>'))
        needle = "is a device" if where == "device" else "is a FIFO"
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, needle)


# ------------------------------------------------------------------ archives: sizes before decompression
def _zae(path: Path, payload: bytes, name: str = "model.dae") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(name, payload)
    return path


@pytest.mark.parametrize("suffix", [".zae", ".dae"])
def test_zip_bomb_mesh_refused_before_unpacking(suffix, tmp_path, capsys):
    _zae(tmp_path / "meshes" / f"c{suffix}", b"\0" * 20_000_000)  # 20 MB of zeros: ~20 kB packed
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision=f'<mesh filename="meshes/c{suffix}"/>'))
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "a zip archive compressed", "not unpacked", "<collision> mesh")


def test_archive_declaring_more_than_the_bound_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(limits, "MESH_MAX_MB", 1)
    import random

    rng = random.Random(0)  # numbers as COLLADA writes them: ~2.5x compressible, 2 MB unpacked, < 1 MB packed
    _zae(tmp_path / "c.zae", " ".join(f"{rng.random():.6f}" for _ in range(220_000)).encode())
    assert (tmp_path / "c.zae").stat().st_size < 1_000_000
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="c.zae"/>'))
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "unpacks to 2 MB", "above the 1 MB")


def test_oversized_mesh_file_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(limits, "MESH_MAX_MB", 1)
    big = tmp_path / "big.stl"
    with open(big, "wb") as fh:
        fh.truncate(3_000_000)  # sparse: 3 MB declared, nothing written
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="big.stl"/>'))
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "3 MB, above the 1 MB a mesh may be")


# ------------------------------------------------------------------ a timestep that would step for hours
def test_tiny_timestep_refused_with_an_estimate(tmp_path, capsys):
    text = diff_drive().replace('<robot name="dd">', '<robot name="dd"><mujoco><option timestep="1e-9"/></mujoco>')
    path = write(tmp_path / "dd.urdf", text)
    t0 = time.monotonic()
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "timestep 1e-09 s makes", "physics steps", " h (at ", "the bound is")
    assert time.monotonic() - t0 < 60


def test_step_budget_says_the_estimate():
    with pytest.raises(InputError, match=r"about 5\.6 h"):
        limits.check_step_budget(1.0, 1e-9, "x", "y")
    with pytest.raises(InputError, match="finite number > 0"):
        limits.check_step_budget(1.0, float("nan"), "x", "y")
    limits.check_step_budget(10.0, 0.002, "x", "y")


# ------------------------------------------------------------------ numbers: refused naming the element
def _chassis_mass(v: str) -> str:
    return diff_drive().replace('<mass value="2.0"/>', f'<mass value="{v}"/>', 1)


BAD_VALUES = [
    ("negative mass", lambda: _chassis_mass("-2.0"), "<mass value='-2.0'> of link 'base_link'"),
    ("nan mass", lambda: _chassis_mass("nan"), "<mass value='nan'> of link 'base_link'"),
    ("inf mass", lambda: _chassis_mass("inf"), "<mass value='inf'>"),
    (
        "zero mass of a wheel",
        lambda: diff_drive().replace('<mass value="0.2"/>', '<mass value="0"/>', 1),
        "of link 'wheel_left': a link that moves on its joint needs a mass > 0",
    ),
    ("negative inertia", lambda: diff_drive().replace('ixx="0.01"', 'ixx="-0.01"', 1), "<inertia ixx='-0.01'>"),
    ("nan inertia", lambda: diff_drive().replace('ixy="0"', 'ixy="nan"', 1), "<inertia ixy='nan'>"),
    ("nan axis", lambda: diff_drive().replace('<axis xyz="0 0 1"/>', '<axis xyz="nan 0 1"/>', 1), "<axis xyz='nan"),
    ("zero axis", lambda: diff_drive().replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1), "not all 0"),
    (
        "negative effort",
        lambda: diff_drive().replace('effort="2"', 'effort="-2"', 1),
        "<limit effort='-2'> of joint 'wheel_left_joint'",
    ),
    (
        "nan damping",
        lambda: diff_drive().replace("</joint>", '<dynamics damping="nan"/></joint>', 1),
        "<dynamics damping='nan'>",
    ),
    (
        "nan friction",
        lambda: diff_drive(tail='<gazebo reference="wheel_left"><mu1>nan</mu1></gazebo>'),
        "<gazebo reference='wheel_left'> <mu1> nan",
    ),
    (
        "negative friction",
        lambda: diff_drive(tail='<gazebo reference="wheel_left"><mu1 value="-1"/></gazebo>'),
        "a friction coefficient must be a finite number >= 0",
    ),
    ("zero scale", lambda: _scaled("0 1 1"), "<collision><mesh scale='0 1 1'> of link 'base_link'"),
    ("nan scale", lambda: _scaled("nan 1 1"), "mesh scale='nan 1 1'"),
    ("negative scale", lambda: _scaled("-1 1 1"), "mirror the mesh file instead"),
]


def _scaled(scale: str) -> str:
    return diff_drive(chassis_collision=f'<mesh filename="c.stl" scale="{scale}"/>')


@pytest.mark.parametrize("desc,make,needle", BAD_VALUES, ids=[b[0] for b in BAD_VALUES])
def test_bad_number_refused_naming_the_element(desc, make, needle, tmp_path, capsys):
    from test_robots_urdf import box_stl

    box_stl(tmp_path / "c.stl", 0.15, 0.1, 0.025)
    text = make()
    path = write(tmp_path / "dd.urdf", text)
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, needle, str(path))


def test_nan_in_an_mjcf_robot_refused_naming_the_joint(tmp_path, capsys):
    from bioform_mj.robots.refs import models_dir

    text = (models_dir() / "paper_robot.xml").read_text()
    assert 'axis="0 1 0"' in text
    path = write(tmp_path / "nan_robot.xml", text.replace('axis="0 1 0"', 'axis="nan 1 0"', 1))
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "joint '", "axis [nan")


def test_zero_friction_patch_refused_at_validation():
    import bioform_mj

    for mu in ("0.0", "nan", "inf"):
        with pytest.raises(InputError, match="faults.friction_patch"):
            bioform_mj.load("paper", overrides=[f"faults.friction_patch=[-5.0,-5.0,5.0,5.0,{mu}]", "plant.kind=mujoco"])


# ------------------------------------------------------------------ names that would forge output lines
@pytest.mark.parametrize("fmt", ["urdf", "mjcf"])
def test_newline_in_a_name_refused_in_one_line(fmt, tmp_path, capsys):
    """A joint named ``x&#10;error: …`` forged ``error:`` lines in a run that exited 0 (issue 28)."""
    forged = "&#10;error: forged line"
    if fmt == "urdf":
        path = write(tmp_path / "dd.urdf", diff_drive().replace('name="wheel_left_joint"', f'name="wl{forged}"'))
    else:
        from bioform_mj.robots.refs import models_dir

        text = (models_dir() / "paper_robot.xml").read_text()
        assert 'name="left_wheel"' in text
        path = write(tmp_path / "p_robot.xml", text.replace('name="back_caster"', f'name="bc{forged}"', 1))
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "control character", "\\n")
    assert not any(line.startswith("error: forged") for line in err)


def test_warning_lines_stay_one_line(capsys):
    import warnings

    from bioform_mj.cli.report import _show_robot_warnings
    from bioform_mj.core.errors import RobotWarning

    saved = warnings.showwarning
    try:
        _show_robot_warnings()
        warnings.warn("name 'a\nerror: forged'", RobotWarning, stacklevel=1)
    finally:
        warnings.showwarning = saved
    err = capsys.readouterr().err.splitlines()
    assert err == ["warning: name 'a\\nerror: forged'"], err


# ------------------------------------------------------------------ a mesh symlinked out of its package
def test_mesh_symlinked_out_of_its_package_is_not_read(tmp_path, capsys):
    """A link to a file outside the package was copied into a run's assets/ under the target's name."""
    from test_robots_urdf import box_stl

    outside = box_stl(tmp_path / "secret" / "id_rsa.stl", 0.15, 0.1, 0.025)
    pkg = tmp_path / "ws" / "ddpkg"
    write(pkg / "package.xml", "<package><name>ddpkg</name></package>")
    (pkg / "meshes").mkdir()
    (pkg / "meshes" / "chassis.stl").symlink_to(outside)
    box_stl(pkg / "meshes" / "real.stl", 0.15, 0.1, 0.025)
    (pkg / "meshes" / "inside.stl").symlink_to(pkg / "meshes" / "real.stl")  # a link inside: fine
    for uri in (
        "package://ddpkg/meshes/chassis.stl",
        "../meshes/chassis.stl",
        "package://ddpkg/../../secret/id_rsa.stl",
    ):
        path = write(pkg / "urdf" / "dd.urdf", diff_drive(chassis_collision=f'<mesh filename="{uri}"/>'))
        code, err = _cli(["robot", "check", str(path), "--package-path", f"ddpkg={pkg}"], capsys)
        if uri.startswith("package://ddpkg/.."):
            _one_error(code, err, "outside its package")
        else:
            _one_error(code, err, "a symlink to", "id_rsa.stl", "outside its package")
    from bioform_mj.robots.refs import PackagePath, RobotRef
    from bioform_mj.robots.urdf import check_file

    path = write(pkg / "urdf" / "dd.urdf", diff_drive(chassis_collision='<mesh filename="../meshes/inside.stl"/>'))
    check_file(RobotRef(str(path), package_path=PackagePath([("ddpkg", str(pkg))])))


def test_scenario_file_that_is_a_fifo_or_huge_is_refused(tmp_path, capsys):
    fifo = tmp_path / "s.toml"
    os.mkfifo(fifo)
    code, err = _cli(["run", str(fifo)], capsys)
    _one_error(code, err, "is a FIFO")
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(20_000_000)  # sparse
    code, err = _cli(["run", str(big)], capsys)
    _one_error(code, err, "20 MB: not a scenario")


def test_mjcf_mesh_that_is_a_fifo_or_too_large_is_refused(tmp_path, capsys, monkeypatch):
    """An MJCF robot's mesh is checked before MuJoCo's compiler opens it (a FIFO blocked it)."""
    from bioform_mj.robots.refs import models_dir
    from test_robots_urdf import box_stl

    text = (models_dir() / "paper_robot.xml").read_text()
    geom = '<geom name="back_caster"'
    assert geom in text and "<asset>" not in text
    text = text.replace("<worldbody>", '<asset><mesh name="m" file="m.stl"/></asset><worldbody>', 1)
    path = write(tmp_path / "m_robot.xml", text)
    os.mkfifo(tmp_path / "m.stl")
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "mesh file", "is a FIFO")
    (tmp_path / "m.stl").unlink()
    box_stl(tmp_path / "m.stl", 0.1, 0.1, 0.1)
    monkeypatch.setattr(limits, "MESH_MAX_MB", 0)
    code, err = _cli(["robot", "check", str(path)], capsys)
    _one_error(code, err, "above the 0 MB a mesh may be")
