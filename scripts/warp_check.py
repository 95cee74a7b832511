#!/usr/bin/env python3
"""Per-world agreement of the MuJoCo Warp batch engine with the CPU engine (issue 13's criterion).

Runs ``--worlds`` seeds of the paper scenario in MuJoCo (jittered initial poses) on the Warp
device and with :func:`bioform_mj.sim.simulate`, and prints per world and follower the final
formation error difference (m), ``ĉ`` relative difference and total velocity error relative
difference; ``--json`` writes them.

    python scripts/warp_check.py --device cuda --worlds 8 --duration 2 --json $OUT/check.json
"""

from __future__ import annotations

import argparse
import json

import numpy as np

#: issue 13's per-world tolerances
TARGETS = {"d_final_formation_m": 1e-3, "c_hat_rel": 5e-3, "vel_err_rel": 1e-2}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--worlds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--set", action="append", default=[], help="extra scenario overrides KEY=VALUE")
    ap.add_argument("--json")
    a = ap.parse_args()
    from bioform_mj.batch.control import run_batch
    from bioform_mj.scenario import load
    from bioform_mj.sim import simulate

    scs = [
        load(
            "paper",
            overrides=[
                "plant.kind=mujoco",
                f"sim.duration={a.duration}",
                "formation.init_jitter=0.05",
                f"sim.seed={s}",
                *a.set,
            ],
        )
        for s in range(a.worlds)
    ]
    gpu = run_batch(scs, a.device)
    rows = []
    for w, sc in enumerate(scs):
        cpu = simulate(sc).summary
        for fc, fg in zip(cpu["followers"], gpu[w]["followers"]):
            rows.append(
                {
                    "world": w,
                    "follower": fc["id"],
                    "d_final_formation_m": abs(fc["final_formation_error_m"] - fg["final_formation_error_m"]),
                    "c_hat_rel": float(np.max(np.abs(np.array(fg["c_hat"]) / np.array(fc["c_hat"]) - 1))),
                    "vel_err_rel": abs(fg["total_velocity_error"] / fc["total_velocity_error"] - 1),
                }
            )
    for key in ("d_final_formation_m", "c_hat_rel", "vel_err_rel"):
        v = np.array([r[key] for r in rows])
        print(
            f"{key}: max {v.max():.3g}, median {np.median(v):.3g}, "
            f"worlds×followers over target: {int((v > TARGETS[key]).sum())}/{len(v)}"
        )
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"device": a.device, "worlds": a.worlds, "duration": a.duration, "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
