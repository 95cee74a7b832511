"""Similarity scaling (design §21): every key by its declared unit, lengths × s, times × σ.

The transform is checked against numbers computed here by hand from each key's physics, and the
dynamic similarity against a second robot: the paper's plant with every length × s and the masses
× σ²/s² (so that the torque limit stays), whose dimensionless trajectory must be the paper's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.core.errors import ScenarioError
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.doc import scenario_keys
from bioform_mj.scenario.loader import apply_scale, from_dict, load
from bioform_mj.scenario.similarity import exponents, factor, key_units


def test_every_scenario_key_declares_a_readable_unit():
    units = key_units()
    # the walk sees every key the reference documents; a robot's mapping is the robot's (kept whole)
    documented = {k for k in scenario_keys() if not k.startswith("plant.robots[].")} | {"plant.robots"}
    assert set(units) == documented
    assert "kept" in units["plant.robots"]
    missing = [k for k, m in units.items() if "unit" not in m]
    assert not missing, f"scenario keys without a unit: {missing}"
    for key, meta in units.items():
        u = meta["unit"]
        for one in u if isinstance(u, tuple) else (u,):
            exponents(one)  # raises on a unit it cannot read
        for why in ("kept", "mixed"):
            assert why not in meta or len(meta[why]) > 10, f"{key}: {why} without a reason"
    mixed = {k for k, m in units.items() if "mixed" in m}
    assert mixed == {"kinematic.A", "kinematic.B", "kinematic.D", "learner.k4", "torque.phi"}


def test_a_key_without_a_unit_is_refused_by_the_transform():
    import dataclasses

    from bioform_mj.scenario.similarity import transform

    @dataclasses.dataclass(frozen=True)
    class Bare:
        x: float = 1.0

    with pytest.raises(ValueError, match="declares no unit"):
        transform(Bare(), 0.5, 2.0)


@pytest.mark.parametrize(
    ("unit", "expected"),
    [
        ("m", 0.4),
        ("s", 6.4),
        ("m/s", 0.4 / 6.4),
        ("m/s^2", 0.4 / 6.4**2),
        ("rad/s²", 1 / 6.4**2),
        ("1/m^2", 1 / 0.16),
        ("1/s", 1 / 6.4),
        ("s^2", 6.4**2),
        ("rad", 1.0),
        ("N·m", 1.0),  # a mass: the robot's, kept
        ("1/kg·m", 1.0),
    ],
)
def test_unit_factor(unit, expected):
    assert factor(unit, 0.4, 6.4) == pytest.approx(expected, rel=1e-15)


def test_time_scale_transforms_each_key_by_its_unit():
    s, sig = 0.5, 2.0
    data = {
        "formation": {"scale": s, "time_scale": sig},
        "faults": {"delay": 0.1, "noise_vel": [0.2, 0.3], "friction_patch": [1, 2, 3, 4, 0.5]},
        "events": [{"time": 5.0, "mass": 2.0}],
    }
    sc = apply_scale(from_dict(data))  # (a friction patch needs MuJoCo to pass validation; not run here)
    assert sc.sim.duration == 40.0  # s × σ
    assert sc.sim.control_dt == 0.001 and sc.sim.physics_dt == 0.001  # numerical steps kept
    assert sc.leader.speed == 0.25 and sc.leader.amplitude == 0.2 and sc.leader.frequency == 0.5
    assert sc.formation.offsets[1] == (2.0, 2.5) and sc.formation.initial_poses[1] == (-0.5, -2.0, 0.0)
    assert sc.estimator.kp == (7.5, 7.5, 7.5) and sc.estimator.kb == (0.5, 0.5)
    assert sc.estimator.ka == (25 * 0.5 / 4, 25 / 4)  # m/s², rad/s²
    assert (sc.kinematic.k1, sc.kinematic.k2, sc.kinematic.k3) == (1.0, 12.0, 8.0)  # 1/s, 1/m², 1/m
    assert (sc.kinematic.A, sc.kinematic.B, sc.kinematic.D) == (1.0, 1.0, 1.0)  # eq. 32: as rates
    assert sc.torque.c == (3 * 0.5 / 4, 3 / 4) and sc.torque.deriv_wn == 25.0 and sc.torque.tau_max == 20.0
    assert sc.learner.k4 == (24.0, 200.0) and sc.learner.k5 == (12.5, 25.0)  # eq. 37: k4 × σ²
    assert sc.disturbance.bias == (0.1 * 0.5 / 4, 0.0) and sc.disturbance.amp == (0.0, 0.1 / 4)
    assert sc.disturbance.freq == (0.0, 0.5)
    assert sc.events[0].time == 10.0 and sc.events[0].mass == 2.0  # a payload's mass is the robot's
    assert sc.faults.delay == 0.2 and sc.faults.noise_vel == (0.2 * 0.5 / 2, 0.3 / 2)
    assert sc.faults.friction_patch == (0.5, 1.0, 1.5, 2.0, 0.5)
    assert sc.limits.speed == 100.0  # a divergence guard, kept
    assert (sc.formation.scale, sc.formation.time_scale) == (0.5, 2.0)


def test_time_scale_one_keeps_the_lengths_only_scaling():
    """The tb3 preset (scale 0.15) as before issue 27: lengths × s, k2 / s², k3 / s, every time and
    ``k1, A, B, D, k4`` as written."""
    sc = load("tb3")
    s = 0.15
    assert sc.formation.time_scale == 1.0
    assert sc.leader.speed == 1.0 * s and sc.leader.y0 == 3.0 * s
    assert sc.kinematic.k2 == 3.0 / s**2 and sc.kinematic.k3 == 4.0 / s
    assert (sc.kinematic.k1, sc.kinematic.A, sc.kinematic.B) == (2.0, 2.0, 2.0)
    assert sc.learner.k4 == (6.0, 50.0) and sc.sim.duration == 20.0
    assert sc.learner.drag_gain == (30.0 / s**2, 50.0)


def _similar(method: str, s: float, sig: float, steps: float, extra: tuple[str, ...] = ()):
    """The paper scenario, lengths × s and times × σ, on the paper's plant with every length × s and
    the masses × m_f = σ²/s²: a = 1/(m r) → a/(m_f s), b = l/(I r) with I ∝ m l² → b/(m_f s²); the
    torques then scale by m_f s²/σ² = 1, so ``tau_max`` stays. Control and physics steps × ``steps``."""
    mf = sig**2 / s**2
    c = (0.4 / (mf * s), 10.0 / (mf * s * s))
    sets = [
        f"formation.scale={s!r}",
        f"formation.time_scale={sig!r}",
        f"plant.c_true=[{c[0]!r}, {c[1]!r}]",
        f"sim.control_dt={0.001 * steps!r}",
        f"sim.physics_dt={0.001 * steps!r}",
        f"sim.log_dt={0.01 * sig!r}",
        "sim.duration=10",
        *extra,
    ]
    return simulate(load("paper", sets, method=method))


def _dimensionless_gap(ref, run, s: float) -> tuple[float, float]:
    """Largest position gap (m of the paper's scale) and heading gap (rad) at the same dimensionless time."""
    n = min(len(ref.log["t"]), len(run.log["t"]))
    p = np.abs(ref.log["pose"][:n, :, :2] - run.log["pose"][:n, :, :2] / s).max()
    th = np.abs(np.angle(np.exp(1j * (ref.log["pose"][:n, :, 2] - run.log["pose"][:n, :, 2])))).max()
    return float(p), float(th)


def test_a_dynamically_similar_robot_drives_the_same_dimensionless_trajectory():
    """s = 0.5, σ = 2 (s σ = 1: eq. 32's |x̃| term is then similar too). Without learning the
    scaled run is the paper's run to rounding when the steps are × σ, and with the steps kept
    (design §21) it differs from it exactly as much as the paper's run with half its step does."""
    s, sig = 0.5, 2.0
    ref = _similar("bioinspired", 1.0, 1.0, 1.0)
    run = _similar("bioinspired", s, sig, sig)
    assert len(run.log["t"]) == len(ref.log["t"])
    assert np.allclose(run.log["t"] / sig, ref.log["t"], rtol=0, atol=1e-9)
    p, th = _dimensionless_gap(ref, run, s)
    assert p < 1e-9 and th < 1e-9
    # steps kept: the scaled run is stepped twice as finely as the paper's, relative to its time
    kept = _similar("bioinspired", s, sig, 1.0)
    half = _similar("bioinspired", 1.0, 1.0, 0.5)
    p_kept, _ = _dimensionless_gap(ref, kept, s)
    p_half, _ = _dimensionless_gap(ref, half, 1.0)
    assert 0.01 < p_kept < 0.1  # the sign terms' discrete chatter, m
    assert p_kept == pytest.approx(p_half, abs=1e-9)


def test_a_dynamically_similar_robot_learns_the_same_dimensionless_c_hat():
    """With learning (gain_scaling c_hat0, the steps × σ): b̂/b follows the paper's to 0.01 %; â/a is
    off by the υ channel's adaptation gain, which σ scales and s does not (× s² from similar,
    design §21): measured 0.953 against 0.935 at the end, the positions within 6 mm of 3-5 m."""
    s, sig = 0.5, 2.0
    gs = ("learner.gain_scaling=c_hat0",)
    ref = _similar("bioinspired-learning", 1.0, 1.0, 1.0, gs)
    run = _similar("bioinspired-learning", s, sig, sig, gs)
    c_ref = ref.log["c_hat"][-1] / np.array(ref.scenario.plant.c_true)
    c_run = run.log["c_hat"][-1] / np.array(run.scenario.plant.c_true)
    assert np.abs(c_run[:, 1] - c_ref[:, 1]).max() < 1e-4
    assert 0.005 < np.abs(c_run[:, 0] - c_ref[:, 0]).max() < 0.05
    p, _ = _dimensionless_gap(ref, run, s)
    assert p < 0.01


@pytest.mark.parametrize("bad", ["0", "-1", "nan", '"fast"', "true", "1e9"])
def test_a_bad_time_scale_is_refused(bad):
    with pytest.raises(ScenarioError, match="formation.time_scale"):
        load("paper", [f"formation.time_scale={bad}"])


def test_bad_time_scale_exits_2_with_one_error_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["run", "paper", "--set", "formation.time_scale=-2", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "formation.time_scale" in err[0]
    assert not out.exists()


def test_the_record_holds_the_scaled_values_with_both_factors_one():
    from bioform_mj.scenario.record import resolved_config

    sc = load("paper", ["formation.scale=0.5", "formation.time_scale=2"])
    cfg = resolved_config(sc)
    assert cfg["formation"]["scale"] == 1.0 and cfg["formation"]["time_scale"] == 1.0
    back = from_dict(cfg)
    assert back.sim.duration == 40.0 and math.isclose(back.leader.speed, 0.25)


def test_a_scaled_scenario_changed_in_python_is_not_scaled_twice():
    """design §18.1: ``simulate`` checks a scenario changed by ``dataclasses.replace``; the times it
    already carries (× σ) are not multiplied again (they were, before time_scale_applied was kept)."""
    import dataclasses

    from bioform_mj.scenario.loader import checked

    sc = load("paper", ["formation.scale=0.5", "formation.time_scale=2"])
    again = checked(dataclasses.replace(sc, name="again"))
    assert again.sim.duration == 40.0 and again.leader.speed == 0.25 and again.kinematic.k2 == 12.0
    twice = checked(dataclasses.replace(sc, formation=dataclasses.replace(sc.formation, time_scale=4.0)))
    assert twice.sim.duration == 80.0 and twice.leader.speed == 0.125  # × 4 of the written, not × 8


def test_auto_without_the_run_package_is_refused_naming_it():
    """The loader resolves "auto" through the resolver the run package registers (no upward import, design §0):
    in a process that imported only the scenario package it says what to import; bioform_mj.load imports it."""
    import subprocess
    import sys

    code = (
        "from bioform_mj.scenario.loader import load\n"
        "try:\n    load('tb3', ['formation.time_scale=auto'])\nexcept Exception as e:\n    print(type(e).__name__, e)\n"
        "import bioform_mj as bf\nprint(round(bf.load('tb3', ['formation.time_scale=auto']).formation.time_scale, 2))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300).stdout.splitlines()
    assert out[0].startswith("ScenarioError") and "import bioform_mj.run first" in out[0], out
    assert float(out[1]) > 1.0, out  # resolved: the tb3 preset asks its robot for more than its top speed
