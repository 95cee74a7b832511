#!/usr/bin/env python3
"""MuJoCo 4's engine thread pool (``mujoco.mju_threadpool``) and sleeping islands on a large preset's own scene.

One process. The preset's closed loop runs once (``--duration`` s, untimed beyond its own loop time), recording
every control step's wheel torques and chassis forces; then ``--rounds`` rounds, in rotating order, of the bare
replay of those inputs (``mj_step`` from a compiled loop, no Python per step) on

- ``plain``: the plant's own ``MjData``, as every run steps it;
- ``pool``: a second ``MjData`` of the same model with a pool of ``--threads`` worker threads bound to it
  (``mju_threadpool``: collision and the islands' constraint solving spread over the workers), started from the
  plant's reset state (``mj_copyData`` keeps the destination's pool);
- ``sleep`` (information only): the plant's ``MjData`` with ``mjENBL_SLEEP`` set (islands at rest stop).

Each variant's final ``qpos`` is compared with the closed loop's (``max |Δqpos|``; 0.0: the same physics bit for
bit). Last, the pool is bound to the plant's own ``MjData`` and the closed loop runs again: every array of its log
is compared with the first run's. Prints wall and CPU seconds per robot-step (CPU counts every thread), the
medians over the rounds, each variant's ratio to ``plain`` (wall), and the load average. Changes nothing.

    python scripts/scale_threads.py [--preset large256] [--duration 1] [--threads 2] [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import mujoco
import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="large256")
    ap.add_argument("--duration", type=float, default=1.0, help="the preset's sim.duration, s (default 1)")
    ap.add_argument("--threads", type=int, default=2, help="worker threads of the pool (default 2)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    if not (a.duration > 0 and a.threads >= 1 and a.rounds >= 1):
        print("error: --duration must be > 0 s, --threads and --rounds >= 1", file=sys.stderr)
        return 2
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.plants.mujoco.kernels import replay as mujoco_replay
    from bioform_mj.run.simulate import make_plant, simulate
    from bioform_mj.scenario.loader import load

    sc = load(a.preset, overrides=[f"sim.duration={a.duration}"], plant="mujoco")
    plant = make_plant(sc)
    m, n = plant.model, plant.n
    steps = int(round(sc.sim.duration / sc.sim.control_dt))
    rec = (np.zeros((steps, m.nu)), np.zeros((steps, n, 6)))

    def closed_loop(record: tuple | None) -> object:
        with warnings.catch_warnings(), quiet_outcomes():
            warnings.simplefilter("ignore")
            return simulate(sc, record_inputs=record, plant=plant)

    print(f"{a.preset}: n = {n}, {steps * plant.n_substeps} steps, load {os.getloadavg()}", flush=True)
    r0 = closed_loop(rec)
    q_loop = plant.data.qpos.copy()
    base = np.ascontiguousarray(plant._base, dtype=np.int64)
    pooled = mujoco.MjData(m)
    mujoco.mju_threadpool(pooled, a.threads)

    def run(variant: str) -> tuple[float, float, float]:
        plant.reset()
        d = plant.data
        if variant == "pool":
            mujoco.mj_copyData(pooled, m, plant.data)  # the reset state; the destination keeps its pool
            d = pooled
        if variant == "sleep":
            m.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
        try:
            t0, c0 = time.perf_counter(), time.process_time()
            mujoco_replay(m._address, d._address, plant.n_substeps, d.ctrl, d.xfrc_applied, base, *rec, d.solver_niter)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        finally:
            m.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
        return wall, cpu, float(np.abs(d.qpos - q_loop).max())

    variants = ["plain", "pool", "sleep"]
    times: dict[str, list[tuple[float, float]]] = {v: [] for v in variants}
    dq: dict[str, float] = {}
    run("plain")  # the replay kernel compiled or loaded
    for r in range(a.rounds):
        for v in variants[r % 3 :] + variants[: r % 3]:
            w, c, dq[v] = run(v)
            times[v].append((w, c))
    rs = steps * plant.n_substeps * n
    wall_plain = np.median([w for w, _ in times["plain"]])
    for v in variants:
        w = float(np.median([x for x, _ in times[v]]))
        c = float(np.median([x for _, x in times[v]]))
        print(
            f"{v:>5}: wall {w / rs * 1e6:.2f} µs/robot-step, CPU {c / rs * 1e6:.2f}, wall ratio to plain "
            f"{wall_plain / w:.2f}x, real-time factor {sc.sim.duration / w:.2f} (wall), max |Δqpos| {dq[v]:.3g}"
        )
    mujoco.mju_threadpool(plant.data, a.threads)
    r1 = closed_loop(None)
    same = sorted(k for k in r0.log if np.array_equal(r0.log[k], r1.log[k], equal_nan=True))
    diff = sorted(k for k in r0.log if k not in same)
    print(
        f"closed loop, pool of {a.threads} on the plant's MjData: wall {r1.summary['wall_time_s']:.2f} s against "
        f"{r0.summary['wall_time_s']:.2f} s without; log arrays equal bit for bit: {len(same)} of {len(r0.log)}"
        + (f" (differ: {', '.join(diff)})" if diff else "")
        + f"; final max |Δqpos| {float(np.abs(plant.data.qpos - q_loop).max()):.3g}"
    )
    print(f"load {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
