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
from bioform_mj.scenario import load
from bioform_mj.sim import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--control-dt", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=3)
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


if __name__ == "__main__":
    main()
