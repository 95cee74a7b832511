"""A run is reproducible from its own record; jitter and the ``lost`` threshold scale as documented."""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest

from bioform_mj.assess.outcomes import follower_outcomes, lost_threshold_m
from bioform_mj.cli.main import main
from bioform_mj.scenario.loader import load
from bioform_mj.scenario.record import resolved_config, to_toml


def test_lost_threshold_scales_with_the_formation():
    assert lost_threshold_m(load("paper")) == pytest.approx(1.0, rel=1e-12)  # offsets (3,0), (4,±5): 10 m extent
    assert lost_threshold_m(load("tb3")) == pytest.approx(0.15, rel=1e-12)  # formation.scale 0.15
    assert lost_threshold_m(load("stretch")) == pytest.approx(0.25, rel=1e-12)
    assert lost_threshold_m(load("paper", ["formation.scale=0.5"])) == pytest.approx(0.5, rel=1e-12)


def _outcomes(sc, final):
    n = sc.n
    logd = {"t": np.array([0.0, 20.0]), "vel": np.zeros((2, n, 2)), "formation_error": np.zeros((2, n))}
    got = follower_outcomes(sc, None, None, logd, np.asarray(final), np.ones((n, 2)), 1e-3)
    return [lst[0]["kind"] if lst else "ok" for lst in got]  # each follower's most severe outcome


def test_a_follower_four_robot_lengths_off_is_lost_at_turtlebot_scale():
    """0.6 m off (four TurtleBot lengths) was `ok` under a fixed 1 m; at tb3's scale the threshold is 0.15 m."""
    assert _outcomes(load("tb3"), [0.6, 0.1, 0.004]) == ["lost", "ok", "ok"]
    assert _outcomes(load("paper"), [0.6, 0.99, 1.01]) == ["ok", "ok", "lost"]  # the paper's robots: 1 m, unchanged


def test_heading_jitter_does_not_scale_position_jitter_does():
    base = load("tb3").initial_poses()
    sc = load("tb3", ["formation.init_jitter=1.0", "sim.seed=4"])
    assert sc.formation.init_jitter == pytest.approx(0.15) and sc.formation.init_jitter_heading == 1.0
    d = sc.initial_poses() - base
    assert np.all(np.abs(d[:, :2]) <= 0.15) and np.abs(d[:, :2]).max() > 0.05
    assert np.all(np.abs(d[:, 2]) <= 1.0) and np.abs(d[:, 2]).max() > 0.15  # would be <= 0.15 rad if scaled
    # unscaled, one number for all three: the draw as before (bit for bit)
    sp = load("paper", ["formation.init_jitter=0.3", "sim.seed=4"])
    ref = np.array(sp.formation.initial_poses) + np.random.default_rng(4).uniform(-0.3, 0.3, size=(3, 3))
    assert np.array_equal(sp.initial_poses(), ref)
    # a heading jitter of its own
    sh = load("paper", ["formation.init_jitter_heading=0.5", "sim.seed=4"])
    dh = sh.initial_poses() - np.array(sh.formation.initial_poses)
    assert np.all(dh[:, :2] == 0) and 0 < np.abs(dh[:, 2]).max() <= 0.5


def test_bad_heading_jitter_is_refused():
    with pytest.raises(Exception, match="formation.init_jitter_heading"):
        load("paper", ["formation.init_jitter_heading=-0.5"])


def test_the_record_loads_back_to_the_same_scenario(tmp_path):
    import dataclasses

    sc = load("tb3", ["formation.init_jitter=0.2", "formation.frame=leader"], plant="ideal")
    cfg = resolved_config(sc)
    assert cfg["formation"]["scale"] == 1.0 and cfg["formation"]["offsets"][1] == pytest.approx([0.6, 0.75])
    text = to_toml(cfg, "a header\nof two lines")
    assert tomllib.loads(text) == json.loads(json.dumps(cfg))  # every value survives TOML
    (tmp_path / "r.toml").write_text(text)
    back = load(str(tmp_path / "r.toml"))
    assert back.formation.scale == 1.0
    # the record carries the scaled values with scale = time_scale = 1 (large16: time_scale 2.31, issue 28)
    assert back == dataclasses.replace(sc, formation=dataclasses.replace(sc.formation, scale=1.0, time_scale=1.0))
    assert np.array_equal(back.initial_poses(), sc.initial_poses())


@pytest.mark.parametrize("record", ["resolved.toml", "summary.json"])
def test_a_run_repeats_bit_for_bit_from_its_own_record(tmp_path, record):
    """tb3 (scale 0.15) with jitter: the record used to hold scaled lengths and the scale (offsets 0.045 m
    instead of 0.3 m on reloading); now `bioform run runs/X/<record>` gives the same log."""
    a, b = tmp_path / "a", tmp_path / "b"
    argv = ["run", "tb3", "--plant", "ideal", "--duration", "0.3", "--seed", "2", "--quiet"]
    assert main([*argv, "--set", "formation.init_jitter=0.2", "--out", str(a)]) == 0
    assert main(["run", str(a / record), "--out", str(b), "--quiet"]) == 0
    la, lb = np.load(a / "log.npz"), np.load(b / "log.npz")
    assert la.files == lb.files
    for k in la.files:
        assert np.array_equal(la[k], lb[k], equal_nan=True), k
    sa = json.loads((a / "summary.json").read_text())
    sb = json.loads((b / "summary.json").read_text())
    assert sa["config"] == sb["config"] and sa["formation_scale"] == 0.15 and sb["formation_scale"] == 1.0
    assert sa["config"]["formation"]["offsets"][0] == pytest.approx([0.45, 0.0])  # 3 m × 0.15, once
    assert [f["outcome"] for f in sa["followers"]] == [f["outcome"] for f in sb["followers"]]


def test_a_file_that_is_no_record_is_refused(tmp_path, capsys):
    p = tmp_path / "x.json"
    p.write_text('{"a": 1}')
    assert main(["run", str(p), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "summary.json" in err[0]


@pytest.mark.parametrize("preset", ["paper", "tb3", "stretch", "hetero", "payload", "fault_push", "large16"])
def test_every_kind_of_preset_round_trips_through_its_record(tmp_path, preset):
    """Faults, events, heterogeneous robots, scaled presets: the record loads back to the same scenario."""
    import dataclasses

    sc = load(preset)
    (tmp_path / "r.toml").write_text(to_toml(resolved_config(sc)))
    back = load(str(tmp_path / "r.toml"))
    # the record carries the scaled values with scale = time_scale = 1 (large16: time_scale 2.31, issue 28)
    assert back == dataclasses.replace(sc, formation=dataclasses.replace(sc.formation, scale=1.0, time_scale=1.0))
