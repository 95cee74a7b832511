#!/usr/bin/env python3
"""Cost of one control step (the hot path) for n = 3 … 256 followers, plant excluded.

Times the numpy reference stack and the numba-compiled one (one kernel call per step from
Python; inside ``bioform run`` the compiled loop calls it without leaving machine code).
Prints µs per step and µs per follower-step; writes JSON with --json PATH.
"""
from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from bioform_mj import graph
from bioform_mj.control.stack import ControlStack
from bioform_mj.scenario import Scenario
from bioform_mj.sim import stack_params


def stack_for(n: int, cls=ControlStack) -> ControlStack:
    sc = Scenario()
    side = int(np.ceil(np.sqrt(n)))
    offs = np.array([[2.0 * (i // side + 1), 2.0 * (i % side - side / 2)] for i in range(n)])
    import dataclasses

    sc = dataclasses.replace(sc, formation=dataclasses.replace(sc.formation, offsets=tuple(map(tuple, offs)),
                                                               initial_poses=tuple((0.0, 0.0, 0.0) for _ in range(n))))
    g = graph.chain(n, leader_access=range(1, n + 1, max(1, n // 8)))
    st = cls(g, stack_params(sc, np.tile([0.4, 10.0], (n, 1))))
    st.reset(np.zeros((n, 3)), np.zeros((n, 2)))
    return st


def bench(n: int, steps: int, cls=ControlStack) -> dict:
    st = stack_for(n, cls)
    rng = np.random.default_rng(0)
    pose = rng.normal(size=(n, 3))
    vel = rng.normal(size=(n, 2)) * 0.1
    lp, lv = np.array([0.0, 3.0, 0.1]), np.array([1.0, 0.1])
    for _ in range(50):
        st.step(lp, lv, pose, vel)
    t0 = time.perf_counter()
    for _ in range(steps):
        st.step(lp, lv, pose, vel)
    dt = (time.perf_counter() - t0) / steps
    return {"n": n, "stack": cls.__name__, "us_per_step": dt * 1e6, "us_per_follower_step": dt * 1e6 / n}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--json", help="write results here")
    args = ap.parse_args()
    from bioform_mj.control.fused import FusedControlStack

    rows = [bench(n, args.steps, cls) for cls in (ControlStack, FusedControlStack) for n in (3, 16, 64, 256)]
    print(f"control step, {platform.processor() or platform.machine()}, {args.steps} steps")
    print(f"{'stack':>18} {'n':>5} {'us/step':>10} {'us/follower-step':>18}")
    for r in rows:
        print(f"{r['stack']:>18} {r['n']:>5} {r['us_per_step']:>10.1f} {r['us_per_follower_step']:>18.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
