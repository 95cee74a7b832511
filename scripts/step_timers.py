#!/usr/bin/env python3
"""Where ``mj_step``'s time goes on a large preset's own scene, by MuJoCo's own timers, and what each step solves.

The closed loop of the preset runs once (``--duration`` s), recording every control step's wheel torques and
chassis forces; the plant is reset and the scene stepped by ``mj_step`` from Python replaying those inputs, with
MuJoCo's timer callback on (``mujoco.set_mjcb_time``: ``MjData.timer``, wall µs, so shares of the step rather than
absolute costs on a loaded machine). Prints the CPU time per robot-step of the replay, the contacts and constraint
rows per robot, the solver's iterations, the contacts by geom pair (two sample steps), each timer's share of the
step, one robot's collision geoms and the options that size the step. Changes nothing.

    python scripts/step_timers.py [--preset large1024] [--duration 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections import Counter

import mujoco


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="large1024")
    ap.add_argument("--duration", type=float, default=1.0, help="simulated s (default 1)")
    a = ap.parse_args(argv)
    if not a.duration > 0:
        print(f"error: --duration must be > 0 s, got {a.duration}", file=sys.stderr)
        return 2
    from bioform_mj.jobs.bench import record_run
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    sc = load(a.preset, overrides=[f"sim.duration={a.duration}"], plant="mujoco")
    plant = make_plant(sc)
    m, d = plant.model, plant.data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = record_run(sc, plant)[:2]  # the closed loop's ctrl and chassis forces, every control step
    steps = len(rec[0])
    plant.reset()

    def name(g: int) -> str:  # the geom's name without the follower prefix
        full = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
        return full.split("/", 1)[-1]

    ncon = nefc = iters = 0
    pairs: Counter = Counter()
    mujoco.set_mjcb_time(lambda: time.perf_counter() * 1e6)
    try:
        for t in d.timer:
            t.duration, t.number = 0.0, 0
        t0 = time.process_time()
        for k in range(steps):
            d.ctrl[:] = rec[0][k]
            d.xfrc_applied[plant._base] = rec[1][k]
            for _ in range(plant.n_substeps):
                mujoco.mj_step(m, d)
                ncon, nefc, iters = ncon + d.ncon, nefc + d.nefc, iters + int(d.solver_niter[0])
            if k in (steps // 2, steps - 1):
                for c in range(d.ncon):
                    pairs[tuple(sorted((name(d.contact.geom1[c]), name(d.contact.geom2[c]))))] += 1
        cpu = time.process_time() - t0
    finally:
        mujoco.set_mjcb_time(None)
    ns, n = steps * plant.n_substeps, plant.n
    print(
        f"{a.preset}: n = {n}, {ns} steps, replay CPU {cpu:.2f} s = {cpu / ns / n * 1e6:.2f} µs per robot-step "
        f"(Python loop, timers on), load {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores"
    )
    print(
        f"per step: {ncon / ns / n:.2f} contacts and {nefc / ns / n:.2f} constraint rows per robot, "
        f"{iters / ns:.2f} solver iterations, {d.nisland} islands"
    )
    print("contacts by geom pair (two steps):", ", ".join(f"{a_}-{b_} {c}" for (a_, b_), c in pairs.most_common(8)))
    whole = d.timer[int(mujoco.mjtTimer.mjTIMER_STEP)].duration
    print("| timer | µs per robot-step (wall) | share of mj_step |")
    print("|---|---|---|")
    for t in mujoco.mjtTimer.__members__.values():
        if t.name != "mjNTIMER" and d.timer[int(t)].duration:
            dur = d.timer[int(t)].duration
            print(f"| {t.name[8:]} | {dur / ns / n:.2f} | {dur / whole * 100:.1f} % |")
    geoms = [
        f"{name(g)} ({mujoco.mjtGeom(m.geom_type[g]).name[7:].lower()}, condim {m.geom_condim[g]})"
        for g in plant.contact_geoms[0]
    ]
    print("follower 1's collision geoms:", ", ".join(geoms))
    o = m.opt
    print(
        f"ngeom {m.ngeom}, nexclude {m.nexclude}, npair {m.npair}, nsensor {m.nsensor} (computed: "
        f"{not o.disableflags & int(mujoco.mjtDisableBit.mjDSBL_SENSOR)}), cone {mujoco.mjtCone(o.cone).name}, "
        f"solver {mujoco.mjtSolver(o.solver).name}, integrator {mujoco.mjtIntegrator(o.integrator).name}, "
        f"impratio {o.impratio:g}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
