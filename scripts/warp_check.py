#!/usr/bin/env python3
"""Per-world agreement of the MuJoCo Warp batch engine with the CPU engine (issue 13's criterion).

Runs ``--worlds`` seeds of a scenario (``--scenario``: a preset or a TOML file; default the paper's)
in MuJoCo (jittered initial poses) on the Warp
device and with :func:`bioform_mj.run.simulate.simulate`, measures each world's own float32 spread
(:func:`bioform_mj.batch.agreement.float32_spread`: the CPU engine perturbed by rounding-sized
noise) and judges every follower (:func:`~bioform_mj.batch.agreement.judge`): within the issue's
tolerance, within the world's own spread (ill-conditioned world), or failed. Prints one line
per follower and a summary; ``--json`` writes the rows. Exit 1 if a follower fails.

    python scripts/warp_check.py --device cuda --worlds 8 --duration 2 --json $OUT/check.json
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--scenario", default="paper", help="a preset name or a scenario TOML file")
    ap.add_argument("--worlds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--realisations", type=int, default=8, help="perturbed CPU runs per world")
    ap.add_argument("--eps", type=float, default=None, help="relative noise per control period (default 1e-6)")
    ap.add_argument("--set", action="append", default=[], help="extra scenario overrides KEY=VALUE")
    ap.add_argument("--json")
    a = ap.parse_args()
    from bioform_mj.batch.agreement import DEFAULT_EPS, METRICS, TOLERANCES, differences, float32_spread, judge
    from bioform_mj.batch.runner import run_batch
    from bioform_mj.scenario.loader import load

    eps = DEFAULT_EPS if a.eps is None else a.eps
    scs = [
        load(
            a.scenario,
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
    dev = run_batch(scs, a.device)
    rows = []
    for w, sc in enumerate(scs):
        ref, spread = float32_spread(sc, a.realisations, eps, seed=w)
        diff = differences(ref, dev[w])
        for f, (d, s, v) in enumerate(zip(diff, spread, judge(diff, spread))):
            rows.append({"world": w, "follower": f + 1, **d, "spread": s, "verdict": {k: v[k] for k in METRICS}})
            print(
                f"world {w} follower {f + 1}: "
                + "  ".join(f"{k} {d[k]:.3g} (spread {s[k]:.3g}: {v[k]})" for k in METRICS)
            )
    for k in METRICS:
        v = np.array([r[k] for r in rows])
        n_sp = sum(r["verdict"][k] == "spread" for r in rows)
        n_f = sum(r["verdict"][k] == "fail" for r in rows)
        print(
            f"{k}: max {v.max():.3g}, median {np.median(v):.3g}, tolerance {TOLERANCES[k]:g}: "
            f"{len(v) - n_sp - n_f}/{len(v)} within it, {n_sp} within their world's float32 spread, {n_f} failed"
        )
    if a.json:
        meta = {"device": a.device, "scenario": a.scenario, "worlds": a.worlds, "duration": a.duration}
        meta.update(realisations=a.realisations, eps=eps, tolerances=TOLERANCES, rows=rows)
        with open(a.json, "w") as fh:
            json.dump(meta, fh, indent=1)
    return 1 if any(r["verdict"][k] == "fail" for r in rows for k in METRICS) else 0


if __name__ == "__main__":
    raise SystemExit(main())
