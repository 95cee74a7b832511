#!/usr/bin/env python3
"""Parallel speed-up of ``bioform sweep``: the same runs serially and on a process pool, in one process.

Default: 16 runs of the paper scenario in MuJoCo (20 s, seeds 0..15 with jittered start
poses). Prints the throughputs and their ratio and writes JSON (``--json``). The issue's
target on a 2-core machine: >= 1.7x with 8+ runs.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
from pathlib import Path

from bioform_mj.sweep import expand, sweep


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=16)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    specs = expand("paper", args.runs, ["bioinspired-learning"], [], ["formation.init_jitter=0.2"], plant=args.plant)
    tmp = Path(tempfile.mkdtemp())
    try:
        sweep(specs[:1], tmp / "warm", workers=1)  # compile/load the kernels once
        serial = sweep(specs, tmp / "serial", workers=1)["timing"]
        pool = sweep(specs, tmp / "pool", workers=args.workers)["timing"]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    ratio = pool["runs_per_s"] / serial["runs_per_s"]
    print(f"{args.runs} runs: serial {serial['wall_s']:.2f} s, {args.workers} workers {pool['wall_s']:.2f} s "
          f"-> speed-up {ratio:.2f}x")
    if args.json:
        args.json.write_text(json.dumps({"serial": serial, "pool": pool, "speedup": ratio}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
