"""The optional CBF safety filter (issue 21 item 4, design §19): the QP against its closed form, and runs."""

from __future__ import annotations

import numpy as np
import pytest

from bioform_mj.control.cbf import cbf_filter
from bioform_mj.core.errors import ScenarioError
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load
from crossing import CROSSING


def _scratch(k):
    return np.zeros((k, 2)), np.zeros(k), np.zeros(k)


def test_one_obstacle_is_the_closed_form_projection():
    """A robot at the origin heading +x at 1 m/s towards a cylinder (r = 0.3 m) 1 m ahead: one
    constraint a·u ≤ b, and the filter returns the Euclidean projection û − (a·û − b)/|a|² a mapped
    back through J⁻¹; far away (beyond range) the command is unchanged."""
    la, gam, d, rng = 0.1, 5.0, 0.05, 2.0
    pose = np.array([[0.0, 0.0, 0.0]])
    rad = np.array([0.3])
    obst = np.array([[1.0, 1.0, 0.0, 0.3, 0.2, 0.0, 0.0]])
    par = np.array([la, gam, d, rng])
    v, w = cbf_filter(0, 1.0, 0.0, pose, rad, obst, par, *_scratch(2))
    p = np.array([la, 0.0])
    dp = p - [1.0, 0.0]
    D = 0.3 + 0.3 + d + la
    a = -2 * dp
    b = gam * (dp @ dp - D * D)
    u_hat = np.array([1.0, 0.0])
    assert a @ u_hat > b  # the command violates the barrier
    u = u_hat - (a @ u_hat - b) / (a @ a) * a
    assert (v, w) == pytest.approx((u[0], u[1] / la), abs=1e-12)
    assert a @ np.array([v, la * w]) == pytest.approx(b, abs=1e-9)
    far = np.array([[1.0, 10.0, 0.0, 0.3, 0.2, 0.0, 0.0]])
    assert cbf_filter(0, 1.0, 0.3, pose, rad, far, par, *_scratch(2)) == (1.0, 0.3)


def test_two_robots_head_on_both_constraints_hold():
    """Two robots facing each other 1 m apart, each commanded at the other at 1 m/s: each one's
    filtered velocity of its look-ahead point satisfies its half of the pair constraint to 1e-9."""
    la, gam, d = 0.1, 5.0, 0.0
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.pi]])
    rad = np.array([0.2, 0.2])
    par = np.array([la, gam, d, 2.0])
    for i in range(2):
        v, w = cbf_filter(i, 1.0, 0.0, pose, rad, np.zeros((0, 7)), par, *_scratch(2))
        th = pose[i, 2]
        u = np.array([np.cos(th) * v - la * np.sin(th) * w, np.sin(th) * v + la * np.cos(th) * w])
        pi = pose[i, :2] + la * np.array([np.cos(th), np.sin(th)])
        j = 1 - i
        pj = pose[j, :2] + la * np.array([np.cos(pose[j, 2]), np.sin(pose[j, 2])])
        dp = pi - pj
        D = 0.4 + d + 2 * la
        assert -2 * dp @ u <= 0.5 * gam * (dp @ dp - D * D) + 1e-9
        assert v < 1.0  # slowed down


CROSS = {**CROSSING, "sim.duration": 3.0, "safety.distance": 0.05}


def test_crossing_without_contact_with_the_filter_and_engines_agree():
    """Followers swapping sides touch without the filter (measured: 2 events each in 8 s) and never
    with it (nor come within the 0.25 m watch range); compiled and stepwise agree bit for bit."""
    off = simulate(load("paper", CROSS))
    assert all(f["robot_contacts"] > 0 for f in off.summary["followers"])
    sc = load("paper", {**CROSS, "safety.filter": "cbf"})
    a, b = simulate(sc), simulate(sc, engine="stepwise")
    assert a.summary["engine"] == "compiled" and b.summary["engine"] == "stepwise"
    for f in a.summary["followers"]:
        assert f["robot_contacts"] == 0 and f["outcome"] != "collided"
    assert np.array_equal(a.log["cmd"], b.log["cmd"]) and np.array_equal(a.log["pose"], b.log["pose"])


@pytest.mark.parametrize(
    "over, key",
    [
        ({"safety.filter": "cbf", "torque.derivative": "analytic"}, "safety.filter"),
        ({"safety.filter": "qp"}, "safety.filter"),
        ({"safety.lookahead": 0.0}, "safety.lookahead"),
        ({"safety.gain": -1.0}, "safety.gain"),
    ],
)
def test_bad_filter_settings_refused(over, key):
    with pytest.raises(ScenarioError) as exc:
        load("paper", over)
    assert exc.value.key == key


def test_filter_leaves_far_apart_robots_alone():
    """The paper's followers never come within the filter's 2 m range of each other: the filtered
    run is bit-identical to the paper's (ideal plant, where robots are points)."""
    a = simulate(load("paper", {"sim.duration": 2.0}))
    b = simulate(load("paper", {"sim.duration": 2.0, "safety.filter": "cbf"}))
    assert np.array_equal(a.log["cmd"], b.log["cmd"]) and np.array_equal(a.log["pose"], b.log["pose"])


def test_crossing_preset_collides_without_the_filter():
    """The shipped ``crossing`` preset is the crossing above: both followers collide by 3 s."""
    fs = simulate(load("crossing", {"sim.duration": 3.0})).summary["followers"]
    assert [f["outcome"] for f in fs] == ["collided", "collided"]
    assert all("follower" in f["outcomes"][0]["detail"] for f in fs)


def test_right_hand_rule_breaks_the_crossing_deadlock():
    """The crossing preset (8 s) with the filter: the pure minimal QP (pass_right = 0) keeps the two
    apart but stuck side by side (measured final formation errors 0.96, 0.88 m); the right-hand rule
    (the default pass_right = 1) lets them pass (0.30, 0.27 m), both without a contact."""
    stuck = simulate(load("crossing", {"safety.filter": "cbf", "safety.pass_right": 0.0})).summary["followers"]
    passed = simulate(load("crossing", {"safety.filter": "cbf"})).summary["followers"]
    assert all(f["robot_contacts"] == 0 for f in stuck + passed)
    assert min(f["final_formation_error_m"] for f in stuck) > 0.8
    assert max(f["final_formation_error_m"] for f in passed) < 0.4


def test_an_infeasible_qp_is_said():
    """Robots closer than the filter can keep apart, on both sides of one: its QP has no solution (issue 28).
    The filter leaves the residual violation in the free scratch slot; a run counts the steps per follower in
    ``cbf_infeasible_steps`` and warns, once per follower, naming it."""
    import warnings

    from bioform_mj.core.errors import RobotWarning

    la, gam, d = 0.1, 5.0, 0.5
    pose = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [-0.1, 0.0, 0.0]])
    par = np.array([la, gam, d, 2.0])
    A, b, lam = _scratch(3)
    cbf_filter(0, 1.0, 0.0, pose, np.zeros(3), np.zeros((0, 7)), par, A, b, lam)
    assert lam[-1] > 1e-6  # the middle robot must move away from both neighbours at once
    cbf_filter(1, 1.0, 0.0, pose, np.zeros(3), np.zeros((0, 7)), par, A, b, lam)
    assert lam[-1] == 0.0  # an end robot's constraints are compatible: solved
    over = {
        "sim.duration": 0.2,
        "safety.filter": "cbf",
        "safety.distance": d,
        "formation.initial_poses": [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [-0.1, 0.0, 0.0]],
    }
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        res = simulate(load("paper", over))
    counts = [f["cbf_infeasible_steps"] for f in res.summary["followers"]]
    assert counts[0] > 0, counts
    said = [str(w.message) for w in got if issubclass(w.category, RobotWarning) and "no solution" in str(w.message)]
    assert said and said[0].startswith("follower 1: the safety filter's QP had no solution at"), said
    quiet = simulate(load("paper", {"sim.duration": 0.2, "safety.filter": "cbf"})).summary["followers"]
    assert [f["cbf_infeasible_steps"] for f in quiet] == [0, 0, 0]
