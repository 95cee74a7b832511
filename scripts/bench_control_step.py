#!/usr/bin/env python3
"""Cost of one control step (the hot path) for n = 3 … 256 followers, plant excluded.

Times the compiled stack through its Python method (``ControlStack.step``: one kernel call
per step, as the step-by-step loop uses it), the bare kernel call (``control_step``, as the
compiled loops call it, here still from Python), and with ``--oracle`` the numpy oracle of
``tests/oracle.py``.
Prints µs per step and µs per follower-step; writes JSON with --json PATH.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from bioform_mj.control.params import stack_params
from bioform_mj.control.stack import ControlStack
from bioform_mj.formation import graph
from bioform_mj.scenario.config import Scenario


def stack_for(n: int, cls=ControlStack) -> ControlStack:
    sc = Scenario()
    side = int(np.ceil(np.sqrt(n)))
    offs = np.array([[2.0 * (i // side + 1), 2.0 * (i % side - side / 2)] for i in range(n)])
    import dataclasses

    sc = dataclasses.replace(
        sc,
        formation=dataclasses.replace(
            sc.formation, offsets=tuple(map(tuple, offs)), initial_poses=tuple((0.0, 0.0, 0.0) for _ in range(n))
        ),
    )
    g = graph.chain(n, leader_access=range(1, n + 1, max(1, n // 8)))
    st = cls(g, stack_params(sc, np.tile([0.4, 10.0], (n, 1))))
    st.reset(np.zeros((n, 3)), np.zeros((n, 2)))
    return st


def bench(n: int, steps: int, cls=ControlStack, bare: bool = False) -> dict:
    st = stack_for(n, cls)
    rng = np.random.default_rng(0)
    pose = rng.normal(size=(n, 3))
    vel = rng.normal(size=(n, 2)) * 0.1
    lp, lv = np.array([0.0, 3.0, 0.1]), np.array([1.0, 0.1])
    if bare:
        from bioform_mj.control.kernel import control_step

        g, s = st.kernel
        comm = st._no_comm

        def step() -> None:
            control_step(g, s, lp, lv, pose, vel, comm)
    else:

        def step() -> None:
            st.step(lp, lv, pose, vel)

    for _ in range(50):
        step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    dt = (time.perf_counter() - t0) / steps
    name = "control_step" if bare else cls.__name__
    return {"n": n, "stack": name, "us_per_step": dt * 1e6, "us_per_follower_step": dt * 1e6 / n}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--json", help="write results here")
    ap.add_argument("--oracle", action="store_true", help="also time the numpy oracle (tests/oracle.py)")
    args = ap.parse_args()
    sizes = (3, 16, 64, 256)
    rows = [bench(n, args.steps) for n in sizes] + [bench(n, args.steps, bare=True) for n in sizes]
    if args.oracle:
        import pathlib
        import sys

        sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests"))
        from oracle import OracleStack

        rows += [bench(n, args.steps, OracleStack) for n in sizes]
    print(f"control step, {platform.processor() or platform.machine()}, {args.steps} steps")
    print(f"{'stack':>18} {'n':>5} {'us/step':>10} {'us/follower-step':>18}")
    for r in rows:
        print(f"{r['stack']:>18} {r['n']:>5} {r['us_per_step']:>10.1f} {r['us_per_follower_step']:>18.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
