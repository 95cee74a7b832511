"""``bioform bench --backend warp``: the MuJoCo Warp batch engine, closed loop vs physics alone.

For each world count W: W worlds of a scenario on the MuJoCo plant (seeds 0…W−1, jittered
initial poses), ``duration`` s simulated.

* **closed loop**: :meth:`BatchRun.run` (per control step ``n_substeps`` × ``mjw.step`` + the
  control kernel, all on the device; CUDA: ``chunk`` control steps captured as a CUDA graph);
* **physics alone**: the same worlds from the same initial state, the same physics steps,
  fed the closed loop's **replayed** inputs (wheel torques and disturbance forces of every
  control step, recorded on the device by an untimed closed-loop run), captured the same
  way. When the recording does not fit in device memory, **constant** random wheel torques
  (±1.5 N·m) instead; the JSON says which (``physics_inputs``).
* **CPU engine**: ``bioform bench``'s compiled loop (one core, C MuJoCo) on the same
  scenario and machine, as robot-steps/s.

Robot-steps/s = W × robots × control steps / wall seconds, timed warm (kernels loaded and
graphs captured before the timed run).
"""

from __future__ import annotations

import dataclasses
import os
import platform
import sys
import time
from collections.abc import Sequence
from typing import Any

#: share of the free device memory the replay recording may take
RECORD_SHARE = 0.5


def bench_worlds(
    W: int,
    scenario: str = "paper",
    duration: float = 0.5,
    device: str = "cpu",
    chunk: int = 100,
    capture: bool | None = None,
    physics: str = "auto",
) -> dict[str, Any]:
    """One row: closed loop and physics alone of ``W`` worlds. ``physics``: ``replay``,
    ``constant`` or ``auto`` (replay when the recording fits)."""
    import numpy as np
    import warp as wp

    from bioform_mj.batch.backend import free_memory
    from bioform_mj.batch.runner import BatchRun
    from bioform_mj.scenario.loader import load

    t0 = time.perf_counter()
    ov = ["plant.kind=mujoco", f"sim.duration={duration}", "formation.init_jitter=0.05"]
    base = load(scenario, overrides=ov)
    check_worlds(W, base, device)  # before the W scenarios exist: --worlds 1e8 must not reach them
    scs = [dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=s)) for s in range(W)]
    b = BatchRun(scs, device)
    setup = time.perf_counter() - t0
    b.run(chunk=chunk, capture=capture)  # warm-up: loads kernels, captures the graph
    wall = b.run(chunk=chunk, capture=capture)
    summ = b.summaries(wall)
    ndiv = sum(1 for s in summ if s["diverged"])
    N, n = b.N, b.n
    mode = physics
    if mode == "auto":
        mode = "replay" if b.record_bytes() < RECORD_SHARE * free_memory(device) else "constant"
    if mode == "replay":
        b.record()
        b.run_replay(chunk=chunk, capture=capture)  # warm-up
        pwall = b.run_replay(chunk=chunk, capture=capture)
        b.rec_ctrl = b.rec_xfrc = None
    else:
        rng = np.random.default_rng(0)
        ctrl = np.zeros((W, b.mjm.nu), dtype=np.float32)
        ctrl[:, b.plant._ctrl.ravel()] = rng.uniform(-1.5, 1.5, (W, 2 * n))
        b.run_physics(N * b.n_sub, ctrl, chunk=chunk, capture=capture)  # warm-up
        pwall = b.run_physics(N * b.n_sub, ctrl, chunk=chunk, capture=capture)
    rs = W * n * N
    dev = wp.get_device(device)
    row = {
        "worlds": W,
        "robots": n,
        "control_steps": N,
        "physics_steps_per_control_step": b.n_sub,
        "setup_s": setup,
        "closed_loop_s": wall,
        "closed_loop_robot_steps_per_s": rs / wall,
        "physics_inputs": mode,
        "physics_s": pwall,
        "physics_robot_steps_per_s": rs / pwall,
        "closed_over_physics": pwall / wall,
        "diverged_worlds": ndiv,
        "nconmax": b.nconmax,
        "njmax": b.njmax,
        "graph_capture": bool(dev.is_cuda and capture is not False),
    }
    del b
    return row


#: host bytes per world before the batch is on the device: its resolved scenario (a dataclass copy,
#: ~5 kB with tracemalloc for the paper scenario) and its summary, with margin
HOST_BYTES_PER_WORLD = 20e3


def check_worlds(W: int, base: Any, device: str) -> None:
    """InputError (exit 2) with the estimate when ``W`` worlds of scenario ``base`` do not fit on
    ``device`` (:func:`~.backend.world_bytes`) or their scenarios in this machine's memory."""
    from bioform_mj.batch.backend import MEMORY_SHARE, free_memory, world_bytes
    from bioform_mj.core.budget import available_memory, fmt_bytes
    from bioform_mj.core.errors import InputError

    one = world_bytes(base.n)
    free = free_memory(device)
    avail = available_memory()
    host_one = HOST_BYTES_PER_WORLD + (one if device == "cpu" else 0.0)
    fit = int(min(MEMORY_SHARE * free // one, MEMORY_SHARE * avail // host_one))
    if W > fit:
        raise InputError(
            f"--worlds {W}: about {fmt_bytes(W * one)} needed on {device} ({one / 1e3:.0f} kB per world, estimated; "
            f"{fmt_bytes(free)} free) and {fmt_bytes(W * host_one)} of host memory ({fmt_bytes(avail)} available): "
            f"at most {fit} worlds fit"
        )


def cpu_engine(scenario: str = "paper", duration: float = 1.0) -> dict[str, Any]:
    """The CPU engine (compiled loop, C MuJoCo, one core) on the same scenario: robot-steps/s."""
    from bioform_mj.run.looptime import loop_time as _loop
    from bioform_mj.scenario.loader import load

    sc = load(scenario, overrides=["plant.kind=mujoco", f"sim.duration={duration}", "formation.init_jitter=0.05"])
    _loop(load(scenario, overrides=["plant.kind=mujoco", "sim.duration=0.05"]), 1)  # compile / load the kernels
    loop, _ = _loop(sc, 2)
    steps = int(round(sc.sim.duration / sc.sim.control_dt))  # a preset's time scale lengthens the run
    rps = steps * sc.n / loop
    cores = os.cpu_count() or 1
    return {
        "scenario": scenario,
        "sim_s": float(sc.sim.duration),
        "loop_s": loop,
        "robot_steps_per_s_one_core": rps,
        "cores": cores,
        "robot_steps_per_s_all_cores_ideal": rps * cores,
        "us_per_robot_step": 1e6 / rps,
    }


def format_table(rows: Sequence[dict[str, Any]], cpu: dict[str, Any] | None) -> str:
    head = (
        "| worlds | robots | control steps | closed loop robot-steps/s | physics alone robot-steps/s "
        "| physics inputs | closed / physics | diverged worlds |\n|---|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r['worlds']} | {r['robots']} | {r['control_steps']} | {r['closed_loop_robot_steps_per_s']:.4g} "
        f"| {r['physics_robot_steps_per_s']:.4g} | {r['physics_inputs']} | **{r['closed_over_physics']:.2f}** "
        f"| {r['diverged_worlds']} |\n"
        for r in rows
    )
    tail = ""
    if cpu is not None:
        tail = (
            f"\nCPU engine (compiled loop, C MuJoCo), same machine: {cpu['robot_steps_per_s_one_core']:.4g} "
            f"robot-steps/s on one core ({cpu['us_per_robot_step']:.2f} µs per robot-step); "
            f"{cpu['cores']} cores, ideal scaling: {cpu['robot_steps_per_s_all_cores_ideal']:.4g}\n"
        )
    return head + body + tail


def run(
    worlds: Sequence[int],
    device: str | None = None,
    scenario: str = "paper",
    duration: float = 0.5,
    chunk: int = 100,
    capture: bool | None = None,
    physics: str = "auto",
    cpu_too: bool = True,
    cpu_duration: float = 1.0,
    json_path: Any = None,
    echo: Any = print,
) -> dict[str, Any]:
    """All world counts, then the CPU engine; prints the table, writes ``json_path``; returns the document."""
    import mujoco
    import warp as wp

    from bioform_mj._version import __version__
    from bioform_mj.batch.backend import require_warp, resolve_device

    require_warp()
    device = resolve_device(device)
    dev = wp.get_device(device)
    from bioform_mj.scenario.loader import load

    base = load(scenario, overrides=["plant.kind=mujoco", f"sim.duration={duration}"])
    for W in worlds:  # every count checked before the first batch runs
        check_worlds(W, base, device)
    echo(
        f"device {dev} ({dev.name}), scenario {scenario}, {duration:g} s simulated, graph capture "
        f"{'on' if dev.is_cuda and capture is not False else 'off'}"
    )
    rows = []
    for W in worlds:
        r = bench_worlds(W, scenario, duration, device, chunk, capture, physics)
        rows.append(r)
        echo(
            f"W={W}: closed loop {r['closed_loop_robot_steps_per_s']:.4g} robot-steps/s, physics alone "
            f"({r['physics_inputs']} inputs) {r['physics_robot_steps_per_s']:.4g}, ratio "
            f"{r['closed_over_physics']:.2f}, {r['diverged_worlds']} diverged"
        )
    cpu = cpu_engine(scenario, cpu_duration) if cpu_too else None
    out = {
        "device": str(dev),
        "device_name": dev.name,
        "scenario": scenario,
        "duration_s": duration,
        "chunk": chunk,
        "versions": {
            "warp": wp.config.version,
            "mujoco": mujoco.__version__,
            "bioform_mj": __version__,
            "python": platform.python_version(),
        },
        "host": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()},
        "rows": rows,
        "cpu_engine": cpu,
    }
    echo("")
    echo(format_table(rows, cpu))
    if json_path is not None:
        from bioform_mj.outputs.files import write_json

        write_json(json_path, out)
        echo(f"wrote {json_path}")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """``scripts/bench_warp.py``: the same benchmark with its own flags."""
    import argparse

    from bioform_mj.core.errors import InputError

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None, help="Warp device: cpu, cuda, cuda:0 (default: cuda if present)")
    ap.add_argument("--worlds", default="4,16", help="comma-separated world counts (default 4,16)")
    ap.add_argument("--duration", type=float, default=0.1, help="simulated seconds per run (default 0.1)")
    ap.add_argument("--scenario", default="paper", help="scenario name or TOML (default paper)")
    ap.add_argument("--chunk", type=int, default=100, help="control steps per captured CUDA graph (default 100)")
    ap.add_argument("--no-capture", action="store_true", help="no CUDA graph capture (eager launches)")
    ap.add_argument(
        "--physics",
        choices=("auto", "replay", "constant"),
        default="auto",
        help="physics-alone inputs (default auto: replay if the recording fits)",
    )
    ap.add_argument("--no-cpu", action="store_true", help="skip the CPU engine")
    ap.add_argument("--json", default=None, help="write the results as JSON here")
    a = ap.parse_args(argv)
    try:
        worlds = parse_worlds(a.worlds)
        run(
            worlds,
            a.device,
            a.scenario,
            a.duration,
            a.chunk,
            False if a.no_capture else None,
            a.physics,
            cpu_too=not a.no_cpu,
            json_path=a.json,
        )
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


def parse_worlds(text: str) -> list[int]:
    from bioform_mj.core.errors import InputError

    try:
        w = [int(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--worlds: expected comma-separated integers, got '{text}'") from None
    if not w or any(x < 1 for x in w):
        raise InputError(f"--worlds: expected positive integers, got '{text}'")
    return w
