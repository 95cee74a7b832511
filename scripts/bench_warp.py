#!/usr/bin/env python3
"""Benchmark of the MuJoCo Warp batch engine: closed loop vs physics alone.

For each world count W: W worlds of the paper scenario on the MuJoCo plant (seeds 0…W−1,
jittered initial poses), ``--duration`` s simulated.

* closed loop: ``bioform_mj.batch.control.BatchRun.run`` (per control step: n_substeps ×
  ``mjw.step`` + the control kernel, all on the device; CUDA: captured as a CUDA graph);
* physics alone: the same worlds from the same initial state, the same number of
  physics steps with constant random wheel torques (±1.5 N·m), captured the same way.

Robot-steps/s = W × n_robots × control steps / wall seconds (warm: kernels are loaded and
graphs captured before the timed loop). Prints a table; ``--json PATH`` writes the rows.

    python scripts/bench_warp.py --device cuda --worlds 1024,4096,32768 --duration 2 --json $OUT/warp.json
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", help="Warp device: cpu, cuda, cuda:0 (default cpu)")
    ap.add_argument("--worlds", default="4,16", help="comma-separated world counts (default 4,16)")
    ap.add_argument("--duration", type=float, default=0.1, help="simulated seconds per run (default 0.1)")
    ap.add_argument("--scenario", default="paper", help="scenario name or TOML (default paper)")
    ap.add_argument("--chunk", type=int, default=100, help="control steps per captured CUDA graph (default 100)")
    ap.add_argument("--no-capture", action="store_true", help="no CUDA graph capture (eager launches)")
    ap.add_argument("--json", default=None, help="write the results as JSON here")
    a = ap.parse_args(argv)

    try:
        import numpy as np
        import warp as wp
        import mujoco_warp  # noqa: F401
    except ImportError as e:
        print(f"error: the batch engine needs the optional GPU extra: pip install 'bioform-mj[gpu]' ({e})",
              file=sys.stderr)
        return 2
    wp.config.quiet = True
    from bioform_mj.batch.control import BatchRun
    from bioform_mj.scenario import load

    dev = wp.get_device(a.device)
    capture = False if a.no_capture else None
    rows = []
    print(f"device {dev} ({dev.name}), scenario {a.scenario}, {a.duration:g} s simulated, "
          f"graph capture {'off' if a.no_capture or not dev.is_cuda else 'on'}", flush=True)
    hdr = (f"{'worlds':>7} {'robots':>6} {'steps':>6} {'setup s':>8} {'loop s':>8} {'closed r-steps/s':>17} "
           f"{'phys s':>8} {'phys r-steps/s':>15} {'ratio':>6} {'diverged':>8}")
    print(hdr, flush=True)
    for W in [int(x) for x in a.worlds.split(",") if x.strip()]:
        t0 = time.perf_counter()
        ov = ["plant.kind=mujoco", f"sim.duration={a.duration}", "formation.init_jitter=0.05"]
        base = load(a.scenario, overrides=ov)
        scs = [base]
        if W > 1:  # one load, then seeds by dataclass replace (loading 32k TOMLs would dominate setup)
            import dataclasses

            scs = [dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=s)) for s in range(W)]
        b = BatchRun(scs, a.device)
        setup = time.perf_counter() - t0
        b.run(chunk=a.chunk, capture=capture)  # warm-up: loads kernels, captures the graph
        wall = b.run(chunk=a.chunk, capture=capture)
        summ = b.summaries(wall)
        ndiv = sum(1 for s in summ if s["diverged"])
        N, n = b.N, b.n
        rng = np.random.default_rng(0)
        ctrl = np.zeros((W, b.mjm.nu), dtype=np.float32)
        ctrl[:, b.plant._ctrl.ravel()] = rng.uniform(-1.5, 1.5, (W, 2 * n))
        b.run_physics(N * b.n_sub, ctrl, chunk=a.chunk, capture=capture)  # warm-up
        pwall = b.run_physics(N * b.n_sub, ctrl, chunk=a.chunk, capture=capture)
        rs = W * n * N
        row = {
            "worlds": W, "robots": n, "control_steps": N, "physics_steps_per_control_step": b.n_sub,
            "setup_s": setup, "closed_loop_s": wall, "closed_loop_robot_steps_per_s": rs / wall,
            "physics_s": pwall, "physics_robot_steps_per_s": rs / pwall, "closed_over_physics": pwall / wall,
            "diverged_worlds": ndiv, "nconmax": b.nconmax, "njmax": b.njmax,
        }
        rows.append(row)
        print(f"{W:>7} {n:>6} {N:>6} {setup:>8.2f} {wall:>8.3f} {rs / wall:>17.4g} {pwall:>8.3f} "
              f"{rs / pwall:>15.4g} {pwall / wall:>6.2f} {ndiv:>8}", flush=True)
        del b
    if a.json:
        import mujoco
        import mujoco_warp as mjw_mod

        out = {
            "device": str(dev), "device_name": dev.name, "scenario": a.scenario, "duration_s": a.duration,
            "graph_capture": bool(dev.is_cuda and not a.no_capture), "chunk": a.chunk,
            "versions": {"warp": wp.config.version, "mujoco": mujoco.__version__,
                         "mujoco_warp": getattr(mjw_mod, "__version__", "?"), "python": platform.python_version()},
            "host": platform.node(), "rows": rows,
        }
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
