"""``bioform bench``: our closed loop against bare ``mujoco.mj_step`` on the same scene, in one process.

For each team size the benchmark builds the very scene a run uses (same robots, same
physics step and substeps), then times

* **bare**: ``mj_step`` alone on that scene, replaying the closed loop's recorded wheel
  torques and chassis forces (a compiled loop calling libmujoco, no Python per step), so
  that the physics does the same work;
* **closed loop**: :func:`bioform_mj.run.simulate.simulate` on that scenario, loop time only
  (``summary.wall_time_s``: control, plant, metrics, logging, divergence guard);
* **ideal**: the same scenario on the ideal plant.

Reported: steps per second, the ratio bare time / loop time (1.0 = the loop costs
nothing beyond physics), microseconds per robot-step, and the real-time factor
(simulated s per wall s). Absolute times drift on shared machines; the ratio is
measured in one process, bare and closed loop alternating (``reps`` each), and is the number to
compare. Each time is taken twice: wall (``time.perf_counter``) and CPU time of this process
(``time.process_time``: what the work costs one core, whatever else the machine runs); ``*_cpu``
columns and ``load_avg`` (``os.getloadavg`` at the start and end of each case) in the JSON say which
to believe on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.outputs.files import write_json
from bioform_mj.run.looptime import loop_times as _loop
from bioform_mj.run.looptime import stop_if_interrupted

#: team size → (preset, default simulated seconds)
CASES: dict[int, tuple[str, float]] = {
    3: ("paper", 5.0),
    16: ("large16", 5.0),
    64: ("large64", 4.0),
    256: ("large256", 2.0),
    1024: ("large1024", 1.0),
}


def _bare(sc: Any, reps: int, plant: Any, between: Any = None) -> dict[str, float]:
    """Bare ``mj_step`` replaying the closed loop's own inputs: best seconds of ``reps``, and the
    solver's iterations per physics step, also under constant torques for comparison. ``between()``,
    if given, runs after each replay (the closed loop's turn: interleaved, both see the machine's load alike).

    The closed loop runs once recording every step's ``ctrl`` and chassis forces; then a
    compiled loop replays them into ``mj_step`` on the same scene from the same initial
    state. Constant torques (0.1 of the limit, no disturbance) are not a fair baseline: the
    contact solver iterates less when the torques do not change (``solver_iters_*`` in the
    JSON), so physics itself costs more in closed loop.
    """
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.plants.mujoco.kernels import replay as mujoco_replay
    from bioform_mj.run.simulate import simulate

    m, d = plant.model, plant.data
    steps = int(round(sc.sim.duration / sc.sim.control_dt))
    rec = (np.zeros((steps, m.nu)), np.zeros((steps, plant.n, 6)))
    with quiet_outcomes():  # the run that records the inputs to replay: timed, not reported
        stop_if_interrupted(simulate(sc, record_inputs=rec, plant=plant))
    replay = mujoco_replay
    base = np.ascontiguousarray(plant._base, dtype=np.int64)
    args = (m._address, d._address, plant.n_substeps, d.ctrl, d.xfrc_applied, base)
    replay(*args, rec[0][:0], rec[1][:0], d.solver_niter)  # compile
    best, best_cpu, iters = float("inf"), float("inf"), 0
    for _ in range(reps):
        plant.reset()
        t0, c0_ = time.perf_counter(), time.process_time()
        iters = replay(*args, rec[0], rec[1], d.solver_niter)
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0_)
        if between is not None:
            between()
    c0 = np.zeros(m.nu)
    c0[plant._ctrl] = 0.1 * plant.tau_max[:, None]
    const = (np.tile(c0, (steps, 1)), np.zeros_like(rec[1]))
    plant.reset()
    t0 = time.perf_counter()
    c_iters = replay(*args, const[0], const[1], d.solver_niter)
    c_time = time.perf_counter() - t0
    physics_steps = steps * plant.n_substeps
    return {
        "bare_s": best,
        "bare_cpu_s": best_cpu,
        "solver_iters_per_step": iters / physics_steps,
        "constant_torque_bare_s": c_time,
        "constant_torque_solver_iters_per_step": c_iters / physics_steps,
    }


def bench_case(n: int, duration: float | None = None, reps: int = 2, numpy_too: bool = False) -> dict[str, Any]:
    """Measure one team size; returns one row of the table."""
    from bioform_mj.scenario.loader import load

    preset, dur = CASES[n]
    dur = duration if duration is not None else dur
    sc = load(preset, overrides=[f"sim.duration={dur}"], plant="mujoco")
    steps = int(round(dur / sc.sim.control_dt))
    n_sub = int(round(sc.sim.control_dt / sc.sim.physics_dt))
    from bioform_mj.run.simulate import make_plant

    load0 = os.getloadavg()[0]
    # compile the kernels (on the smallest grid preset: they do not depend on n, a 1024-robot scene takes minutes)
    _loop(load(CASES[16][0] if n >= 16 else preset, overrides=["sim.duration=0.05"], plant="mujoco"), 1)
    t0 = time.perf_counter()
    plant = make_plant(sc)  # one scene per case: recorded, replayed bare and run in closed loop (reset each time)
    build_s = time.perf_counter() - t0
    loops: list[tuple[float, float, dict]] = []
    bare_d = _bare(sc, reps, plant, between=lambda: loops.append(_loop(sc, 1, plant=plant)))
    bare, bare_cpu = bare_d["bare_s"], bare_d["bare_cpu_s"]
    loop, loop_cpu, summ = min(t[0] for t in loops), min(t[1] for t in loops), loops[-1][2]
    ideal, ideal_cpu, _ = _loop(load(preset, overrides=[f"sim.duration={dur}"], plant="ideal"), reps)
    row: dict[str, Any] = {
        "n": n,
        "preset": preset,
        "sim_s": dur,
        "control_dt_s": sc.sim.control_dt,
        "physics_dt_s": sc.sim.physics_dt,
        "substeps": n_sub,
        "control_steps": steps,
        **bare_d,
        "loop_s": loop,
        "loop_cpu_s": loop_cpu,
        "ratio": bare / loop,
        "ratio_cpu": bare_cpu / loop_cpu,
        "bare_steps_per_s": steps / bare,
        "loop_steps_per_s": steps / loop,
        "us_per_robot_step": loop / (steps * n) * 1e6,
        "bare_us_per_robot_step": bare / (steps * n) * 1e6,
        "us_per_robot_step_cpu": loop_cpu / (steps * n) * 1e6,
        "realtime_factor": dur / loop,
        "realtime_factor_cpu": dur / loop_cpu,
        "bare_realtime_factor": dur / bare,
        "bare_realtime_factor_cpu": dur / bare_cpu,
        "ideal_s": ideal,
        "ideal_us_per_robot_step": ideal / (steps * n) * 1e6,
        "ideal_cpu_s": ideal_cpu,
        "ideal_realtime_factor": dur / ideal,
        "load_avg": [load0, os.getloadavg()[0]],
        "scene_build_s": build_s,
        "max_final_formation_error_m": max(f["final_formation_error_m"] for f in summ["followers"]),
    }
    if numpy_too:
        t_np, _cpu, _ = _loop(sc, 1, engine="stepwise", plant=plant)
        row["stepwise_loop_s"] = t_np
        row["stepwise_ratio"] = bare / t_np
    return row


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a Markdown table."""
    head = (
        "| n | physics dt | bare steps/s | loop steps/s | ratio (bare/loop) | ratio, CPU time | µs per robot-step "
        "(CPU) | real-time factor (CPU) | ideal µs per robot-step | load |\n|---|---|---|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['n']} | {r['physics_dt_s'] * 1e3:g} ms | {r['bare_steps_per_s']:.0f} | {r['loop_steps_per_s']:.0f} "
        f"| **{r['ratio']:.2f}** | **{r['ratio_cpu']:.2f}** | {r['us_per_robot_step']:.2f} "
        f"({r['us_per_robot_step_cpu']:.2f}) | {r['realtime_factor']:.2f} ({r['realtime_factor_cpu']:.2f}) "
        f"| {r['ideal_us_per_robot_step']:.2f} | {r['load_avg'][0]:.1f} |\n"
        for r in rows
    )
    return head + body


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark; print the table; write JSON (default ``runs/bench.json``)."""
    ap = argparse.ArgumentParser(prog="bioform bench", description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sizes", default="3,16,64,256", help=f"comma-separated team sizes (of {', '.join(map(str, CASES))})"
    )
    ap.add_argument("--duration", type=float, help="simulated seconds per case (default: per size)")
    ap.add_argument("--reps", type=int, default=2, help="repetitions; the best time counts (default 2)")
    ap.add_argument(
        "--numpy",
        "--stepwise",
        dest="numpy",
        action="store_true",
        help="also time the step-by-step engine (one Python call per control step)",
    )
    ap.add_argument("--json", type=Path, default=Path("runs/bench.json"), help="output JSON")
    return run(ap.parse_args(argv))


def run(args: argparse.Namespace) -> int:
    from bioform_mj.core.errors import InputError

    if getattr(args, "backend", "cpu") == "warp":
        return _run_warp(args)
    if getattr(args, "device", None) is not None:
        raise InputError("--device applies to --backend warp only")

    try:
        sizes = [int(s) for s in str(args.sizes).split(",") if s.strip()]
    except ValueError:
        raise InputError(f"--sizes: expected comma-separated integers, got '{args.sizes}'") from None
    bad = [s for s in sizes if s not in CASES]
    if bad or not sizes:
        raise InputError(f"--sizes: {bad or sizes} not available (choose from {', '.join(map(str, CASES))})")
    if args.reps < 1:
        raise InputError(f"--reps must be >= 1, got {args.reps}")
    if args.duration is not None and not (args.duration > 0 and args.duration <= 3600):
        raise InputError(f"--duration must be in (0, 3600] s, got {args.duration}")
    from bioform_mj.outputs.files import check_out_file

    json_path = check_out_file(args.json, "--json")  # before the work: its folder is made when written
    rows = []
    for n in sizes:
        rows.append(bench_case(n, args.duration, args.reps, numpy_too=getattr(args, "numpy", False)))
        r = rows[-1]
        print(
            f"n={n:4d}: ratio {r['ratio']:.2f} (CPU time {r['ratio_cpu']:.2f}), {r['us_per_robot_step']:.2f} "
            f"µs/robot-step (CPU {r['us_per_robot_step_cpu']:.2f}), real-time factor {r['realtime_factor']:.2f} "
            f"(CPU {r['realtime_factor_cpu']:.2f}), load {r['load_avg'][0]:.1f}; solver iterations per physics step "
            f"{r['solver_iters_per_step']:.2f} (constant torques: {r['constant_torque_solver_iters_per_step']:.2f})",
            flush=True,
        )
    import mujoco

    from bioform_mj._version import __version__

    out = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "mujoco": mujoco.__version__,
            "bioform_mj": __version__,
            "numpy": np.__version__,
        },
        "rows": rows,
    }
    if len(rows) > 1 and 16 in sizes and 256 in sizes:
        r16 = next(r for r in rows if r["n"] == 16)
        r256 = next(r for r in rows if r["n"] == 256)
        out["cost_per_robot_step_256_over_16"] = r256["us_per_robot_step"] / r16["us_per_robot_step"]
    print()
    print(format_table(rows))
    if "cost_per_robot_step_256_over_16" in out:
        print(f"cost per robot-step, n=256 / n=16: {out['cost_per_robot_step_256_over_16']:.2f}")
    write_json(json_path, out)
    print(f"wrote {args.json}")
    return 0


def _run_warp(args: argparse.Namespace) -> int:
    """``--backend warp``: :mod:`bioform_mj.batch.bench` (closed loop vs physics alone, and this CPU engine)."""
    from bioform_mj.batch.backend import require_warp, resolve_device

    require_warp()  # exit 2 with the install line, before any work
    from bioform_mj.batch.bench import parse_worlds
    from bioform_mj.batch.bench import run as warp_run
    from bioform_mj.outputs.files import check_out_file

    worlds = parse_worlds(args.worlds)
    if args.duration is not None and not (args.duration > 0 and args.duration <= 3600):
        from bioform_mj.core.errors import InputError

        raise InputError(f"--duration must be in (0, 3600] s, got {args.duration}")
    device = resolve_device(args.device)
    json_path = check_out_file(args.json, "--json")
    warp_run(
        worlds,
        device,
        duration=args.duration if args.duration is not None else 0.5,
        json_path=json_path,
        echo=lambda s: print(s, flush=True),
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
