"""Virtual-leader trajectories: analytic velocities against closed forms and finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bioform_mj.formation import leader


def test_paper_leader_closed_form():
    traj = leader.paper()
    t = np.linspace(0, 20, 401)
    pose, vel, acc = traj.states(t)
    ydot = -0.4 * np.sin(t - math.pi / 2)
    yddot = -0.4 * np.cos(t - math.pi / 2)
    np.testing.assert_allclose(pose[:, 1], 3 + 0.4 * np.cos(t - math.pi / 2), atol=1e-12)
    np.testing.assert_allclose(vel[:, 0], np.sqrt(1 + ydot**2), atol=1e-12)
    np.testing.assert_allclose(vel[:, 1], yddot / (1 + ydot**2), atol=1e-12)
    np.testing.assert_allclose(pose[:, 2], np.arctan2(ydot, 1.0), atol=1e-12)


@pytest.mark.parametrize(
    "traj",
    [leader.paper(), leader.line(1, 2, 0.7, 0.3), leader.circle(0, 0, 3, 1.5), leader.figure_eight(0, 0, 4, 0.4)],
)
def test_derivatives_match_finite_differences(traj):
    t = np.linspace(0.3, 9.7, 50)
    h = 1e-5
    pose, vel, acc = traj.states(t)
    pp, vp, _ = traj.states(t + h)
    pm, vm, _ = traj.states(t - h)
    np.testing.assert_allclose(
        vel[:, 1],
        (np.unwrap(np.stack([pm[:, 2], pp[:, 2]]), axis=0)[1] - np.unwrap(np.stack([pm[:, 2], pp[:, 2]]), axis=0)[0])
        / (2 * h),
        atol=1e-6,
    )
    np.testing.assert_allclose(acc, (vp - vm) / (2 * h), atol=1e-5)
    speed = np.hypot(pp[:, 0] - pm[:, 0], pp[:, 1] - pm[:, 1]) / (2 * h)
    np.testing.assert_allclose(vel[:, 0], speed, atol=1e-6)


def test_circle_constant_speed_and_rate():
    _, vel, acc = leader.circle(0, 0, 2.0, 1.0).states(np.linspace(0, 10, 100))
    np.testing.assert_allclose(vel[:, 0], 1.0, atol=1e-12)
    np.testing.assert_allclose(vel[:, 1], 0.5, atol=1e-12)
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)


def test_bounds_cover_sampled_accelerations():
    traj = leader.figure_eight(0, 0, 4, 0.4)
    g1, g2 = traj.bounds(20.0)
    _, _, acc = traj.states(np.random.default_rng(0).uniform(0, 20, 5000))
    assert np.abs(acc[:, 0]).max() <= g1
    assert np.abs(acc[:, 1]).max() <= g2
    assert traj.min_speed(20.0) > 0.1
