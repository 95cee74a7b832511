"""The CPU-vectorised environment (``envs/vector.py``, issue 30 item 5) and the TorchRL-style batched interface
(``envs/tdict.py``): every world's episode is the single environment's episode of the same seed and actions,
bit for bit (both run the same compiled period; the single environment's first period runs step by step, the
tests of ``test_envs_fast`` tie the two), on threads; memory is estimated before the worlds are built;
per-world resets with seeds and ``_reset`` masks; bad input named."""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from bioform_mj.envs import parallel_env  # noqa: E402
from bioform_mj.envs.tdict import TorchRLStyle  # noqa: E402
from bioform_mj.envs.vector import VectorEnv  # noqa: E402

OV = ["sim.duration=0.05", "sim.control_dt=0.001", "plant.kind=mujoco", "formation.init_jitter=0.05"]


def _actions(env, W, T, seed=5):
    rng = np.random.default_rng(seed)
    lo, hi = env.low, env.high
    return rng.uniform(lo, hi, size=(T, W, env.n, 2))


def _single(seed, acts, action, overrides=OV, **options):
    env = parallel_env("paper", action=action, overrides=overrides, **options)
    obs, _ = env.reset(seed=seed)
    rows = [(np.stack([obs[a] for a in env.possible_agents]), None, False, False)]
    for u in acts:
        obs, rew, term, trunc, _ = env.step({a: u[i] for i, a in enumerate(env.possible_agents)})
        if not obs:
            break
        a0 = env.possible_agents[0]
        rows.append((np.stack([obs[a] for a in env.possible_agents]), np.array([rew[a] for a in env.possible_agents]),
                     term[a0], trunc[a0]))  # fmt: skip
        if not env.agents:
            break
    return rows


@pytest.mark.slow  # ~5 s with the kernels' first load from numba's cache
@pytest.mark.parametrize("action", ["velocity", "torque"])
def test_each_world_is_the_single_environment(action):
    """3 worlds on 2 threads, seeds 4, 5, 6, random actions over a whole episode (50 periods at 1 ms, then
    truncation): observations, rewards and flags of world w equal the single environment's of seed 4 + w."""
    W = 3
    venv = VectorEnv("paper", W, threads=2, action=action, overrides=OV)
    obs = venv.reset(seed=4).copy()
    acts = _actions(venv, W, venv.N)
    got = [[(obs[w].copy(), None, False, False)] for w in range(W)]
    for t in range(venv.N):
        obs, rew, term, trunc = venv.step(acts[t])
        for w in range(W):
            got[w].append((obs[w].copy(), rew[w].copy(), bool(term[w]), bool(trunc[w])))
    assert trunc.all() and not venv.running.any()
    assert venv.shared.all()  # one model for every world's physics
    for w in range(W):
        ref = _single(4 + w, acts[:, w], action)
        assert len(ref) == len(got[w]) == venv.N + 1
        for (o1, r1, te1, tr1), (o2, r2, te2, tr2) in zip(got[w], ref):
            assert np.array_equal(o1, o2)
            assert (r1 is None and r2 is None) or np.array_equal(r1, r2)
            assert (te1, tr1) == (te2, tr2)
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(acts[0])
    venv.close()


def test_masks_seeds_and_the_torchrl_style_keys():
    """A ``_reset`` mask resets only its worlds (the others keep their step), per-world seeds repeat an
    episode, and the keys and shapes are TorchRL's multi-agent ones (("agents", "observation") (W, n, obs),
    ("agents", "reward") (W, n, 1), "done"/"terminated"/"truncated" (W, 1))."""
    W = 2
    td_env = TorchRLStyle(VectorEnv("paper", W, threads=1, overrides=OV))
    td = td_env.reset(seed=[7, 8])
    assert td["agents"]["observation"].shape == (W, 3, td_env.env.obs_size)
    assert td["done"].shape == (W, 1) and not td["done"].any()
    first = td["agents"]["observation"].copy()
    act = np.zeros((W, 3, 2))
    out = td_env.step({"agents": {"action": act}})
    assert out["agents"]["reward"].shape == (W, 3, 1)
    assert out["terminated"].shape == out["truncated"].shape == (W, 1)
    stepped = out["agents"]["observation"].copy()
    td = td_env.reset({"_reset": np.array([[False], [True]])}, seed=[8])
    assert np.array_equal(td["agents"]["observation"][1], first[1])  # world 1: seed 8 again, its first obs
    assert np.array_equal(td["agents"]["observation"][0], stepped[0])  # world 0 untouched
    assert list(td_env.env.k) == [1, 0]
    with pytest.raises(ValueError, match="seeds"):
        td_env.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"world 1: action of follower_2"):
        bad = np.zeros((W, 3, 2))
        bad[1, 1, 0] = np.nan
        td_env.step({"agents": {"action": bad}})
    with pytest.raises(ValueError, match="shape"):
        td_env.step({"agents": {"action": np.zeros((W, 2, 2))}})


def test_memory_is_estimated_before_the_worlds_are_built(monkeypatch):
    """10**6 worlds: refused from one built world's size, naming the estimate, before the others are built."""
    from bioform_mj.envs import vector

    # a fixed 16 GiB available, as this machine has: the same answer where /proc/meminfo is absent or larger
    monkeypatch.setattr(vector, "_available_bytes", lambda: float(2**34))
    with pytest.raises(ValueError, match=r"1000000 worlds need ~\d+\.\d+ GiB"):
        VectorEnv("paper", 10**6, overrides=OV)
    with pytest.raises(ValueError, match="bound of 0.00 GiB"):
        VectorEnv("paper", 2, overrides=OV, max_bytes=1000)
    with pytest.raises(ValueError, match="worlds must be"):
        VectorEnv("paper", 0, overrides=OV)
    with pytest.raises(ValueError, match="MuJoCo plant"):
        VectorEnv("paper", 2, overrides=["plant.kind=ideal"])


def _compare(venv, acts, action, seed, overrides, **options):
    """Every world's rows of ``venv``'s episode under ``acts`` (T, W, n, 2) against the single environment's
    episode of seed ``seed + w`` (the same ``overrides`` and ``options``): observations, rewards, flags,
    bit for bit, and a world stays ended (its rows unchanged) once it ended."""
    W = venv.nworld
    obs = venv.reset(seed=seed)
    got = [[(obs[w].copy(), None, False, False)] for w in range(W)]
    done = np.zeros(W, dtype=bool)
    for t in range(len(acts)):
        if not venv.running.any():
            break
        obs, rew, term, trunc = venv.step(acts[t])
        for w in range(W):
            if done[w]:
                assert not term[w] and not trunc[w] and np.array_equal(obs[w], got[w][-1][0])
                continue
            got[w].append((obs[w].copy(), rew[w].copy(), bool(term[w]), bool(trunc[w])))
            done[w] = term[w] or trunc[w]
    for w in range(W):
        ref = _single(seed + w, acts[:, w], action, overrides, **options)
        assert len(ref) == len(got[w])
        for (o1, r1, te1, tr1), (o2, r2, te2, tr2) in zip(got[w], ref):
            assert np.array_equal(o1, o2)
            assert (r1 is None and r2 is None) or np.array_equal(r1, r2)
            assert (te1, tr1) == (te2, tr2)
    return got


def test_ends_and_own_models_are_the_single_environment():
    """A speed limit that ends worlds at different periods (the guards: zero observations, the terminal
    reward, compiled in ``periods``), and a randomised friction: a world whose friction was drawn steps with
    its own model, not the shared one; both the single environment's episodes bit for bit."""
    ov = ["sim.duration=1", "sim.control_dt=0.01", "limits.speed=0.9", "plant.kind=mujoco"]
    W = 3
    venv = VectorEnv("paper", W, threads=1, action="velocity", v_max=1.0, overrides=ov)
    ramp = np.array([0.02, 0.03, 0.04])[:, None, None] * np.array([1.0, 0.0])  # world w: +0.01 (w + 2) m/s a period
    acts = np.stack([np.broadcast_to(np.minimum(ramp * (t + 1), 1.0), (W, venv.n, 2)) for t in range(venv.N)])
    got = _compare(venv, acts, "velocity", 0, ov, v_max=1.0)
    ends = [len(g) - 1 for g in got]
    assert all(g[-1][2] for g in got) and len(set(ends)) == W  # every world terminated, at different periods
    assert all(not g[-1][0].any() for g in got)  # the guards failed: zero observations
    venv.close()
    rz = {"friction": (0.7, 1.3)}
    venv = VectorEnv("paper", 2, threads=2, randomize=rz, overrides=OV)
    _compare(venv, _actions(venv, 2, venv.N), "velocity", 11, OV, randomize=rz)
    assert not venv.shared.any()
    venv.close()


def test_worlds_sharing_a_warm_mjdata_do_not_leak():
    """Three worlds of different seeds and drawn frictions (their own models) on two threads: thread 1 steps
    worlds 1 and 2 on one ``MjData``, each world's state copied in and out every period. Each world is the
    single environment's episode of its seed (a state left behind by the other world would change it), and
    at the episode's end each world's own ``MjData`` holds what stepping it directly (``warm=False``) left:
    state, warm start, time, contacts."""
    rz = {"friction": (0.7, 1.3)}
    W = 3
    venv = VectorEnv("paper", W, threads=2, randomize=rz, overrides=OV)
    acts = _actions(venv, W, venv.N, seed=3)
    _compare(venv, acts, "velocity", 21, OV, randomize=rz)
    assert venv.warm.all() and not venv.shared.any() and venv._blocks == [(0, 1), (1, 3)]
    frictions = {float(e._plant.model.geom_friction[0, 0]) for e in venv.envs}
    assert len(frictions) == W  # three different models
    cold = VectorEnv("paper", W, threads=2, randomize=rz, overrides=OV, warm=False)
    cold.reset(seed=21)
    for t in range(cold.N):
        cold.step(acts[t])
    assert not cold.warm.any() and not cold.running.any()
    for e1, e2 in zip(venv.envs, cold.envs):
        d1, d2 = e1._plant.data, e2._plant.data
        assert d1.time == d2.time > 0 and d1.ncon == d2.ncon > 0
        for f in ("qpos", "qvel", "qacc_warmstart", "ctrl", "xpos", "efc_force"):
            assert np.array_equal(getattr(d1, f), getattr(d2, f)), f
    venv.close()
    cold.close()
    with pytest.raises(ValueError, match="payload"):
        VectorEnv("paper", 2, randomize={"payload": (0.0, 0.5)}, overrides=OV)


def _team_threads() -> int:
    import threading

    return sum(th.name == "bioform-vector" for th in threading.enumerate())


def test_the_threads_are_released():
    """Two threads: the calling thread steps one block, one worker (``envs.team``) the other; the worker starts
    at the first step, ``close()`` joins it, the next step starts it again (the episode goes on bit for bit as
    in an environment never closed), and an environment dropped without ``close()`` joins it at collection."""
    import gc

    assert _team_threads() == 0
    acts = _actions(VectorEnv("paper", 2, threads=1, overrides=OV), 2, 10)
    ref = VectorEnv("paper", 2, threads=2, overrides=OV)
    venv = VectorEnv("paper", 2, threads=2, overrides=OV)
    ref.reset(seed=3)
    venv.reset(seed=3)
    assert _team_threads() == 0  # nothing before the first step
    for t in range(10):
        out = venv.step(acts[t])
        want = ref.step(acts[t])
        assert _team_threads() == 2
        if t == 4:
            venv.close()
            venv.close()  # twice: nothing left to stop
            assert _team_threads() == 1
    assert all(np.array_equal(a, b) for a, b in zip(out, want))
    ref.close()
    assert _team_threads() == 1
    del venv
    gc.collect()
    assert _team_threads() == 0


@pytest.mark.slow  # a fresh interpreter: ~10 s to import and build
def test_no_thread_outlives_the_interpreter(tmp_path):
    """A script that steps a 2-thread environment and exits without ``close()`` ends (exit status 0): its
    worker is stopped and joined at exit (a ``weakref.finalize`` of the environment, run at exit)."""
    import subprocess
    import sys

    script = tmp_path / "run.py"
    script.write_text(
        "import numpy as np\nfrom bioform_mj.envs import vector_env\n"
        f"v = vector_env('paper', 2, 2, overrides={OV!r})\nv.reset(seed=0)\nv.step(np.zeros((2, 3, 2)))\n"
        "print(v._stopper.alive, v._stopper.atexit)\n"
    )
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "True True"  # its finalizer runs at exit


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2, reason="2 CPUs")
def test_pinned_threads():
    """``pin=True``: the calling thread on the first CPU it may use, the worker on the second, from the first
    step to ``close()``, which gives the calling thread its CPUs back; the same bits as unpinned. A thread per
    CPU at most, and ``pin`` a bool, refused before any world is built."""
    cpus = sorted(os.sched_getaffinity(0))
    acts = _actions(VectorEnv("paper", 2, threads=1, overrides=OV), 2, 5)
    ref = VectorEnv("paper", 2, threads=2, overrides=OV)
    venv = VectorEnv("paper", 2, threads=2, overrides=OV, pin=True)
    ref.reset(seed=1)
    venv.reset(seed=1)
    for t in range(5):
        out, want = venv.step(acts[t]), ref.step(acts[t])
        assert all(np.array_equal(a, b) for a, b in zip(out, want))
        assert os.sched_getaffinity(0) == {cpus[0]}
        (worker,) = venv._team[1]
        assert os.sched_getaffinity(worker.native_id) == {cpus[1]}
    venv.close()
    ref.close()
    assert sorted(os.sched_getaffinity(0)) == cpus
    with pytest.raises(ValueError, match="a CPU per thread"):
        VectorEnv("paper", 2, threads=len(cpus) + 1, overrides=OV, pin=True)
    with pytest.raises(ValueError, match="pin must be"):
        VectorEnv("paper", 2, overrides=OV, pin="yes")


def test_without_futexes_a_thread_pool_steps_the_same_bits(monkeypatch):
    """Where ``envs.team`` is not available (not Linux): the check and the blocks as separate compiled calls
    on a ``ThreadPoolExecutor`` (the calling thread steps block 0), the same bits as the team's."""
    from bioform_mj.envs import vector

    acts = _actions(VectorEnv("paper", 3, threads=1, overrides=OV), 3, 6)
    ref = VectorEnv("paper", 3, threads=2, overrides=OV)
    ref.reset(seed=2)
    want = [ref.step(acts[t]) for t in range(6)]
    assert ref._team is not None and _team_threads() == 1
    monkeypatch.setattr(vector, "HAVE_TEAM", False)
    venv = VectorEnv("paper", 3, threads=2, overrides=OV)
    venv.reset(seed=2)
    for t in range(6):
        out = venv.step(acts[t])
        assert all(np.array_equal(a, b) for a, b in zip(out, want[t]))
    assert venv._team is None and venv._pool is not None and _team_threads() == 1
    bad = acts[0].copy()
    bad[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match="world 2"):
        venv.step(bad)
    venv.close()
    ref.close()
    assert venv._pool is None


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_a_copy_continues_every_world_bit_for_bit(how):
    """``pickle`` / ``deepcopy`` of a ``VectorEnv`` (and of ``TorchRLStyle(..., torch=True)`` around it, whose
    torch module is not picklable), before any reset and mid-episode after worlds were reset at different
    periods: the copy gives the same observations, rewards, flags and auto-reset starts as the original, bit for
    bit, for 40 periods (through episode ends: 25-period episodes), with start randomisation on."""
    import copy
    import pickle

    dup = (lambda x: pickle.loads(pickle.dumps(x))) if how == "pickle" else copy.deepcopy
    ov = ["sim.duration=0.25", "sim.control_dt=0.01", "plant.kind=mujoco"]
    v = VectorEnv("paper", worlds=3, threads=2, overrides=ov, randomize={"position": (-0.2, 0.2)})
    fresh = dup(v)
    rng = np.random.default_rng(0)

    def run(env, periods, seed):
        r, out = np.random.default_rng(seed), []
        for _ in range(periods):
            obs, rew, term, trunc = env.step(r.uniform(env.low, env.high, (3, env.n, 2)).astype(np.float32))
            out += [obs.ravel(), rew.ravel(), term, trunc]
            if (term | trunc).any():
                out.append(env.reset(mask=term | trunc).ravel())
        return np.concatenate([np.asarray(x, float).ravel() for x in out])

    assert fresh.reset(seed=4).tobytes() == v.reset(seed=4).tobytes()
    assert run(fresh, 5, 1).tobytes() == run(v, 5, 1).tobytes()
    v.reset(mask=[1])  # world 1 starts its next episode 5 periods after the others
    for _ in range(12):
        v.step(rng.uniform(v.low, v.high, (3, v.n, 2)))
    c = dup(v)
    want = run(v, 40, 2)
    assert run(c, 40, 2).tobytes() == want.tobytes()
    td = TorchRLStyle(v, torch=True) if _has_torch() else TorchRLStyle(v)
    tc = dup(td)
    act = {"agents": {"action": np.zeros((3, v.n, 2))}}
    a, b = td.step(act)["agents"]["observation"], tc.step(act)["agents"]["observation"]
    assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
    for e in (v, fresh, c, tc.env):
        e.close()


def _has_torch() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def test_the_replay_history_is_bounded_when_a_world_is_never_reset():
    """A world that ended and is never reset while another runs episode after episode: the history a copy
    replays stays within ``2·N + 2`` periods (it kept one entry a step before: 60 here), its bytes within the
    documented ``(3·N + 2)·W·(16·n + 1)`` and equal to what it holds counted by hand; a pickled copy still
    continues both worlds bit for bit (the ended world's MuJoCo state too, then its next episode)."""
    import pickle

    import mujoco

    ov = ["sim.duration=0.05", "sim.control_dt=0.01", "plant.kind=mujoco"]  # N = 5 periods
    v = VectorEnv("paper", worlds=2, threads=1, overrides=ov)
    N, n, W = v.N, v.n, 2
    assert N == 5
    rng = np.random.default_rng(3)
    v.reset(seed=0)
    longest = 0
    for _ in range(60):
        _, _, term, trunc = v.step(rng.uniform(v.low, v.high, (W, n, 2)))
        if term[0] or trunc[0]:
            v.reset(mask=[0])  # world 0 runs on; world 1 ended at period 5 and is never reset
        longest = max(longest, len(v._hist))
    assert not v.running[1] and v.running[0]
    assert longest <= 2 * N + 2
    per = W * (n * 2 * 8 + 1)  # a period's actions (float64) and running flags
    by_hand = len(v._hist) * per + N * n * 2 * 8  # + world 1's ended episode: N periods of its actions
    assert v.history_bytes == by_hand <= (3 * N + 2) * per
    assert v.history_bytes < 60 * per / 2  # what one entry a step had held
    c = pickle.loads(pickle.dumps(v))
    sig = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    assert c.world_state(1, sig).tobytes() == v.world_state(1, sig).tobytes()
    for e in (v, c):
        e.reset(mask=[1])
    for _ in range(12):
        u = rng.uniform(v.low, v.high, (W, n, 2))
        a, b = v.step(u), c.step(u)
        for x, y in zip(a, b):
            assert x.tobytes() == y.tobytes()
        for e in (v, c):
            if (a[2] | a[3]).any():
                e.reset(mask=a[2] | a[3])
    v.close()
    c.close()


def test_any_thread_steps_any_world_the_same_bits():
    """The threads claim each other's worlds (``envs/worlds.py``): every world stepped each period by one thread
    alone, that thread alternating (so each world moves between the two threads' warm ``MjData`` and is taken
    from its own block and from the other's), gives the observations, rewards and flags of one thread stepping
    its own block, bit for bit, through episode ends and resets."""
    from bioform_mj.envs.worlds import block, count_warned, start

    W = 4
    a, b = VectorEnv("paper", W, 1, overrides=OV), VectorEnv("paper", W, 2, overrides=OV)
    acts = _actions(a, W, 70)
    turn = [0]

    def alone(v, ctl, spin_ns):  # dispatch's work on the calling thread, as thread 0 or thread 1
        start(v)
        block(v, turn[0] % 2)
        turn[0] += 1
        return count_warned(v)

    assert a.reset(seed=9).tobytes() == b.reset(seed=9).tobytes()
    b._compile()
    b._dispatch = alone
    assert b.warm.all() and b.threads == 2
    for u in acts:
        ra, rb = a.step(u), b.step(u)
        for x, y in zip(ra, rb):
            assert x.tobytes() == y.tobytes()
        done = ra[2] | ra[3]
        if done.any():
            assert a.reset(mask=done).tobytes() == b.reset(mask=done).tobytes()
    assert turn[0] == 70
    a.close()
    b.close()


def test_the_memory_estimate_counts_each_threads_period_arguments():
    """Each world has one ``PeriodArgs`` a thread (``envs/worlds.py``: any thread steps any world), ~14.5 KB each
    (measured: 4,000 of them, RSS), so the memory grows with worlds × threads (``threads`` may be as many as the
    worlds): the estimate counts :data:`~bioform_mj.envs.vector.ARGS_BYTES` a world and thread. A bound that holds
    ``W`` worlds' own memory and one thread's arguments each takes 1 thread and refuses 4 (it took both)."""
    from bioform_mj.envs.vector import ARGS_BYTES, _world_bytes

    env = parallel_env("paper", overrides=OV)
    env.reset(seed=0)
    W, per = 4, _world_bytes(env)
    assert 14_500 <= ARGS_BYTES < per / 10
    bound = W * (per + ARGS_BYTES)
    VectorEnv("paper", W, 1, overrides=OV, max_bytes=bound).close()
    with pytest.raises(ValueError, match=r"4 worlds need ~.* GiB .* 4 threads"):
        VectorEnv("paper", W, 4, overrides=OV, max_bytes=bound)
