"""URDF robots (design §12): imported so that the robot stays a robot, every guess said, bad input
refused with one line; and a run's scene.xml that loads on its own (issue 18, items 1 and 7).

Every URDF here is written by the test, with inertials whose sums the assertions compute by hand.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import struct
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.assess.check import EXIT_FAIL
from bioform_mj.cli import main as cli
from bioform_mj.core.errors import InputError
from bioform_mj.robots.analysis import layout_of
from bioform_mj.robots.entries import resolve_robot
from bioform_mj.robots.packages import find_package
from bioform_mj.robots.prepare import prepare_robot
from bioform_mj.robots.refs import PackagePath, RobotRef
from bioform_mj.robots.urdf import check_file

HALF_PI = repr(math.pi / 2)

# the symmetric diff drive: chassis box, two wheels on continuous joints, a caster front and back
M_CHASSIS, I_CHASSIS = 2.0, (0.01, 0.012, 0.02)
M_WHEEL, I_WHEEL_DIAM, I_WHEEL_AXIS = 0.2, 1.3e-4, 2.5e-4
M_CASTER, I_CASTER, X_CASTER = 0.05, 4e-6, 0.12
R_WHEEL, L_HALF, Z_AXLE = 0.05, 0.12, 0.05
R_CASTER = 0.015


def inertial(m: float, ixx: float, iyy: float, izz: float, xyz: str = "0 0 0") -> str:
    return (
        f'<inertial><origin xyz="{xyz}"/><mass value="{m!r}"/>'
        f'<inertia ixx="{ixx!r}" iyy="{iyy!r}" izz="{izz!r}" ixy="0" ixz="0" iyz="0"/></inertial>'
    )


def wheel(
    side: str, y: float, extra: str = "", hubcap: bool = False, jtype: str = "continuous", effort: bool = True
) -> str:
    lim = '<limit lower="-3.14" upper="3.14" effort="2" velocity="10"/>' if jtype == "revolute" else ""
    lim = lim or ('<limit effort="2" velocity="10"/>' if effort else "")
    s = f"""
  <joint name="wheel_{side}_joint" type="{jtype}"><parent link="base_link"/><child link="wheel_{side}"/>
    <origin xyz="0 {y!r} 0" rpy="-{HALF_PI} 0 0"/><axis xyz="0 0 1"/>{lim}</joint>
  <link name="wheel_{side}">{inertial(M_WHEEL, I_WHEEL_DIAM, I_WHEEL_DIAM, I_WHEEL_AXIS)}
    <collision><geometry><cylinder radius="{R_WHEEL!r}" length="0.02"/></geometry></collision>{extra}</link>"""
    if hubcap:
        s += f"""
  <joint name="hubcap_{side}_joint" type="fixed"><parent link="wheel_{side}"/><child link="hubcap_{side}"/>
    <origin xyz="0 0 0.012"/></joint>
  <link name="hubcap_{side}">{inertial(0.03, 1e-5, 1e-5, 2e-5)}
    <visual><geometry><cylinder radius="0.03" length="0.004"/></geometry></visual></link>"""
    return s


def diff_drive(
    *,
    chassis_collision: str = '<box size="0.3 0.2 0.05"/>',
    caster_extra: str = "",
    hubcaps: bool = False,
    tail: str = "",
    wheel_type: str = "continuous",
    chassis_visual: str = "",
    effort: bool = True,
) -> str:
    """A two-wheel differential drive with a caster front and back, symmetric about the axle."""
    caster = ""
    for name, x in (("caster_front", X_CASTER), ("caster_back", -X_CASTER)):
        z = R_CASTER - Z_AXLE
        caster += f"""
  <joint name="{name}_joint" type="fixed"><parent link="base_link"/><child link="{name}"/>
    <origin xyz="{x!r} 0 {z!r}"/></joint>
  <link name="{name}">{inertial(M_CASTER, I_CASTER, I_CASTER, I_CASTER)}
    <collision><geometry><sphere radius="{R_CASTER!r}"/></geometry></collision>{caster_extra}</link>"""
    vis = f"<visual><geometry>{chassis_visual}</geometry></visual>" if chassis_visual else ""
    return f"""<?xml version="1.0"?>
<robot name="dd">
  <link name="base_footprint"/>
  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>
    <origin xyz="0 0 {Z_AXLE!r}"/></joint>
  <link name="base_link">{inertial(M_CHASSIS, *I_CHASSIS)}{vis}
    <collision><origin xyz="0 0 0.03"/><geometry>{chassis_collision}</geometry></collision></link>
  {wheel("left", L_HALF, hubcap=hubcaps, jtype=wheel_type, effort=effort)}
  {wheel("right", -L_HALF, hubcap=hubcaps, jtype=wheel_type, effort=effort)}
  {caster}
  {tail}
</robot>
"""


def hand_formula() -> tuple[float, float, float]:
    """``(mass, a_eff, b_eff)`` of :func:`diff_drive` from its inertials (design §8)."""
    m = M_CHASSIS + 2 * M_WHEEL + 2 * M_CASTER
    # yaw inertia about the vertical through the axle midpoint: the chassis' izz (its centre is there),
    # each wheel's diametral inertia + m l², each caster's + m x²
    yaw = I_CHASSIS[2] + 2 * (I_WHEEL_DIAM + M_WHEEL * L_HALF**2) + 2 * (I_CASTER + M_CASTER * X_CASTER**2)
    a = 1 / (m * R_WHEEL + 2 * I_WHEEL_AXIS / R_WHEEL)
    b = L_HALF / (yaw * R_WHEEL + 2 * I_WHEEL_AXIS * L_HALF**2 / R_WHEEL)
    return m, a, b


def box_stl(path: Path, hx: float, hy: float, hz: float) -> Path:
    """A binary STL of a box with half extents ``hx, hy, hz`` (m), centred on the origin."""
    v = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for a, b, c in faces:
            n = np.cross(v[b] - v[a], v[c] - v[a])
            f.write(struct.pack("<12fH", *(n / np.linalg.norm(n)), *v[a], *v[b], *v[c], 0))
    return path


def tiny_png(path: Path) -> Path:
    """A 2 × 2 RGB PNG (a texture file for MuJoCo)."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = b"".join(b"\0" + bytes([200, 40, 40] * 2) for _ in range(2))
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png)
    return path


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def compiled(ref) -> tuple[mujoco.MjModel, object]:
    spec, layout, _, _ = prepare_robot(ref)
    return spec.compile(), layout


def body(model: mujoco.MjModel, name: str) -> int:
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    assert b >= 0, f"no body {name!r}"
    return b


# ------------------------------------------------------------------ the robot stays a robot
def test_import_keeps_every_link_a_body_with_a_free_root_and_the_urdf_masses(tmp_path):
    path = write(tmp_path / "dd.urdf", diff_drive(hubcaps=True))
    model, layout = compiled(str(path))
    root = body(model, "base_footprint")
    assert model.body_parentid[root] == 0
    assert model.jnt_type[model.body_jntadr[root]] == mujoco.mjtJoint.mjJNT_FREE  # not welded to the world
    for link in ("base_link", "wheel_left", "wheel_right", "caster_front", "caster_back", "hubcap_left"):
        body(model, link)  # every link kept, with its URDF name (fusestatic off)
    hub = body(model, "hubcap_left")
    assert model.body_parentid[hub] == body(model, "wheel_left")  # the fixed hubcap rides on its wheel
    assert model.body_jntnum[hub] == 0
    m, _, _ = hand_formula()
    assert abs(model.body_subtreemass[root] - (m + 2 * 0.03)) < 1e-9  # the URDF inertials' sum
    assert layout.base == "base_footprint"
    assert layout.wheel_joints == ("wheel_left_joint", "wheel_right_joint")
    assert abs(layout.wheel_radius - R_WHEEL) < 1e-9 and abs(layout.half_track - L_HALF) < 1e-9
    joined = " ".join(layout.import_notes)
    assert "wheels found: left 'wheel_left_joint', right 'wheel_right_joint'" in joined
    assert "free joint" in joined


def test_robot_check_on_a_urdf_matches_the_formula_by_hand(tmp_path, capsys):
    path = write(tmp_path / "dd.urdf", diff_drive())
    out = tmp_path / "report.json"
    code = cli.main(["robot", "check", str(path), "--json", str(out)])
    text = capsys.readouterr().out
    assert code in (0, EXIT_FAIL)
    rep = json.loads(out.read_text())
    m, a, b = hand_formula()
    assert abs(rep["a_eff"] / a - 1) < 1e-3, (rep["a_eff"], a)  # measured: < 1e-9
    assert abs(rep["b_eff"] / b - 1) < 1e-3, (rep["b_eff"], b)
    assert "note: self-collision off" in text and "note: root link 'base_footprint' gets a free joint" in text


def test_link_without_inertial_is_massless_and_said(tmp_path):
    """The URDF spec: a link without <inertial> has zero mass (MuJoCo's importer would give the lidar its
    collision box at 1000 kg/m³, 0.5 kg here; a published Husky weighed 176 kg instead of 57 that way)."""
    tail = """
  <joint name="lidar_joint" type="fixed"><parent link="base_link"/><child link="lidar"/>
    <origin xyz="0 0 0.1"/></joint>
  <link name="lidar"><collision><geometry><box size="0.1 0.1 0.05"/></geometry></collision></link>"""
    path = write(tmp_path / "dd.urdf", diff_drive(tail=tail))
    model, layout = compiled(str(path))
    assert model.body_mass[body(model, "lidar")] == 0.0
    note = next(n for n in layout.import_notes if "without <inertial>" in n)
    assert "massless" in note and "'lidar'" in note
    assert model.body_subtreemass[1] == pytest.approx(hand_formula()[0], rel=1e-12)


def test_inertia_that_is_not_positive_definite_loses_its_products(tmp_path):
    """A published inertia tensor with eigenvalues <= 0 (PAL's PMB2 antennas): Gazebo takes it, MuJoCo refuses
    it; the import drops the products of inertia and says so."""
    tail = """
  <joint name="ant_joint" type="fixed"><parent link="base_link"/><child link="ant"/><origin xyz="0 0 0.1"/></joint>
  <link name="ant"><inertial><mass value="0.1"/>
    <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="5e-4" ixz="0" iyz="0"/></inertial></link>"""
    path = write(tmp_path / "dd.urdf", diff_drive(tail=tail))
    model, layout = compiled(str(path))
    assert model.body_inertia[body(model, "ant")] == pytest.approx([1e-4, 1e-4, 1e-4])
    assert any("not positive definite" in n and "'ant'" in n for n in layout.import_notes)


def test_gazebo_mu1_becomes_the_caster_friction(tmp_path):
    tail = """
  <gazebo reference="caster_front"><mu1>0.05</mu1><mu2>0.07</mu2><material>Gazebo/Grey</material></gazebo>
  <gazebo reference="caster_back"><mu1>0.0</mu1><mu2>0.0</mu2></gazebo>
  <gazebo><plugin name="diff_drive" filename="libgazebo_ros_diff_drive.so"/></gazebo>
  <transmission name="left_trans"><type>transmission_interface/SimpleTransmission</type></transmission>"""
    path = write(tmp_path / "dd.urdf", diff_drive(tail=tail))
    model, layout = compiled(str(path))
    for link, mu in (("caster_front", 0.05), ("caster_back", 0.0)):
        b = body(model, link)
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_contype[g]]
        assert geoms and all(model.geom_friction[g, 0] == mu for g in geoms)
    notes = " | ".join(layout.import_notes)
    assert "link 'caster_front': sliding friction 0.05 from <gazebo> mu1" in notes and "mu2 0.07 not used" in notes
    assert "libgazebo_ros_diff_drive.so" in notes and "reference 'caster_front': material" in notes
    assert "1 <transmission> element(s) ignored ('left_trans')" in notes


def test_self_collision_off_unless_asked(tmp_path):
    path = write(tmp_path / "dd.urdf", diff_drive())
    off, _ = compiled(str(path))
    on, lay_on = compiled(RobotRef(str(path), self_collide=True))
    # bodies with collision geoms or joints: base_footprint has neither; base_link, 2 wheels, 2 casters
    assert off.nexclude == 5 * 4 // 2 and on.nexclude == 0
    assert not any("self-collision off" in n for n in lay_on.import_notes)


def test_revolute_wheels_lose_their_limits_and_other_limits_are_said(tmp_path):
    tail = (
        """
  <joint name="pan" type="revolute"><parent link="base_link"/><child link="head"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="head">"""
        + inertial(0.1, 1e-4, 1e-4, 1e-4)
        + "</link>"
    )
    path = write(tmp_path / "dd.urdf", diff_drive(wheel_type="revolute", tail=tail))
    model, layout = compiled(str(path))
    assert layout.frozen_joints == ("pan",)  # held by default (design §13): welded where the file puts it
    model, layout = compiled(RobotRef(model=str(path), free_joints=True))  # left free: its limits as published
    for j in layout.wheel_joints:
        assert not model.jnt_limited[model.joint(j).id]
    assert model.jnt_limited[model.joint("pan").id] and tuple(model.jnt_range[model.joint("pan").id]) == (-1, 1)
    notes = " | ".join(layout.import_notes)
    assert "wheel joint 'wheel_left_joint' is revolute with limits [-3.14, 3.14] rad: removed" in notes
    assert "joint limits kept: 'pan' [-1, 1] rad" in notes
    assert abs(layout.tau_max - 2.0) < 1e-12  # <limit effort> of the wheels: the motor limit


def test_gazebo_diff_drive_plugin_names_the_wheels_and_their_torque(tmp_path):
    """The maker's own simulation drives these joints at most this hard: read, and said. Here the
    plugin names the front/rear pair of a four-wheel base, which geometry alone cannot choose."""
    extra = (
        wheel("left", L_HALF, effort=False).replace("wheel_left", "rear_left").replace('"0 0.12 0"', '"-0.1 0.12 0"')
    )
    extra += (
        wheel("right", -L_HALF, effort=False)
        .replace("wheel_right", "rear_right")
        .replace(f'"0 {-L_HALF!r} 0"', f'"-0.1 {-L_HALF!r} 0"')
    )
    plugin = """
  <gazebo><plugin name="drive" filename="libgazebo_ros_diff_drive.so">
    <leftJoint>wheel_left_joint</leftJoint><rightJoint>wheel_right_joint</rightJoint><wheelTorque>1.25</wheelTorque>
  </plugin></gazebo>"""
    path = write(tmp_path / "dd.urdf", diff_drive(effort=False, tail=extra + plugin))
    with pytest.raises(InputError, match="cannot tell the driven wheels"):  # without the plugin
        prepare_robot(str(write(tmp_path / "bare.urdf", diff_drive(effort=False, tail=extra))))
    _, layout = compiled(str(path))
    assert layout.wheel_joints == ("wheel_left_joint", "wheel_right_joint")
    assert layout.tau_max == 1.25
    notes = " | ".join(layout.import_notes)
    assert "wheels from the Gazebo diff-drive plugin 'libgazebo_ros_diff_drive.so'" in notes
    assert "wheel torque limit 1.25 N·m from the Gazebo diff-drive plugin" in notes
    assert "plugin 'libgazebo_ros_diff_drive.so' (beyond its wheels and wheel torque)" in notes


def test_world_root_is_dropped(tmp_path):
    text = diff_drive().replace(
        '<link name="base_footprint"/>',
        '<link name="world"/><joint name="fix" type="fixed"><parent link="world"/><child link="base_footprint"/>'
        '</joint>\n  <link name="base_footprint"/>',
    )
    model, layout = compiled(str(write(tmp_path / "dd.urdf", text)))
    root = body(model, "base_footprint")
    assert model.jnt_type[model.body_jntadr[root]] == mujoco.mjtJoint.mjJNT_FREE
    assert any("link 'world' and its fixed joint 'fix'" in n for n in layout.import_notes)


def test_base_welded_to_the_root_is_the_root(tmp_path):
    path = write(tmp_path / "dd.urdf", diff_drive())
    _, layout = compiled(RobotRef(str(path), base="base_link"))
    assert layout.base == "base_footprint"
    assert any("base 'base_link' is welded to the root link 'base_footprint'" in n for n in layout.import_notes)


# ------------------------------------------------------------------ package:// and the search path
def _package(tmp_path: Path) -> tuple[Path, str]:
    """A ROS workspace ``ws/src/ddpkg`` (package.xml, meshes/chassis.stl) and a URDF outside it."""
    pkg = tmp_path / "ws" / "src" / "ddpkg"
    write(pkg / "package.xml", "<package><name>ddpkg</name></package>")
    box_stl(pkg / "meshes" / "chassis.stl", 0.15, 0.1, 0.025)
    box_stl(pkg / "meshes" / "shell.stl", 0.16, 0.11, 0.03)
    urdf = diff_drive(
        chassis_collision='<mesh filename="package://ddpkg/meshes/chassis.stl"/>',
        chassis_visual='<mesh filename="package://ddpkg/meshes/shell.stl"/>',
    )
    return pkg, urdf


def _chassis_half_extent(model: mujoco.MjModel) -> np.ndarray:
    b = body(model, "base_link")
    g = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == b and model.geom_contype[g])
    assert model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
    m = model.geom_dataid[g]
    vert = model.mesh_vert[model.mesh_vertadr[m] : model.mesh_vertadr[m] + model.mesh_vertnum[m]]
    return np.sort(np.ptp(vert, axis=0) / 2)


def test_package_uri_resolved_by_the_package_path_flag(tmp_path, monkeypatch):
    pkg, text = _package(tmp_path)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("BIOFORM_PACKAGE_PATH", raising=False)
    path = write(tmp_path / "robot" / "dd.urdf", text)
    args = cli.build_parser().parse_args(["robot", "check", str(path), "--package-path", f"ddpkg={pkg}"])
    from bioform_mj.cli.robot import ref_from_args

    ref = ref_from_args(args.model, args)
    assert ref.package_path == PackagePath([("ddpkg", str(pkg.resolve()))])
    model, _ = compiled(ref)
    assert np.allclose(_chassis_half_extent(model), [0.025, 0.1, 0.15], atol=1e-6)  # the STL's box


def test_package_uri_resolved_by_ros_package_path(tmp_path, monkeypatch):
    pkg, text = _package(tmp_path)
    path = write(tmp_path / "robot" / "dd.urdf", text)
    monkeypatch.delenv("BIOFORM_PACKAGE_PATH", raising=False)
    monkeypatch.setenv("ROS_PACKAGE_PATH", os.pathsep.join([str(tmp_path / "nothing"), str(tmp_path / "ws")]))
    model, layout = compiled(str(path))  # ws → src → ddpkg: found by its package.xml, two levels down
    assert np.allclose(_chassis_half_extent(model), [0.025, 0.1, 0.15], atol=1e-6)
    assert find_package("ddpkg")[0] == pkg.resolve()
    assert "ROS_PACKAGE_PATH" in find_package("ddpkg")[1]


def test_search_order_and_the_environment_forms(tmp_path, monkeypatch):
    a, b = tmp_path / "a" / "ddpkg", tmp_path / "b" / "ddpkg"
    a.mkdir(parents=True)
    b.mkdir(parents=True)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "a"))
    monkeypatch.setenv("BIOFORM_PACKAGE_PATH", f"ddpkg={b}")
    assert find_package("ddpkg")[0] == b.resolve()  # ours before ROS's
    assert find_package("ddpkg", PackagePath([("ddpkg", str(a))]))[0] == a.resolve()  # explicit first
    monkeypatch.setenv("BIOFORM_PACKAGE_PATH", str(b))  # a DIR entry: the package itself
    assert find_package("ddpkg")[0] == b.resolve()
    monkeypatch.delenv("BIOFORM_PACKAGE_PATH")
    assert find_package("ddpkg")[0] == a.resolve()
    assert find_package("other")[0] is None
    # last resort: a parent folder of the URDF named like the package (NAME/urdf/robot.urdf)
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    assert find_package("ddpkg", near=b / "urdf" / "r.urdf") == (b.resolve(), "a parent folder of the URDF file")


def test_missing_visual_mesh_is_dropped_and_said(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("BIOFORM_PACKAGE_PATH", raising=False)
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_visual='<mesh filename="package://nopkg/m/shell.stl"/>'))
    model, layout = compiled(str(path))
    assert model.nmesh == 0
    note = next(n for n in layout.import_notes if "visual mesh(es) dropped" in n)
    assert "'package://nopkg/m/shell.stl' of link 'base_link'" in note and "package 'nopkg'" in note


def test_collada_collision_mesh_converted_with_its_unit(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("collada")
    box = trimesh.creation.box(extents=[300.0, 200.0, 50.0])  # in millimetres, as the file says
    dae = trimesh.exchange.dae.export_collada(box)
    dae = dae.decode() if isinstance(dae, bytes) else dae
    dae = dae.replace("<asset>", '<asset><unit meter="0.001" name="millimeter"/>', 1)
    write(tmp_path / "meshes" / "chassis.dae", dae)
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="meshes/chassis.dae"/>'))
    model, layout = compiled(str(path))
    assert np.allclose(_chassis_half_extent(model), [0.025, 0.1, 0.15], atol=1e-6)
    assert any("collision mesh 'chassis.dae' of link 'base_link' converted with trimesh" in n for n in layout.notes)


def test_xacro_expanded_when_the_package_is_there(tmp_path, monkeypatch):
    """Asked for (``xacro = true``): a property, and ``$(find NAME)`` resolved through the same search path
    as ``package://``, in the sandboxed process (design §12); the import says xacro ran."""
    pytest.importorskip("xacro")
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    pkg, _ = _package(tmp_path)
    xmlns = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'
    props = '<xacro:property name="mc" value="2.0"/><xacro:property name="pkg" value="$(find ddpkg)"/>'
    text = diff_drive(chassis_collision='<mesh filename="${pkg}/meshes/chassis.stl"/>')
    text = text.replace('<robot name="dd">', f'<robot name="dd" {xmlns}>\n  {props}')
    text = text.replace(f'<mass value="{M_CHASSIS!r}"/>', '<mass value="${mc}"/>', 1)
    assert "${mc}" in text
    path = write(tmp_path / "robot" / "dd.urdf.xacro", text)
    model, layout = compiled(RobotRef(str(path), package_path=PackagePath([("ddpkg", str(pkg))]), xacro=True))
    assert abs(model.body_subtreemass[body(model, "base_footprint")] - hand_formula()[0]) < 1e-9
    assert any("expanded by xacro, which runs the file as a program" in n for n in layout.notes)
    assert np.allclose(_chassis_half_extent(model), [0.025, 0.1, 0.15], atol=1e-6)


# ------------------------------------------------------------------ bad input: one error line, exit 2
def _two_roots() -> str:
    return diff_drive(tail='<link name="stray"/>')


def _cycle() -> str:
    return diff_drive(
        tail='<joint name="loop" type="fixed"><parent link="caster_front"/><child link="base_footprint"/></joint>'
    )


def _no_wheels() -> str:
    return diff_drive().replace('type="continuous"', 'type="fixed"')


BAD_URDF = [
    ("two roots", _two_roots, "2 root links ('base_footprint', 'stray')"),
    ("cycle", _cycle, "no root link"),
    ("no links", lambda: '<robot name="x"></robot>', "no <link>"),
    ("no wheel joints", _no_wheels, "no continuous or revolute <joint>"),
    (
        "unresolved package",
        lambda: diff_drive(chassis_collision='<mesh filename="package://nopkg/meshes/c.stl"/>'),
        "<collision> mesh 'package://nopkg/meshes/c.stl' of link 'base_link': package 'nopkg' is on no search path",
    ),
    (
        "missing collision mesh",
        lambda: diff_drive(chassis_collision='<mesh filename="meshes/gone.stl"/>'),
        "<collision> mesh 'meshes/gone.stl' of link 'base_link': no file",
    ),
    ("not xml", lambda: "<robot name='x'><link name='a'>", "not valid XML"),
    ("not a urdf", lambda: "<sdf version='1.6'/>", "not <robot>"),
    (
        "a joint to nowhere",
        lambda: diff_drive(tail='<joint name="j" type="fixed"><parent link="base_link"/><child link="x"/></joint>'),
        "<joint name='j'>: child link 'x' is not a <link> of the file",
    ),
    (
        "wheels that do not touch the floor",
        lambda: diff_drive().replace(f'<cylinder radius="{R_WHEEL!r}"', '<cylinder radius="0.01"'),
        "no continuous or revolute joint can be a driven wheel",
    ),
]


@pytest.mark.parametrize("desc,make,needle", BAD_URDF, ids=[b[0] for b in BAD_URDF])
def test_bad_urdf_exits_2_with_one_line_naming_it(desc, make, needle, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("BIOFORM_PACKAGE_PATH", raising=False)
    path = write(tmp_path / "bad.urdf", make())
    out = tmp_path / "r.json"
    code = cli.main(["robot", "check", str(path), "--json", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error:") and needle in lines[0] and str(path) in lines[0], err
    assert not out.exists()


def test_bad_urdf_in_a_scenario_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    write(tmp_path / "bad.urdf", diff_drive(chassis_collision='<mesh filename="package://nopkg/c.stl"/>'))
    sc = write(tmp_path / "sc.toml", '[plant]\nkind = "mujoco"\nrobots = ["bad.urdf"]\n')
    out = tmp_path / "out"
    code = cli.main(["run", str(sc), "--duration", "0.05", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "package 'nopkg'" in err, err
    assert not out.exists()


def test_collada_collision_without_trimesh_says_how_to_convert(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "trimesh", None)  # as if the optional extra were not installed
    write(tmp_path / "meshes" / "c.dae", "<COLLADA/>")
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="meshes/c.dae"/>'))
    assert cli.main(["robot", "check", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "MuJoCo cannot read .dae meshes" in err[0] and "bioform-mj[urdf]" in err[0]
    assert "convert it to STL" in err[0]


def test_xacro_not_asked_for_says_how_to_ask(tmp_path, capsys, monkeypatch):
    """A robot file is data (design §12): a file that needs xacro is refused, naming --xacro, unless asked."""
    path = write(tmp_path / "dd.urdf.xacro", diff_drive())
    assert cli.main(["robot", "check", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pass --xacro" in err[0] and f"`xacro {path} > dd.urdf`" in err[0], err
    # a .urdf that still holds macros is xacro too; a commented-out include (as published) is not
    macro = write(tmp_path / "m.urdf", diff_drive().replace('"0.2"', '"${0.1*2}"', 1))
    assert cli.main(["robot", "check", str(macro)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(it holds xacro macros)" in err[0] and "> m.expanded.urdf`" in err[0], err
    if importlib.util.find_spec("xacro") is not None:  # asked for: $(find) through our search path
        missing = write(tmp_path / "f.urdf.xacro", diff_drive(tail='<xacro:include filename="$(find nopkg)/x.xacro"/>'))
        missing.write_text(
            missing.read_text().replace('name="dd"', 'name="dd" xmlns:xacro="http://ros.org/wiki/xacro"')
        )
        assert cli.main(["robot", "check", str(missing), "--xacro"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "$(find nopkg): package 'nopkg' is on no search path" in err[0], err
    commented = diff_drive().replace("<robot name", '<!-- <xacro:include filename="x"/> -->\n<robot name')
    from bioform_mj.robots.urdf import _read_text

    assert _read_text(write(tmp_path / "c.urdf", commented), PackagePath()) == commented


def test_package_path_flag_and_key_refuse_a_missing_directory(tmp_path, capsys):
    path = write(tmp_path / "dd.urdf", diff_drive())
    assert cli.main(["robot", "check", str(path), "--package-path", f"x={tmp_path / 'none'}"]) == 2
    assert "--package-path x=" in capsys.readouterr().err
    sc = write(tmp_path / "sc.toml", '[plant]\nkind = "mujoco"\nrobots = ["dd.urdf"]\npackage_path = {x = "none"}\n')
    assert cli.main(["run", str(sc), "--duration", "0.05", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plant.package_path.x" in err[0] and str(tmp_path / "none") in err[0], err


# ------------------------------------------------------------------ entries, TOML, scenario key
def test_bare_urdf_and_xml_names_in_a_toml_file_are_relative_to_it(tmp_path, monkeypatch):
    from bioform_mj.scenario.loader import load

    d = tmp_path / "proj"
    write(d / "dd.urdf", diff_drive())
    write(d / "pkgs" / "ddpkg" / "package.xml", "<package><name>ddpkg</name></package>")
    mjcf = Path(resolve_robot("paper").model).read_text()
    write(d / "robot.xml", mjcf)
    write(
        d / "sc.toml",
        '[plant]\nkind = "mujoco"\nrobots = ["dd.urdf", "robot.xml", {model = "dd.urdf", self_collide = true}]\n'
        'package_path = {ddpkg = "pkgs/ddpkg"}\n',
    )
    monkeypatch.chdir(tmp_path)  # not the TOML file's folder
    sc = load(str(d / "sc.toml"))
    models = [r.model for r in sc.plant.robots]
    assert models == [str((d / "dd.urdf").resolve()), str((d / "robot.xml").resolve()), str((d / "dd.urdf").resolve())]
    assert sc.plant.robots[2].self_collide and not sc.plant.robots[0].self_collide
    assert all(r.package_path == PackagePath([("ddpkg", str((d / "pkgs/ddpkg").resolve()))]) for r in sc.plant.robots)
    from bioform_mj.scenario.loader import from_dict

    assert from_dict(sc.to_dict()) == sc  # the tables and the scenario's package_path round-trip
    assert "package_path" not in load("paper").to_dict()["plant"]  # absent when unused: sweep keys unchanged
    # --set adds a package
    again = load(str(d / "sc.toml"), ["plant.package_path.other=" + json.dumps(str(d))])
    assert dict(again.plant.package_path) == {"ddpkg": str((d / "pkgs/ddpkg").resolve()), "other": str(d)}
    # --package-path of run/table1/sweep: the same key, absolute
    args = cli.build_parser().parse_args(["sweep", str(d / "sc.toml"), "--out", "o", "--package-path", "p2=proj"])
    monkeypatch.chdir(tmp_path)
    assert cli._package_overrides(args) == [f"plant.package_path.p2={json.dumps(str(d))}"]
    with pytest.raises(InputError, match="unknown robot 'dd'"):
        resolve_robot("dd")  # no suffix, no separator: a shipped name, which it is not


def test_check_file_needs_no_mujoco_and_names_the_package(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    path = write(tmp_path / "dd.urdf", diff_drive(chassis_collision='<mesh filename="package://nopkg/c.stl"/>'))
    with pytest.raises(InputError, match="nopkg"):
        check_file(RobotRef(str(path)))
    pkg = tmp_path / "nopkg"
    box_stl(pkg / "c.stl", 0.1, 0.1, 0.1)
    check_file(RobotRef(str(path), package_path=PackagePath([("nopkg", str(pkg))])))


# ------------------------------------------------------------------ a run, and its scene.xml (item 7)
MJCF_WITH_MESH = """<mujoco model="meshbot">
  <compiler meshdir="meshes" texturedir="textures"/>
  <asset><mesh name="shell" file="shell.stl"/><texture name="paint" type="2d" file="paint.png"/>
    <material name="paint" texture="paint"/></asset>
  <worldbody>
    <body name="base" pos="0 0 0.05">
      <freejoint/>
      <inertial pos="0 0 0" mass="2" diaginertia="0.01 0.012 0.02"/>
      <geom type="mesh" mesh="shell" pos="0 0 0.03" contype="0" conaffinity="0" material="paint"/>
      <geom type="box" size="0.15 0.1 0.025" pos="0 0 0.03"/>
      <geom type="sphere" size="0.015" pos="0.12 0 -0.035" friction="0.01"/>
      <geom type="sphere" size="0.015" pos="-0.12 0 -0.035" friction="0.01"/>
      <body name="lw" pos="0 0.12 0"><joint name="left_wheel" axis="0 1 0"/>
        <geom name="left_wheel_collision" type="sphere" size="0.05" mass="0.2"/></body>
      <body name="rw" pos="0 -0.12 0"><joint name="right_wheel" axis="0 1 0"/>
        <geom name="right_wheel_collision" type="sphere" size="0.05" mass="0.2"/></body>
    </body>
  </worldbody>
  <actuator>
    <motor name="left_motor" joint="left_wheel" ctrlrange="-0.3 0.3"/>
    <motor name="right_motor" joint="right_wheel" ctrlrange="-0.3 0.3"/>
  </actuator>
</mujoco>
"""


def test_run_with_urdf_and_mesh_robots_and_its_scene_loads_alone(tmp_path, monkeypatch, capsys):
    """``bioform run`` of a TOML scenario with URDF robots (package:// meshes through --package-path)
    and an MJCF robot with an STL mesh; the run's scene.xml loads from another folder (2.4 s here,
    with the MuJoCo kernels compiled)."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    pkg, text = _package(tmp_path)
    proj = tmp_path / "proj"
    write(proj / "dd.urdf", text)
    write(proj / "mesh_robot.xml", MJCF_WITH_MESH)
    box_stl(proj / "meshes" / "shell.stl", 0.14, 0.09, 0.02)
    tiny_png(proj / "textures" / "paint.png")
    write(proj / "sc.toml", '[plant]\nkind = "mujoco"\nrobots = ["dd.urdf", "mesh_robot.xml", "dd.urdf"]\n')
    out = tmp_path / "run"
    code = cli.main(
        ["run", str(proj / "sc.toml"), "--duration", "0.5", "--package-path", f"ddpkg={pkg}", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["sim_time_s"] >= 0.5 - 1e-9
    assert any("dd.urdf: self-collision off" in w for w in summary["import_warnings"])
    assert "warning: dd.urdf: wheels found" in err
    xml = (out / "scene.xml").read_text()
    for machine_path in (str(tmp_path), str(Path.home()), str(Path(mujoco.__file__).parent)):
        assert machine_path not in xml
    assert sorted(p.name for p in (out / "assets").iterdir()) == [
        "chassis.stl",
        "paint.png",
        "shell-2.stl",
        "shell.stl",
    ]
    monkeypatch.chdir(tmp_path / "ws")  # elsewhere
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    assert model.ntex >= 1 and model.tex_height[model.texture("f2/paint").id] == 2  # texturedir resolved
    assert model.nmesh == 2 * 2 + 1  # two URDF robots × (chassis, shell), one MJCF shell
    assert model.nexclude == 2 * 10  # each URDF robot's own pairs, none between robots
    assert [layout_of(model, p).file for p in ("f1/", "f2/")] == ["dd.urdf", "mesh_robot.xml"]  # no folder


def test_portable_xml_copies_each_file_once_and_renames_clashes(tmp_path):
    from bioform_mj.outputs.scenexml import portable_xml, write_scene

    a, b = box_stl(tmp_path / "a" / "m.stl", 0.1, 0.1, 0.1), box_stl(tmp_path / "b" / "M.STL", 0.2, 0.1, 0.1)
    xml = (
        f'<mujoco><compiler meshdir="x"/><asset><mesh name="m1" file="{a}"/><mesh name="m2" file="{a}"/>'
        f'<mesh name="m3" file="{b}"/></asset><worldbody><geom type="mesh" mesh="m1"/>'
        '<geom type="mesh" mesh="m3"/></worldbody></mujoco>'
    )
    text, copies = portable_xml(xml)
    assert copies == {str(a): "m.stl", str(b): "M-2.stl"} and "meshdir" not in text and str(tmp_path) not in text
    out = tmp_path / "run"
    out.mkdir()
    assert write_scene(out, xml) == ["M-2.stl", "m.stl"]
    assert (out / "assets" / "M-2.stl").read_bytes() == b.read_bytes()
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    assert np.isclose(model.mesh_vert[model.mesh_vertadr[2] :].max(), 0.2, atol=1e-6)


def test_a_runs_assets_folder_is_a_runs_own_and_overwrite_clears_it(tmp_path):
    from bioform_mj.outputs.rundir import RunDir, survey

    run = tmp_path / "run"
    box_stl(run / "assets" / "m.stl", 0.1, 0.1, 0.1)
    (run / "scene.xml").write_text("<mujoco/>")
    assert survey(run) == (["assets/", "scene.xml"], [])
    with RunDir(run, overwrite=True):
        assert not (run / "assets").exists()
    (run / "assets").mkdir()
    (run / "assets" / "notes.txt").write_text("mine")  # not a suffix a run writes: the user's, kept
    assert survey(run)[1] == ["assets/notes.txt"]


def test_an_xml_urdf_and_model_uris_and_file_uris(tmp_path, monkeypatch):
    """An ``.xml`` whose root is ``<robot>`` is URDF; ``model://NAME`` is searched like a package;
    ``file://`` is a file."""
    from bioform_mj.robots.urdf import is_urdf

    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    pkg, _ = _package(tmp_path)
    text = diff_drive(
        chassis_collision='<mesh filename="model://ddpkg/meshes/chassis.stl"/>',
        chassis_visual=f'<mesh filename="file://{pkg}/meshes/shell.stl"/>',
    )
    path = write(tmp_path / "robot.xml", text)
    assert is_urdf(path) and not is_urdf(resolve_robot("paper").model)
    model, layout = compiled(RobotRef(str(path), package_path=PackagePath([("ddpkg", str(pkg))])))
    assert np.allclose(_chassis_half_extent(model), [0.025, 0.1, 0.15], atol=1e-6)
    assert model.nmesh == 2 and not any("dropped" in n for n in layout.import_notes)
