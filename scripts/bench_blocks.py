#!/usr/bin/env python3
"""The closed loop's cost beyond ``mj_step``, part by part, timed in neighbouring blocks (tight under load).

Two plants of one scene: plant A replays the recording of a closed loop (``jobs.bench.record_run``) bare, plant B runs
``simulate`` in chunks of ``--block`` s (``run.loop.MAX_CHUNK_S``, ``MIN_CHUNK_WALL_S = 0``); before each of B's chunks
A replays the same steps, and the thread CPU time of the two kernel calls (only) is kept: a pair a few ms apart, so
a drift of the machine's load falls on both. Per variant of B's chunk, the median of the blocks' ratios bare / chunk
and of each run's totals. Variants (a copy of ``plants/mujoco/kernels.run_chunk`` with switches, inputs taken from
the recording so that the physics is the loop's bit for bit in every variant; checked at the end of every run):

* ``loop``: the plant's own ``run_chunk``; ``replay``: the bare replay kernel on plant B (the method's control: 1.00);
* ``flat``: the replay's loop in a kernel of its own (flat arguments); ``call``: the same loop in a kernel that takes
  ``run_chunk``'s arguments (nested named tuples) and uses three of them: what the call itself costs;
* ``skeleton``: the copy with everything switched off (the recorded inputs written, ``mj_step``);
* ``+watch``: and the warning check and the contact watch after each physics step;
* ``+observe``: and the pose/velocity read-back, proximity, tilt and slip watches;
* ``+control``: and the control step (its torques computed, the recorded ones applied: the same numbers);
* ``+log``: and metrics, guards and logging (``after_control``): the loop's work.

docs/findings/performance.md ("The gap at n = 3") reads these numbers.

Usage: ``PYTHONPATH=src python scripts/bench_blocks.py [--preset paper] [--duration 10] [--rounds 4] [--block 0.2]``.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

from bioform_mj.control.kernel import control_step
from bioform_mj.core.engine import OK, PLANT_FAILED, after_control, record_odometry
from bioform_mj.core.equations import njit
from bioform_mj.plants.mujoco import plant as mj_plant
from bioform_mj.plants.mujoco.contacts import watch_contacts, watch_proximity
from bioform_mj.plants.mujoco.kernels import (
    _mj_step,
    _warned,
    copy_row,
    delivered_add,
    delivered_feed,
    observe,
    odometry_read,
    replay,
    sense,
    watch_slip,
    watch_tilt,
)
from bioform_mj.run import loop as run_loop

#: variant → switches (watch, observe, control, log); None: the plant's own chunk; "replay": the bare kernel on B
VARIANTS: dict[str, tuple[int, int, int, int] | str | None] = {
    "loop": None,
    "replay": "replay",
    "flat": "flat",
    "call": "call",
    "skeleton": (0, 0, 0, 0),
    "+watch": (1, 0, 0, 0),
    "+observe": (1, 1, 0, 0),
    "+control": (1, 1, 1, 0),
    "+log": (1, 1, 1, 1),
}


@njit
def parts_chunk(lp, k0, k1, n_sub, mp, dp, io, w, c_true, j0, rec_ctrl, rec_xfrc, sd, sen, odo, cl, px, rows, fl):
    """``run_chunk`` with the recorded inputs always applied and its parts switched by ``fl`` (4,)."""
    g, s, comm, N, dt, L_pose, L_vel, pose, vel, met, acc, lg, stride, form, lim, diag = lp
    qpos, qvel, q7, v6, axle, up, ctrl, ctrl_id, ctrl_scale, xfrc, xmat, base = io[:12]
    warn, act_force, to_wheel, feed, feed_on, dacc = io[16:]
    tilt_cos, tip_step, wheel_dof, wheel_sign, radius, half_track, slip_ratio, v_floor, need, slip_run, slip_step = w
    ncon, con, meta, owner, ci, cf, f6, hdt = cl
    gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order = px
    px_every = int(ranges[3])
    f_watch, f_obs, f_ctl, f_log = fl[0], fl[1], fl[2], fl[3]
    j = j0
    for k in range(k0, k1):
        for c in range(ctrl.shape[0]):
            ctrl[c] = rec_ctrl[k, c]
        for i in range(base.shape[0]):
            for c in range(6):
                xfrc[base[i], c] = rec_xfrc[k, i, c]
        for sub in range(n_sub):
            _mj_step(mp, dp)
            if f_watch and _warned(warn):
                return k - k0, j, PLANT_FAILED
            if sen.on:
                sense(sd, sen, odo)
            if feed_on:
                delivered_add(act_force, ctrl_id, to_wheel, dacc)
            if f_watch:
                watch_contacts(mp, dp, ncon, con, meta, owner, ci, cf, f6, hdt, (k * n_sub + sub + 1) * hdt)
        if feed_on:
            delivered_feed(dacc, n_sub, feed, s.tau_body)
        if f_obs:
            observe(qpos, qvel, q7, v6, axle, pose, vel, up)
            if (k + 1) % px_every == 0:
                watch_proximity(mp, dp, gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order, pose, (k + 1) * dt)
            watch_tilt(up, tilt_cos, tip_step, k + 1)
            watch_slip(qvel, wheel_dof, wheel_sign, radius, half_track, vel, slip_ratio, v_floor, need, slip_run,
                       slip_step, k + 1)  # fmt: skip
        if k + 1 < N:
            if f_ctl:
                if sen.on:
                    odometry_read(odo, dt)
                    control_step(g, s, L_pose[k + 1], L_vel[k + 1], odo.mpose, odo.mvel, comm)
                else:
                    control_step(g, s, L_pose[k + 1], L_vel[k + 1], pose, vel, comm)
            if f_log:
                j1, status = after_control(
                    k + 1, N, stride, s, pose, vel, met, acc, lg, j, L_pose, L_vel, dt, c_true, form, lim, diag
                )
                if sen.on and j1 > j:
                    record_odometry(lg, j, odo.mpose, odo.mvel)
                if j1 > j and rows.shape[0] > j:
                    copy_row(rows, j, qpos, qvel, sd)
                j = j1
                if status != OK:
                    return k + 1 - k0, j, status
    return k1 - k0, j, OK


@njit
def flat_chunk(k0, k1, n_sub, mp, dp, ctrl, xfrc, base, rec_ctrl, rec_xfrc):
    """The recorded inputs of steps ``k0 … k1−1`` written as :func:`parts_chunk` writes them, and ``mj_step``."""
    for k in range(k0, k1):
        for c in range(ctrl.shape[0]):
            ctrl[c] = rec_ctrl[k, c]
        for i in range(base.shape[0]):
            for c in range(6):
                xfrc[base[i], c] = rec_xfrc[k, i, c]
        for _ in range(n_sub):
            _mj_step(mp, dp)
    return k1 - k0


@njit
def call_chunk(lp, k0, k1, n_sub, mp, dp, io, w, c_true, j0, rec_ctrl, rec_xfrc, sd, sen, odo, cl, px, rows):
    """:func:`flat_chunk` with ``run_chunk``'s arguments."""
    return flat_chunk(k0, k1, n_sub, mp, dp, io[6], io[9], io[11], rec_ctrl, rec_xfrc), j0, OK


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="paper")
    ap.add_argument("--duration", type=float, default=10.0, help="sim.duration, s (default 10)")
    ap.add_argument("--rounds", type=int, default=4, help="runs per variant, in rotating order (default 4)")
    ap.add_argument("--block", type=float, default=0.2, help="simulated s per block (default 0.2)")
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")  # the presets' demand warnings: not this probe's report
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.jobs.bench import record_run
    from bioform_mj.run.simulate import make_plant, simulate
    from bioform_mj.scenario.loader import load

    sc = load(a.preset, overrides=[f"sim.duration={a.duration}"], plant="mujoco")
    pa, pb = make_plant(sc), make_plant(sc)
    own_chunk = mj_plant.run_chunk
    state: dict = {"v": None, "log": []}
    with quiet_outcomes():
        rc, rx, q_loop = record_run(sc, pb)
        base = np.ascontiguousarray(pa._base, dtype=np.int64)
        ra = (pa.model._address, pa.data._address, pa.n_substeps, pa.data.ctrl, pa.data.xfrc_applied, base)
        rb = (pb.model._address, pb.data._address, pb.n_substeps, pb.data.ctrl, pb.data.xfrc_applied, base)

        def timed(*args):
            k0, k1, v = args[1], args[2], state["v"]
            t0 = time.thread_time()
            replay(*ra, rc[k0:k1], rx[k0:k1], pa.data.solver_niter)
            t1 = time.thread_time()
            if v is None:
                out = own_chunk(*args)
            elif v == "replay":
                replay(*rb, rc[k0:k1], rx[k0:k1], pb.data.solver_niter)
                out = (k1 - k0, args[9], OK)
            elif v == "flat":
                io = args[6]
                out = (flat_chunk(k0, k1, pb.n_substeps, rb[0], rb[1], io[6], io[9], io[11], rc, rx), args[9], OK)
            elif v == "call":
                out = call_chunk(*args[:10], rc, rx, *args[12:])
            else:
                out = parts_chunk(*args[:10], rc, rx, *args[12:], np.array(v, dtype=np.int64))
            t2 = time.thread_time()
            if k1 > k0:
                state["log"].append((t1 - t0, t2 - t1))
            return out

        mj_plant.run_chunk = timed
        saved = run_loop.MAX_CHUNK_S, run_loop.MIN_CHUNK_WALL_S
        run_loop.MAX_CHUNK_S, run_loop.MIN_CHUNK_WALL_S = a.block, 0.0
        res: dict[str, list[np.ndarray]] = {k: [] for k in VARIANTS}
        try:
            names = list(VARIANTS)
            for r in range(a.rounds + 1):  # round 0: compile and warm up, not kept
                if r == 1:
                    print("uptime:", os.popen("uptime").read().strip(), flush=True)
                for name in names[r % len(names) :] + names[: r % len(names)]:
                    state["v"], state["log"] = VARIANTS[name], []
                    pa.reset()
                    simulate(sc, plant=pb)
                    for p in (pa, pb):  # every variant did the loop's physics bit for bit
                        assert float(np.abs(p.data.qpos - q_loop).max()) == 0.0, name
                    if r:
                        res[name].append(np.array(state["log"]))
        finally:
            mj_plant.run_chunk = own_chunk
            run_loop.MAX_CHUNK_S, run_loop.MIN_CHUNK_WALL_S = saved
    print("uptime:", os.popen("uptime").read().strip())
    steps = int(round(sc.sim.duration / sc.sim.control_dt))
    print(f"{a.preset}, n = {sc.n}, {steps} steps, blocks of {a.block:g} s, {a.rounds} runs per variant")
    for name in VARIANTS:
        blocks = np.concatenate(res[name])
        per = blocks[:, 0] / blocks[:, 1]
        tot = [x[:, 0].sum() / x[:, 1].sum() for x in res[name]]
        q25, q50, q75 = np.percentile(per, [25, 50, 75])
        us = np.median([x[:, 1].sum() for x in res[name]]) / (steps * sc.n) * 1e6
        print(
            f"  {name:9s} bare/this: blocks {q50:.3f} (middle half {q25:.3f}-{q75:.3f}, {len(per)} blocks), "
            f"runs {np.median(tot):.3f} [{' '.join(f'{x:.2f}' for x in tot)}]; CPU µs/robot-step {us:.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
