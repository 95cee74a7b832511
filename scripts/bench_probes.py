#!/usr/bin/env python3
"""The probes behind docs/findings/performance.md's "Method" section, each in one process.

``--replay`` (default large256): bare replays of one recorded closed loop on a fresh plant, on the plant
``simulate`` ran on and on a new ``MjData`` of that model, in rotating order for ``--rounds`` rounds: CPU µs per
robot-step (process and thread), each round's ratio to the fresh plant's, the final ``qpos`` (bit-identical?) and
the solver's iterations.

``--chunks`` (default 3,16,64,256): per team size one plant and its recording, then ``--rounds`` rounds of bare
replay, the loop with fixed 0.1 s chunks (``MIN_CHUNK_WALL_S = 0``) and the loop as it is, in rotating order;
the median of the neighbouring pairs' ratios (bare / loop, wall and CPU).

Usage: ``python scripts/bench_probes.py --replay [--preset large256] [--duration 1] [--rounds 8]`` or
``python scripts/bench_probes.py --chunks [--sizes 3,16,64,256] [--rounds 6]``.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np


def replay_effect(preset: str, duration: float, rounds: int) -> None:
    import mujoco

    from bioform_mj.jobs.bench import record_run
    from bioform_mj.plants.mujoco.kernels import replay
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    sc = load(preset, plant="mujoco", overrides=[f"sim.duration={duration}"])
    steps = int(round(sc.sim.duration / sc.sim.control_dt))
    a, b = make_plant(sc), make_plant(sc)
    rc, rx, _q = record_run(sc, a)  # simulate ran on a
    base = np.ascontiguousarray(a._base, dtype=np.int64)
    c = mujoco.MjData(a.model)

    def reset_c() -> None:
        mujoco.mj_resetData(a.model, c)
        mujoco.mj_forward(a.model, c)

    cases = {"fresh": (b.model, b.data, b.reset), "after": (a.model, a.data, a.reset), "newdata": (a.model, c, reset_c)}

    def rep(m, d, reset) -> tuple[float, float, int, np.ndarray]:
        reset()
        c0, t0 = time.process_time(), time.thread_time()
        it = replay(m._address, d._address, a.n_substeps, d.ctrl, d.xfrc_applied, base, rc, rx, d.solver_niter)
        return time.process_time() - c0, time.thread_time() - t0, int(it), d.qpos.copy()

    rep(*cases["fresh"])  # compile
    res: dict[str, list[tuple[float, float]]] = {k: [] for k in cases}
    fin = {}
    keys = list(cases)
    for r in range(rounds):
        for k in keys[r % 3 :] + keys[: r % 3]:
            cpu, thr, it, q = rep(*cases[k])
            res[k].append((cpu, thr))
            fin[k] = (it, q)
    us = 1e6 / (steps * sc.n)
    print(f"{preset}: n = {sc.n}, {steps} steps, load {os.getloadavg()[0]:.1f}")
    f = np.array(res["fresh"])
    for k in keys:
        v = np.array(res[k])
        rr = v[:, 0] / f[:, 0]
        print(
            f"  {k:8s} CPU µs/robot-step median {np.median(v[:, 0]) * us:.2f} (thread {np.median(v[:, 1]) * us:.2f}); "
            f"per-round ratio to fresh {np.median(rr):.3f} ({rr.min():.2f}-{rr.max():.2f}); solver iterations "
            f"{fin[k][0]}; max abs(Δqpos) vs fresh {float(np.abs(fin[k][1] - fin['fresh'][1]).max()):.1e}"
        )


def chunks(sizes: list[int], rounds: int) -> None:
    from bioform_mj.jobs.bench import CASES, record_run, replayer
    from bioform_mj.run import loop as lp
    from bioform_mj.run.looptime import loop_times
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    print("uptime:", os.popen("uptime").read().strip(), flush=True)
    wall0 = lp.MIN_CHUNK_WALL_S
    for n in sizes:
        preset, dur = CASES[n]
        sc = load(preset, overrides=[f"sim.duration={dur}"], plant="mujoco")
        steps = int(round(sc.sim.duration / sc.sim.control_dt))
        plant = make_plant(sc)
        rep = replayer(plant, *record_run(sc, plant)[:2])
        t: dict[str, list[tuple[float, float]]] = {"bare": [], "before": [], "after": []}
        load0 = os.getloadavg()[0]
        for r in range(rounds):
            for what in [["bare", "before", "after"], ["after", "before", "bare"], ["before", "bare", "after"]][r % 3]:
                if what == "bare":
                    w, c, _ = rep()
                else:
                    lp.MIN_CHUNK_WALL_S = 0.0 if what == "before" else wall0
                    w, c, _ = loop_times(sc, 1, plant=plant)
                t[what].append((w, c))
        lp.MIN_CHUNK_WALL_S = wall0
        b = np.array(t["bare"])
        us = 1e6 / (steps * n)
        out = []
        for what in ("before", "after"):
            lo = np.array(t[what])
            pc = b[:, 1] / lo[:, 1]
            out.append(
                f"{what}: ratio {np.median(b[:, 0] / lo[:, 0]):.2f} (CPU {np.median(pc):.2f}; CPU pairs "
                f"{' '.join(f'{x:.2f}' for x in pc)}), loop CPU µs/robot-step {np.median(lo[:, 1]) * us:.2f}"
            )
        print(
            f"n={n:4d} ({preset}, {steps} steps, bare CPU µs/robot-step {np.median(b[:, 1]) * us:.2f}, load "
            f"{load0:.1f}->{os.getloadavg()[0]:.1f}): " + " | ".join(out),
            flush=True,
        )
    print("uptime:", os.popen("uptime").read().strip())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--replay", action="store_true", help="the replay effect probe (default)")
    g.add_argument("--chunks", action="store_true", help="ratios with fixed and adaptive chunks")
    ap.add_argument("--preset", default="large256")
    ap.add_argument("--duration", type=float, default=1.0, help="sim.duration of --replay, s (default 1)")
    ap.add_argument("--sizes", default="3,16,64,256")
    ap.add_argument("--rounds", type=int, default=None, help="default 8 (--replay), 6 (--chunks)")
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")  # the presets' demand warnings: not this probe's report
    from bioform_mj.core.errors import quiet_outcomes

    with quiet_outcomes():
        if a.chunks:
            chunks([int(x) for x in a.sizes.split(",")], a.rounds or 6)
        else:
            replay_effect(a.preset, a.duration, a.rounds or 8)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
