"""Environment steps/s of bioform_mj.envs against ``bioform run``'s compiled loop (design §20).

Both on the same scenario (default: the paper's, MuJoCo plant, control at 100 Hz, physics at
1 kHz: 10 substeps per control step), measured in one process, alternating, ``--repeat`` times;
prints the median of each and their ratio (issue 22 asks for >= 0.5). Run:

    .venv/bin/python scripts/bench_envs.py [--scenario paper] [--duration 20] [--control-dt 0.01]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bioform_mj.envs import parallel_env
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--control-dt", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--worlds", type=int, default=0, help="also the batched environment with this many worlds")
    ap.add_argument("--device", default="cpu", help="Warp device of the batched environment")
    a = ap.parse_args()
    ov = [f"sim.duration={a.duration}", f"sim.control_dt={a.control_dt}", f"plant.kind={a.plant}"]
    env = parallel_env(a.scenario, action="velocity", overrides=ov)
    sc = load(a.scenario, ov)
    simulate(sc)  # compile / load kernels outside the timing
    env_rates, run_rates = [], []
    for _ in range(a.repeat):
        env.reset(seed=0)
        act = {ag: np.array([0.2, 0.1]) for ag in env.agents}
        t0 = time.perf_counter()
        steps = 0
        while env.agents:
            env.step(act)
            steps += 1
        env_rates.append(steps / (time.perf_counter() - t0))
        r = simulate(sc)
        run_rates.append(r.summary["steps"] / r.summary["wall_time_s"])
    e, r = statistics.median(env_rates), statistics.median(run_rates)
    print(f"scenario {a.scenario}, plant {a.plant}, n = {sc.n}, control_dt {a.control_dt:g} s, {a.duration:g} s")
    print(f"environment: {e:,.0f} steps/s ({e * sc.n:,.0f} agent-steps/s); bioform run (compiled): {r:,.0f} steps/s")
    print(f"ratio environment / compiled loop: {e / r:.2f}")
    if a.worlds:
        batch(a, ov, sc)


def batch(a, ov, sc) -> None:
    """The batched environment against the batch engine's own closed loop (``BatchRun.run``), same worlds."""
    import warp as wp

    from bioform_mj.envs import batch_env

    be = batch_env(a.scenario, worlds=a.worlds, device=a.device, overrides=ov)
    act = np.tile(np.array([0.2, 0.1]), (a.worlds, sc.n, 1))
    be.reset()
    be.step(act)  # kernels loaded
    env_rates, run_rates = [], []
    for _ in range(a.repeat):
        be.reset()
        wp.synchronize_device(be.run.device)
        t0 = time.perf_counter()
        for _k in range(be.N):
            be.step(act)
        wp.synchronize_device(be.run.device)
        env_rates.append(be.N / (time.perf_counter() - t0))
        wall = be.run.run()
        run_rates.append(be.N / wall)
    e, r = statistics.median(env_rates), statistics.median(run_rates)
    agents = a.worlds * sc.n
    print(f"batched environment, {a.worlds} worlds on {a.device}: {e:,.1f} steps/s ({e * agents:,.0f} agent-steps/s)")
    print(f"batch engine closed loop (BatchRun.run): {r:,.1f} steps/s; ratio {e / r:.2f}")


if __name__ == "__main__":
    main()
