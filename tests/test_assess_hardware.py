"""The hardware-feasibility verdict of a run (issue 21 item 5, design §19): numbers against the robots' specs."""

from __future__ import annotations

import numpy as np
import pytest

from bioform_mj.assess.hardware import line, preset_control_rate
from bioform_mj.robots.entries import resolve_robot
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load
from crossing import CROSSING


def _run(name, **over):
    return simulate(load(name, {"sim.duration": 0.3, **over}, plant="mujoco"))


def test_paper_robot_at_its_own_rate_passes_and_says_what_it_skipped():
    """Paper robots at the paper preset's 1 kHz: control_rate 1000 ≤ 1000 Hz passes; torque sources
    have no no-load speed: wheel_speed skipped with the reason, not passed."""
    res = _run("paper")
    hw = res.summary["hardware"]
    c = hw["checks"]
    assert c["control_rate"]["value"] == pytest.approx(1000.0) and c["control_rate"]["limit"] == pytest.approx(1000.0)
    assert c["control_rate"]["pass"] is True
    assert c["wheel_speed"]["pass"] is None and "no-load" in c["wheel_speed"]["reason"]
    assert "top_speed" in c["wheel_speed"]["reason"]  # how to give it (design §21)
    f = res.summary["followers"]
    assert c["torque"]["value"] == pytest.approx(max(x["peak_abs_torque"] for x in f))
    assert c["torque"]["limit"] == pytest.approx(5.0) and c["torque"]["pass"] is True
    assert c["torque_saturation"]["value"] == pytest.approx(max(x["saturation_fraction"] for x in f))
    # the log's largest |dυ/dt| against the paper robot's static margin
    v = res.log["vel"][:, :, 0]
    acc = np.abs(np.diff(v, axis=0)) / np.diff(res.log["t"])[:, None]
    assert c["tip_over"]["value"] == pytest.approx(acc.max())
    # never "pass" with a check skipped (design §21): incomplete, naming it
    assert hw["verdict"] == ("fail" if hw["failed"] else "incomplete")
    assert "wheel_speed" in hw["not_checked"] and "wheel_speed" in line(hw)
    assert set(hw["failed"]) == {k for k, x in c.items() if x["pass"] is False}


def test_faster_than_the_robot_runs_fails_control_rate():
    res = _run("paper", **{"sim.control_dt": 0.0005, "sim.physics_dt": 0.0005})
    c = res.summary["hardware"]["checks"]["control_rate"]
    assert c["value"] == pytest.approx(2000.0) and c["limit"] == pytest.approx(1000.0) and c["pass"] is False
    assert res.summary["hardware"]["verdict"] == "fail" and "control_rate" in line(res.summary["hardware"])


def test_dc_motor_no_load_speed_is_the_limit():
    """TurtleBot3 (XL430 <dcmotor>, tb3.toml): the wheel's no-load speed V_max / (K g) = 5.97 rad/s
    (the preset's comment: 0 torque at 5.97 rad/s); the value is the log's largest |υ ± l ω| / r."""
    res = simulate(load("tb3", {"sim.duration": 0.3}))
    c = res.summary["hardware"]["checks"]["wheel_speed"]
    assert c["limit"] == pytest.approx(5.97, abs=0.02)
    p = res.plant.params
    vel = res.log["vel"]
    rates = [
        np.max(np.abs(vel[:, i, 0][:, None] + np.array([-1, 1]) * p[i].half_track * vel[:, i, 1][:, None]))
        / p[i].wheel_radius
        for i in range(3)
    ]
    assert c["value"] == pytest.approx(max(rates)) and c["pass"] is bool(max(rates) <= c["limit"])
    assert preset_control_rate(resolve_robot("tb3").model) == (pytest.approx(1000.0), "tb3")


def test_collision_fails_separation():
    """Two followers swapping sides touch (test_safety's crossing): separation check fails with
    the min separation (≤ 0) against the safety distance and the contact count said."""
    sc = load("paper", {**CROSSING, "sim.duration": 2.5, "safety.distance": 0.1})
    res = simulate(sc)
    c = res.summary["hardware"]["checks"]["separation"]
    f = res.summary["followers"]
    assert c["value"] == pytest.approx(min(x["min_separation_m"] for x in f)) and c["value"] <= 0.0
    assert c["limit"] == pytest.approx(0.1) and c["pass"] is False and "contact events" in c["reason"]


def test_ideal_plant_skips_what_it_cannot_know():
    res = simulate(load("paper", {"sim.duration": 0.05}))
    c = res.summary["hardware"]["checks"]
    for k in ("wheel_speed", "tip_over", "control_rate", "slip", "separation"):
        assert c[k]["pass"] is None and c[k]["reason"]
    assert c["torque"]["pass"] is True
    assert res.summary["hardware"]["verdict"] in ("incomplete", "fail")
    assert res.summary["hardware"]["verdict"] == "fail" or "not checked" in line(res.summary["hardware"])


def test_cli_prints_one_verdict_line_and_writes_the_block(tmp_path, capsys):
    import json

    from bioform_mj.cli.main import main

    code = main(["run", "paper", "--plant", "mujoco", "--set", "sim.duration=0.2", "--out", str(tmp_path / "r")])
    out = capsys.readouterr()
    lines = [x for x in (out.out + out.err).splitlines() if "hardware:" in x]
    assert code == 0 and len(lines) == 1
    hw = json.loads((tmp_path / "r" / "summary.json").read_text())["hardware"]
    assert hw["verdict"] in ("pass", "fail", "incomplete") and set(hw["checks"]) >= {
        "torque",
        "tip_over",
        "control_rate",
    }
    assert lines[0].startswith("hardware: pass") == (hw["verdict"] == "pass")
