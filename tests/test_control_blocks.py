"""Control blocks against closed forms: neuron, estimator locality, learner, derivative filter, torque law."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from oracle import Estimator, wheel_to_body  # the estimator's graph sums are checked against the kernel in test_engines

from bioform_mj.core import equations as eq
from bioform_mj.formation import graph
from bioform_mj.plants.ideal import IdealPlant

# The properties below are asserted on the package's own equations (control/equations.py),
# applied elementwise; the numpy oracle is only used where a test needs the graph sums.
wrap = np.vectorize(eq.wrap, otypes=[float])
_sat = np.vectorize(eq.sat, otypes=[float])
_neuron = np.vectorize(eq.neuron_step, otypes=[float])
_learn = np.vectorize(eq.learner_step, otypes=[float, float, float, float])


def sat_sign(x, phi):
    return _sat(x, phi)


def shunting_step(vs, x, A, B, D, dt):
    return _neuron(vs, x, A, B, D, dt)


def tracking_error(est, pose, off):
    out = np.empty_like(np.asarray(pose, dtype=float))
    for i in range(out.shape[0]):
        out[i] = eq.tracking_error(*est[i], *pose[i], *off[i])
    return out


def sliding_mode_torques(cmd, dcmd, vel, c_hat, c_gain, phi):
    out = np.empty_like(np.asarray(cmd, dtype=float))
    for i in range(out.shape[0]):
        out[i] = eq.sliding_mode(
            cmd[i, 0],
            cmd[i, 1],
            dcmd[i, 0],
            dcmd[i, 1],
            vel[i, 0],
            vel[i, 1],
            c_hat[i, 0],
            c_hat[i, 1],
            c_gain[0],
            c_gain[1],
            phi,
        )
    return out


class Learner:
    """eq.learner_step over (n, 2) arrays (both channels), as the kernel applies it."""

    def __init__(self, n, k4, k5, c_min, c_max, kd=(0.0, 0.0)):
        self.k4, self.k5, self.kd = np.asarray(k4, float), np.asarray(k5, float), np.asarray(kd, float)
        self.c_min = np.broadcast_to(np.asarray(c_min, float), (n, 2)).copy()
        self.c_max = np.broadcast_to(np.asarray(c_max, float), (n, 2)).copy()
        self.z_hat, self.e_int, self.c_hat, self.d_hat = (np.zeros((n, 2)) for _ in range(4))

    def reset(self, z0, c_hat0):
        self.z_hat[:] = z0
        self.e_int[:] = 0.0
        self.c_hat[:] = np.clip(c_hat0, self.c_min, self.c_max)
        self.d_hat[:] = 0.0

    def step(self, tau, z, dt):
        self.z_hat, self.e_int, self.c_hat, self.d_hat = _learn(
            self.z_hat,
            self.e_int,
            self.c_hat,
            self.d_hat,
            tau,
            z,
            self.k4,
            self.k5,
            self.kd,
            self.c_min,
            self.c_max,
            dt,
        )


class DerivativeFilter:
    """eq.filter_step with eq.filter_coefficients over (n, 2) arrays."""

    def __init__(self, n, wn, dt):
        self.c = eq.filter_coefficients(wn, dt)
        self.dt = dt
        self.y = np.zeros((n, 2))
        self.dy = np.zeros((n, 2))

    def reset(self, u0):
        self.y[:] = u0
        self.dy[:] = 0.0

    def step(self, u):
        f = np.vectorize(
            lambda y, dy, uu: eq.filter_derivative(y, dy, uu, *self.c, self.dt), otypes=[float, float, float]
        )
        self.y, self.dy, d = f(self.y, self.dy, u)
        return d


def test_wrap_range():
    a = np.linspace(-20, 20, 10001)
    w = wrap(a)
    assert w.max() <= math.pi and w.min() > -math.pi
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    assert wrap(-math.pi) == pytest.approx(math.pi)


@settings(max_examples=300, deadline=None)
@given(
    x=st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=20),
    A=st.floats(0.01, 50),
    B=st.floats(0.01, 50),
    D=st.floats(0.01, 50),
    dt=st.floats(1e-5, 10.0),
    steps=st.integers(1, 30),
)
def test_neuron_output_stays_in_open_interval(x, A, B, D, dt, steps):
    x = np.array(x)
    vs = np.zeros_like(x)
    for k in range(steps):
        vs = shunting_step(vs, x * (1 if k % 2 else -0.5), A, B, D, dt)
        assert np.all(vs < B) and np.all(vs > -D)


def test_neuron_matches_eq33_closed_form():
    # B = D: V' = -(A + |x|) V + B x; for constant x, V(t) = V_inf (1 - exp(-(A+|x|) t)).
    A, B, x, t = 2.0, 2.0, 1.5, 0.7
    vs = np.zeros(1)
    for _ in range(700):
        vs = shunting_step(vs, np.array([x]), A, B, B, 1e-3)
    lam = A + abs(x)
    assert vs[0] == pytest.approx(B * x / lam * (1 - math.exp(-lam * t)), rel=1e-12)


def test_tracking_error_body_frame():
    est = np.array([[3.0, 4.0, 0.5]])
    pose = np.array([[1.0, 1.0, math.pi / 2]])
    off = np.array([[1.0, 1.0]])
    e = tracking_error(est, pose, off)
    # world error (1, 2); heading +90° → body x̃ = e_y = 2, ỹ = -e_x = -1
    np.testing.assert_allclose(e[0], [2.0, -1.0, wrap(0.5 - math.pi / 2)], atol=1e-12)


def test_estimator_locality():
    """A follower's update reads only its neighbours, and the leader only when a_ir = 1."""
    g = graph.chain(4, leader_access=[1])
    est = Estimator(g, [15, 15, 15], [25, 25], [1, 1], [0.1, 0.1])
    rng = np.random.default_rng(1)
    est.reset(rng.normal(size=(4, 3)))
    est.vel[:] = rng.normal(size=(4, 2))
    base_pose, base_vel = est.pose.copy(), est.vel.copy()

    def advance(lp, lv, mutate=None):
        est.pose[:], est.vel[:] = base_pose, base_vel
        if mutate:
            mutate()
        est.step(lp, lv, 1e-3)
        return est.pose.copy(), est.vel.copy()

    lp, lv = np.array([1.0, 2.0, 0.3]), np.array([1.0, 0.1])
    p0, v0 = advance(lp, lv)
    # change the leader: only follower 1 (index 0) reacts in one step
    p1, v1 = advance(lp + 5.0, lv + 1.0)
    changed = np.any(p1 != p0, axis=1) | np.any(v1 != v0, axis=1)
    assert changed.tolist() == [True, False, False, False]

    # change follower 4's estimate: only followers 3 and 4 react
    def bump():
        est.pose[3] += 1.0
        est.vel[3] += 1.0

    p2, v2 = advance(lp, lv, bump)
    changed = np.any(p2 != p0, axis=1) | np.any(v2 != v0, axis=1)
    assert changed.tolist() == [False, False, True, True]


def test_estimator_wraps_heading_differences():
    g = graph.from_edges(1, [], [1])
    est = Estimator(g, [15, 15, 15], [25, 25], [1, 1], [0, 0])
    est.reset(np.array([[0.0, 0.0, math.pi - 0.01]]))
    est.step(np.array([0.0, 0.0, -math.pi + 0.01]), np.zeros(2), 1e-3)
    # the short way round is +0.02 rad: the estimate must increase past π, i.e. wrap to near −π
    assert wrap(est.pose[0, 2] - (math.pi - 0.01)) > 0


def test_learner_converges_on_ideal_dynamics_with_persistent_excitation():
    n, dt = 4, 1e-3
    c_true = np.array([[0.4, 10.0], [1.0, 3.0], [0.1, 50.0], [2.0, 0.5]])
    L = Learner(n, [6, 50], [25, 50], c_min=0.01, c_max=100)
    z = np.zeros((n, 2))
    L.reset(z, c_true * 0.5)
    for k in range(20000):
        t = k * dt
        tau = np.stack([3 * np.sin(t) + 1.5 * np.sin(3.1 * t), np.cos(1.3 * t)], axis=-1) * np.ones((n, 1))
        z = z + dt * tau * c_true  # exact for piecewise-constant torque
        L.step(tau, z, dt)
    np.testing.assert_allclose(L.c_hat, c_true, rtol=0.01)


def test_learner_implicit_step_is_stable_where_explicit_euler_diverges():
    """|τ| far beyond sqrt(k5/(k4 dt)) (design §8): the backward-Euler step stays bounded."""
    n, dt = 1, 1e-3
    L = Learner(n, [6, 50], [25, 50], c_min=1e-3, c_max=1e3)
    z = np.zeros((n, 2))
    L.reset(z, np.array([[0.2, 5.0]]))
    tau = np.array([[200.0, 200.0]])  # sqrt(25/(6e-3)) ≈ 65
    for _ in range(3000):
        z = z + dt * tau * np.array([[0.4, 10.0]])
        L.step(tau, z, dt)
    assert np.all(np.isfinite(L.c_hat))
    np.testing.assert_allclose(L.c_hat, [[0.4, 10.0]], rtol=1e-3)


def test_learner_projection_keeps_bounds():
    L = Learner(1, [6, 50], [25, 50], c_min=np.array([[0.3, 8.0]]), c_max=np.array([[0.5, 12.0]]))
    L.reset(np.zeros((1, 2)), np.array([[0.4, 10.0]]))
    z = np.zeros((1, 2))
    for _ in range(2000):
        z = z + 1e-3 * np.array([[50.0, -50.0]])  # far from any c inside the bounds
        L.step(np.array([[1.0, 1.0]]), z, 1e-3)
    assert 0.3 <= L.c_hat[0, 0] <= 0.5 and 8.0 <= L.c_hat[0, 1] <= 12.0


def test_derivative_filter_tracks_sine_and_rejects_alternation():
    dt, wn = 1e-3, 50.0
    f = DerivativeFilter(1, wn, dt)
    t = np.arange(0, 5, dt)
    u = np.sin(t)
    f.reset(np.array([[u[0], u[0]]]))
    out = np.array([f.step(np.array([[ui, ui]]))[0, 0] for ui in u])
    # after the transient, error against cos t is the ~2/wn lag (0.04 rad)
    assert np.max(np.abs(out[2000:] - np.cos(t[2000:] - 2 / wn))) < 2e-3
    f.reset(np.zeros((1, 2)))
    alt = np.array([f.step(np.full((1, 2), 0.025 * (-1) ** k))[0, 0] for k in range(2000)])
    assert np.abs(alt[1000:]).max() < 0.025 * wn**2 * dt  # a raw difference would give 50


def test_sat_sign():
    x = np.array([-2.0, -0.05, 0.0, 0.05, 2.0])
    np.testing.assert_array_equal(sat_sign(x, 0.0), np.sign(x))
    np.testing.assert_allclose(sat_sign(x, 0.1), [-1, -0.5, 0, 0.5, 1])


def test_torque_law_sign_fix_turns_the_right_way():
    """design §5: with τ_b = τ_R − τ_L, a positive ω error must raise ω on the plant."""
    cmd = np.array([[0.0, 1.0]])
    tau = sliding_mode_torques(
        cmd, np.zeros((1, 2)), np.zeros((1, 2)), np.array([[0.4, 10.0]]), np.array([3.0, 3.0]), 0.0
    )
    assert tau[0, 1] > tau[0, 0]
    np.testing.assert_allclose(wheel_to_body(tau), [[0.0, 0.3]])
    plant = IdealPlant(np.array([0.4, 10.0]), np.zeros((1, 3)), 1e-3, 1e-3, lambda t: np.zeros((1, 2)))
    plant.step(tau, 0.0)
    _, vel = plant.observe()
    assert vel[0, 1] == pytest.approx(10.0 * 0.3 * 1e-3)
    assert vel[0, 0] == pytest.approx(0.0)


def test_ideal_plant_matches_unicycle_closed_form():
    """Constant turn: υ̇ = a τ_a, ω̇ = b τ_b, from rest; pose against the exact integral."""
    plant = IdealPlant(np.array([0.4, 10.0]), np.zeros((1, 3)), 1e-2, 1e-3, lambda t: np.zeros((1, 2)))
    tau = np.array([[1.0, 1.0]])
    for k in range(100):
        plant.step(tau, k * 1e-2)
    pose, vel = plant.observe()
    assert vel[0, 0] == pytest.approx(0.8 * 1.0, rel=1e-9)
    assert pose[0, 0] == pytest.approx(0.4, rel=1e-9)
    assert pose[0, 1] == pytest.approx(0.0, abs=1e-12)


def test_knobs_are_the_gains_numbers_in_order():
    """kernel.Knobs (what the inlined step pieces read of the gains, issue 28) holds exactly the numbers of Gains,
    each equal to the Gains field of that name, and no array."""
    from bioform_mj.control import kernel as K

    n, m = 3, 2
    nums = {f: float(i) + 0.5 for i, f in enumerate(K.Gains._fields)}
    nums.update(deriv=2, bio=True, learning=False, steer=True, leader_frame=False, cbf=True)
    arr = {f: np.full((n, 2), 7.0) for f in K.Gains._fields if f not in K.KNOBS}
    arr.update(src=np.zeros(m, dtype=np.int64), dst=np.ones(m, dtype=np.int64), lim=np.ones(n), lacc=np.ones(n))
    arr.update(cbf_par=np.ones(5), cbf_rad=np.ones(n), cbf_b=np.ones(n), cbf_lam=np.ones(n), cbf_bad=np.zeros(n))
    g = K.Gains(**{f: arr[f] if f in arr else nums[f] for f in K.Gains._fields})
    kn = K.knobs(g)
    assert kn._fields == K.KNOBS
    assert len(K.KNOBS) + len(arr) == len(K.Gains._fields) == 53
    for f in K.KNOBS:
        assert getattr(kn, f) == nums[f] and type(getattr(kn, f)) is type(nums[f]), f
