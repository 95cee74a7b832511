#!/usr/bin/env python3
"""What MuJoCo's own options buy on a large preset's scene (issue 28 item 6), in one process.

The closed loop of the preset runs once, recording every control step's wheel torques and chassis
forces; then its scene is stepped by ``mj_step`` alone (the compiled replay of ``bioform bench``),
replaying those inputs, once per variant and round (interleaved, so the machine's load falls on all
alike). Times are CPU seconds of this process (``time.process_time``), the best of the rounds; each
variant's final ``qpos`` is compared with the first variant's (0: bit-identical).

Variants (``+`` combines): ``base`` (the run's scene as built), ``sensor`` (the robot files' sensors
computed, as before issue 28), ``nosensor``, ``noisland`` (``mjDSBL_ISLAND``), ``sleep``
(``mjENBL_SLEEP``), ``nomid`` (``mjDSBL_MIDPHASE``), ``cg`` / ``pgs`` (solver), ``tol6`` (tolerance 1e-6).

Usage: ``python scripts/scale_levers.py [--preset large256] [--duration 1] [--rounds 3]
[--variants sensor,base,noisland,sleep]``.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import mujoco
import numpy as np

DB, EB = mujoco.mjtDisableBit, mujoco.mjtEnableBit


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="large256")
    ap.add_argument("--duration", type=float, default=1.0, help="simulated s (default 1)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--variants", default="sensor,base,noisland,sleep,nomid")
    a = ap.parse_args(argv)
    from bioform_mj.jobs.bench import record_run
    from bioform_mj.plants.mujoco.kernels import replay
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    sc = load(a.preset, overrides=[f"sim.duration={a.duration}"], plant="mujoco")
    plant = make_plant(sc)
    m, d = plant.model, plant.data
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = record_run(sc, plant)[:2]  # the closed loop's ctrl and chassis forces, every control step
    steps = len(rec[0])
    opt = m.opt
    base = (opt.disableflags, opt.enableflags, opt.solver, opt.tolerance)
    setters = {
        "base": lambda: None,
        "sensor": lambda: setattr(opt, "disableflags", opt.disableflags & ~int(DB.mjDSBL_SENSOR)),
        "nosensor": lambda: setattr(opt, "disableflags", opt.disableflags | int(DB.mjDSBL_SENSOR)),
        "noisland": lambda: setattr(opt, "disableflags", opt.disableflags | int(DB.mjDSBL_ISLAND)),
        "nomid": lambda: setattr(opt, "disableflags", opt.disableflags | int(DB.mjDSBL_MIDPHASE)),
        "sleep": lambda: setattr(opt, "enableflags", opt.enableflags | int(EB.mjENBL_SLEEP)),
        "cg": lambda: setattr(opt, "solver", int(mujoco.mjtSolver.mjSOL_CG)),
        "pgs": lambda: setattr(opt, "solver", int(mujoco.mjtSolver.mjSOL_PGS)),
        "tol6": lambda: setattr(opt, "tolerance", 1e-6),
    }
    variants = a.variants.split(",")
    for v in variants:
        for part in v.split("+"):
            if part not in setters:
                raise SystemExit(f"error: unknown variant '{part}' (choose from {', '.join(setters)})")
    bidx = np.ascontiguousarray(plant._base, dtype=np.int64)
    args = (m._address, d._address, plant.n_substeps, d.ctrl, d.xfrc_applied, bidx)
    replay(*args, rec[0][:0], rec[1][:0], d.solver_niter)  # compile
    times: dict[str, list[float]] = {v: [] for v in variants}
    final: dict[str, tuple[np.ndarray, int]] = {}
    load0 = os.getloadavg()[0]
    for _ in range(a.rounds):
        for v in variants:
            opt.disableflags, opt.enableflags, opt.solver, opt.tolerance = base
            for part in v.split("+"):
                setters[part]()
            plant.reset()
            t0 = time.process_time()
            iters = replay(*args, rec[0], rec[1], d.solver_niter)
            times[v].append(time.process_time() - t0)
            final[v] = (d.qpos.copy(), iters)
    opt.disableflags, opt.enableflags, opt.solver, opt.tolerance = base
    print(
        f"{a.preset}: n = {plant.n}, {steps} control steps x {plant.n_substeps} physics steps, ncon {d.ncon}, "
        f"nefc {d.nefc}, load {load0:.1f} -> {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores"
    )
    print("| variant | CPU s (range) | µs per robot-step | speed vs first | solver iterations/step | max abs(Δqpos) |")
    print("|---|---|---|---|---|---|")
    first = min(times[variants[0]])
    for v in variants:
        t = times[v]
        dq = float(np.abs(final[v][0] - final[variants[0]][0]).max())
        print(
            f"| {v} | {min(t):.3f}–{max(t):.3f} | {min(t) / (steps * plant.n) * 1e6:.2f} | {first / min(t):.2f} "
            f"| {final[v][1] / (steps * plant.n_substeps):.2f} | {dq:.1e} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
