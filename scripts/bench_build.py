#!/usr/bin/env python3
"""How long building the MuJoCo plant of a large preset takes, per robot, against MuJoCo's own work (issue 28).

For each team size n (the ``large{n}`` presets: n paper robots), in one process after one untimed build of
large16, phases interleaved over ``--reps`` rounds (best of each; CPU seconds of this process,
``time.process_time``, beside wall seconds):

- ``plant``: ``make_plant`` of the preset (robots prepared, scene composed, compiled, the plant's lookups, the
  contact watch and the start-overlap check), as ``bioform run`` builds it;
- ``compile``: MuJoCo's ``MjSpec.compile`` of that very scene alone (the floor under any build of it);
- ``mujoco``: the reference build by MuJoCo alone: a plain ``MjSpec`` with n copies of the prepared robot attached
  one by one (``MjSpec.attach``, as the scene did before the grouped attach) and compiled;
- with ``--one-by-one``: ``make_plant`` with the robots attached one by one (``robots.scene.GROUP_FROM`` raised),
  the build as it was before (n = 1024: minutes).

Prints a table (µs per robot, the ratios plant/compile and plant/mujoco) and optionally writes it as JSON.

    python scripts/bench_build.py [--sizes 64,256,1024] [--reps 2] [--one-by-one] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings


def _timed(fn) -> tuple[float, float, object]:
    """(wall s, CPU s, result) of ``fn()``."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - w0, time.process_time() - c0, out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="64,256,1024", help="team sizes n (presets large{n}; default 64,256,1024)")
    ap.add_argument("--reps", type=int, default=2, help="rounds of each phase (best taken; default 2)")
    ap.add_argument("--one-by-one", action="store_true", help="also build with the robots attached one by one")
    ap.add_argument("--json", default="", help="write the rows to this file")
    a = ap.parse_args(argv)
    try:
        sizes = [int(s) for s in a.sizes.split(",")]
    except ValueError:
        print(f"error: --sizes must be integers separated by commas, got {a.sizes!r}", file=sys.stderr)
        return 2
    if a.reps < 1 or any(n not in (16, 64, 256, 1024) for n in sizes):
        print("error: --sizes from 16, 64, 256, 1024 (the large presets); --reps >= 1", file=sys.stderr)
        return 2
    import mujoco

    from bioform_mj.robots import scene
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.prepare import prepare_robot
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    mujoco.set_mju_user_warning(lambda msg: None)  # the reference's attach conflicts are not the point here
    warnings.simplefilter("ignore")

    def reference(robot_entry, poses) -> tuple[float, float]:
        """(wall s, CPU s) of MuJoCo attaching n copies (made before the clock starts) one by one and compiling."""
        spec = mujoco.MjSpec()
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
        robot = prepare_robot(robot_entry)[0]
        robot.option = spec.option
        copies = [robot.copy() for _ in poses]  # MuJoCo 4 attaches a spec by reference: one spec per robot

        def build() -> object:
            for i, (x, y, th) in enumerate(poses):
                frame = spec.worldbody.add_frame(pos=[x, y, 0.0], quat=scene.yaw_quat(th))
                spec.attach(copies[i], prefix=scene.follower_prefix(i), frame=frame)
            return spec.compile()

        return _timed(build)[:2]

    make_plant(load("large16", plant="mujoco"))  # once untimed: imports, numba's cached kernels, MuJoCo's first compile
    rows = []
    for n in sizes:
        sc = load(f"large{n}", plant="mujoco")
        entry = resolve_robot(sc.plant.robots[0])
        poses = sc.initial_poses()
        best: dict[str, tuple[float, float]] = {}
        for _ in range(a.reps):
            phases = {
                "plant": lambda sc=sc: make_plant(sc),
            }
            if a.one_by_one:
                phases["one_by_one"] = lambda sc=sc: _one_by_one(scene, make_plant, sc)
            w, c = reference(entry, poses)
            best["mujoco"] = min(best.get("mujoco", (w, c)), (w, c), key=lambda t: t[1])
            for name, fn in phases.items():
                w, c, out = _timed(fn)
                if name == "plant":
                    spec = out.spec
                    wc, cc, _ = _timed(spec.compile)
                    best["compile"] = min(best.get("compile", (wc, cc)), (wc, cc), key=lambda t: t[1])
                best[name] = min(best.get(name, (w, c)), (w, c), key=lambda t: t[1])
        row = {"n": n, "load": os.getloadavg()[0]}
        for name, (w, c) in best.items():
            row[f"{name}_wall_s"], row[f"{name}_cpu_s"] = w, c
        rows.append(row)
        per = {k: best[k][1] / n * 1e6 for k in best}
        line = ", ".join(f"{k} {best[k][1]:.2f} s CPU ({per[k]:.0f} µs/robot; wall {best[k][0]:.2f} s)" for k in best)
        print(
            f"n={n:5d}: {line}; plant/compile {best['plant'][1] / best['compile'][1]:.2f}, "
            f"plant/mujoco {best['plant'][1] / best['mujoco'][1]:.2f}, load {row['load']:.1f}",
            flush=True,
        )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


def _one_by_one(scene, make_plant, sc) -> object:
    """``make_plant`` with the robots attached one by one (the build before the grouped attach)."""
    old = scene.GROUP_FROM
    scene.GROUP_FROM = 1 << 30
    try:
        return make_plant(sc)
    finally:
        scene.GROUP_FROM = old


if __name__ == "__main__":
    raise SystemExit(main())
