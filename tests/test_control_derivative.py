"""The command derivative (design §6, issue 14): each option against closed forms, the filter's
limit as ω_n → ∞, the analytic derivative against a finite difference of a logged run, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.core import equations as eq
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

DT = 1e-3


def _filter_run(u, wn, dt=DT):
    """The ``filter`` option's estimates for the sequence ``u`` (started at rest on ``u[0]``)."""
    c = eq.filter_coefficients(wn, dt)
    y, dy, out = u[0], 0.0, []
    for uk in u:
        y, dy, d = eq.filter_derivative(y, dy, uk, *c, dt)
        out.append(d)
    return np.array(out)


def _difference_run(u, dt=DT):
    prev, out = u[0], []
    for uk in u:
        out.append(eq.backward_difference(uk, prev, dt))
        prev = uk
    return np.array(out)


def test_difference_of_a_sine_is_the_cosine_half_a_step_back():
    t = np.arange(0.0, 3.0, DT)
    d = _difference_run(np.sin(t))
    np.testing.assert_allclose(d[1:], np.cos(t[1:] - DT / 2), atol=1e-6)


def test_filter_of_a_sine_is_the_cosine_with_its_lag():
    """Critically damped 2nd order at ω = 1: phase lag 2 atan(1/ω_n), gain 1/(1 + 1/ω_n²); the
    zero-order hold's half-step delay and the output's change over the step (centred half a step
    later) cancel."""
    wn = 50.0
    t = np.arange(0.0, 5.0, DT)
    d = _filter_run(np.sin(t), wn)
    ref = np.cos(t - 2.0 * math.atan(1.0 / wn)) / (1.0 + 1.0 / wn**2)
    assert np.max(np.abs(d[2000:] - ref[2000:])) < 5e-5


@pytest.mark.parametrize("seed", [0, 1])
def test_filter_tends_to_the_backward_difference(seed):
    """The trap of issue 14: ``ẏ_f`` at the sample instant loses a step's derivative as ``ω_n·dt``
    grows; the output's change over the step tends to the backward difference instead."""
    u = np.cumsum(np.random.default_rng(seed).normal(size=400)) * 0.01  # rough: a random walk
    ref = _difference_run(u)
    errs = [np.max(np.abs(_filter_run(u, wn) - ref)) for wn in (1e2, 1e3, 1e4, 1e5, 1e7)]
    assert all(b < a or b == 0.0 for a, b in zip(errs, errs[1:])), errs
    assert errs[-1] <= 1e-9 * np.max(np.abs(ref))
    # the old estimate, ẏ_f at the sample instant, vanishes instead
    c = eq.filter_coefficients(1e5, DT)
    y, dy = 0.0, 0.0
    y, dy = eq.filter_step(y, dy, 1.0, *c)
    assert abs(dy) < 1e-30 and abs(eq.filter_derivative(0.0, 0.0, 1.0, *c, DT)[2] - 1.0 / DT) < 1e-9


def _circle_and_estimate(t):
    """A closed-form robot on a circle (its υ, ω) and a closed-form leader estimate with its rates."""
    R, w0 = 2.0, 0.5
    th = w0 * t
    robot = (R * math.sin(th), -R * math.cos(th) + 1.0, th, R * w0, w0)
    px, py, pth = 0.8 * t, 3.0 + 0.4 * math.sin(t), 0.3 * math.sin(0.7 * t)
    v_ir, w_ir = 1.0 + 0.1 * math.sin(t), 0.2 * math.cos(1.3 * t)
    rates = (0.8, 0.4 * math.cos(t), 0.21 * math.cos(0.7 * t), 0.1 * math.cos(t), -0.26 * math.sin(1.3 * t))
    return robot, (px, py, pth, v_ir, w_ir), rates


def _command(t, law_u=None):
    (x, y, th, _, _), (px, py, pth, v_ir, w_ir), _ = _circle_and_estimate(t)
    ex, ey, eth = eq.tracking_error(px, py, pth, x, y, th, 0.5, -0.3)
    u = ex if law_u is None else law_u(t)
    return np.array(eq.velocity_command(ey, eth, u, v_ir, w_ir, 2.0, 3.0, 4.0))


def _analytic(t, du=None):
    (x, y, th, v, w), (px, py, pth, v_ir, w_ir), (dpx, dpy, dpth, dv_ir, dw_ir) = _circle_and_estimate(t)
    ex, ey, eth = eq.tracking_error(px, py, pth, x, y, th, 0.5, -0.3)
    c, s = math.cos(th), math.sin(th)
    dex, dey, deth = eq.error_rate(ex, ey, v, w, v_ir, dpth, eth, c * dpx + s * dpy, -s * dpx + c * dpy)
    return np.array(
        eq.command_rate(ey, eth, v_ir, dv_ir, dw_ir, dey, deth, dex if du is None else du(t), 2.0, 3.0, 4.0)
    )


@pytest.mark.parametrize("t", [0.3, 1.7, 4.2])
def test_analytic_derivative_matches_the_closed_form_command(t):
    """Backstepping (u = x̃) on a closed-form robot and estimate: the chain rule against a central
    difference of eq. 31 itself."""
    h = 1e-5
    fd = (_command(t + h) - _command(t - h)) / (2 * h)
    np.testing.assert_allclose(_analytic(t), fd, rtol=1e-7, atol=1e-7)


def test_neuron_rate_is_the_limit_of_the_exact_step():
    for vs, x in ((0.0, 1.3), (0.7, -2.0), (-1.5, 0.4), (1.9, 0.0)):
        h = 1e-7
        fd = (eq.neuron_step(vs, x, 2.0, 2.0, 2.0, h) - vs) / h
        assert eq.neuron_rate(vs, x, 2.0, 2.0, 2.0) == pytest.approx(fd, rel=1e-5, abs=1e-6)


@pytest.mark.parametrize("method", ["bioinspired-learning", "backstepping"])
def test_analytic_agrees_with_a_fine_difference_of_a_logged_smooth_run(method):
    """With smooth sign terms (boundary layers) the logged analytic derivative at ``t_k`` equals
    the central difference of the logged command ``(cmd[k+1] − cmd[k−1]) / 2dt``."""
    sc = load(
        "paper",
        method=method,
        overrides=[
            "sim.duration=4",
            "sim.log_dt=0.001",
            'torque.derivative="analytic"',
            "torque.phi=0.05",
            "estimator.phi=[0.1,0.1]",
            "estimator.ka=[1,1]",
            "estimator.kb=[25,25]",
        ],
    )
    r = simulate(sc)
    cmd, dcmd = r.log["cmd"], r.log["dcmd"]
    fd = (cmd[2:] - cmd[:-2]) / (2 * sc.sim.control_dt)
    an = dcmd[1:-1]
    sl = slice(200, None)  # after the first 0.2 s (the initial transient is steep, still smooth)
    scale = np.max(np.abs(an[sl]), axis=0)
    err = np.max(np.abs(fd[sl] - an[sl]), axis=0)
    assert np.all(err <= 0.02 * scale), (err, scale)


@pytest.mark.parametrize(
    "setting,needle",
    [
        ('torque.derivative="exact"', "torque.derivative"),
        ("torque.deriv_wn=0", "torque.deriv_wn"),
        ("torque.deriv_wn=-5", "torque.deriv_wn"),
    ],
)
def test_bad_derivative_settings_exit_2_with_one_error_line(tmp_path, capsys, setting, needle):
    code = main(["run", "paper", "--duration", "0.1", "--set", setting, "--out", str(tmp_path / "r"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and needle in err[0]
    assert not (tmp_path / "r").exists()
