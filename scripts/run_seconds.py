#!/usr/bin/env python3
"""A whole large-preset run, bin by bin: does a robot-step cost more late in a run than early?

One process. The preset's closed loop runs (its own ``sim.duration``, or ``--duration`` before the time scale) with an
observer that notes the process's CPU time every ``--bin`` simulated seconds: the loop's CPU per robot-step per bin.
Then the plant is reset and the recorded inputs (every control step's wheel torques and chassis forces) are replayed
by ``mj_step`` from Python, timing each step's CPU: MuJoCo's own cost per bin, with the contacts and constraint rows
per robot, the solver's iterations per step, the islands, the contacts between two robots and the contacts by geom
pair (every 50th control step), and with ``--timers`` MuJoCo's timers as shares of ``mj_step``. The replay's final
``qpos`` is compared with the loop's (0: the same physics bit for bit). Changes nothing.

    python scripts/run_seconds.py [--preset large256] [--duration D] [--bin 2.31] [--timers]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections import Counter

import mujoco
import numpy as np


class _Clock:
    """An observer noting (simulated s, process CPU s) at each of its calls."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.marks: list[tuple[float, float]] = []

    def start(self, run) -> None:
        self.marks.append((run.t, time.process_time()))

    sample = finish = start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="large256")
    ap.add_argument("--duration", type=float, default=None, help="sim.duration, s (default: the preset's)")
    ap.add_argument("--bin", type=float, default=2.31, help="simulated s per row (default 2.31)")
    ap.add_argument("--timers", action="store_true", help="MuJoCo's timers (a callback per timer: slower)")
    a = ap.parse_args(argv)
    if (a.duration is not None and not a.duration > 0) or not a.bin > 0:
        print("error: --duration and --bin must be > 0 s", file=sys.stderr)
        return 2
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.run.simulate import make_plant, simulate
    from bioform_mj.scenario.loader import load

    sc = load(a.preset, overrides=[f"sim.duration={a.duration}"] if a.duration else [], plant="mujoco")
    plant = make_plant(sc)
    m, d, n, dt = plant.model, plant.data, plant.n, sc.sim.control_dt
    steps = int(round(sc.sim.duration / dt))
    rec = (np.zeros((steps, m.nu)), np.zeros((steps, n, 6)))
    clock = _Clock(a.bin)
    print(f"{a.preset}: n = {n}, {steps} control steps of {dt} s, load {os.getloadavg()}", flush=True)
    with warnings.catch_warnings(), quiet_outcomes():
        warnings.simplefilter("ignore")
        r = simulate(sc, record_inputs=rec, plant=plant, observers=[clock])
    print(f"loop: {r.loop_cpu_s:.1f} s CPU = {r.loop_cpu_s / steps / n * 1e6:.2f} µs per robot-step", flush=True)
    q_loop = d.qpos.copy()
    marks = clock.marks
    loop_bins = [
        (t1, (c2 - c1) / ((t2 - t1) / dt) / n * 1e6) for (t1, c1), (t2, c2) in zip(marks, marks[1:]) if t2 > t1
    ]

    def kind(g: int) -> str:
        if m.geom_bodyid[g] == 0:
            return "world"
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
        return name.split("/", 1)[-1]

    plant.reset()
    root = m.body_rootid
    if a.timers:
        mujoco.set_mjcb_time(lambda: time.perf_counter() * 1e6)
    per = int(round(a.bin / dt))
    rows: list[dict] = []
    try:
        for k in range(steps):
            if k % per == 0:
                rows.append(dict(t=k * dt, cpu=0.0, ncon=0, nefc=0, it=0, steps=0, isl=0, rr=0, pairs=Counter()))
                for t in d.timer:
                    t.duration, t.number = 0.0, 0
            row = rows[-1]
            d.ctrl[:] = rec[0][k]
            d.xfrc_applied[plant._base] = rec[1][k]
            c0 = time.process_time()
            for _ in range(plant.n_substeps):
                mujoco.mj_step(m, d)
            row["cpu"] += time.process_time() - c0
            row["ncon"] += d.ncon
            row["nefc"] += d.nefc
            row["it"] += int(d.solver_niter[0])
            row["isl"] += d.nisland
            row["steps"] += plant.n_substeps
            if k % 50 == 0:
                for c in range(d.ncon):
                    g1, g2 = d.contact.geom1[c], d.contact.geom2[c]
                    b1, b2 = m.geom_bodyid[g1], m.geom_bodyid[g2]
                    row["rr"] += bool(b1 and b2 and root[b1] != root[b2])
                    row["pairs"][tuple(sorted((kind(g1), kind(g2))))] += 1
            if a.timers and (k % per == per - 1 or k == steps - 1):
                whole = d.timer[int(mujoco.mjtTimer.mjTIMER_STEP)].duration or 1.0
                row["timers"] = {
                    t.name[8:]: round(d.timer[int(t)].duration / whole * 100, 1)
                    for t in mujoco.mjtTimer.__members__.values()
                    if t.name != "mjNTIMER" and d.timer[int(t)].duration and t.name != "mjTIMER_STEP"
                }
    finally:
        mujoco.set_mjcb_time(None)
    print(f"replay's final qpos against the loop's: max |Δ| {float(np.abs(d.qpos - q_loop).max()):.3g}")
    print(
        "| t (s) | loop CPU µs/robot-step | mj_step CPU µs/robot-step | contacts/robot | rows/robot | iterations/step "
        "| islands | robot-robot contacts (sampled) | contacts by pair (sampled) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        s = row["steps"]
        lp = next((c for t, c in loop_bins if abs(t - row["t"]) < dt * 1.5), float("nan"))
        pairs = ", ".join(f"{x}-{y} {c}" for (x, y), c in row["pairs"].most_common(3))
        print(
            f"| {row['t']:.2f} | {lp:.2f} | {row['cpu'] / s / n * 1e6:.2f} | {row['ncon'] / s / n:.2f} | "
            f"{row['nefc'] / s / n:.2f} | {row['it'] / s:.2f} | {row['isl'] / s:.0f} | {row['rr']} | {pairs} |"
        )
        if "timers" in row:
            print(f"|   | timers, % of mj_step: {row['timers']} |")
    print(f"load {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
