"""The PettingZoo environment (bioform_mj.envs, design §20): PettingZoo's own API and seed tests,
a Controller's episode against ``bioform run`` of the same scenario, the torque law tracking the
agents' commands, locality of the observations, and every bad input as a named ValueError."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import parallel_api_test, parallel_seed_test  # noqa: E402
from pettingzoo.test.seed_test import seed_test  # noqa: E402
from pettingzoo.utils import parallel_to_aec  # noqa: E402

from bioform_mj.envs import ControllerPolicy, parallel_env, run_episode
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

SHORT = ["sim.duration=0.3", "sim.control_dt=0.01", "formation.init_jitter=0.05"]


@pytest.mark.parametrize("plant", ["ideal", "mujoco"])
@pytest.mark.parametrize("action", ["velocity", "torque"])
def test_pettingzoo_api_and_seed_tests(plant, action):
    """PettingZoo's parallel API test, its parallel seed test and the AEC seed test (through
    ``parallel_to_aec``) pass, with a seeded jitter so that reset(seed) really matters; no warning."""
    mk = lambda: parallel_env("paper", action=action, overrides=[*SHORT, f"plant.kind={plant}"])  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # PettingZoo reports API problems as warnings
        parallel_api_test(mk(), num_cycles=40)
        parallel_seed_test(mk, num_cycles=40)
        seed_test(lambda: parallel_to_aec(mk()), num_cycles=40)


def test_seed_decides_the_episode_bit_for_bit():
    """Same seed: identical observations and rewards bit for bit; another seed (jittered start): different."""

    def episode(seed):
        env = parallel_env("paper", overrides=[*SHORT, "plant.kind=mujoco"])
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        trace = [np.concatenate([obs[a] for a in env.possible_agents])]
        while env.agents:
            act = {a: rng.uniform(-0.3, 0.3, 2) for a in env.agents}
            obs, rew, *_ = env.step(act)
            trace.append(np.concatenate([obs[a] for a in obs] + [np.array(list(rew.values()))]))
        return np.concatenate(trace)

    a, b, c = episode(3), episode(3), episode(4)
    assert a.tobytes() == b.tobytes()
    assert np.max(np.abs(a - c)) > 1e-3


@pytest.mark.parametrize("plant", ["ideal", "mujoco"])
def test_controller_episode_matches_bioform_run(plant):
    """The paper's controller run through the environment gives ``bioform run``'s summary: Table I's
    metric, final and RMS formation error and outcomes within 1e-9 relative (measured: ≤ 1.4e-14 on
    MuJoCo, the rounding of numpy's hypot against the log's; 0 on the ideal plant)."""
    ov = ["sim.duration=2", f"plant.kind={plant}"]
    env = parallel_env("paper", action="torque", overrides=ov)
    ep = run_episode(env, ControllerPolicy(env), seed=0)
    run = simulate(load("paper", ov))
    assert ep["steps"] == run.summary["steps"] == 2000
    for f, g in zip(run.summary["followers"], ep["followers"]):
        for key in ("total_velocity_error", "final_formation_error_m", "rms_formation_error_m"):
            assert g[key] == pytest.approx(f[key], rel=1e-9, abs=1e-12), key
        assert g["c_hat"] == pytest.approx(f["c_hat"], rel=1e-9)
        assert g["outcome"] == f["outcome"] and [o["kind"] for o in g["outcomes"]] == [o["kind"] for o in f["outcomes"]]
    # and the episode is not trivial: every follower closes on its slot from its initial error
    fe0 = env._rows_fe[0]
    for i, g in enumerate(ep["followers"]):
        assert g["final_formation_error_m"] < 0.7 * fe0[i], (g["final_formation_error_m"], fe0[i])


FAULTS = {  # the shipped fault presets, their fault moved into a 2 s episode
    "fault_actuator": ["faults.actuator=[[1,0.5,1.5,0.2]]"],
    "fault_delay": ["faults.window=[0.5,1.5]"],
    "fault_link": ["faults.link_fail=[[1,2,0.5,1.5]]"],
    "fault_noise": ["faults.window=[0.5,1.5]"],
    "fault_packet_loss": ["faults.window=[0.5,1.5]"],
    "fault_push": ["faults.push=[[2,0.5,0.2,200.0,200.0,5.0]]"],
}


@pytest.fixture(scope="module")
def no_fault_run():
    return simulate(load("paper", ["sim.duration=2", "plant.kind=mujoco"])).summary


@pytest.mark.parametrize("preset", sorted(FAULTS))
def test_faults_reach_the_environment_as_in_bioform_run(preset, no_fault_run):
    """Per-step faults (a weakened motor, delay, link failure, noise, packet loss, a push) act in the
    environment as in ``bioform run`` (same Faults object, same order; observations carry the network
    as delivered): the paper's controller gives the run's metrics within 1e-9 relative (measured
    <= 1.1e-13), and each fault moves them (>= 0.02 against the run without faults)."""
    ov = ["sim.duration=2", *FAULTS[preset]]
    env = parallel_env(preset, action="torque", overrides=ov)
    ep = run_episode(env, ControllerPolicy(env))
    run = simulate(load(preset, ov)).summary
    keys = ("total_velocity_error", "final_formation_error_m", "rms_formation_error_m")
    moved = 0.0
    for f, g, b in zip(run["followers"], ep["followers"], no_fault_run["followers"]):
        for key in keys:
            assert g[key] == pytest.approx(f[key], rel=1e-9), key
            moved = max(moved, abs(g[key] - b[key]))
    assert moved > 0.02


def test_velocity_action_is_tracked_by_the_torque_law():
    """``action = "velocity"``: a constant command (0.3 m/s, 0.5 rad/s) is tracked by the paper's
    sliding-mode law on MuJoCo robots: after 2 s every robot's υ and ω within 3 % of it."""
    env = parallel_env("paper", action="velocity", overrides=["sim.duration=2", "plant.kind=mujoco"])
    env.reset(seed=0)
    cmd = np.array([0.3, 0.5])
    while env.agents:
        env.step({a: cmd for a in env.agents})
    _, vel = env.measured_state()
    assert np.allclose(vel, cmd, rtol=0.03), vel


def test_observations_are_local():
    """The leader block is filled only for followers with leader access; the neighbour blocks follow
    the graph's in-neighbours; the slot error is the tracking error from the follower's own estimate
    (eq. 27), checked against a hand computation."""
    env = parallel_env("paper", overrides=["sim.duration=1", "sim.control_dt=0.01"])
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, *_ = env.step({a: np.array([0.1, 0.0]) for a in env.agents})
    K, s = env.K, env._s
    access = np.asarray(env.graph.leader_access)
    pose, _ = env.measured_state()
    for a, i in env._index.items():
        o = obs[a]
        lead = o[7 + 6 * K :]
        assert lead[0] == access[i]
        if not access[i]:
            assert np.all(lead == 0)
        present = o[7 : 7 + 6 * K].reshape(K, 6)[:, 0]
        assert int(present.sum()) == len(env._nbrs[i])
        off = np.asarray(env._sc.formation.offsets)[i]
        ex, ey = s.est_pose[i, 0] - pose[i, 0] - off[0], s.est_pose[i, 1] - pose[i, 1] - off[1]
        c, sn = np.cos(pose[i, 2]), np.sin(pose[i, 2])
        assert o[2:4] == pytest.approx([c * ex + sn * ey, -sn * ex + c * ey], abs=1e-12)
    assert access.sum() < env.n  # the paper's graph: not every follower sees the leader


def test_bad_input_is_named():
    env = parallel_env("paper", overrides=SHORT)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    env.reset(seed=0)
    good = {a: np.zeros(2) for a in env.agents}
    for bad, match in [
        ({**good, "follower_9": np.zeros(2)}, "unknown agent 'follower_9'"),
        ({k: v for k, v in good.items() if k != "follower_2"}, "no action for live agent.*follower_2"),
        ({**good, "follower_1": np.zeros(3)}, "follower_1 must"),
        ({**good, "follower_3": np.array([np.nan, 0.0])}, "follower_3 .* not finite"),
        ({**good, "follower_2": np.array([100.0, 0.0])}, "follower_2 .* outside the action space"),
    ]:
        with pytest.raises(ValueError, match=match):
            env.step(bad)
    while env.agents:
        env.step(good)
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step(good)
    with pytest.raises(ValueError, match="unknown agent"):
        env.action_space("leader")
    with pytest.raises(ValueError, match="unknown action mode 'wheel'"):
        parallel_env("paper", action="wheel")
    with pytest.raises(ValueError, match="unknown reward term 'speed'"):
        parallel_env("paper", reward={"speed": 1.0})
    with pytest.raises(ValueError, match="no_such_preset|unknown"):
        parallel_env("no_such_preset")


def test_reward_terms():
    """The reward is −dt·(w_f·e + w_e·effort): with only the formation term it equals −dt·(true formation error)."""
    env = parallel_env("paper", reward={"effort": 0.0}, overrides=SHORT)
    env.reset(seed=1)
    _, rew, *_ = env.step({a: np.array([0.2, 0.1]) for a in env.agents})
    fe = env._formation_error(env.k)
    assert [rew[a] for a in env.possible_agents] == pytest.approx(-env.dt * fe, rel=1e-12)


def test_divergence_terminates_with_the_remaining_time_penalty():
    """A state beyond ``limits`` ends the episode for every agent (terminated, named in infos), and the
    reward of that step carries −w_terminal·(T − t), so that ending early never pays."""
    env = parallel_env(
        "paper",
        v_max=1.0,
        reward={"effort": 0.0},
        overrides=["sim.duration=1", "sim.control_dt=0.01", "limits.speed=0.05"],
    )
    env.reset(seed=0)
    while env.agents:
        obs, rew, term, trunc, info = env.step({a: np.array([0.5, 0.0]) for a in env.agents})
    assert all(term.values()) and not any(trunc.values())
    assert "limits.speed" in info["follower_1"]["diverged"]
    t = info["follower_1"]["t"]
    assert t < 1.0
    fe = env._formation_error(env.k)
    expect = -env.dt * fe - env.weights["terminal"] * (1.0 - t)
    assert [rew[a] for a in env.possible_agents] == pytest.approx(expect, rel=1e-6)


def test_a_collision_costs_reward_and_is_named():
    """The crossing preset (two followers swap sides, design §19): driven straight at each other with a
    velocity command, they touch; the step's reward of each carries -w_collision per contact event and
    infos name them; the episode's summary lists the ``collided`` outcome."""
    env = parallel_env("crossing", action="velocity", reward={"formation": 0.0, "effort": 0.0, "terminal": 0.0},
                       overrides=["sim.duration=6", "sim.control_dt=0.01", "safety.filter=none"])  # fmt: skip
    env.reset(seed=0)
    hit_rewards, named = [], set()
    while env.agents:
        pose, _ = env.measured_state()
        act = {}
        for a, i in env._index.items():
            j = 1 - i if env.n == 2 else (i + 1) % env.n
            dx, dy = pose[j, 0] - pose[i, 0], pose[j, 1] - pose[i, 1]
            err = np.arctan2(dy, dx) - pose[i, 2]
            act[a] = np.array([0.5, float(np.clip(3.0 * np.arctan2(np.sin(err), np.cos(err)), -6, 6))])
        _, rew, _, _, info = env.step(act)
        for a, r in rew.items():
            if r != 0.0:
                hit_rewards.append(r)
                named |= set(info[a].get("collided", []))
    assert hit_rewards and all(r <= -env.weights["collision"] + 1e-12 for r in hit_rewards)
    assert named
    kinds = {o["kind"] for f in env.episode_summary()["followers"] for o in f["outcomes"]}
    assert "collided" in kinds


def test_float32_observations_for_learning_libraries():
    """``dtype="float32"``: observations and their space in float32 (BenchMARL's and SB3's networks),
    the same numbers as float64 rounded once; the API test still passes."""
    mk = lambda dtype: parallel_env("paper", dtype=dtype, overrides=SHORT)  # noqa: E731
    e64, e32 = mk("float64"), mk("float32")
    o64, _ = e64.reset(seed=2)
    o32, _ = e32.reset(seed=2)
    for a in e64.possible_agents:
        assert o32[a].dtype == np.float32 and e32.observation_space(a).dtype == np.float32
        assert np.array_equal(o32[a], o64[a].astype(np.float32))
    parallel_api_test(mk("float32"), num_cycles=10)
    with pytest.raises(ValueError, match="unknown observation dtype"):
        mk("float16")
