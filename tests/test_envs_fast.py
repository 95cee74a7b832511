"""The environment's period as one compiled call (``envs/fast.py``, issue 30 item 6) gives the bits of the
step-by-step path it replaces: observations, rewards, flags, infos, the plant's watches (contacts, proximity,
tilt, slip), the episode's summary and the random stream, on the MuJoCo and the ideal plant, for a seeded random
policy, the paper's controller (through :class:`ControllerPolicy`'s own one-call path), a collision
and a divergence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from bioform_mj.control.stack import ControlStack  # noqa: E402
from bioform_mj.envs import ControllerPolicy, parallel_env  # noqa: E402


class _SlowStack(ControlStack):
    """The paper's stack through ``ControlStack.step`` (ControllerPolicy's one-call path is for the exact type)."""


def _episode(env, act, fast: bool, seed: int = 3):
    """Every output of an episode of ``act(env, obs)`` with the fast period on or off (``_fast_ok``)."""
    obs, _ = env.reset(seed=seed)
    env._fast_ok = fast and env._fast_ok
    out = []
    while env.agents:
        step = env.step(act(env, obs))
        obs = step[0]
        out.append(step)
    p = env._plant
    if hasattr(p, "contacts"):
        c = p.contacts
        watch = [x.copy() for x in (c.contacts.ci, c.contacts.cf, c.proximity.rf, c.proximity.ri, p.tip_step,
                                    p.slip_step, p.slip_run, p.data.qpos, p.data.qvel)]  # fmt: skip
    else:  # the ideal plant: its state [x, y, θ, υ, ω]
        watch = [p.x.copy()]
    return out, watch, env.episode_summary(), env._fastp is not None


def _same(a, b) -> None:
    (sa, wa, ma, fa), (sb, wb, mb, fb) = a, b
    assert fa and not fb  # the first ran the compiled period, the second did not
    assert len(sa) == len(sb)
    for x, y in zip(sa, sb):
        for agent in x[0]:
            assert np.array_equal(x[0][agent], y[0][agent]), agent
            assert x[0][agent].dtype == y[0][agent].dtype
        assert x[1:] == y[1:]  # rewards, terminations, truncations, infos: equal floats, not close
    for u, v in zip(wa, wb):
        assert np.array_equal(u, v, equal_nan=True)
    assert ma == mb


def _random(seed: int):
    rng = np.random.default_rng(seed)

    def act(env, obs):
        return {a: env.action_space(a).sample() if rng.random() < 0.5 else
                rng.uniform(env.action_space(a).low, env.action_space(a).high) for a in env.agents}  # fmt: skip

    return act


@pytest.mark.slow  # ~5 s with the kernels' first load from numba's cache
@pytest.mark.parametrize("plant", ["mujoco", "ideal"])
@pytest.mark.parametrize("action", ["velocity", "torque"])
def test_fast_period_is_the_step_by_step_path(action, plant):
    """Seeded random actions (float32 samples and float64 draws) on both plants at 1 ms: bit for bit."""
    ov = ["sim.duration=0.15", "sim.control_dt=0.001", f"plant.kind={plant}", "formation.init_jitter=0.05"]
    env = parallel_env("paper", action=action, overrides=ov)
    for a in env.possible_agents:
        env.action_space(a).seed(7)
    fast = _episode(env, _random(1), True)
    for a in env.possible_agents:
        env.action_space(a).seed(7)
    _same(fast, _episode(env, _random(1), False))


@pytest.mark.parametrize("plant", ["mujoco", "ideal"])
def test_controller_policy_one_call_is_control_stack_step(plant):
    """The paper's controller through the environment (the benchmark's episode): ControllerPolicy's
    compiled call and ``ControlStack.step`` give the same torques, metric and episode."""
    ov = ["sim.duration=0.2", "sim.control_dt=0.001", f"plant.kind={plant}"]
    env = parallel_env("paper", action="torque", overrides=ov)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        runs = []
        for fast, ctrl in ((True, None), (False, "slow")):
            env.reset(seed=0)
            pol = ControllerPolicy(env)
            pol.reset()
            if ctrl == "slow":
                st = pol.controller
                pol.controller = _SlowStack(st.graph, st.p)
                pol.controller.reset(np.array(st.state.est_pose), np.array(env._vel))
            runs.append((_episode(env, lambda e, o, pol=pol: pol(o), fast, seed=0), pol.verr.copy()))
    (fast_run, verr_fast), (slow_run, verr_slow) = runs
    _same(fast_run, slow_run)
    assert np.array_equal(verr_fast, verr_slow) and verr_fast.min() > 0


def test_fast_period_collision_and_divergence():
    """The crossing preset driven into a collision (contact events, the proximity watch, ``collided``
    infos) and a speed limit that ends the episode (the guards, the terminal reward): bit for bit."""

    def head_on(env, obs):
        pose, _ = env.measured_state()
        act = {}
        for a, i in env._index.items():
            j = 1 - i if env.n == 2 else (i + 1) % env.n
            err = np.arctan2(pose[j, 1] - pose[i, 1], pose[j, 0] - pose[i, 0]) - pose[i, 2]
            act[a] = np.array([0.5, float(np.clip(3.0 * np.arctan2(np.sin(err), np.cos(err)), -6, 6))])
        return act

    ov = ["sim.duration=4", "sim.control_dt=0.01", "safety.filter=none", "plant.kind=mujoco"]
    env = parallel_env("crossing", action="velocity", overrides=ov)
    fast = _episode(env, head_on, True, seed=0)
    assert any("collided" in s[4][a] for s in fast[0] for a in s[4])
    _same(fast, _episode(env, head_on, False, seed=0))
    ov = ["sim.duration=1", "sim.control_dt=0.01", "limits.speed=0.6", "plant.kind=mujoco"]
    env = parallel_env("paper", action="velocity", v_max=1.0, overrides=ov)
    push = lambda env, obs: {a: np.array([0.02 * env.k, 0.0]) for a in env.agents}  # noqa: E731
    fast = _episode(env, push, True, seed=0)
    assert "diverged" in fast[0][-1][4]["follower_1"] and len(fast[0]) >= 2  # ended in a compiled period
    _same(fast, _episode(env, push, False, seed=0))


@pytest.mark.parametrize("plant", ["mujoco", "ideal"])
def test_fast_period_around_a_payload_event(plant):
    """The payload preset with its pick-up moved to t = 0.05 s: the event's period runs step by step, the
    arguments are built again from the plant's new masses (the ideal plant: its ``c``) after it, and the
    episode is the same bits."""
    import dataclasses

    from bioform_mj.scenario.loader import load

    sc = load("payload", ["sim.control_dt=0.01", f"plant.kind={plant}"])
    sc = dataclasses.replace(sc, events=(dataclasses.replace(sc.events[0], time=0.05),))
    env = parallel_env(sc, action="torque", max_cycles=15)
    for a in env.possible_agents:
        env.action_space(a).seed(3)
    fast = _episode(env, _random(2), True)
    if plant == "mujoco":
        assert env._plant._payload_added
    else:
        i = sc.events[0].follower - 1
        assert not np.array_equal(env._plant.c_true()[i], env.nominal_c_true[i])  # the payload changed c_i
    for a in env.possible_agents:
        env.action_space(a).seed(3)
    _same(fast, _episode(env, _random(2), False))
