"""``bioform bench``: our closed loop against bare ``mujoco.mj_step`` on the same scene, in one process.

For each team size the benchmark builds the very scene a run uses (same robots, same
physics step and substeps), runs the closed loop once recording its inputs, then times

* **bare**: ``mj_step`` alone on that scene, replaying the closed loop's recorded wheel
  torques and chassis forces (a compiled loop calling libmujoco, no Python per step), so
  that the physics does the same work (the JSON's ``replay_max_abs_dqpos``: 0.0 when the
  replay ended in the loop's final state bit for bit);
* **closed loop**: :func:`bioform_mj.run.simulate.simulate` on that scenario, loop time only
  (``summary.wall_time_s``: control, plant, metrics, logging, divergence guard);
* **ideal**: the same scenario on the ideal plant.

Reported: steps per second, the ratio bare time / loop time (1.0 = the loop costs
nothing beyond physics), microseconds per robot-step, and the real-time factor
(simulated s per wall s), all over the steps the run simulates (the large presets' time scale
σ = 2.31 makes ``--duration 2`` a 4.62 s run). Absolute times drift on shared machines; the ratio is
measured in one process on one ``MjModel``/``MjData``, both from ``plant.reset()``, in ``reps`` pairs of
neighbouring runs alternating in both orders (bare, loop | loop, bare | …), and is the median of the
pairs' ratios (docs/findings/performance.md, "Method"). Each time is taken twice: wall
(``time.perf_counter``) and CPU time of this process (``time.process_time``: what the work costs one
core, whatever else the machine runs); ``*_cpu`` columns, each pair's ratio and ``load_avg``
(``os.getloadavg`` at the start and end of each case) in the JSON say which to believe on a shared machine.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import time
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import RobotWarning
from bioform_mj.outputs.files import write_json
from bioform_mj.run.looptime import loop_times as _loop
from bioform_mj.run.looptime import stop_if_interrupted

#: team size → (preset, default simulated seconds): each timed run ≥ ~0.5 s of CPU, so that a pair's ratio is not
#: a few scheduler quanta's luck (paper: 20 s = 20000 steps; 5 s scattered its pairs by ±15 % on a quiet machine)
CASES: dict[int, tuple[str, float]] = {
    3: ("paper", 20.0),
    16: ("large16", 5.0),
    64: ("large64", 4.0),
    256: ("large256", 2.0),
    1024: ("large1024", 1.0),
}


#: most alternated bare/loop pairs ``bioform bench`` runs (each runs the scene twice)
MAX_REPS = 100


def record_run(sc: Any, plant: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One closed loop on ``plant`` recording every control step's ``ctrl`` and chassis forces (untimed):
    ``(ctrl (steps, nu), xfrc (steps, n, 6), final qpos)``; ``steps`` the run's own (``sc.sim.duration``, which
    carries the preset's time scale)."""
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.run.simulate import simulate

    m = plant.model
    steps = int(round(sc.sim.duration / sc.sim.control_dt))
    rec = (np.zeros((steps, m.nu)), np.zeros((steps, plant.n, 6)))
    with quiet_outcomes():  # the run that records the inputs to replay: not reported
        stop_if_interrupted(simulate(sc, record_inputs=rec, plant=plant))
    return rec[0], rec[1], plant.data.qpos.copy()


def replayer(plant: Any, rec_ctrl: np.ndarray, rec_xfrc: np.ndarray):
    """``replay()`` → ``(wall s, CPU s, solver iterations)``: bare ``mj_step`` on ``plant``'s own
    ``MjModel``/``MjData`` from ``plant.reset()`` (the state and the solver's warm start a run starts
    from), fed ``rec_ctrl``/``rec_xfrc`` by a compiled loop (no Python per step). Compiled here."""
    from bioform_mj.plants.mujoco.kernels import replay as mujoco_replay

    m, d = plant.model, plant.data
    base = np.ascontiguousarray(plant._base, dtype=np.int64)
    args = (m._address, d._address, plant.n_substeps, d.ctrl, d.xfrc_applied, base)
    mujoco_replay(*args, rec_ctrl[:0], rec_xfrc[:0], d.solver_niter)  # compile / load

    def replay(ctrl: np.ndarray = rec_ctrl, xfrc: np.ndarray = rec_xfrc) -> tuple[float, float, int]:
        plant.reset()
        t0, c0 = time.perf_counter(), time.process_time()
        iters = mujoco_replay(*args, ctrl, xfrc, d.solver_niter)
        return time.perf_counter() - t0, time.process_time() - c0, int(iters)

    return replay


def _blocks(
    sc: Any, plant: Any, rec_ctrl: np.ndarray, rec_xfrc: np.ndarray, q_loop: np.ndarray, reps: int
) -> np.ndarray:
    """The loop and the bare replay in neighbouring blocks: ``reps`` closed loops on ``plant``; after each of their
    chunks (``simulate``'s progress call) a second plant of the scene replays the chunk's recorded steps bare, so the
    two times of a block are a few ms apart and a drift of the machine's load falls on both (docs/findings/
    performance.md, "The gap at n = 3"). Rows ``(bare CPU s, loop CPU s)`` per block (thread CPU time; the loop's
    includes its Python between chunks), the first chunk of each run left out (it holds the loop's start)."""
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.plants.mujoco.kernels import replay as mujoco_replay
    from bioform_mj.run.simulate import make_plant, simulate

    twin = make_plant(sc)
    m, d = twin.model, twin.data
    args = (m._address, d._address, twin.n_substeps, d.ctrl, d.xfrc_applied, np.ascontiguousarray(twin._base, np.int64))
    rows: list[tuple[float, float]] = []
    for _ in range(reps):
        twin.reset()
        at = {"k": 0, "t": time.thread_time()}

        def progress(k: int, _n: int, at: dict = at) -> None:
            t_loop = time.thread_time() - at["t"]
            if k > at["k"]:
                t0 = time.thread_time()
                mujoco_replay(*args, rec_ctrl[at["k"] : k], rec_xfrc[at["k"] : k], d.solver_niter)
                if at["k"] > 0:
                    rows.append((time.thread_time() - t0, t_loop))
                at["k"] = k
            at["t"] = time.thread_time()

        with quiet_outcomes():
            stop_if_interrupted(simulate(sc, plant=plant, progress=progress))
        if not np.array_equal(d.qpos, q_loop):  # the blocks replayed the loop's physics bit for bit
            raise RuntimeError("bench: the block replay did not end in the loop's state")
    return np.array(rows).reshape(-1, 2)


def _paired(sc: Any, plant: Any, reps: int) -> dict[str, Any]:
    """Bare replay and closed loop on the one ``plant``, ``reps`` pairs, alternating in both orders
    (bare, loop, loop, bare, bare, loop, …: a drift of the machine's load falls on both alike).

    Each pair's ratio is bare / loop of its two neighbouring runs; the benchmark's ratio is the median
    of those (``ratio_pairs`` lists them; ``ratio_middle_half``: their 25th and 75th percentiles), and each time
    the median of its runs (``*_best``: the least).
    Then the same in blocks (:func:`_blocks`): ``ratio_blocks``, the median of the blocks' CPU ratios, scatters far
    less than a whole run's on a loaded machine. Both start from ``plant.reset()`` (same state, the solver's warm
    start zeroed); the replay's final
    ``qpos`` is compared with the recording loop's (``replay_max_abs_dqpos``: 0.0 when the replay did the
    loop's physics bit for bit). Constant torques (0.1 of the limit, no disturbance), once, for comparison:
    the contact solver iterates less when the torques do not change, so that is not a fair baseline.
    """
    rec_ctrl, rec_xfrc, q_loop = record_run(sc, plant)
    replay = replayer(plant, rec_ctrl, rec_xfrc)
    bare: list[tuple[float, float]] = []
    loop: list[tuple[float, float]] = []
    summ: dict = {}
    iters, dq = 0, float("nan")
    for i in range(reps):
        for what in ("bare", "loop") if i % 2 == 0 else ("loop", "bare"):
            if what == "bare":
                w, c, iters = replay()
                bare.append((w, c))
                dq = float(np.abs(plant.data.qpos - q_loop).max())
            else:
                w, c, summ = _loop(sc, 1, plant=plant)
                loop.append((w, c))
    c0 = np.zeros(plant.model.nu)
    c0[plant._ctrl] = 0.1 * plant.tau_max[:, None]
    _w, _c, c_iters = replay(np.tile(c0, (len(rec_ctrl), 1)), np.zeros_like(rec_xfrc))
    c_time = _w
    b, lp = np.array(bare), np.array(loop)
    pairs, pairs_cpu = b[:, 0] / lp[:, 0], b[:, 1] / lp[:, 1]
    blocks = _blocks(sc, plant, rec_ctrl, rec_xfrc, q_loop, reps)
    per_block = blocks[:, 0] / blocks[:, 1]  # none where every run was one chunk or two (a short --duration)
    physics_steps = len(rec_ctrl) * plant.n_substeps
    return {
        "bare_s": float(np.median(b[:, 0])),
        "bare_cpu_s": float(np.median(b[:, 1])),
        "bare_best_s": float(b[:, 0].min()),
        "loop_s": float(np.median(lp[:, 0])),
        "loop_cpu_s": float(np.median(lp[:, 1])),
        "loop_best_s": float(lp[:, 0].min()),
        "ratio": float(np.median(pairs)),
        "ratio_cpu": float(np.median(pairs_cpu)),
        "ratio_pairs": [float(x) for x in pairs],
        "ratio_cpu_pairs": [float(x) for x in pairs_cpu],
        "ratio_middle_half": [float(x) for x in np.percentile(pairs, [25.0, 75.0])],
        "ratio_cpu_middle_half": [float(x) for x in np.percentile(pairs_cpu, [25.0, 75.0])],
        "ratio_blocks": float(np.median(per_block)) if len(per_block) else None,
        "ratio_blocks_middle_half": [float(x) for x in np.percentile(per_block, [25.0, 75.0])]
        if len(per_block)
        else [],
        "blocks": int(len(blocks)),
        "replay_max_abs_dqpos": dq,
        "solver_iters_per_step": iters / physics_steps,
        "constant_torque_bare_s": c_time,
        "constant_torque_solver_iters_per_step": c_iters / physics_steps,
        "summary": summ,
    }


def bench_case(n: int, duration: float | None = None, reps: int = 3, numpy_too: bool = False) -> dict[str, Any]:
    """Measure one team size; returns one row of the table. ``duration``: the scenario's ``sim.duration``
    (s, before the preset's time scale; the row's ``sim_s`` is what was simulated)."""
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    preset, dur = CASES[n]
    dur = duration if duration is not None else dur
    sc = load(preset, overrides=[f"sim.duration={dur}"], plant="mujoco")
    sim_s = float(sc.sim.duration)  # the large presets' time scale (σ = 2.31) lengthens the run
    steps = int(round(sim_s / sc.sim.control_dt))
    n_sub = int(round(sc.sim.control_dt / sc.sim.physics_dt))
    load0 = os.getloadavg()[0]
    # compile the kernels (on the smallest grid preset: they do not depend on n, a 1024-robot scene takes minutes)
    with warnings.catch_warnings():  # a 0.05 s warm-up: what it asks of the robots is not the measured run's
        warnings.simplefilter("ignore", RobotWarning)
        _loop(load(CASES[16][0] if n >= 16 else preset, overrides=["sim.duration=0.05"], plant="mujoco"), 1)
    t0 = time.perf_counter()
    plant = make_plant(sc)  # one scene per case: recorded, replayed bare and run in closed loop (reset each time)
    build_s = time.perf_counter() - t0
    pr = _paired(sc, plant, reps)
    summ = pr.pop("summary")
    bare, bare_cpu, loop, loop_cpu = pr["bare_s"], pr["bare_cpu_s"], pr["loop_s"], pr["loop_cpu_s"]
    ideal, ideal_cpu, _ = _loop(load(preset, overrides=[f"sim.duration={dur}"], plant="ideal"), reps)
    rs = steps * n  # robot-steps of one run
    row: dict[str, Any] = {
        "n": n,
        "preset": preset,
        "sim_s": sim_s,
        "duration_s": dur,
        "time_scale": sim_s / dur,
        "control_dt_s": sc.sim.control_dt,
        "physics_dt_s": sc.sim.physics_dt,
        "substeps": n_sub,
        "control_steps": steps,
        "reps": reps,
        **pr,
        "bare_steps_per_s": steps / bare,
        "loop_steps_per_s": steps / loop,
        "us_per_robot_step": loop / rs * 1e6,
        "bare_us_per_robot_step": bare / rs * 1e6,
        "us_per_robot_step_cpu": loop_cpu / rs * 1e6,
        "bare_us_per_robot_step_cpu": bare_cpu / rs * 1e6,
        "realtime_factor": sim_s / loop,
        "realtime_factor_cpu": sim_s / loop_cpu,
        "bare_realtime_factor": sim_s / bare,
        "bare_realtime_factor_cpu": sim_s / bare_cpu,
        "ideal_s": ideal,
        "ideal_us_per_robot_step": ideal / rs * 1e6,
        "ideal_cpu_s": ideal_cpu,
        "ideal_realtime_factor": sim_s / ideal,
        "load_avg": [load0, os.getloadavg()[0]],
        "scene_build_s": build_s,
        "max_final_formation_error_m": max(f["final_formation_error_m"] for f in summ["followers"]),
    }
    if numpy_too:
        t_np, _cpu, _ = _loop(sc, 1, engine="stepwise", plant=plant)
        row["stepwise_loop_s"] = t_np
        row["stepwise_ratio"] = bare / t_np
    return row


def _middle_half(pairs: Sequence[float]) -> str:
    """The spread of the pairs' ratios: their 25th–75th percentiles, ``"a–b"``."""
    lo, hi = np.percentile(np.asarray(pairs, dtype=float), [25.0, 75.0])
    return f"{lo:.2f}–{hi:.2f}"


def _blocks_text(row: dict[str, Any]) -> str:
    """``ratio_blocks`` and its middle half, or ``n/a`` (no blocks: a run of one or two chunks)."""
    x = row.get("ratio_blocks")
    if x is None:
        return "n/a"
    lo, hi = row["ratio_blocks_middle_half"]
    return f"{x:.3f}, middle half {lo:.2f}–{hi:.2f}, {row['blocks']} blocks"


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
    ap.add_argument(
        "--duration", type=float, help="sim.duration per case, s, before the preset's time scale (default: per size)"
    )
    ap.add_argument(
        "--reps", type=int, default=3, help="alternated bare/loop pairs; the median pair ratio counts (default 3)"
    )
    ap.add_argument(
        "--numpy",
        "--stepwise",
        dest="numpy",
        action="store_true",
        help="also time the step-by-step engine (one Python call per control step)",
    )
    ap.add_argument("--json", type=Path, default=Path("runs/bench.json"), help="output JSON")
    return run(ap.parse_args(argv))


@contextlib.contextmanager
def _each_robot_warning_once() -> Iterator[None]:
    """Show each distinct :class:`RobotWarning` text once while the block runs (a bench case runs one scene
    ``2 reps + 3`` times, and each run warns what the scenario asks of the robots). Done on ``showwarning``:
    the ``"once"`` filter forgets what it showed whenever the filters change, which every run's
    ``quiet_outcomes`` does."""
    seen: set[str] = set()
    with warnings.catch_warnings():
        show = warnings.showwarning

        def showwarning(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
            if issubclass(category, RobotWarning):
                if str(message) in seen:
                    return
                seen.add(str(message))
            show(message, category, filename, lineno, file, line)

        warnings.showwarning = showwarning
        yield


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
    if not 1 <= args.reps <= MAX_REPS:  # --reps 1000000000 ran on with no end said (issue 28)
        raise InputError(f"--reps must be in 1..{MAX_REPS} (each pair runs the scene twice), got {args.reps}")
    if args.duration is not None and not (args.duration > 0 and args.duration <= 3600):
        raise InputError(f"--duration must be in (0, 3600] s, got {args.duration}")
    from bioform_mj.outputs.files import check_out_file

    json_path = check_out_file(args.json, "--json")  # before the work: its folder is made when written
    rows = []
    for n in sizes:
        with _each_robot_warning_once():  # the case runs its scene 2 reps + 3 times
            rows.append(bench_case(n, args.duration, args.reps, numpy_too=getattr(args, "numpy", False)))
        r = rows[-1]
        print(
            f"n={n:4d}: ratio {r['ratio']:.2f} (CPU time {r['ratio_cpu']:.2f}; pairs "
            f"{', '.join(f'{x:.2f}' for x in r['ratio_pairs'])}; middle half {_middle_half(r['ratio_pairs'])}; "
            f"in blocks {_blocks_text(r)}), "
            f"{r['us_per_robot_step']:.2f} "
            f"µs/robot-step (CPU {r['us_per_robot_step_cpu']:.2f}), real-time factor {r['realtime_factor']:.2f} "
            f"(CPU {r['realtime_factor_cpu']:.2f}), load {r['load_avg'][0]:.1f}; solver iterations per physics step "
            f"{r['solver_iters_per_step']:.2f} (constant torques: {r['constant_torque_solver_iters_per_step']:.2f}); "
            f"replay vs loop final qpos {r['replay_max_abs_dqpos']:.1e}",
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
