"""The formation environment as trainers use it (issue 30, design §20): auto-resets that explore,
start and domain randomisation, pickles and copies that continue an episode bit for bit, float32
actions at the bounds, PettingZoo's state/max_cycles/render tests, the Gymnasium single-agent
wrapper under Gymnasium's and SB3's checkers, and SuperSuit + SB3 ``SubprocVecEnv`` training on MuJoCo."""

from __future__ import annotations

import copy
import functools
import math
import pickle
import warnings

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

import bioform_mj.envs as envs_mod  # noqa: E402
from bioform_mj.envs import follower_env, parallel_env  # noqa: E402

SHORT = ["sim.duration=0.3", "sim.control_dt=0.01"]
PLANTS = ["ideal", "mujoco"]
RAND = {"position": (-0.3, 0.3), "heading": (-0.5, 0.5)}


def _mk(plant, **kw):
    return parallel_env("paper", overrides=[*SHORT, f"plant.kind={plant}", *kw.pop("extra", [])], **kw)


@pytest.mark.parametrize("plant", PLANTS)
def test_auto_resets_explore_and_are_reproducible(plant):
    """After ``reset(seed=1)``, 16 ``reset()`` give 16 distinct episode seeds and, with start randomisation,
    16 distinct starts, every start within the stated ranges; the sequence is the same in another
    environment seeded alike; ``reset(seed=s)`` is the episode of seed ``s`` whatever came before."""
    a, b = _mk(plant, randomize=RAND), _mk(plant, randomize=RAND)
    nominal = np.array(a.base_scenario.initial_poses())
    out = []
    for env in (a, b):
        env.reset(seed=1)
        seeds, starts = [], []
        for _ in range(16):
            _, info = env.reset()
            seeds.append(info["follower_1"]["seed"])
            pose, _ = env.measured_state()
            starts.append(pose.copy())
            d = pose - nominal
            assert np.all(np.abs(d[:, :2]) <= 0.3 + 1e-6)
            assert np.all(np.abs(np.angle(np.exp(1j * d[:, 2]))) <= 0.5 + 1e-6)
        out.append((seeds, np.array(starts)))
    assert len(set(out[0][0])) == 16
    assert len({s.round(9).tobytes() for s in out[0][1]}) == 16
    assert out[0][0] == out[1][0] and out[0][1].tobytes() == out[1][1].tobytes()
    o1, _ = a.reset(seed=5)
    o2, _ = _mk(plant, randomize=RAND).reset(seed=5)
    assert all(o1[k].tobytes() == o2[k].tobytes() for k in o1)


def test_without_randomisation_the_scenario_seed_starts_and_jitter_explores():
    """No ``randomize``: the first ``reset()`` is the scenario's own ``sim.seed`` (as before); auto-resets
    still draw new seeds, so a scenario with ``init_jitter`` gives 16 distinct starts over 16 resets."""
    env = _mk("ideal", extra=["formation.init_jitter=0.1"])
    _, info = env.reset()
    assert info["follower_1"]["seed"] == env.base_scenario.sim.seed
    starts = set()
    for _ in range(16):
        env.reset()
        starts.add(env.measured_state()[0].round(9).tobytes())
    assert len(starts) == 16


def test_domain_randomisation_draws_within_the_ranges():
    """Payload (MuJoCo), friction, actuator and a scenario key are drawn per episode within their ranges
    and reach the episode: the payload as events of the episode's scenario (and in c_true after the first
    step), friction in the compiled model, packet loss in the episode's scenario; c_true on the ideal plant."""
    rz = {"payload": (1.0, 3.0), "friction": (0.5, 1.5), "actuator": (0.6, 0.9), "faults.packet_loss": (0.0, 0.2)}
    env = _mk("mujoco", randomize=rz)
    c0 = None
    fr0 = None
    for s in range(4):
        env.reset(seed=s)
        p = env.episode_parameters
        assert np.all((p["payload"] >= 1.0) & (p["payload"] <= 3.0)) and p["payload"].shape == (3,)
        assert 0.5 <= p["friction"] <= 1.5 and 0.0 <= p["faults.packet_loss"] <= 0.2
        sc = env.episode_scenario
        assert sorted(e.mass for e in sc.events) == sorted(p["payload"].tolist())
        assert sc.faults.packet_loss == p["faults.packet_loss"]
        assert [r[3] for r in sc.faults.actuator] == p["actuator"].tolist()
        if c0 is None:
            c0, fr0 = env.nominal_c_true.copy(), env._nominal_friction[0].copy()
        assert np.allclose(env._plant.model.geom_friction[:, 0], p["friction"] * fr0, rtol=1e-12)
        env.step({a: np.zeros(2) for a in env.agents})
        assert np.all(env._plant.c_true()[:, 0] < c0[:, 0])  # heavier: a = 1/(m r ...) smaller
    ide = _mk("ideal", randomize={"c_true": (0.8, 1.2)})
    ide.reset(seed=0)
    f = ide._plant.c_true() / np.array(ide.base_scenario.plant.c_true)
    assert np.all((f >= 0.8) & (f <= 1.2)) and len(np.unique(f.round(12))) == 6
    assert np.array_equal(ide.nominal_c_true, np.tile(ide.base_scenario.plant.c_true, (3, 1)))


@pytest.mark.parametrize(
    ("plant", "rz", "match"),
    [
        ("ideal", {"mass": (0, 1)}, "unknown randomisation key 'mass'"),
        ("ideal", {"position": (0.3, -0.3)}, r"randomize\['position'\] is reversed"),
        ("ideal", {"heading": (math.nan, 0.1)}, r"randomize\['heading'\] must be finite"),
        ("ideal", {"position": 0.3}, r"randomize\['position'\] must be a range"),
        ("ideal", {"faults.packet_loss": (0.0, 2.0)}, r"randomize\['faults.packet_loss'\] bound 2"),
        ("ideal", {"payload": (-1.0, 1.0)}, r"randomize\['payload'\] bound -1"),
        ("ideal", {"actuator": (0.5, 1.5)}, r"randomize\['actuator'\] bound 1.5"),
        ("ideal", {"c_true": (0.0, 1.0)}, r"randomize\['c_true'\] bound 0"),
        ("ideal", {"friction": (0.5, 1.0)}, r"randomize\['friction'\] needs plant.kind = mujoco"),
        ("mujoco", {"c_true": (0.5, 1.0)}, r"randomize\['c_true'\] needs plant.kind = ideal"),
        ("mujoco", {"friction": (-0.5, 1.0)}, r"randomize\['friction'\] must be > 0"),
        ("mujoco", {"friction": (0.0, 1.0)}, r"randomize\['friction'\] must be > 0 .*no grip.*got low 0"),
    ],
)
def test_bad_randomisation_is_named_before_any_step(plant, rz, match):
    with pytest.raises(ValueError, match=match):
        _mk(plant, randomize=rz)


def _trace(env, steps, rng):
    out = []
    for _ in range(steps):
        if not env.agents:
            o, _ = env.reset()
            out += [o[a] for a in sorted(o)]
            continue
        act = {a: rng.uniform(-0.3, 0.3, 2) for a in env.agents}
        o, r, *_ = env.step(act)
        out += [o[a] for a in sorted(o)] + [np.array([r[a] for a in sorted(r)])]
    return np.concatenate(out) if out else np.zeros(0)


@pytest.mark.parametrize("plant", PLANTS)
def test_pickles_and_copies_continue_bit_for_bit(plant):
    """Before reset, after reset and mid-episode, ``pickle`` and ``deepcopy`` give an environment that
    continues bit for bit: 40 steps through an episode's end and the auto-reset after it (its random
    stream is copied too), with start randomisation on."""
    env = _mk(plant, randomize=RAND)
    fresh = pickle.loads(pickle.dumps(env))
    for e in (env, fresh):
        e.reset(seed=7)
    assert _trace(env, 5, np.random.default_rng(0)).tobytes() == _trace(fresh, 5, np.random.default_rng(0)).tobytes()
    env.reset(seed=3)
    for when in range(3):
        _trace(env, 7 * when, np.random.default_rng(when))
        copies = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
        want = _trace(env, 40, np.random.default_rng(10 + when))
        for c in copies:
            got = _trace(c, 40, np.random.default_rng(10 + when))
            assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("action", ["velocity", "torque"])
def test_float32_and_float64_actions_at_the_bounds(action):
    """The action space is float32; float32 and float64 actions at either bound (2π rounds up in float32)
    are taken, as are 500 samples of the space; beyond a bound by more than float32 rounding, or NaN: refused."""
    env = _mk("ideal", action=action)
    env.reset(seed=0)
    sp = env.action_space("follower_1")
    assert sp.dtype == np.float32
    hi64 = env._high[0]
    assert action == "torque" or float(np.float32(2 * math.pi)) > 2 * math.pi  # the case that used to stop a run
    for hi in (sp.high, sp.high.astype(np.float64), hi64):
        for sign in (1, -1):
            env.step({a: sign * hi for a in env.agents})
            if not env.agents:
                env.reset()
    for _ in range(500):
        if not env.agents:
            env.reset()
        env.step({a: env.action_space(a).sample() for a in env.agents})
    for bad, what in ((hi64 * (1 + 1e-6), "outside the action space"), (np.array([np.nan, 0.0]), "not finite")):
        if not env.agents:
            env.reset()
        with pytest.raises(ValueError, match=f"follower_1 .*{what}"):
            env.step({**{a: np.zeros(2) for a in env.agents}, "follower_1": bad})


@pytest.mark.parametrize("plant", PLANTS)
def test_pettingzoo_state_and_max_cycles_tests(plant):
    """PettingZoo's ``state_test`` and ``max_cycles_test`` pass without a warning (finite state bounds,
    ``env()`` the AEC constructor, ``max_cycles`` the truncation); the state is (n·5,) in the space."""
    from pettingzoo.test import max_cycles_test, state_test

    ov = [*SHORT, f"plant.kind={plant}"]

    class Mod:  # what max_cycles_test takes: a module with parallel_env and env
        parallel_env = staticmethod(lambda **k: envs_mod.parallel_env("paper", overrides=ov, **k))
        env = staticmethod(lambda **k: envs_mod.env("paper", overrides=ov, **k))

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        state_test(envs_mod.env("paper", overrides=ov), envs_mod.parallel_env("paper", overrides=ov), num_cycles=20)
        max_cycles_test(Mod)
    env = envs_mod.parallel_env("paper", overrides=ov, max_cycles=7)
    env.reset(seed=0)
    assert env.state().shape == (15,) and env.state() in env.state_space
    steps = 0
    while env.agents:
        *_, trunc, _ = env.step({a: np.zeros(2) for a in env.agents})
        steps += 1
    assert steps == 7 and all(trunc.values())
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="max_cycles"):
            envs_mod.parallel_env("paper", max_cycles=bad)


@pytest.mark.parametrize("plant", PLANTS)
def test_render_rgb_array(plant):
    """``render_mode="rgb_array"``: PettingZoo's ``render_test`` passes (uint8 (H, W, 3) frames of the
    ``--video`` renderer, which changes as the robots move); no render mode: a RuntimeError saying what to do."""
    from pettingzoo.test import render_test

    from bioform_mj.outputs.gl import GLUnavailable

    ov = [*SHORT, f"plant.kind={plant}"]
    env = envs_mod.parallel_env("paper", overrides=ov, render_mode="rgb_array")
    env.reset(seed=0)
    try:
        f0 = env.render()
    except GLUnavailable as exc:
        pytest.skip(f"no off-screen OpenGL here: {exc}")
    for _ in range(10):
        env.step({a: np.array([1.0, 0.0]) for a in env.agents})
    f1 = env.render()
    assert f0.shape == f1.shape == (540, 960, 3) and f0.dtype == np.uint8
    assert np.mean(f0 != f1) > 0.01
    env.close()
    # as PettingZoo's own environments are tested: the env() function itself, "human" included
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_test(functools.partial(envs_mod.env, "paper", overrides=ov))
    plain = envs_mod.parallel_env("paper", overrides=ov)
    plain.reset(seed=0)
    with pytest.raises(RuntimeError, match="render_mode='rgb_array'"):
        plain.render()
    with pytest.raises(ValueError, match="unknown render_mode 'ansi'"):
        envs_mod.parallel_env("paper", render_mode="ansi")
    import matplotlib

    if matplotlib.get_backend().lower() == "agg":  # no display here: "human" says it shows nothing, once per env
        said = [w for w in caught if "render_mode='human'" in str(w.message) and "'agg'" in str(w.message)]
        assert len(said) == 1
        human = envs_mod.parallel_env("paper", overrides=ov, render_mode="human")
        with pytest.warns(UserWarning, match="nothing is shown"):
            human.reset(seed=0)  # a human-mode reset renders (as Gymnasium's and PettingZoo's do)
        assert human.step({a: np.zeros(2) for a in human.agents})[0] and human.render() is None


@pytest.mark.parametrize("plant", PLANTS)
@pytest.mark.parametrize("action", ["velocity", "torque"])
def test_single_follower_gymnasium_env_passes_both_checkers(plant, action):
    """``follower_env``: Gymnasium's ``check_env`` and SB3's pass with every warning an error; the other
    followers run the paper's controller; an episode truncates at ``sim.duration``."""
    from gymnasium.utils.env_checker import check_env

    e = follower_env("paper", action=action, overrides=[*SHORT, f"plant.kind={plant}"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(e, skip_render_check=True)
        try:
            from stable_baselines3.common.env_checker import check_env as sb3_check_env
        except ImportError:
            sb3_check_env = None
        if sb3_check_env is not None:
            sb3_check_env(e)
    obs, _ = e.reset(seed=0)
    n = 0
    while True:
        obs, r, term, trunc, _ = e.step(np.float32([1.0, -1.0]))
        n += 1
        if term or trunc:
            break
    assert trunc and n == 30 and obs.dtype == np.float32
    with pytest.raises(ValueError, match="outside the action space"):
        e.reset(seed=0)
        e.step(np.array([1.01, 0.0]))


@pytest.mark.train
def test_supersuit_sb3_subprocess_training_on_mujoco(tmp_path, monkeypatch):
    """PettingZoo's tutorial path: SuperSuit's vector environment in 2 worker processes (the environment is
    pickled to them) trains SB3's PPO on the MuJoCo plant for 768 steps."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3"))  # SB3's logger makes /tmp/SB3-DATE/ otherwise
    ss = pytest.importorskip("supersuit")
    sb3 = pytest.importorskip("stable_baselines3")
    import torch

    torch.set_num_threads(1)
    env = _mk("mujoco", dtype="float32", randomize={"position": (-0.2, 0.2)}, extra=["sim.duration=0.5"])
    env.reset(seed=0)  # reset before it is pickled: the failure of issue 30
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 2, num_cpus=2, base_class="stable_baselines3")
    try:
        model = sb3.PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, device="cpu")
        model.learn(total_timesteps=400)
        assert model.num_timesteps == 768  # 2 copies x 3 followers x 64 steps x 2 rollouts
    finally:
        venv.close()


def test_a_moved_mujoco_start_equals_a_fresh_build_within_rounding():
    """The MuJoCo scene is compiled once at the written poses and each start set in ``qpos0``: the robots'
    poses after reset equal those of a scene compiled at that start (``bioform run``'s) within 1e-12 m/rad,
    and the written start (no randomisation drawn) is bit for bit the fresh build's."""
    from bioform_mj.run.simulate import make_plant

    env = _mk("mujoco", randomize=RAND)
    env.reset(seed=11)
    moved = env.measured_state()[0]
    fresh = make_plant(env.episode_scenario)
    fresh.reset()
    built = fresh.observe()[0]
    assert np.max(np.abs(moved - built)) < 1e-12
    plain = _mk("mujoco")
    plain.reset(seed=0)
    ref = make_plant(plain.episode_scenario)
    ref.reset()
    assert plain.measured_state()[0].tobytes() == ref.observe()[0].tobytes()


def test_gymnasium_vector_env_auto_resets_explore():
    """Gymnasium's ``SyncVectorEnv`` of two ``follower_env`` copies (next-step auto-reset): the first
    observations of 34 episodes all differ (start randomisation on), and the run repeats with the same seed."""
    import gymnasium

    def run():
        venv = gymnasium.vector.SyncVectorEnv(
            [lambda: follower_env("paper", overrides=["sim.duration=0.05", "sim.control_dt=0.01"], randomize=RAND)] * 2
        )
        obs, _ = venv.reset(seed=4)
        starts = [o.copy() for o in obs]
        done = np.zeros(2, dtype=bool)
        while len(starts) < 34:
            obs, _, term, trunc, _ = venv.step(np.zeros((2, 2), np.float32))
            starts += [obs[i].copy() for i in np.flatnonzero(done)]  # next-step autoreset: a new episode's start
            done = term | trunc
        venv.close()
        return np.array(starts)

    a, b = run(), run()
    assert a.tobytes() == b.tobytes()
    assert len(a) >= 34 and len({row.tobytes() for row in a}) == len(a)


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_follower_env_copy_continues_bit_for_bit(how):
    """``follower_env`` mid-episode (the other followers run the paper's controller, whose state is copied
    with it): a pickled or deep-copied environment gives the same observations and rewards, bit for bit,
    to the episode's end."""
    e = follower_env("paper", overrides=["sim.duration=0.5", "sim.control_dt=0.01", "plant.kind=mujoco"])
    e.reset(seed=0)
    for _ in range(10):
        e.step(np.float32([0.3, 0.1]))
    c = pickle.loads(pickle.dumps(e)) if how == "pickle" else copy.deepcopy(e)
    n = 0
    while True:
        a, b = e.step(np.float32([0.3, -0.2])), c.step(np.float32([0.3, -0.2]))
        assert a[0].tobytes() == b[0].tobytes() and a[1:4] == b[1:4]
        n += 1
        if a[2] or a[3]:
            break
    assert n == 40


def test_follower_env_is_registered_and_passes_the_render_check():
    """``gymnasium.make(GYMNASIUM_ID, ...)`` and ``make_vec`` build the follower environment; Gymnasium's
    ``check_env`` with its render check (which remakes the environment from its spec in every render mode)
    passes with every warning an error, on ``follower_env(...)`` too; "human" is refused, naming the modes."""
    import gymnasium
    from gymnasium.utils.env_checker import check_env

    from bioform_mj.envs.single import GYMNASIUM_ID
    from bioform_mj.outputs.gl import GLUnavailable

    ov = [*SHORT, "plant.kind=ideal"]
    made = gymnasium.make(GYMNASIUM_ID, scenario="paper", overrides=ov)
    direct = follower_env("paper", overrides=ov)
    assert made.unwrapped.spec.id == direct.spec.id == GYMNASIUM_ID
    o1, _ = made.reset(seed=3)
    o2, _ = direct.reset(seed=3)
    a = np.float32([0.7, -0.2])
    assert o1.tobytes() == o2.tobytes() and made.step(a)[0].tobytes() == direct.step(a)[0].tobytes()
    venv = gymnasium.make_vec(GYMNASIUM_ID, num_envs=2, vectorization_mode="sync", scenario="paper", overrides=ov,
                               randomize=RAND)  # fmt: skip
    obs, _ = venv.reset(seed=0)  # seeds 0 and 1: different starts
    assert obs.shape == (2, direct.observation_space.shape[0]) and not np.array_equal(obs[0], obs[1])
    venv.close()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(follower_env("paper", overrides=ov, render_mode="rgb_array"))
            check_env(made.unwrapped)
    except GLUnavailable as exc:
        pytest.skip(f"no off-screen OpenGL here: {exc}")
    with pytest.raises(ValueError, match="unknown render_mode 'human' .*rgb_array"):
        follower_env("paper", overrides=ov, render_mode="human")
