#!/usr/bin/env python3
"""Parallel speed-up of ``bioform sweep``: the same runs serially and on forked workers, in one process.

Default: 16 runs of the paper scenario in MuJoCo (20 s, seeds 0..15 with jittered start
poses). Serial and parallel alternate ``--reps`` times; the best wall time of each counts
(other load on the machine only ever slows a repetition down). Prints the throughputs, their
ratio and the load average, and writes JSON (``--json``). The issue's target on a 2-core
machine: >= 1.7x with 8+ runs.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
from pathlib import Path

from bioform_mj.jobs.sweep import expand, sweep


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=16)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--reps", type=int, default=1, help="alternating repetitions; the best time of each counts")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    specs = expand("paper", args.runs, ["bioinspired-learning"], [], ["formation.init_jitter=0.2"], plant=args.plant)
    tmp = Path(tempfile.mkdtemp())
    serial, pool = [], []
    load = [os.getloadavg()[0]]
    try:
        sweep(specs[:1], tmp / "warm", workers=1, warn=None)  # compile/load the kernels once
        for i in range(args.reps):
            serial.append(sweep(specs, tmp / f"serial{i}", workers=1, warn=None)["timing"])
            pool.append(sweep(specs, tmp / f"pool{i}", workers=args.workers, warn=None)["timing"])
            load.append(os.getloadavg()[0])
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    s = min(t["wall_s"] for t in serial)
    p = min(t["wall_s"] for t in pool)
    ratio = s / p

    def fmt(vals: list[float], digits: int = 2) -> str:
        return ", ".join(f"{v:.{digits}f}" for v in vals)

    print(
        f"{args.runs} runs: serial {s:.2f} s, {args.workers} workers {p:.2f} s -> speed-up {ratio:.2f}x "
        f"(best of {args.reps}; serial {fmt([t['wall_s'] for t in serial])}; pool {fmt([t['wall_s'] for t in pool])}; "
        f"1-min load average {fmt(load, 1)})"
    )
    if args.json:
        args.json.write_text(
            json.dumps({"serial": serial, "pool": pool, "speedup": ratio, "loadavg": load}, indent=2) + "\n"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
