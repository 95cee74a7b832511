"""The batched environment on MuJoCo Warp (``bioform_mj.envs.batch_env``, design §20) against the
parallel environment world by world, on Warp's CPU device: the same layout, the same episodes within
the batch engine's agreement criterion (design §11: 1 mm formation error, 0.5 % ĉ), per-world resets,
zero-copy arrays, and bad input named."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pettingzoo")
wp = pytest.importorskip("warp")
pytest.importorskip("mujoco_warp")

from bioform_mj.envs import batch_env, parallel_env  # noqa: E402

OV = ["sim.duration=0.5", "sim.control_dt=0.01", "plant.kind=mujoco", "formation.init_jitter=0.1"]
W = 3


def actions(k: int) -> np.ndarray:
    """(W, n, 2) velocity commands, different per world and varying in time."""
    base = np.array([0.3 + 0.1 * np.sin(k / 5), 0.2 * np.cos(k / 7)])
    return np.stack([np.tile(base * (1 + 0.2 * w), (3, 1)) for w in range(W)])


@pytest.fixture(scope="module")
def batched():
    be = batch_env("paper", worlds=W, device="cpu", overrides=OV)
    obs = [be.reset().numpy().copy()]
    rew, k = [], 0
    while True:
        o, r, term, trunc = be.step(actions(k))
        k += 1
        obs.append(o.numpy().copy())
        rew.append(r.numpy().copy())
        if (term | trunc).all():
            break
    return be, np.array(obs), np.array(rew), term, trunc, k


def test_batch_env_agrees_with_the_parallel_env_world_by_world(batched):
    """Each world is the parallel environment's episode of its seed: observations within 1e-4 (measured
    1.2e-5: float32 physics), rewards within 1e-4 relative, the final formation error within 1 mm and ĉ
    within 0.5 % (design §11), truncated at sim.duration like it."""
    be, obs, rew, term, trunc, steps = batched
    assert steps == 50 and trunc.all() and not term.any()
    c_hat = be.run.s.c_hat.numpy()
    ferr = be.run.s.ferr.numpy()
    for w in range(W):
        env = parallel_env("paper", overrides=OV)
        ob, _ = env.reset(seed=w)
        ref_obs, ref_rew, kk = [np.stack([ob[a] for a in env.possible_agents])], [], 0
        while env.agents:
            ob, r, *_ = env.step({a: actions(kk)[w, i] for i, a in enumerate(env.possible_agents)})
            kk += 1
            ref_obs.append(np.stack([ob[a] for a in env.possible_agents]))
            ref_rew.append([r[a] for a in env.possible_agents])
        ref_obs = np.array(ref_obs)
        assert np.abs(obs[:, w] - ref_obs).max() < 1e-4
        assert rew[:, w] == pytest.approx(np.array(ref_rew), rel=1e-4, abs=1e-9)
        fe = env._formation_error(env.k)
        assert np.abs(ferr[w] - fe).max() < 1e-3
        assert c_hat[w] == pytest.approx(np.array(env._s.c_hat), rel=5e-3)
    assert np.abs(obs[0, 0] - obs[0, 1]).max() > 1e-3  # the worlds' seeds really differ (jittered starts)


def test_batch_env_resets_one_world_and_shares_its_arrays(batched):
    """``reset([1])`` restarts world 1 only (its observation is its initial one again); the arrays are
    Warp arrays that NumPy reads without a copy through DLPack."""
    be, obs, *_ = batched
    before = be.obs.numpy().copy()
    o = be.reset([1])
    now = o.numpy()
    assert np.array_equal(now[1], obs[0, 1])  # world 1 at its start, bit for bit
    assert np.array_equal(now[0], before[0]) and np.array_equal(now[2], before[2])
    view = np.from_dlpack(be.obs)
    assert view.ctypes.data == be.obs.ptr and view.shape == (3, 3, be.obs_size)  # the device buffer itself
    o2, r, term, trunc = be.step(actions(0))
    assert not term[1] and not trunc[1]
    assert trunc[0] and trunc[2]  # ended worlds stay ended until reset


def test_batch_env_bad_input(batched):
    be = batched[0]
    be.reset()
    with pytest.raises(ValueError, match=r"shape \(3, 3, 2\)"):
        be.step(np.zeros((3, 2)))
    a = actions(0)
    a[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match="world 2, follower_2 .* not finite or outside"):
        be.step(a)
    a = actions(0)
    a[0, 2, 1] = 100.0
    with pytest.raises(ValueError, match="world 0, follower_3"):
        be.step(a)
    with pytest.raises(ValueError, match="world index out of range"):
        be.reset([5])
    with pytest.raises(ValueError, match="per-step faults"):
        batch_env("fault_noise", worlds=2)
    with pytest.raises(ValueError, match="plant.kind = 'ideal'"):
        batch_env("paper", worlds=2)
    with pytest.raises(ValueError, match="worlds must be >= 1"):
        batch_env("paper", worlds=0, overrides=OV)


def test_torchrl_style_keys_on_the_warp_batched_env(batched):
    """``TorchRLStyle`` over the Warp-batched environment: a ``_reset`` mask restarts only its world (the
    same first observation as the fixture's reset, the same next one for the same actions), TorchRL's keys
    and shapes, and a seed at reset refused (the worlds' seeds are fixed by ``batch_env(seeds=...)``)."""
    from bioform_mj.envs.tdict import TorchRLStyle

    be, obs, rew, *_ = batched
    td_env = TorchRLStyle(be)
    mask = np.array([[False], [True], [False]])
    td = td_env.reset({"_reset": mask})
    assert td["agents"]["observation"].shape == (W, 3, be.obs_size)
    assert np.array_equal(td["agents"]["observation"][1], obs[0][1])
    assert td["done"].shape == (W, 1) and not td["done"][1, 0]
    out = td_env.step({"agents": {"action": actions(0)}})
    assert np.array_equal(out["agents"]["observation"][1], obs[1][1])
    assert np.array_equal(out["agents"]["reward"][1, :, 0], rew[0][1])
    assert out["agents"]["reward"].shape == (W, 3, 1) and out["terminated"].shape == (W, 1)
    with pytest.raises(ValueError, match="seeds are fixed"):
        td_env.reset(seed=1)


def test_batch_env_takes_float32_actions_at_the_bounds(batched):
    """A float32 action at a bound (a tanh policy saturated: float32(2π) = 6.2831855 > 2π) is taken and
    clipped onto the bound: the same next observations, bit for bit, as the float64 bound; beyond the
    bound by more than float32 rounding (2π·(1 + 1e-6)) it is refused, naming the world and follower."""
    be = batched[0]
    hi = np.broadcast_to(be.high, (W, 3, 2))
    assert float(np.float32(hi[0, 0, 1])) > hi[0, 0, 1]  # the case that stopped a run
    got = []
    for a in (hi.astype(np.float32), hi.astype(np.float64), -hi.astype(np.float32)):
        be.reset()
        got.append(be.step(a)[0].numpy().copy())
    assert np.array_equal(got[0], got[1]) and not np.array_equal(got[0], got[2])
    be.reset()
    over = hi.copy()
    over[1, 2, 1] *= 1 + 1e-6
    with pytest.raises(ValueError, match="world 1, follower_3 .* outside the action space"):
        be.step(over)


def _run(env, k0: int, periods: int) -> list[np.ndarray]:
    """``periods`` steps from period ``k0`` with :func:`actions`, resetting the worlds that end: every array the
    caller sees (observations, rewards, flags, the observations after a reset), copied off the device."""
    out = []
    for k in range(k0, k0 + periods):
        o, r, term, trunc = env.step(actions(k))
        out += [o.numpy().copy(), r.numpy().copy(), term.copy(), trunc.copy()]
        if (term | trunc).any():
            out.append(env.reset(np.flatnonzero(term | trunc)).numpy().copy())
    return out


def test_batch_env_pickles_and_copies_and_the_copy_continues_bit_for_bit(batched):
    """``pickle`` and ``deepcopy`` of the Warp-batched environment (and of ``TorchRLStyle`` around it) before any
    reset and mid-episode, its worlds reset at different periods: the copy rebuilds on the same device and
    replays the calls since the oldest current episode began, so it holds the same observations and continues
    every world bit for bit (Warp's CPU device) through episode ends and the resets after them; the record it
    replays starts at that oldest episode (the calls before it are dropped)."""
    import copy
    import pickle

    from bioform_mj.envs.tdict import TorchRLStyle

    be = batched[0]
    fresh = batch_env("paper", worlds=W, device="cpu", overrides=OV)
    early = pickle.loads(pickle.dumps(fresh))  # before any reset: a working environment of its own
    assert np.array_equal(early.reset().numpy(), fresh.reset().numpy())
    assert np.array_equal(_run(early, 0, 3)[0], _run(fresh, 0, 3)[0])
    be.reset()
    _run(be, 0, 30)
    be.reset([0])  # world 0 restarts at period 30; worlds 1, 2 run on (their episodes began at period 0)
    _run(be, 30, 12)
    be.reset([1, 2])  # now the oldest current episode is world 0's: the 30 periods before it are dropped
    assert len(be._log) == 12 + 2 and be._ep_start.tolist() == [0, 13, 13]
    _run(be, 42, 5)
    copies = [pickle.loads(pickle.dumps(be)), copy.deepcopy(TorchRLStyle(be)).env]  # each a rebuild: ~10 s here
    for c in copies:
        assert np.array_equal(c.obs.numpy(), be.obs.numpy()) and np.array_equal(c._ended, be._ended)
    ref = _run(be, 47, 40)  # world 0's episode ends at its period 50 (truncation) and is reset; 1, 2 run on
    assert any(x.dtype == bool and x[0] and not x[1:].any() for x in ref)
    for c in copies:
        got = _run(c, 47, 40)
        assert len(got) == len(ref) and all(np.array_equal(a, b) for a, b in zip(got, ref))


def test_batch_env_record_for_copies_is_bounded_and_says_when_it_drops(batched, monkeypatch):
    """A world whose episode ended and is never reset keeps the oldest episode open, so the record a copy replays
    would grow by W·n·2 floats a period without end: past ``RECORD_CAP_BYTES`` it is dropped with one warning,
    pickling refuses naming the worlds not reset since, and once every world is reset copies work again, bit for
    bit. Here the cap is set to 10 periods' actions (W·n·2·8 = 144 bytes each)."""
    import pickle

    from bioform_mj.envs import batched as mod

    be = batched[0]
    per_step = W * 3 * 2 * 8
    be.reset()  # under the real cap: the record is this one reset
    assert be._log_bytes == W and len(be._log) == 1
    monkeypatch.setattr(mod, "RECORD_CAP_BYTES", 10 * per_step + W)
    with pytest.warns(UserWarning, match="cannot be pickled or copied until every world has been reset") as got:
        for k in range(14):
            be.step(actions(k))
            assert be._log_bytes <= mod.RECORD_CAP_BYTES
    # the warning names the caller's line (the step() call here), not batched.py's own step()
    (w,) = [w for w in got if "cannot be pickled" in str(w.message)]
    assert w.filename == __file__, w.filename
    assert be._ep_start.tolist() == [-1, -1, -1] and be._log == []
    with pytest.raises(TypeError, match=r"cannot pickle or copy this batch_env: .*worlds \[0, 1, 2\]"):
        pickle.dumps(be)
    be.reset([0, 1])
    _run(be, 14, 3)
    with pytest.raises(TypeError, match=r"not since: worlds \[2\]"):
        pickle.dumps(be)
    be.reset([2])
    _run(be, 17, 2)
    assert be._ep_start.min() >= 0 and be._log_bytes <= mod.RECORD_CAP_BYTES
    c = pickle.loads(pickle.dumps(be))
    assert np.array_equal(c.obs.numpy(), be.obs.numpy())
    got, ref = _run(c, 19, 4), _run(be, 19, 4)
    assert all(np.array_equal(a, b) for a, b in zip(got, ref))
