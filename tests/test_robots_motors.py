"""DC motors (design §8.2, issue 12): datasheet numbers, ground truth, identification, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bioform_mj.assess.identify import identify
from bioform_mj.cli.main import main
from bioform_mj.plants.mujoco.plant import MujocoPlant
from bioform_mj.robots.params import robot_truth
from bioform_mj.robots.refs import RobotRef, models_dir
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

# Dynamixel XL430-W250-T, ROBOTIS e-Manual: 1.4 N·m stall, 57 rpm no load, both at 11.1 V; gear 258.5
XL430_STALL_NM = 1.4
XL430_NO_LOAD_RAD_S = 57 * 2 * np.pi / 60


def _wheel_torque(driver: str, rate: float, tau_cmd: float) -> float:
    """Joint torque of the tb3's left DC motor at wheel rate ``rate`` rad/s for command ``tau_cmd`` N·m."""
    p = MujocoPlant([RobotRef("tb3", motor="dc", driver=driver)], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    m, d = p.model, p.data
    a = int(p._ctrl[0, 0])
    dof = int(p._wheel_dof[0, 0])
    d.ctrl[a] = p._ctrl_scale[0, 0] * tau_cmd
    d.qvel[dof] = rate * p._wheel_sign[0, 0]
    mujoco.mj_forward(m, d)
    return float(d.qfrc_actuator[dof] * p._wheel_sign[0, 0])


def test_xl430_stall_torque_no_load_speed_and_line_match_the_datasheet():
    p = robot_truth(RobotRef("tb3", motor="dc", driver="voltage"))
    assert p.motor == "dc" and p.driver == "voltage"
    assert p.motor_stall_torque == pytest.approx(XL430_STALL_NM, rel=0.02)
    assert p.motor_no_load_speed == pytest.approx(XL430_NO_LOAD_RAD_S, rel=0.02)
    # simulated: full voltage at rest = stall torque; at no-load speed zero; a straight line between
    assert _wheel_torque("voltage", 0.0, XL430_STALL_NM) == pytest.approx(XL430_STALL_NM, rel=0.02)
    assert abs(_wheel_torque("voltage", XL430_NO_LOAD_RAD_S, XL430_STALL_NM)) < 0.02 * XL430_STALL_NM
    for frac in (0.25, 0.5, 0.75):
        line = XL430_STALL_NM * (1 - frac)
        assert _wheel_torque("voltage", frac * XL430_NO_LOAD_RAD_S, XL430_STALL_NM) == pytest.approx(line, rel=0.02)
    # back-EMF drag of the voltage driver: stall / no-load = (gK)²/R
    assert p.motor_damping == pytest.approx(XL430_STALL_NM / XL430_NO_LOAD_RAD_S, rel=0.02)


def test_current_driver_delivers_the_command_up_to_the_torque_speed_line():
    assert _wheel_torque("current", 0.0, 0.3) == pytest.approx(0.3, rel=1e-9)
    assert _wheel_torque("current", 3.0, 0.3) == pytest.approx(0.3, rel=1e-9)  # below the line: exact
    w = 0.9 * XL430_NO_LOAD_RAD_S  # beyond it: clipped to the line (voltage limit)
    assert _wheel_torque("current", w, 0.3) == pytest.approx(XL430_STALL_NM * 0.1, rel=0.02)


def test_ideal_motors_stay_the_default():
    for name in ("paper", "tb3"):
        p = robot_truth(name)
        assert p.motor == "ideal" and p.motor_damping == 0.0
    assert robot_truth("paper").tau_max == (5.0, 5.0)


def test_identification_with_dc_motors_agrees_with_the_stated_ground_truth():
    # paper robot, voltage driver: a_eff, b_eff from rest and back-EMF drag k = 2 a c/r, 2 b c l/r
    r = identify(RobotRef("paper", motor="dc", driver="voltage"))
    assert abs(r["relative_error"]["a"]) < 0.01 and abs(r["relative_error"]["b"]) < 0.01
    (kv, kw), (kv_id, kw_id) = r["drag_rate_per_s"]["formula"], r["drag_rate_per_s"]["identified"]
    assert kv == pytest.approx(1.0, rel=1e-6) and kw == pytest.approx(5.0, rel=1e-6)  # c = 0.125 N·m·s
    assert kv_id == pytest.approx(kv, rel=0.10) and kw_id == pytest.approx(kw, rel=0.02)
    # tb3, current driver (below the torque–speed line): a_eff, b_eff, no drag
    r = identify(RobotRef("tb3", motor="dc"))
    assert abs(r["relative_error"]["a"]) < 0.05 and abs(r["relative_error"]["b"]) < 0.02
    assert r["drag_rate_per_s"]["formula"] == [0.0, 0.0]


def test_summary_reports_the_motor_ground_truth(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "tb3", "--quiet", "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    for f in s["followers"]:
        u = f["unmodelled"]
        assert u["motor"] == "dc" and u["driver"] == "current"
        assert u["stall_torque_Nm"] == pytest.approx(1.4, rel=0.02)
        assert f["final_formation_error_m"] < 0.01
        # the formation holds, but the learner ends far from c_true (measured â −82 %, b̂ −68 % in 20 s
        # from 0.5 c): said as c_hat_off since issue 18 (was: ok), and nothing else
        assert [o["kind"] for o in f["outcomes"]] in ([], ["c_hat_off"])
        assert f["outcome"] == ("c_hat_off" if max(map(abs, f["c_hat_rel_error"])) > 0.25 else "ok")


def test_plant_measures_the_torque_the_dc_motor_delivers():
    # design §8.2: mean over the period of actuator_force × gear × wheel sign, as [τ_a, τ_b]
    p = MujocoPlant([RobotRef("tb3", motor="dc", tau_max=0.05)], np.zeros((1, 3)), 0.001, 0.001, None, slots=False)
    assert p.feed_delivered
    tb = np.zeros((1, 2))
    p.step(np.array([[0.05, 0.03]]), 0.0)  # at rest: below the torque–speed line, delivered exactly
    p.feed_delivered_torque(tb)
    np.testing.assert_allclose(tb[0], [0.08, -0.02], rtol=1e-9)
    for k in range(1, 300):  # full torque: the robot runs into the line (0.197 m/s), delivery falls off
        p.step(np.array([[0.05, 0.05]]), k * 0.001)
    p.feed_delivered_torque(tb)
    assert abs(tb[0, 0]) < 0.01 and abs(tb[0, 1]) < 1e-3
    assert not MujocoPlant(["tb3"], np.zeros((1, 3)), 0.001, 0.001, None, slots=False).feed_delivered


@pytest.mark.equivalence
def test_dc_feed_compiled_and_stepwise_loops_are_bit_identical():
    sc = load("tb3", overrides=["sim.duration=1"])
    a, b = simulate(sc, engine="compiled"), simulate(sc, engine="stepwise")
    assert a.summary["engine"] == "compiled" and b.summary["engine"] == "stepwise"
    for k in a.log:
        assert np.array_equal(a.log[k], b.log[k]), k


def _c_hat_rel_error(overrides: list[str]) -> tuple[np.ndarray, list[str]]:
    r = simulate(load("tb3", overrides=["sim.duration=20", *overrides]))
    f = r.summary["followers"]
    return np.array([np.array(x["c_hat"]) / np.array(x["c_true"]) - 1 for x in f]), [x["outcome"] for x in f]


def test_learner_fed_the_delivered_torque_is_unbiased_with_dc_motors():
    # tb3 preset (XL430, current driver), 20 s. Fed the commanded torque the learner drifted from
    # c_true to −48 … −53 % (started at c_true) and ended −27 … −55 % (started at 0.5 c, outcome
    # c_hat_at_bound after 1 s). Fed the delivered torque: started at c_true it stays within 4 %
    # (measured −3.7 … +0.9 %); from 0.5 c it ends −13 … −28 % low (measured): no bias, slow learning,
    # since the robot runs at its 0.197 m/s no-load speed during the catch-up, where torque is small.
    err, outcome = _c_hat_rel_error(["learner.c_hat0_scale=[1,1]"])
    assert np.all(np.abs(err) < 0.06), err
    assert outcome == ["ok"] * 3
    err, outcome = _c_hat_rel_error([])
    assert np.all(np.abs(err) < 0.32), err
    # more than 25 % off is said (sim.C_HAT_OFF, issue 18: was ok), within it ok
    assert outcome == ["c_hat_off" if np.abs(e).max() > 0.25 else "ok" for e in err]


def _scenario(tmp_path: Path, robot: str, model_text: str | None = None) -> Path:
    if model_text is not None:
        (tmp_path / "bot.xml").write_text(model_text)
    toml = tmp_path / "s.toml"
    toml.write_text(f'[plant]\nkind = "mujoco"\nrobots = [{robot}]\n')
    return toml


@pytest.mark.parametrize(
    "case, key",
    [
        ("no_dcmotor", "plant.robots.motor"),
        ("bad_driver", "].driver"),
        ("zero_voltage", "plant.robots.motor"),
        ("negative_constant", "bot.xml"),
    ],
)
def test_bad_motor_input_exits_2_naming_the_key(tmp_path, capsys, case, key):
    tb3 = (models_dir() / "tb3_robot.xml").read_text()
    if case == "no_dcmotor":
        toml = _scenario(tmp_path, '{ model = "lab", motor = "dc" }')
    elif case == "bad_driver":
        toml = _scenario(tmp_path, '{ model = "tb3", motor = "dc", driver = "pwm" }')
    elif case == "zero_voltage":
        toml = _scenario(
            tmp_path, '{ model = "bot.xml", motor = "dc" }', tb3.replace('ctrlrange="-11.1 11.1"', 'ctrlrange="0 0"')
        )
    else:
        toml = _scenario(
            tmp_path,
            '{ model = "bot.xml", motor = "dc" }',
            tb3.replace('nominal="11.1 0.0054158607 1542.9932"', 'motorconst="-0.0072 0" resistance="14.7"'),
        )
    out = tmp_path / "out"
    code = main(["run", str(toml), "--duration", "0.1", "--quiet", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.count("\n") == 0 and err.startswith("error:") and key in err and "Traceback" not in err
    assert not out.exists()
