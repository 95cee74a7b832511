"""design §13.3: the scene's own slippery surfaces (friction patch, ``floor_friction``) against a robot's
priority geoms: the smaller friction of the pair (ODE/Gazebo's rule), not the priority geom's own.

The robot: the shipped TurtleBot3 with its wheels given ``priority = 2`` and μ 0.5 (what a URDF wheel
with Gazebo ``mu1`` 0.5 becomes, urdf.py) and its frictionless ball caster (priority 2, condim 1).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from bioform_mj.robots.entries import resolve_robot
from bioform_mj.robots.refs import models_dir
from bioform_mj.robots.scene import build_scene
from bioform_mj.robots.surfaces import min_friction_candidates

#: robot 1 on a patch around the origin, robot 2 two metres away on the floor
POSES = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
PATCH = (-0.5, -0.5, 0.5, 0.5)


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    src = (models_dir() / "tb3_robot.xml").read_text()
    wheel = 'condim="3" friction="1 0.005 0.0001" solref="0.002 1"'
    assert src.count(wheel) == 1
    path = tmp_path_factory.mktemp("surfaces") / "tb3_mu05.xml"
    path.write_text(src.replace(wheel, 'condim="3" priority="2" friction="0.5 0.005 0.0001" solref="0.002 1"'))
    return resolve_robot(str(path))


def _contacts(robot, **kw) -> tuple[mujoco.MjModel, dict]:
    """Compile the two-robot scene, settle 20 steps; {(robot geom, surface): every contact of the two}."""
    m = build_scene([robot, robot], POSES, **kw).compile()
    d = mujoco.MjData(m)
    for _ in range(20):
        mujoco.mj_step(m, d)
    out = {}
    for c in d.contact[: d.ncon]:
        a, b = m.geom(c.geom[0]).name, m.geom(c.geom[1]).name
        surf, geom = (a, b) if a in ("floor", "friction_patch") else (b, a)
        out.setdefault((geom, surf), []).append(c)
    return m, out


def test_icy_patch_beats_a_priority_wheel_and_the_caster_stays_frictionless(robot):
    m, every = _contacts(robot, friction_patch=(*PATCH, 0.05))
    # the explicit pair replaces MuJoCo's own contact of the two geoms: one contact per wheel, none with its 0.5
    for side in ("left", "right"):
        (k,) = every[(f"f1/{side}_wheel_collision", "friction_patch")]
        assert k.friction[0] == pytest.approx(0.05)
    c = {key: ks[0] for key, ks in every.items()}
    assert m.npair == 4  # 2 robots x 2 wheels; the caster (mu 0) needs none
    for side in ("left", "right"):
        on, off = c[(f"f1/{side}_wheel_collision", "friction_patch")], c[(f"f2/{side}_wheel_collision", "floor")]
        assert on.friction[0] == pytest.approx(0.05) and on.friction[1] == pytest.approx(0.05)  # min(0.5, 0.05)
        assert off.friction[0] == pytest.approx(0.5)  # off the patch: its own, as before
        # everything but friction as MuJoCo's priority rule gives it (the wheel's condim and solref)
        assert on.dim == off.dim == 3 and np.array_equal(on.solref, off.solref) and on.solref[0] == 0.002
        assert np.array_equal(on.solimp, off.solimp) and on.includemargin == off.includemargin
    caster_on, caster_off = c[("f1/back_caster", "friction_patch")], c[("f2/back_caster", "floor")]
    assert caster_on.dim == caster_off.dim == 1 and caster_on.friction[0] < 1e-4  # frictionless on the patch too


def test_patch_rougher_than_the_wheel_leaves_its_friction_by_priority(robot):
    m, every = _contacts(robot, friction_patch=(*PATCH, 0.8))
    c = {key: ks[0] for key, ks in every.items()}
    assert m.npair == 0  # min(0.5, 0.8) = 0.5 is what the priority gives already
    assert c[("f1/left_wheel_collision", "friction_patch")].friction[0] == pytest.approx(0.5)


def test_floor_friction_below_the_wheels_is_the_floors(robot):
    m, every = _contacts(robot, floor_friction=0.3)
    c = {key: ks[0] for key, ks in every.items()}
    assert m.npair == 4
    assert c[("f2/right_wheel_collision", "floor")].friction[0] == pytest.approx(0.3)
    assert c[("f2/back_caster", "floor")].dim == 1
    from bioform_mj.plants.mujoco.plant import MujocoPlant

    plant = MujocoPlant([robot, robot], POSES, 0.001, 0.001, floor_friction=0.3)
    assert plant._wheel_friction(1) == pytest.approx(0.3)  # the traction limit's μ is the pair's


def test_no_patch_or_shipped_robots_add_no_pair(robot):
    """Bit-identical where nothing is more slippery than a priority geom: no pair is added at all."""
    assert build_scene([robot, robot], POSES).compile().npair == 0
    for name in ("paper", "tb3", "lab"):  # their priority geoms are frictionless casters
        spec = build_scene([resolve_robot(name)] * 2, POSES, friction_patch=(*PATCH, 0.05), floor_friction=0.2)
        assert not min_friction_candidates(spec, "friction_patch") and spec.compile().npair == 0


def test_published_urdf_caster_with_gazebo_mu_gets_the_patch_friction(monkeypatch):
    """The Create 3 URDF (tests/zoo): caster and bumper with Gazebo mu1 0.1 (priority 2), wheels mu1 1."""
    from pathlib import Path

    from bioform_mj.robots.refs import RobotRef

    zoo = Path(__file__).resolve().parent / "zoo" / "create3_urdf"
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(zoo))
    ref = RobotRef(
        model=str(zoo / "create3.urdf"),
        base="base_link",
        left_wheel="left_wheel_joint",
        right_wheel="right_wheel_joint",
        tau_max=0.05,
    )
    m, every = _contacts(ref, friction_patch=(*PATCH, 0.05))
    c = {key: ks[0] for key, ks in every.items()}
    assert m.npair == 4  # 2 robots x (caster, bumper); the wheels (mu 1, priority 0) get the patch's by priority
    on = {g: k for (g, s), k in c.items() if s == "friction_patch"}
    off = {g: k for (g, s), k in c.items() if s == "floor"}
    caster_on = [k for g, k in on.items() if g.startswith("f1/front_caster_link/")]
    caster_off = [k for g, k in off.items() if g.startswith("f2/front_caster_link/")]
    assert len(caster_on) == len(caster_off) == 1
    assert caster_on[0].friction[0] == pytest.approx(0.05) and caster_off[0].friction[0] == pytest.approx(0.1)
    assert on["f1/left_wheel_joint_contact"].friction[0] == pytest.approx(0.05)
    assert off["f2/left_wheel_joint_contact"].friction[0] == pytest.approx(1.0)


def test_obstacle_against_a_priority_wheel_is_the_smaller_friction_already(robot):
    """An obstacle (mu 1, priority 0) touching the left wheel's side: MuJoCo's priority rule gives the wheel's
    0.5 = min(0.5, 1), no pair needed; the shipped tb3 wheel (mu 1, priority 0) gets max(1, 1) = 1."""
    from bioform_mj.formation.obstacles import Obstacle

    wall = Obstacle(
        name="obstacle_1", shape="box", x=0.0, y=0.08 + 0.009 + 0.05 - 5e-4, size=(0.02, 0.05, 0.05), yaw=0.0
    )
    for ref, mu in ((robot, 0.5), (resolve_robot("tb3"), 1.0)):
        m = build_scene([ref], POSES[:1], obstacles=[wall]).compile()
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        touch = [c for c in d.contact[: d.ncon] if m.geom("obstacle_1").id in c.geom]
        assert (
            m.npair == 0
            and touch
            and {m.geom(g).name for c in touch for g in c.geom}
            == {
                "obstacle_1",
                "f1/left_wheel_collision",
            }
        )
        assert all(c.friction[0] == pytest.approx(mu) for c in touch)
