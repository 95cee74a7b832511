"""Contacts between robots and with obstacles, impossible starts, obstacles in scenarios (issue 21, design §19).

Ground truth is MuJoCo's geometry: the paper robot's wheels are ellipsoids of half-width 0.02 m
at y = ±0.2 m, so two robots side by side with centres 0.6 m apart have a 0.16 m gap.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.core.errors import InputError, ScenarioError
from bioform_mj.run.simulate import make_plant, simulate
from bioform_mj.scenario.loader import load
from crossing import CROSSING

CROSS = {
    "name": "crossing",
    **CROSSING,
    "sim.duration": 3.0,
    "leader.x0": 0.0,
    "safety.distance": 0.1,
}


def _crossing(**more):
    return load("paper", {**CROSS, **more})


@pytest.fixture(scope="module")
def crossing():
    sc = _crossing()
    return sc, simulate(sc), simulate(sc, engine="stepwise")


def _contact_keys(f):
    return {k: v for k, v in f.items() if "contact" in k or "separation" in k or "close" in k or "outcome" in k}


def test_crossing_followers_collide_and_say_so(crossing):
    """Both followers touch each other (MuJoCo's contact list): ``collided`` naming the other, with
    the time; min separation ≤ 0 (interpenetration, exact); too close for ≥ the contact time.
    Measured: first touch t = 1.858 s, 2 contact events each (0.768 s in contact), min separation −6.0 mm,
    largest impulse 61.4 N·s, peak force 6.64 kN, too close 1.38 s."""
    _, res, _ = crossing
    for i, f in enumerate(res.summary["followers"]):
        other = f"follower {2 - i}"
        kinds = [o["kind"] for o in f["outcomes"]]
        assert "collided" in kinds and "too_close" in kinds
        hit = next(o for o in f["outcomes"] if o["kind"] == "collided")
        assert other in hit["detail"] and 1.0 < hit["t"] < 2.5
        assert f["outcome"] == "collided"  # the most severe here
        assert f["robot_contacts"] >= 1 and f["obstacle_contacts"] == 0
        assert f["robot_contact_max_impulse_ns"] > 0.1 and f["robot_contact_peak_force_n"] > 1.0
        assert f["min_separation_m"] <= 0.0 and f["min_separation_exact"] is True
        assert f["min_separation_with"] == other
        assert f["too_close_s"] >= f["robot_contact_time_s"] > 0


def test_crossing_engines_agree_bit_for_bit(crossing):
    """The compiled loop and the stepwise loop watch the same contacts (same physics, same kernels)."""
    _, a, b = crossing
    assert a.summary["engine"] == "compiled" and b.summary["engine"] == "stepwise"
    for fa, fb in zip(a.summary["followers"], b.summary["followers"]):
        assert _contact_keys(fa) == _contact_keys(fb)


def test_min_separation_side_by_side_is_the_geometry():
    """Two robots abreast at rest, centres 0.6 m apart: closest approach = 0.6 − 2 × 0.22 = 0.16 m
    (wheel to wheel, ``mj_geomDistance``) to 0.1 mm; no contact. Driving on in their slots the run's
    minimum stays within 5 mm of it (measured 0.1575 m: the start-up wobble)."""
    over = {
        "sim.duration": 0.5,
        "leader.kind": "line",
        "leader.speed": 0.2,
        "plant.kind": "mujoco",
        "graph.edges": [[1, 2]],
        "graph.leader_access": [1, 2],
        "formation.offsets": [[1.0, 0.3], [1.0, -0.3]],
        "formation.initial_poses": [[-1.0, 2.7, 0.0], [-1.0, 3.3, 0.0]],
    }
    plant = make_plant(load("paper", over))
    for _ in range(8):  # zero torque: they stand
        plant.step(np.zeros((2, 2)), 0.0)
    w = plant.contact_watch()
    assert w.min_sep == pytest.approx([0.16, 0.16], abs=1e-4) and w.sep_exact.all()
    assert list(w.min_sep_with) == [1, 0] and w.events.sum() == 0
    res = simulate(load("paper", over))
    for f in res.summary["followers"]:
        assert f["min_separation_exact"] is True
        assert 0.155 <= f["min_separation_m"] <= 0.16 + 1e-6
        kinds = [o["kind"] for o in f["outcomes"]]  # the learner's c_hat_off (design §14) is not a contact's
        assert not {"collided", "too_close"} & set(kinds) and f["robot_contacts"] == 0
        assert f["too_close_s"] is None  # safety.distance = 0: not watched


def test_obstacle_in_the_way_is_hit_and_named(tmp_path, capsys):
    """A box across a follower's path: ``collided`` with ``obstacle_1``, a ``warning:`` line, the
    obstacle in the compiled scene at its position."""
    sc = load(
        "paper",
        {
            "sim.duration": 2.0,
            "leader.kind": "line",
            "leader.y0": 0.0,
            "leader.speed": 1.0,
            "plant.kind": "mujoco",
            "graph.edges": [],
            "graph.leader_access": [1],
            "formation.offsets": [[1.0, 0.0]],
            "formation.initial_poses": [[-1.0, 0.0, 0.0]],
            "obstacles": [{"shape": "box", "position": [0.3, 0.0], "size": [0.05, 1.0, 0.3]}],
        },
    )
    plant = make_plant(sc)
    g = plant.model.geom("obstacle_1").id
    assert np.allclose(plant.data.geom_xpos[g], [0.3, 0.0, 0.3])
    res = simulate(sc, plant=plant)
    f = res.summary["followers"][0]
    assert f["obstacle_contacts"] >= 1 and f["robot_contacts"] == 0
    hit = next(o for o in f["outcomes"] if o["kind"] == "collided")
    assert "obstacle_1" in hit["detail"] and 0.0 < hit["t"] < 2.0
    assert f["min_obstacle_clearance_m"] <= 0.0 and f["min_obstacle_clearance_with"] == "obstacle_1"


def test_overlapping_start_refused_naming_followers():
    """Two followers abreast 0.3 m apart: each one's inner wheel (|y| 0.03..0.07 m from the middle)
    sits 1.5 cm deep in the other's chassis (half-width 0.095 m): InputError naming both, with the
    depth, before any work; one inside an obstacle: naming the obstacle."""
    sc = _crossing(**{"formation.initial_poses": [[-1.0, 0.15, 0.0], [-1.0, -0.15, 0.0]]})
    with pytest.raises(InputError, match=r"followers 1 and 2 overlap by 1.5 cm"):
        simulate(sc)
    sc = _crossing(obstacles=[{"shape": "cylinder", "position": [-1.0, 0.5], "size": [0.3, 0.2]}])
    with pytest.raises(InputError, match=r"follower 1 stands inside obstacle_1"):
        simulate(sc)


def test_overlapping_start_cli_exit_2(tmp_path, capsys):
    code = main(
        [
            "run",
            "paper",
            "--plant",
            "mujoco",
            "--set",
            "formation.initial_poses=[[0,0,0],[0,0,0],[-1,4,0]]",
            "--out",
            str(tmp_path / "r"),
            "--quiet",
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: impossible initial poses")
    assert "followers 1 and 2" in err[0]


def test_sweep_row_fails_for_an_impossible_start_only():
    from bioform_mj.jobs.sweep import expand, run_one

    specs = expand(
        "paper",
        1,
        ["bioinspired-learning"],
        ["formation.initial_poses=[[0,0,0],[0,0.2,0],[-1,4,0]];[[0,0,0],[-1,-4,0],[-1,4,0]]"],
        overrides=["plant.kind=mujoco", "sim.duration=0.2"],
        warn=None,
    )
    rows = [run_one(s) for s in specs]
    assert rows[0]["status"] == "failed" and "followers 1 and 2 overlap" in rows[0]["error"]
    assert rows[1]["status"] == "ok" and rows[1]["collisions"] == 0 and rows[1]["min_separation_m"] is None


@pytest.mark.parametrize(
    "override, key",
    [
        ({"obstacles": [{"shape": "box", "position": [1, 1], "size": [-0.1, 0.2, 0.3]}]}, "obstacles[0].size"),
        ({"obstacles": [{"shape": "cone", "position": [1, 1], "size": [0.1, 0.2]}]}, "obstacles[0].shape"),
        ({"obstacles": [{"shape": "cylinder", "position": [1, 1], "size": [0.1, 0.2, 0.3]}]}, "obstacles[0].size"),
        ({"safety.distance": -0.1}, "safety.distance"),
        (
            {"obstacle_field.count": 50, "obstacle_field.region": [0, 0, 1, 1], "obstacle_field.size": [0.3, 0.4]},
            "obstacle_field",
        ),
        (
            {"obstacles": [{"shape": "box", "position": [1, 1], "size": [0.1, 0.2, 0.3]}], "plant.kind": "ideal"},
            "obstacles",
        ),
    ],
)
def test_bad_obstacles_and_safety_refused(override, key):
    base = {"plant.kind": "mujoco"}
    with pytest.raises(ScenarioError) as exc:
        load("paper", {**base, **override})
    assert exc.value.key == key


def test_bad_obstacle_cli_one_error_line(tmp_path, capsys):
    code = main(["run", "paper", "--plant", "mujoco", "--set", "safety.distance=-1", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "safety.distance" in err[0] and err[0].startswith("error:")


def test_obstacle_field_seeded_keeps_out_of_leader_path():
    """Same seed, same field; another seed, another; every obstacle ≥ keep_out from the leader's
    sampled path, ≥ gap from the others, inside the region."""
    over = {
        "plant.kind": "mujoco",
        "sim.duration": 10.0,
        "obstacle_field.count": 12,
        "obstacle_field.region": [0.0, -2.0, 10.0, 8.0],
        "obstacle_field.keep_out": 1.0,
        "obstacle_field.gap": 0.2,
    }
    a = load("paper", {**over, "sim.seed": 3}).obstacle_list()
    b = load("paper", {**over, "sim.seed": 3}).obstacle_list()
    c = load("paper", {**over, "sim.seed": 4}).obstacle_list()
    assert [o.to_dict() for o in a] == [o.to_dict() for o in b] and len(a) == 12
    assert [o.to_dict() for o in a] != [o.to_dict() for o in c]
    sc = load("paper", {**over, "sim.seed": 3})
    t = np.arange(0, 10.0, 0.01)
    path = sc.build_leader().states(t)[0][:, :2]
    for i, o in enumerate(a):
        assert np.min(o.distance(path)) >= 1.0 - 0.02  # sampled every 0.05 s at 1 m/s: 2.5 cm
        assert 0.0 <= o.x <= 10.0 and -2.0 <= o.y <= 8.0
        for p in a[i + 1 :]:
            assert np.hypot(o.x - p.x, o.y - p.y) >= o.radius + p.radius + 0.2 - 1e-12


def test_box_distance_matches_geometry():
    """Signed footprint distance of a yawed box: inside −, on the edge 0, corners by Pythagoras."""
    from bioform_mj.formation.obstacles import Obstacle

    ob = Obstacle("obstacle_1", "box", 1.0, 2.0, (0.5, 0.2, 0.3), np.pi / 2)  # long side along y
    d = ob.distance(np.array([[1.0, 2.0], [1.0, 2.5], [1.3, 2.0], [1.5, 3.0]]))
    assert d == pytest.approx([-0.2, 0.0, 0.1, np.hypot(0.3, 0.5)])


def test_no_contact_fields_on_the_ideal_plant():
    res = simulate(dataclasses.replace(load("paper", {"sim.duration": 0.05})))
    f = res.summary["followers"][0]
    assert "min_separation_m" not in f and f["outcomes"] == []
    json.dumps(res.summary)


def test_obstacles_drawn_in_figure_and_rerun(tmp_path):
    """The log keeps the obstacles; the trajectory figure fills one footprint per obstacle and the
    rerun recording holds them as static boxes and cylinders."""
    from bioform_mj.formation.obstacles import from_rows
    from bioform_mj.outputs.figures import _trajectories
    from bioform_mj.outputs.rerun_log import read_entities, write_rrd

    sc = _crossing(
        **{
            "sim.duration": 0.1,
            "obstacles": [
                {"shape": "box", "position": [2.0, 0.0], "size": [0.1, 0.5, 0.2], "yaw": 0.5},
                {"shape": "cylinder", "position": [3.0, 1.0], "size": [0.2, 0.3]},
            ],
        }
    )
    res = simulate(sc)
    rows = res.log["obstacles"]
    assert rows.shape == (2, 7)
    obs = from_rows(rows)
    assert [o.shape for o in obs] == ["box", "cylinder"] and obs[0].yaw == pytest.approx(0.5)
    assert obs[1].size == pytest.approx((0.2, 0.3))
    fig = _trajectories(res.log, "t")
    assert len(fig.axes[0].patches) == 2
    ents = read_entities(write_rrd(res, tmp_path / "run.rrd"))
    assert "/world/obstacles/boxes" in ents and "/world/obstacles/cylinders" in ents


def test_obstacles_preset_followers_hit_the_fixed_obstacles():
    """The preset's fixed obstacles stand on the slot paths: follower 1 touches obstacle_1 when its
    slot reaches x = 5 (measured t = 7.59 s), follower 2 obstacle_2 at x = 6 (9.63 s); 3 fixed + 8
    field obstacles in the scene."""
    sc = load("obstacles", {"sim.duration": 10.0})
    assert len(sc.obstacle_list()) == 11
    fs = simulate(sc).summary["followers"]
    hit = {f["id"]: next((o for o in f["outcomes"] if o["kind"] == "collided"), None) for f in fs}
    assert "obstacle_1" in hit[1]["detail"] and 7.0 < hit[1]["t"] < 8.5
    assert "obstacle_2" in hit[2]["detail"] and 9.0 < hit[2]["t"] < 10.0


def test_table1_marks_every_outcome_kind():
    from bioform_mj.jobs.table1 import _mark

    f = {
        "outcome": "tipped",
        "outcomes": [
            {"kind": "tipped", "detail": "", "t": 1.0},
            {"kind": "collided", "detail": "touched follower 2", "t": 0.9},
            {"kind": "collided", "detail": "touched obstacle_1", "t": 2.0},
        ],
    }
    assert _mark({}, f) == " [tipped, collided]"
    assert _mark({}, {"outcome": "ok", "outcomes": []}) == ""
    assert _mark({"diverged": {"message": "x"}}, f) == " [diverged]"


def test_contact_list_found_with_a_mapped_radius_off_the_geometry():
    """A mapped wheel radius 40 % above the geometry: the robots start on their tyres all the same (the start
    height is the tyre's, design §14.4; before, they hung 4 cm above the floor), the watch finds MuJoCo's
    contact list, and the state at the start is the plant's."""
    sc = load("paper", {"plant.kind": "mujoco", "plant.robots": [{"model": "paper", "wheel_radius": 0.14}]})
    plant = make_plant(sc)
    assert plant.contacts.off == "" and plant.contacts.meta[3] > 1000
    d = mujoco_data_at_start(plant)
    assert d.ncon >= 2 * sc.n and np.allclose(plant.data.qpos, d.qpos)  # every robot's wheels on the floor


def mujoco_data_at_start(plant):
    import mujoco

    d = mujoco.MjData(plant.model)
    mujoco.mj_forward(plant.model, d)
    return d


def test_obstacle_field_keeps_off_the_start_positions():
    """A field over the followers' start area with keep_out: none within keep_out of a start (the
    same field kept off the leader's path only puts 13 of its 40 obstacles within 0.8 m of a start)."""
    over = {
        "plant.kind": "mujoco",
        "sim.duration": 2.0,
        "obstacle_field.count": 40,
        "obstacle_field.size": [0.05, 0.1],
        "obstacle_field.region": [-3.0, -5.0, 1.0, 5.0],
        "obstacle_field.keep_out": 0.8,
    }
    sc = load("paper", over)
    starts = sc.initial_poses()[:, :2]
    obs = sc.obstacle_list()
    assert min(float(np.min(o.distance(starts))) for o in obs) >= 0.8
    make_plant(sc)  # no impossible start
