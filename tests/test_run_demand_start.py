"""Issue 27 item 3: the start-up the demand check missed on TIAGo (design §21).

Measured (TIAGo MJCF at its fair scale, s 1.011, σ 2.64, the first 0.4 s logged every 1 ms, follower 1): the ideal twin
and the MuJoCo run start alike — the same torques to 3 digits over the first 10 ms (the sign terms chatter from the
first step in both), both at rest, no settle in either; the twin's own start-up peak is its peak (1.57 m/s² at
t = 0.12 s: the 0.29 of the limit the check reported). MuJoCo's robot then turns a third slower (ω 0.31 against 0.46
rad/s at 0.1 s), the learner follows it down, ĉ reaches its projection bound (â 0.0064 = 0.05 c_true) by t = 0.3 s
and eq. 38's division by ĉ puts ±100 N·m on the wheels: 172 m/s², 753 rad/s² from log differences. The cause, by
counterfactual: the caster swivels' damping (0.5 N·m·s/rad), turned from the file's angles; at 0 no collapse, a
1.75 m/s² peak (ideal casters besides: 1.64, the twin's 1.57). No ideal twin
shows that (its ĉ stays near c_true); the demand now says what the torque law asks with ĉ at its bound
(``accel_at_c_bound``: ``2 a min(τ_bound, τ_max)`` against the acceleration limit), warned before the run.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from bioform_mj.core.errors import RobotWarning
from bioform_mj.run.demand import c_lower_bound, compare, warning_lines
from bioform_mj.scenario.loader import load

A, B = 0.4, 10.0  # the paper robot's c_true


def _lim(torque: float, traction: float, tip: float) -> dict:
    acc = {"torque": 2 * A * torque, "traction": 2 * A * traction, "tip backward": tip}
    by = min(acc, key=acc.get)
    return {
        "top_speed_mps": None,
        "top_speed_source": None,
        "torque_nm": torque,
        "traction_torque_nm": traction,
        "accel_mps2": acc[by],
        "accel_limited_by": by,
        "yaw_accel_radps2": 2 * B * min(torque, traction),
        "yaw_accel_limited_by": "torque",
        "lateral_accel_mps2": 10.0,
    }


PK = {"wheel_speed_mps": 1.0, "accel_mps2": 1.0, "yaw_accel_radps2": 1.0, "lateral_accel_mps2": 1.0}


def test_the_sign_terms_at_the_projection_bound_are_compared_with_the_acceleration_limit():
    """Paper scenario (c = 3, 3; ĉ(0) = 0.5 c; c_bounds [0.1, 10]): the bound 0.05 c = (0.02, 0.5), the sign terms
    there 3/(2·0.02) + 3/(2·0.5) = 78 N·m per wheel. The paper robot's 5 N·m motors give 5 of it: 2·0.4·5 = 4 m/s²,
    exactly its torque-set limit (no warning). Mapped to 30 N·m above its 12 N·m traction with a 20 m/s² tip margin:
    24 m/s², 4x the traction-set 9.6 m/s² limit, warned. A projection band [0.5, 2] × c_true: 3/0.4 + 3/10 = 7.8."""
    sc = load("paper", overrides=["plant.kind=ideal"])
    assert c_lower_bound(sc, (A, B)) == pytest.approx((0.02, 0.5))
    pk = {**PK, "c_hat_min": [0.2, 5.0]}
    own = compare(sc, pk, _lim(5.0, 12.0, 6.0), c_true=(A, B))["accel_at_c_bound"]
    assert own["torque_at_bound_nm"] == pytest.approx(78.0) and own["torque_given_nm"] == 5.0
    assert own["value"] == pytest.approx(4.0) and own["ratio"] == 1.0
    assert not [ln for ln in warning_lines("f", {"accel_at_c_bound": own}) if "projection bound" in ln]
    strong = compare(sc, pk, _lim(30.0, 12.0, 20.0), c_true=(A, B))["accel_at_c_bound"]
    assert strong["value"] == pytest.approx(24.0) and strong["limit"] == pytest.approx(9.6)
    (line,) = warning_lines("followers 1, 2, 3", {"accel_at_c_bound": strong})
    assert "projection bound (â = 0.02, b̂ = 0.5)" in line and "ask 78 N·m per wheel" in line and "2.5x" in line
    banded = load("paper", overrides=["plant.kind=ideal", "learner.projection_band=[0.5, 2.0]"])
    assert c_lower_bound(banded, (A, B)) == pytest.approx((0.2, 5.0))
    assert compare(banded, pk, _lim(30.0, 12.0, 20.0), c_true=(A, B))["accel_at_c_bound"]["torque_given_nm"] == (
        pytest.approx(7.8)
    )
    plain = load("paper", overrides=["plant.kind=ideal", "method=bioinspired"])  # no learner: no bound
    assert c_lower_bound(plain, (A, B)) is None and "accel_at_c_bound" not in compare(
        plain, pk, _lim(5, 12, 6), c_true=(A, B)
    )


@pytest.mark.slow
def test_a_start_at_the_bound_is_warned_before_the_run_and_bounds_what_the_run_does(tmp_path, monkeypatch):
    """A scenario whose peak is at the start: the paper robot mapped to 30 N·m (its traction 12 N·m) with ĉ(0) at its
    projection bound (c_hat0_scale 0.05, c_bounds [1, 20]). Before the run: the warning, 2 a τ_max = 24 m/s² against
    the 9.8 m/s² limit; the run's own peak |dυ/dt| over its first 0.3 s (log every 1 ms) is beyond both: the wheels
    slip and the sign terms chatter at ±30 N·m (measured 660 m/s², as TIAGo's 172 m/s² once its ĉ hit the bound)."""
    from bioform_mj.assess import prerun
    from bioform_mj.run.simulate import simulate

    monkeypatch.setenv(prerun.CACHE_ENV, str(tmp_path / "cache"))
    monkeypatch.delenv(prerun.SKIP_ENV, raising=False)
    ov = [
        "plant.kind=mujoco",
        "sim.duration=0.3",
        "sim.log_dt=0.001",
        "learner.c_hat0_scale=[0.05, 0.05]",
        "learner.c_bounds=[1.0, 20.0]",
        'plant.robots=[{model = "paper", tau_max = 30.0}]',
    ]
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = simulate(load("paper", overrides=ov))
    lines = [
        str(w.message) for w in said if issubclass(w.category, RobotWarning) and "projection bound" in str(w.message)
    ]
    groups = res.summary["demand"]["robots"]  # followers whose settled loads differ in the 9th digit: own groups
    assert len(lines) == len(groups) >= 1 and sum(len(g["followers"]) for g in groups) == 3, lines
    it = groups[0]["demand"]["accel_at_c_bound"]
    assert it["torque_given_nm"] == 30.0 and it["value"] == pytest.approx(2 * A * 30.0, rel=1e-3)
    t, v = res.log["t"], res.log["vel"][:, :, 0]
    peak = float(np.max(np.abs(np.diff(v, axis=0)) / np.diff(t)[:, None]))
    assert peak > it["value"] > it["limit"], (peak, it)  # measured 660 m/s²: slip and chatter, beyond even 2 a τ_max
