#!/usr/bin/env python3
"""Are two source trees' environments the same bits? Seeded rollouts of the learning environments, array by array.

The counterpart of ``scripts/logs_identical.py`` (runs) for ``bioform_mj.envs`` (design §20): records, under each
source tree in a fresh process (``PYTHONPATH`` = that tree's ``src``; the same interpreter), seeded rollouts with
seeded random actions of

- ``parallel_*``: ``parallel_env`` on the MuJoCo plant at 1 ms (velocity actions in float32, torque actions in
  float64, the paper's controller through ``ControllerPolicy``) and on the ideal plant (velocity), through
  episode ends and auto-resets (``reset(seed=None)``);
- ``follower``: ``follower_env`` (one follower, the others the paper's controller), MuJoCo, 1 ms;
- ``vector_*``: ``vector_env`` of 5 worlds on 2 threads (warm ``MjData``, and ``warm=False``) and on 1 thread,
  worlds reset as they end, and a ``pickle`` copy taken mid-way continued beside the original;

every step's observations, rewards and flags, and compares the two recordings: the same names, and per array the
same dtype, shape and values (``np.array_equal`` with ``equal_nan``). Prints one line per rollout and exits 1
if any differs (or a recording imported ``bioform_mj`` from elsewhere than its tree), else 0; a tree with no
``bioform_mj`` package: one ``error:`` line, exit 2 (it had compared the installed package with itself).

    python scripts/envs_identical.py REF_SRC NEW_SRC [--only vector_warm,follower] [--steps 400]
    python scripts/envs_identical.py --record OUT.npz [--steps 400]     (one tree: the current PYTHONPATH)

``REF_SRC``/``NEW_SRC``: a checkout's root or its ``src`` folder (e.g. ``/work/main`` and ``.``).
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: control period (s) and episode length (s): 1 ms, 0.15 s (150 periods), so a rollout crosses episode ends
OVERRIDES = ["plant.kind=mujoco", "sim.control_dt=0.001", "sim.duration=0.15"]
#: the recording's key of the source tree its ``bioform_mj`` was imported from (checked against the tree asked for)
SOURCE = "_source"
ROLLOUTS = ("parallel_velocity", "parallel_torque", "parallel_controller", "parallel_ideal", "follower",
            "vector_warm", "vector_cold", "vector_one")  # fmt: skip


def _parallel(name: str, steps: int) -> dict[str, np.ndarray]:
    from bioform_mj.envs import ControllerPolicy, parallel_env

    ov = list(OVERRIDES)
    if name == "parallel_ideal":
        ov[0] = "plant.kind=ideal"
    action = "torque" if name in ("parallel_torque", "parallel_controller") else "velocity"
    env = parallel_env("paper", action=action, overrides=ov)
    rng = np.random.default_rng(7)
    obs, _ = env.reset(seed=3)
    pol = ControllerPolicy(env) if name == "parallel_controller" else None
    if pol is not None:
        pol.reset()
    out: dict[str, list] = {"obs": [], "reward": [], "terminated": [], "truncated": []}
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()  # the environment's own stream: the next episode
            if pol is not None:
                pol.reset()
        if pol is not None:
            act = pol()
        else:
            hi = env._high
            dt = np.float32 if name == "parallel_velocity" else np.float64
            act = {a: (rng.uniform(-1, 1, 2) * hi[i]).astype(dt) for i, a in enumerate(env.agents)}
        obs, rew, term, trunc, _ = env.step(act)
        ags = env.possible_agents
        out["obs"].append(np.stack([obs.get(a, np.full(env.obs_size, np.nan)) for a in ags]))
        out["reward"].append(np.array([rew.get(a, np.nan) for a in ags]))
        out["terminated"].append(np.array([term.get(a, False) for a in ags]))
        out["truncated"].append(np.array([trunc.get(a, False) for a in ags]))
    return {k: np.asarray(v) for k, v in out.items()}


def _follower(steps: int) -> dict[str, np.ndarray]:
    from bioform_mj.envs import follower_env

    env = follower_env("paper", overrides=list(OVERRIDES))
    rng = np.random.default_rng(11)
    env.reset(seed=5)
    out: dict[str, list] = {"obs": [], "reward": [], "done": []}
    for _ in range(steps):
        o, r, te, tr, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        out["obs"].append(o)
        out["reward"].append(r)
        out["done"].append((te, tr))
        if te or tr:
            env.reset()
    return {k: np.asarray(v) for k, v in out.items()}


def _vector(name: str, steps: int) -> dict[str, np.ndarray]:
    from bioform_mj.envs import vector_env

    W = 5
    threads = 1 if name == "vector_one" else 2
    ve = vector_env("paper", W, threads, overrides=list(OVERRIDES), warm=name != "vector_cold")
    rng = np.random.default_rng(13)
    hi = ve.high
    o = ve.reset(seed=[100, 101, 102, 103, 104])
    # worlds start at different periods: world w is reset again after 10·w periods
    out: dict[str, list] = {"reset_obs": [o.copy()]}
    copy = None
    for k in range(steps):
        if k and k < 40 and k % 10 == 0:
            out["reset_obs"].append(ve.reset(seed=200 + k, mask=[k // 10]).copy())
        if k == steps // 2:
            copy = pickle.loads(pickle.dumps(ve))
        U = rng.uniform(-1, 1, (W, ve.n, 2)) * hi
        res = [ve.step(U)] + ([copy.step(U)] if copy is not None else [])
        for j, (ob, r, te, tr) in enumerate(res):
            tag = "" if j == 0 else "copy_"
            for key, v in (("obs", ob), ("reward", r), ("terminated", te), ("truncated", tr)):
                out.setdefault(tag + key, []).append(v)
        done = res[0][2] | res[0][3]
        if done.any():
            out["reset_obs"].append(ve.reset(mask=done).copy())
            if copy is not None:
                out.setdefault("copy_reset", []).append(copy.reset(mask=done).copy())
    ve.close()
    copy.close()
    got = {k: np.asarray(v) for k, v in out.items()}
    for key in ("obs", "reward", "terminated", "truncated", "reset"):  # the copy continued bit for bit
        mine = got["reset_obs"][-len(got["copy_reset"]) :] if key == "reset" else got[key][steps // 2 :]
        if not np.array_equal(mine, got["copy_" + key]):
            raise AssertionError(f"{name}: the pickled copy's {key} differ from the original's")
    return got


def record(path: str, steps: int, only: list[str]) -> None:
    """Every rollout of ``only`` into one ``.npz`` (keys ``rollout/array``)."""
    arrays: dict[str, np.ndarray] = {}
    for name in only:
        if name.startswith("parallel_"):
            got = _parallel(name, steps)
        elif name == "follower":
            got = _follower(steps)
        else:
            got = _vector(name, steps)
        arrays.update({f"{name}/{k}": v for k, v in got.items()})
    import bioform_mj

    arrays[SOURCE] = np.array(str(Path(bioform_mj.__file__).resolve().parent.parent))  # the tree it ran
    tmp = path + ".part.npz"
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _src(p: str) -> str:
    q = Path(p).resolve()
    return str(q / "src" if (q / "src" / "bioform_mj").is_dir() else q)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs="*", help="REF_SRC NEW_SRC")
    ap.add_argument("--record", help="record the rollouts of the current PYTHONPATH into this .npz")
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--only", default=",".join(ROLLOUTS))
    a = ap.parse_args()
    only = [s for s in a.only.split(",") if s]
    bad = [s for s in only if s not in ROLLOUTS]
    if bad or a.steps < 1 or (len(a.trees) != 2 if a.record is None else bool(a.trees)):
        msg = f"unknown rollout {bad[0]!r}" if bad else "give REF_SRC NEW_SRC, or --record OUT.npz; --steps >= 1"
        print(f"error: {msg}", file=sys.stderr)
        return 2
    if a.record:
        record(a.record, a.steps, only)
        return 0
    # a tree without the package ran the installed one instead: "identical" of one tree against itself
    if missing := [t for t in a.trees if not (Path(_src(t)) / "bioform_mj").is_dir()]:
        print(f"error: {missing[0]}: no bioform_mj package there (nor under its src/)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for i, tree in enumerate(a.trees):
            f = os.path.join(tmp, f"{i}.npz")
            env = dict(os.environ, PYTHONPATH=_src(tree))
            cmd = [sys.executable, __file__, "--record", f, "--steps", str(a.steps), "--only", ",".join(only)]
            p = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if p.returncode != 0:
                print(f"error: recording under {tree} failed: {p.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                return 1
            files.append(np.load(f))
            ran = str(files[-1][SOURCE])
            if ran != _src(tree):  # PYTHONPATH lost to another copy of the package (an installed one)
                print(f"error: the recording for {tree} imported bioform_mj from {ran}", file=sys.stderr)
                return 1
        ref, new = files
        differ = 0
        for name in only:
            keys = sorted(k for k in ref.files if k.startswith(name + "/"))
            nkeys = sorted(k for k in new.files if k.startswith(name + "/"))
            same = keys == nkeys and all(
                ref[k].dtype == new[k].dtype
                and ref[k].shape == new[k].shape
                and np.array_equal(ref[k], new[k], equal_nan=ref[k].dtype.kind in "fc")
                for k in keys
            )
            sizes = ", ".join(f"{k.split('/', 1)[1]} {ref[k].shape}" for k in keys)
            print(f"{name}: {'identical' if same else 'DIFFERENT'} ({sizes})")
            differ += not same
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
