"""Building a large scene: the grouped attach, one preparation per distinct robot and the per-robot lookups give
the scene, the compiled model and the plant's lookups of the robot-by-robot build exactly (issue 28 item 6;
docs/findings/performance.md, "Building the scene").

Ground truth is computed independently: the robot-by-robot build (``GROUP_FROM`` raised above n, the way every scene
was built before), a fresh ``prepare_robot`` per robot, and brute-force walks (every geom of the model, every
body's chain of parents, every pair of robots)."""

from __future__ import annotations

import threading
import warnings

import mujoco
import numpy as np
import pytest

from bioform_mj.plants.mujoco.contacts import robot_geoms
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots import prepare, scene
from bioform_mj.robots.layout import subtree, welded_to
from bioform_mj.robots.refs import models_dir

PAPER = str(models_dir() / "paper_robot.xml")
LAB = str(models_dir() / "lab_robot.xml")
STRETCH = str(models_dir() / "stretch_robot.xml")


def _team(n: int) -> tuple[list[str], np.ndarray]:
    """n robots of three kinds (one with joints beyond its wheels), 1.5 m apart in a row, headings varied."""
    files = [(PAPER, LAB, STRETCH)[i % 3] for i in range(n)]
    poses = np.array([[1.5 * i, 0.25 * (i % 4), 0.37 * i - 2.0] for i in range(n)])
    return files, poses


def _arrays(model: mujoco.MjModel) -> dict[str, bytes]:
    """Every numeric array of a compiled model, as bytes (bit-exact comparison)."""
    out = {}
    for name in dir(model):
        a = getattr(model, name, None) if not name.startswith("_") else None
        if isinstance(a, np.ndarray):
            out[name] = a.shape, a.dtype.str, a.tobytes()
    return out


def _build(monkeypatch, files, poses, group_from: int, fan: int = scene.GROUP_FAN, **kw) -> tuple[str, dict]:
    monkeypatch.setattr(scene, "GROUP_FROM", group_from)
    monkeypatch.setattr(scene, "GROUP_FAN", fan)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no MuJoCo warning (the empty prefix's included) reaches the caller
        spec = scene.build_scene(files, poses, **kw)
        model = spec.compile()  # a grouped scene says nothing at compile either
        xml = spec.to_xml()
    return xml, _arrays(model)


@pytest.mark.parametrize(
    "group_from,fan,kw",
    [
        (16, 8, {}),  # the defaults: 20 robots = one group of 16 and one of 4
        (2, 3, {"sensors": True}),  # three levels of groups, with the odometry sensors
        (3, 2, {"payloads": [(0.5 + 0.1 * i, 0.01 * i) for i in range(20)], "friction_patch": (0, -1, 5, 1, 0.3)}),
    ],
)
def test_grouped_attach_is_the_robot_by_robot_scene(monkeypatch, group_from, fan, kw):
    """The scene attached in groups writes the same MJCF and compiles to the same model, byte for byte, as the
    scene attached robot by robot (the same names, default classes, body order, poses)."""
    files, poses = _team(20)
    ref_xml, ref_model = _build(monkeypatch, files, poses, 10**9, **kw)
    xml, model = _build(monkeypatch, files, poses, group_from, fan, **kw)
    assert xml == ref_xml
    assert model.keys() == ref_model.keys() and len(model) > 100
    assert [k for k in model if model[k] != ref_model[k]] == []
    assert all(f'name="f{i + 1}/base"' in xml for i in range(20))


def test_prepare_robots_reads_each_distinct_robot_once(monkeypatch):
    """Repeats of one robot are copies of its one preparation: prepare_robot runs once per distinct entry, the
    copies are independent specs (a payload on one leaves the others) and the scene equals the one built from a
    fresh preparation per robot."""
    files, poses = _team(7)
    calls: list = []
    real = prepare.prepare_robot

    def counting(entry):
        calls.append(entry)
        return real(entry)

    monkeypatch.setattr(prepare, "prepare_robot", counting)
    got = prepare.prepare_robots(files)
    assert sorted(calls) == sorted({PAPER, LAB, STRETCH})
    assert len(got) == 7 and len({id(g[0]) for g in got}) == 7
    fresh = [real(f) for f in files]
    for (s, lay, axle, yaw), (s0, lay0, axle0, yaw0) in zip(got, fresh):
        assert lay == lay0 and yaw == yaw0 and np.array_equal(axle, axle0)
        assert s.to_xml() == s0.to_xml()
    base = got[3][0].body(got[3][1].base)
    mass0 = got[0][0].body(got[0][1].base).mass
    base.mass = 99.0
    assert got[0][0].body(got[0][1].base).mass == mass0 == fresh[0][0].body(fresh[0][1].base).mass
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = scene.build_scene(files, poses, prepared=prepare.prepare_robots(files)).to_xml()
        b = scene.build_scene(files, poses, prepared=fresh).to_xml()
    assert a == b


def _ancestors(model: mujoco.MjModel, b: int) -> list[int]:
    out = [b]
    while out[-1] != 0:
        out.append(int(model.body_parentid[out[-1]]))
    return out


def test_subtree_and_welded_to_against_parent_walks():
    """subtree / welded_to (looking only within the body's own tree) against a walk up every body's parents."""
    files, poses = _team(6)
    m = scene.build_scene(files, poses).compile()
    for root in range(m.nbody):
        want = [b for b in range(m.nbody) if root in _ancestors(m, b)]
        assert subtree(m, root).tolist() == want
        below = {b: _ancestors(m, b)[: _ancestors(m, b).index(root)] for b in want}  # b up to root's child
        chain = [b for b in want if all(m.body_jntnum[a] == 0 for a in below[b])]
        assert welded_to(m, root).tolist() == chain
    assert len(subtree(m, 0)) == m.nbody


def test_plant_lookups_against_brute_force():
    """The plant's collision geoms per robot (every geom of the model tested for its tree), and the start-overlap
    check (every pair tested) on a team where followers 2 and 3 stand 0.15 m apart, the others 1.5 m."""
    files, poses = _team(6)
    poses[2, :2] = poses[1, :2] + [0.15, 0.0]
    plant = MujocoPlant(files, poses, 0.004, 0.004)
    m, d = plant.model, plant.data
    for i, b in enumerate(plant._base):
        want = [
            g
            for g in range(m.ngeom)
            if m.body_rootid[m.geom_bodyid[g]] == m.body_rootid[b] and (m.geom_contype[g] or m.geom_conaffinity[g])
        ]
        assert plant.contact_geoms[i] == want and len(want) >= 3
    geoms, radii = robot_geoms(m, d, plant._base, plant._axle_world(d))
    assert geoms == plant.contact_geoms and np.array_equal(radii, plant.footprint_radius)
    dd = mujoco.MjData(m)
    mujoco.mj_forward(m, dd)
    want = []
    for i in range(6):
        for j in range(i + 1, 6):
            dist = min(mujoco.mj_geomDistance(m, dd, a, b, 1.0, None) for a in geoms[i] for b in geoms[j])
            if dist < -1e-4:
                want.append((i + 1, j + 1))
                d23 = dist
    got = plant.start_overlaps()
    assert want == [(2, 3)]
    assert got == [f"followers 2 and 3 overlap by {-d23 * 100:.3g} cm"]


def test_team_checks_see_each_robot_as_alone():
    """The pre-run checks that look at one robot of a team (tip margins, floor contacts, the level-stance check, which
    now look only at that robot's geoms, contacts and rolling joints) give for each robot of a 6-robot team what
    they give for the same robot alone in its own scene (support geoms, contact roles and counts exactly;
    margins, heights and loads to 1e-6)."""
    from bioform_mj.assess.check import tip_margins
    from bioform_mj.robots.contacts import floor_contacts
    from bioform_mj.robots.level_support import level_support

    files, poses = _team(6)
    team = MujocoPlant(files, poses, 0.004, 0.004)
    scratch, settled = mujoco.MjData(team.model), team.settled_data()
    mujoco.mj_kinematics(team.model, scratch)
    for i, f in enumerate(files):
        alone = MujocoPlant([f], poses[i : i + 1], 0.004, 0.004)
        s1, d1 = mujoco.MjData(alone.model), alone.settled_data()
        mujoco.mj_kinematics(alone.model, s1)
        got, want = tip_margins(team.model, scratch, f"f{i + 1}/"), tip_margins(alone.model, s1, "f1/")
        assert [n.split("/", 1)[1] for n in got["support_geoms"]] == [n.split("/", 1)[1] for n in want["support_geoms"]]
        assert len(got["support_geoms"]) >= 3
        for k in ("forward", "backward", "lateral"):
            assert got["tip_accel_mps2"][k] == pytest.approx(want["tip_accel_mps2"][k], rel=1e-6)
        assert got["com_height_m"] == pytest.approx(want["com_height_m"], rel=1e-6)
        fc, fc1 = (
            floor_contacts(team.model, settled, team.layouts[i], f"f{i + 1}/"),
            floor_contacts(alone.model, d1, alone.layouts[0], "f1/"),
        )
        key = ("body", "geom", "role", "points", "rolls", "welded_to_base", "condim")
        assert [tuple(r[k] for k in key) for r in fc] == [tuple(r[k] for k in key) for r in fc1]
        assert [r["role"] for r in fc].count("wheel") == 2
        assert [r["load_n"] for r in fc] == pytest.approx([r["load_n"] for r in fc1], rel=1e-6, abs=1e-9)
        w = team.params[i].mass * 9.81
        assert (level_support(team.model, settled, team.layouts[i], w, 0.99) is None) == (
            level_support(alone.model, d1, alone.layouts[0], w, 0.99) is None
        )


def test_the_empty_prefix_filter_is_per_thread_and_puts_the_handler_back():
    """Two scene builds' filters of the empty-prefix warning open in two threads at once (A opens, B opens, A
    closes, B closes: the order in which swapping the process's handler per block left A's filter installed):
    MuJoCo's own warning from a real empty-prefix attach is dropped in each thread inside its block, the same text
    from a thread outside any block and any other text reach the handler installed before, and that handler is
    installed again at the end."""
    text = scene._EMPTY_PREFIX
    seen: list[str] = []

    def mine(msg: str) -> None:
        seen.append(msg)

    def attach_empty() -> None:  # MuJoCo warns `text` in the calling thread
        group = mujoco.MjSpec()
        group.worldbody.add_body(name="b").add_geom(size=[0.1, 0, 0])
        parent = mujoco.MjSpec()
        parent.attach(group, prefix="", frame=parent.worldbody.add_frame())

    a_open, b_open, main_done, a_closed = (threading.Event() for _ in range(4))
    errors: list[BaseException] = []

    def a() -> None:
        try:
            with scene._without_warning(text):
                a_open.set()
                assert b_open.wait(30) and main_done.wait(30)
                attach_empty()
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors.append(exc)
        finally:
            a_closed.set()

    def b() -> None:
        try:
            assert a_open.wait(30)
            with scene._without_warning(text):
                b_open.set()
                assert a_closed.wait(30)
                attach_empty()
                mujoco.get_mju_user_warning()("another warning")
        except BaseException as exc:  # noqa: BLE001
            errors.append(exc)

    before = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(mine)
    try:
        threads = [threading.Thread(target=a), threading.Thread(target=b)]
        for t in threads:
            t.start()
        assert b_open.wait(30)
        attach_empty()  # both blocks open, none in this thread: passed on
        main_done.set()
        for t in threads:
            t.join(30)
        assert not errors, errors
        assert seen == [text, "another warning"]
        assert mujoco.get_mju_user_warning() is mine
    finally:
        mujoco.set_mju_user_warning(before)
