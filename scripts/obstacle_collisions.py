"""How often each of the four methods collides on the ``obstacles`` preset (design §19, docs/safety.md).

Runs the preset for every method and seeds 0..N−1 (the seed draws the random obstacle field) for
``--duration`` s (default 12: every fixed obstacle is reached by then) and prints a Markdown table:
runs with a collision, followers that touched an obstacle / another robot, mean time too close.

    PYTHONPATH=src python scripts/obstacle_collisions.py [--seeds 10] [--duration 12]
"""

from __future__ import annotations

import argparse

import numpy as np

from bioform_mj.control.stack import METHODS
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--duration", type=float, default=12.0)
    ap.add_argument("--preset", default="obstacles")
    ap.add_argument("--set", action="append", default=[], help="extra KEY=VALUE overrides")
    args = ap.parse_args()
    extra = ", " + ", ".join(args.set) if args.set else ""
    print(f"{args.preset}, seeds 0..{args.seeds - 1}, {args.duration:g} s{extra}")
    print()
    head = ["method", "runs with a collision", "followers on an obstacle", "followers on a robot"]
    head += ["too close (s, mean per follower)", "tipped", "rms formation error (m, mean)"]
    print("| " + " | ".join(head) + " |")
    print("|---|---|---|---|---|---|---|")
    for m in METHODS:
        runs = obst = robot = tipped = 0
        close, rms = [], []
        for seed in range(args.seeds):
            sc = load(args.preset, [f"sim.duration={args.duration}", f"sim.seed={seed}", *args.set], method=m)
            fs = simulate(sc).summary["followers"]
            runs += any(f["robot_contacts"] + f["obstacle_contacts"] for f in fs)
            obst += sum(1 for f in fs if f["obstacle_contacts"])
            robot += sum(1 for f in fs if f["robot_contacts"])
            tipped += sum(1 for f in fs if any(o["kind"] == "tipped" for o in f["outcomes"]))
            close += [f["too_close_s"] or 0.0 for f in fs]
            rms += [f["rms_formation_error_m"] for f in fs]
        k = args.seeds * 3
        print(
            f"| {m} | {runs}/{args.seeds} | {obst}/{k} | {robot}/{k} | {np.mean(close):.2f} | {tipped}/{k} | "
            f"{np.mean(rms):.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
