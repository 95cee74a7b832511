"""Self contacts of the published geoms (design §13.1): a wheel geom inside the chassis is named although the
scene replaces it by a contact proxy, with its depth; the collision filter is MuJoCo's own."""

from __future__ import annotations

import mujoco
import pytest

from bioform_mj.assess.check import check
from bioform_mj.robots.overlaps import geom_overlaps
from bioform_mj.robots.refs import RobotRef

R, L, W = 0.05, 0.12, 0.01  # wheel radius, half track, half width (m)

#: a base whose wheels hang on suspension slides (as an iRobot Create 3 description publishes them), the
#: chassis box reaching {hy} m to each side: past the wheel's inner face at L - W it overlaps the wheel
SUSPENDED = """<mujoco model="suspended">
  <option timestep="0.001"/>
  <worldbody>
    <body name="base" pos="0 0 {r}">
      <freejoint/>
      <inertial pos="0.03 0 0.02" mass="3" diaginertia="0.02 0.02 0.03"/>
      <geom name="chassis" type="box" size="0.1 {hy} 0.03" pos="0 0 0.03"/>
      <geom name="caster" type="sphere" size="0.01" pos="0.08 0 {cz}" friction="0.0001" condim="1"/>
      <body name="left_sus" pos="0 {l} 0">
        <joint name="left_slide" type="slide" axis="0 0 1" range="-0.01 0.01"/>
        <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
        <body name="left_wheel_link">
          <joint name="left_wheel" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="0.2" diaginertia="1e-4 2e-4 1e-4"/>
          <geom name="left_tire" type="cylinder" size="{r} {w}" quat="0.7071068 0.7071068 0 0"/>
        </body>
      </body>
      <body name="right_sus" pos="0 -{l} 0">
        <joint name="right_slide" type="slide" axis="0 0 1" range="-0.01 0.01"/>
        <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
        <body name="right_wheel_link">
          <joint name="right_wheel" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="0.2" diaginertia="1e-4 2e-4 1e-4"/>
          <geom name="right_tire" type="cylinder" size="{r} {w}" quat="0.7071068 0.7071068 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _suspended(tmp_path, overlap: float):
    path = tmp_path / f"suspended_{overlap:g}.xml"
    path.write_text(SUSPENDED.format(r=R, l=L, w=W, hy=L - W + overlap, cz=-(R - 0.01)))
    return str(path)


def test_wheel_geom_inside_the_chassis_is_named_with_its_depth(tmp_path):
    """The tyre cylinders reach 8 mm into the chassis box (the smallest way out: along the axle; 50 mm down,
    150 mm along x). The scene replaces them by ellipsoid proxies and freezes the slides (the wheels are then
    the base's weld children, filtered), so its contact list has none of it: the pairs come from the published
    geoms at qpos0, not simulated, no force, a note each and no warning."""
    depth = 0.008
    rep = check(RobotRef(_suspended(tmp_path, depth), base="base", tau_max=1.0), identify_=False)
    assert any("proxy" in n and "left_tire" in n for n in rep["notes"])  # the scene did replace them
    pairs = {frozenset((c["body1"], c["body2"])): c for c in rep["self_contacts"]}
    assert set(pairs) == {frozenset(("base", "left_wheel_link")), frozenset(("base", "right_wheel_link"))}
    for side in ("left", "right"):
        c = pairs[frozenset(("base", f"{side}_wheel_link"))]
        assert c["depth_m"] == pytest.approx(depth, abs=1e-3)
        assert sorted(c["geoms"][0]) == sorted(["chassis", f"{side}_tire"])
        assert c["simulated"] is False and c["force_n"] == 0.0
        assert any(f"'{side}_wheel_link'" in n and "8 mm" in n and "frozen" in n for n in rep["notes"])
    assert not any("self_contacts" in r for r in rep["reasons"])
    # the slides left free: the wheels are no longer weld children of the base, the scene collides the pairs
    free = check(RobotRef(_suspended(tmp_path, depth), base="base", tau_max=1.0, free_joints=True), identify_=False)
    assert {c["simulated"] for c in free["self_contacts"]} == {True}
    assert len(free["self_contacts"]) == 2
    # 1 mm clear of the wheels: nothing
    clear = RobotRef(_suspended(tmp_path, -0.001), base="base", tau_max=1.0)
    assert check(clear, identify_=False)["self_contacts"] == []


#: bodies under one free root whose geoms overlap in every way MuJoCo's collision filter distinguishes (world
#: positions in the comments; the base box spans ±0.1 m)
FILTERS = """<mujoco>
  <asset><mesh name="tet" vertex="0 0 0  0.05 0 0  0 0.05 0  0 0 0.05"/></asset>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" pos="0 0 -0.5"/>
    <body name="base">
      <freejoint/>
      <geom name="base_box" type="box" size="0.1 0.1 0.1"/>
      <body name="child" pos="0.15 0 0">  <!-- x 0.09..0.21: 10 mm into the base -->
        <joint type="hinge" axis="0 1 0"/>
        <geom name="child_box" type="box" size="0.06 0.05 0.05"/>
        <body name="grandchild">  <!-- ball at (0.1, 0, 0.14): 10 mm into the base's top -->
          <joint type="hinge" axis="0 1 0"/>
          <geom name="grandchild_ball" type="sphere" size="0.05" pos="-0.05 0 0.14"/>
        </body>
        <body name="excluded">  <!-- ball at (0, 0, -0.14): 10 mm into the base's bottom, excluded -->
          <joint type="hinge" axis="0 1 0"/>
          <geom name="excluded_ball" type="sphere" size="0.05" pos="-0.15 0 -0.14"/>
        </body>
        <body name="masked">  <!-- box at y -0.14: 10 mm into the base, contype/conaffinity 2 against 1 -->
          <joint type="hinge" axis="0 1 0"/>
          <geom name="masked_box" type="box" size="0.05 0.05 0.05" pos="-0.15 -0.14 0" contype="2" conaffinity="2"/>
        </body>
        <body name="near">  <!-- box at y 0.1505: 0.5 mm off the base, within its 1 mm margin -->
          <joint type="slide" axis="0 0 1"/>
          <geom name="near_box" type="box" size="0.05 0.05 0.05" pos="-0.15 0.1505 0" margin="0.001"/>
        </body>
        <body name="mesh_body">  <!-- tetrahedron from (-0.12, 0, 0): 20 mm into the base -->
          <joint type="ball"/>
          <geom name="mesh_geom" type="mesh" mesh="tet" pos="-0.27 0 0"/>
        </body>
      </body>
      <body name="welded" pos="0.05 0 0.2">  <!-- no joint: the base's weld; into the grandchild's ball -->
        <geom name="welded_box" type="box" size="0.03 0.05 0.05"/>
      </body>
      <body name="welded2" pos="0.15 0 -0.07">  <!-- no joint: 10 mm into the child box (its weld child) -->
        <geom name="welded2_box" type="box" size="0.03 0.03 0.03"/>
      </body>
    </body>
  </worldbody>
  <contact>
    <exclude body1="base" body2="excluded"/>
    <pair geom1="base_box" geom2="child_box"/>
  </contact>
</mujoco>
"""


def test_geom_overlaps_are_the_pairs_mujoco_collides():
    """geom_overlaps (box prefilter, our reading of MuJoCo's filter, mj_geomDistance) finds exactly the body
    pairs of MuJoCo's own contact list at the same configuration, with its depths: a parent–child pair only
    through an explicit <pair>, a grandchild, a body welded to the base against the base's jointed child
    (weld-level filter: not against the base, nor the child), no pair across contype/conaffinity masks or an
    <exclude>, a pair 0.5 mm apart within its 1 mm margin (depth 0), a mesh, none with the world's floor."""
    model = mujoco.MjModel.from_xml_string(FILTERS)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    base = model.body("base").id
    want: dict[frozenset, float] = {}
    for k in range(data.ncon):
        c = data.contact[k]
        b1, b2 = int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])
        if 0 in (b1, b2):
            continue
        key = frozenset((b1, b2))
        want[key] = max(want.get(key, 0.0), -float(c.dist))
    got = {frozenset(p): row["depth_m"] for p, row in geom_overlaps(model, data, base).items()}
    name = lambda pairs: sorted(sorted(model.body(b).name for b in p) for p in pairs)  # noqa: E731
    assert name(got) == name(want)
    assert name(got) == [  # what the filter's cases make of it, by hand
        ["base", "child"],  # parent and child, but an explicit <pair>
        ["base", "grandchild"],
        ["base", "mesh_body"],
        ["base", "near"],  # 0.5 mm apart, margin 1 mm
        ["grandchild", "welded"],  # welded to the base, against a body two joints down
    ]  # not: base/excluded (<exclude>), base/masked (masks), child/welded2 (weld parent), base/welded (same weld)
    for key, d in want.items():
        assert got[key] == pytest.approx(d, abs=1e-6), name([key])
    assert got[frozenset((base, model.body("near").id))] == 0.0
