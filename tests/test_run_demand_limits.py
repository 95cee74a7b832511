"""A robot's limits, the scenario's demand against them, and ``"auto"`` scaling (design §21).

The numbers come from outside the code under test: the published files (PMB2's URDF wheel
``<limit velocity>`` and tyre radius, ``tests/zoo/expectations.json``), the TurtleBot3 preset's
datasheet figures, and similarity (a scenario scaled by s and σ asks s/σ the speed, s/σ² the
acceleration, 1/σ² the yaw acceleration of the original).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from bioform_mj.assess.check import check
from bioform_mj.cli.main import main
from bioform_mj.core.errors import InputError, ScenarioError
from bioform_mj.robots.entries import resolve_robot
from bioform_mj.robots.refs import RobotRef
from bioform_mj.scenario.loader import load

ZOO = Path(__file__).resolve().parent / "zoo"
EXPECT = json.loads((ZOO / "expectations.json").read_text())


def _zoo_ref(name: str, **over) -> RobotRef:
    e = EXPECT[name]
    pk = {k: str(ZOO / v) for k, v in e["packages"].items()}
    from bioform_mj.robots.refs import as_package_path

    return resolve_robot(
        RobotRef(model=str(ZOO / e["file"]), package_path=as_package_path(pk, "package_path"), **e["mapping"], **over)
    )


def test_urdf_wheel_velocity_is_the_top_speed_with_its_source():
    """PMB2 (PAL): wheel <limit velocity> 10.152284263959391 rad/s on a 0.0985 m tyre = 1.0 m/s, PAL's figure."""
    rep = check(_zoo_ref("pmb2_urdf"), identify_=False)
    lim = rep["limits"]
    assert lim["top_speed_source"] == "urdf" and "file's" in lim["top_speed_note"]
    assert lim["top_speed_mps"] == pytest.approx(10.152284263959391 * EXPECT["pmb2_urdf"]["r_m"], rel=1e-4)
    st = EXPECT["pmb2_urdf"]["statics"]
    assert lim["torque_nm"] == pytest.approx(st["tau_max_nm"]) and lim["traction_torque_nm"] == pytest.approx(
        st["traction_torque_nm"], rel=0.02
    )
    # the acceleration limits from the parts: 2 a τ against traction and tip-over, 2 b min(τ, τ_traction)
    a, b = rep["a_eff"], rep["b_eff"]
    tips = rep["tip_accel_mps2"]
    grip = min(lim["torque_nm"], lim["traction_torque_nm"])
    assert lim["accel_mps2"] == pytest.approx(min(2 * a * grip, tips["forward"], tips["backward"]))
    assert lim["yaw_accel_radps2"] == pytest.approx(2 * b * grip)
    assert lim["lateral_accel_mps2"] == tips["lateral"] and lim["missing"] == []


def test_a_placeholder_urdf_velocity_is_named_and_not_used(tmp_path):
    text = (ZOO / "diffbot_urdf" / "diffbot.urdf").read_text()
    assert text.count('velocity="1.0"') == 2
    f = tmp_path / "diffbot.urdf"
    f.write_text(text.replace('velocity="1.0"', 'velocity="100"'))
    rep = check(resolve_robot(RobotRef(model=str(f), **EXPECT["diffbot_urdf"]["mapping"])), identify_=False)
    lim = rep["limits"]
    assert lim["top_speed_mps"] is None and lim["missing"] == ["top_speed"]
    assert "placeholder" in lim["top_speed_note"] and "top_speed" in lim["top_speed_note"]


def test_mapping_top_speed_first_then_the_dc_motor_no_load_speed():
    """tb3: the mapping's 0.22 m/s (ROBOTIS' Burger); without it, the XL430 <dcmotor>'s no-load
    wheel speed 5.97 rad/s × 0.033 m = 0.197 m/s (the tb3 preset's comment)."""
    lim = check(resolve_robot(RobotRef("tb3", top_speed=0.22)), identify_=False)["limits"]
    assert (lim["top_speed_mps"], lim["top_speed_source"]) == (0.22, "mapping")
    from bioform_mj.run.demand import run_limits
    from bioform_mj.run.simulate import make_plant

    sc = load("tb3", {"sim.duration": 0.1})
    lims = run_limits(sc, make_plant(sc))
    assert lims[0]["top_speed_source"] == "dcmotor" and lims[0]["top_speed_mps"] == pytest.approx(0.197, abs=0.001)


@pytest.mark.parametrize("bad", ["0", "-0.2", '"fast"', "nan"])
def test_a_bad_top_speed_is_refused(bad):
    with pytest.raises(InputError, match="top_speed"):
        load("tb3", [f'plant.robots=[{{model = "tb3", top_speed = {bad}}}]'])


def test_robot_check_prints_the_limits_block_and_refuses_a_bad_top_speed(tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["robot", "check", "tb3", "--top-speed", "0.22", "--json", str(out)]) in (0, 1)
    text = capsys.readouterr().out
    block = text[text.index("  limits:") :].splitlines()[:5]
    assert "top speed 0.22 m/s at the tyre (mapping)" in block[1] and "traction" in block[2]
    assert json.loads(out.read_text())["limits"]["top_speed_mps"] == 0.22
    assert main(["robot", "check", "tb3", "--top-speed", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "top-speed" in err[0]


def _paper_similar(s: float, sig: float, steps: float | None = None):
    mf = sig**2 / s**2
    k = sig if steps is None else steps
    return load(
        "paper",
        [
            f"formation.scale={s!r}",
            f"formation.time_scale={sig!r}",
            f"sim.control_dt={0.001 * k!r}",
            f"sim.physics_dt={0.001 * k!r}",
            f"sim.log_dt={0.01 * k!r}",
            "sim.duration=10",
            "method=bioinspired",
        ],
    ), (0.4 / (mf * s), 10.0 / (mf * s * s))


def test_the_demand_of_a_similar_scenario_scales_by_its_units():
    """The demand check's peaks of the paper scenario and of its similar copy (s = 0.5, σ = 2 on the
    paper plant with lengths × s, masses × σ²/s²): wheel speed × s/σ, acceleration × s/σ², yaw
    acceleration × 1/σ², the least ĉ × the plant's c ratio."""
    from bioform_mj.run.demand import peaks

    s, sig = 0.5, 2.0
    ref, c_ref = _paper_similar(1.0, 1.0)
    sim, c_sim = _paper_similar(s, sig, steps=1.0)  # the twin steps a scenario slowed by σ × σ itself
    p0 = peaks(ref, c_ref, 0.2)
    p1 = peaks(sim, c_sim, 0.2 * s)
    assert p0["wheel_speed_mps"] > 1.0 and p0["yaw_accel_radps2"] > 5.0  # the paper asks this much
    assert p1["wheel_speed_mps"] == pytest.approx(p0["wheel_speed_mps"] * s / sig, rel=1e-9)
    assert p1["accel_mps2"] == pytest.approx(p0["accel_mps2"] * s / sig**2, rel=1e-9)
    assert p1["yaw_accel_radps2"] == pytest.approx(p0["yaw_accel_radps2"] / sig**2, rel=1e-9)
    assert p1["c_hat_min"][1] / c_sim[1] == pytest.approx(p0["c_hat_min"][1] / c_ref[1], rel=1e-9)
    assert peaks(sim, c_sim, 0.2 * s)["from"] == "memory"  # cached


def test_a_run_warns_each_exceeded_limit_with_its_ratio_and_the_verdict_is_never_a_silent_pass(tmp_path, capsys):
    """tb3 preset (lengths × 0.15, times kept): its leader-following asks more wheel speed than the
    XL430 gives; one warning: line per exceeded limit with the ratio, all in summary.json's demand."""
    out = tmp_path / "r"
    assert main(["run", "tb3", "--set", "sim.duration=3", "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    d = json.loads((out / "summary.json").read_text())
    items = d["demand"]["robots"][0]["demand"]
    assert set(items) == {
        "wheel_speed",
        "accel",
        "yaw_accel",
        "lateral_accel",
        "sign_torque",
        "torque_vs_traction",
        "accel_at_c_bound",  # the method learns: the sign terms at ĉ's projection bound (issue 27)
        "wheel_torque",  # the motion and the wheel's own resistance against τ_max (issue 27)
    }
    ws = items["wheel_speed"]
    assert ws["limit"] == pytest.approx(0.197, abs=0.001) and ws["ratio"] == pytest.approx(ws["value"] / ws["limit"])
    assert ws["ratio"] > 1
    said = [ln for ln in err.splitlines() if ln.startswith("warning:") and "x the robot's limit" in ln]
    exceeded = sum(1 for r in d["demand"]["robots"] for it in r["demand"].values() if (it["ratio"] or 0) > 1)
    assert len(said) == exceeded >= 1
    assert re.search(r"peak wheel ground speed [\d.]+ m/s is [\d.]+x", err)
    # at σ = 1 the speed ratio is the time factor that brings the wheels to the top speed (speeds ∝ 1/σ)
    assert f"formation.time_scale >= {ws['ratio']:.3g}" in err
    assert d["hardware"]["verdict"] in ("pass", "fail", "incomplete")
    if any(c["pass"] is None for c in d["hardware"]["checks"].values()):
        assert d["hardware"]["verdict"] != "pass"


def test_auto_scales_to_the_robot_and_its_demand_then_fits_the_margins():
    """tb3 (half track 0.08 m, XL430 no-load 0.197 m/s): s = 0.08 / 0.2; σ chosen so that the demand at
    (s, σ) stays within 0.8 of the top speed and 0.5 of the acceleration limits."""
    from bioform_mj.run.auto_scale import robot_limits
    from bioform_mj.run.demand import compare, peaks

    sc = load("tb3", ['formation.scale="auto"', 'formation.time_scale="auto"'])
    assert sc.formation.scale == pytest.approx(0.08 / 0.2, rel=1e-6)
    assert 2.0 < sc.formation.time_scale < 30.0 and "set by" in sc.formation.scale_note
    assert sc.sim.duration == pytest.approx(20.0 * sc.formation.time_scale)
    p, lim = robot_limits(resolve_robot(sc.plant.robots[0]))
    items = compare(sc, peaks(sc, (p.a_eff, p.b_eff), p.half_track), lim)
    assert items["wheel_speed"]["ratio"] <= 0.8 + 1e-6
    assert items["accel"]["ratio"] <= 0.5 + 1e-6 and items["yaw_accel"]["ratio"] <= 0.5 + 1e-6


@pytest.mark.slow  # ≈ 4 s alone (the σ search's twins); 0.2 s after the test above (cached)
def test_auto_time_scale_of_a_shortened_run_is_the_full_runs():
    """σ is a property of the scenario's motion, not of how long a run watches it (design §21, issue 27 gap 5:
    TIAGo got σ 2.51 for a 0.3 s run, 2.64 for 20 s): a 0.3 s run of the tb3 preset gets the σ of its 20 s run,
    bit for bit, and only its own duration × σ; the note says over which span σ was set."""
    full = load("tb3", ['formation.scale="auto"', 'formation.time_scale="auto"'])
    short = load("tb3", ['formation.scale="auto"', 'formation.time_scale="auto"', "sim.duration=0.3"])
    assert short.formation.time_scale == full.formation.time_scale > 1
    assert short.sim.duration == pytest.approx(0.3 * full.formation.time_scale)
    assert "over the scenario's first 20 s (unscaled), not only the run's 0.3 s" in short.formation.scale_note
    assert "not only the run's" not in full.formation.scale_note


def test_auto_for_a_robot_without_a_top_speed_says_what_is_missing(tmp_path, capsys):
    with pytest.raises(ScenarioError, match="top_speed"):
        load("paper", ['formation.time_scale="auto"'])
    out = tmp_path / "o"
    assert main(["run", "paper", "--set", 'formation.time_scale="auto"', "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "top_speed" in err[0]
    assert not out.exists()


def test_the_sliding_gain_is_put_against_the_robots_resistance():
    """A dead band 2 a f and a drag k_υ υ the sign terms must dominate (eqs. 38–39): 0.3 + 1.0 × 0.2 =
    0.5 m/s² against c_a, 2.0 + 0.5 × 1.0 = 2.5 rad/s² against c_b; the warning names the gain."""
    from bioform_mj.run.demand import compare, warning_lines

    sc = load("paper", ["formation.scale=0.4", "formation.time_scale=4"])
    ca, cb = sc.torque.c
    assert (ca, cb) == pytest.approx((3 * 0.4 / 16, 3 / 16))
    pk = {"wheel_speed_mps": 0.1, "accel_mps2": 0.1, "yaw_accel_radps2": 0.1, "lateral_accel_mps2": 0.0}
    pk |= {"c_hat_min": [0.2, 5.0], "speed_mps": 0.2, "yaw_rate_radps": 1.0}
    lim = {"top_speed_mps": 1.0, "top_speed_source": "mapping", "accel_mps2": 1.0, "accel_limited_by": "torque"}
    lim |= {"yaw_accel_radps2": 10.0, "yaw_accel_limited_by": "torque", "lateral_accel_mps2": 5.0}
    lim |= {"torque_nm": 1.0, "traction_torque_nm": 2.0}
    items = compare(sc, pk, lim, {"deadband_accel": [0.3, 2.0], "drag_rate_per_s": [1.0, 0.5]})
    assert items["sliding_gain_v"]["value"] == pytest.approx(0.5) and items["sliding_gain_v"]["limit"] == ca
    assert items["sliding_gain_w"]["ratio"] == pytest.approx(2.5 / cb)
    lines = warning_lines("follower 1", items, 4.0)
    assert len(lines) == 2 and all("the sliding gain torque.c[" in ln for ln in lines)
    none = compare(sc, pk, lim, {"deadband_accel": [0.0, 0.0], "drag_rate_per_s": [0.0, 0.0]})
    assert "sliding_gain_v" not in none and warning_lines("follower 1", none) == []


@pytest.mark.parametrize("power", [1.0, 1.5, 2.0])
def test_auto_sigma_search_lands_within_the_margin_for_a_demand_falling_faster_than_similar(power):
    """A demand 7 σ^-power of the margin (power 1: similar; more: eq. 32's neuron when s σ ≠ 1): the
    least σ found fits (≤ 1) and sits at 0.9-1 of the margin, i.e. within 11 % of 7^(1/power)."""
    from bioform_mj.run.auto_scale import _solve

    calls = []

    def need(sig):
        calls.append(sig)
        return 7.0 * sig**-power, "wheel speed"

    sig, fit, why = _solve(need)
    exact = 7.0 ** (1 / power)
    assert fit <= 1.0 and fit >= 0.9 and why == "wheel speed"
    assert exact <= sig <= exact * 0.9 ** (-1 / power) + 1e-9
    assert len(calls) <= 5
    assert _solve(lambda s: (0.5 / s, "fits"))[:2] == (1.0, 0.5)  # fits as written: σ = 1
