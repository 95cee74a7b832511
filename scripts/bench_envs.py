"""Environment steps/s of bioform_mj.envs against ``bioform run``'s compiled loop (design §20).

Both on the same scenario (default: the paper's, MuJoCo plant, control at 100 Hz, physics at
1 kHz: 10 substeps per control step), measured in one process, alternating, ``--repeat`` times;
prints the median of each and their ratio (issue 22 asks for >= 0.5 at 10 ms, issue 30 at the
preset's own 1 ms). ``--policy controller`` (issue 30's measure): the paper's controller through
the environment (``action = "torque"``, :class:`ControllerPolicy`); ``constant``: a constant
velocity action (the environment alone). Run:

    .venv/bin/python scripts/bench_envs.py [--scenario paper] [--duration 20] [--control-dt 0.01] [--policy controller]

``--matrix``: the environment against the compiled loop for both plants at 1 ms and 10 ms, one process
(issue 30's table in docs/envs.md). ``--vector W --threads T``: the CPU-vectorised environment
(``envs.vector_env``, W worlds, velocity actions, its torque law and observations) against
``mujoco.rollout`` stepping the same W worlds (the models the environment steps with: its shared one)
over the same physics steps with T threads, open loop (the physics alone: issue 30 asks for >= 0.7);
also against ``mujoco.rollout`` of the worlds' own W models, and of the same worlds called once per
period (the state carried: what any closed loop must do); and the environment with ``warm=False`` (every
world stepping its own ``MjData``, the layout before issue 30's warm data), all alternating in one process.
With one thread the ratios of CPU time (``time.thread_time``: what the other processes of a loaded machine
take is left out) are printed too.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bioform_mj.envs import ControllerPolicy, parallel_env
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--control-dt", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--policy", choices=("constant", "controller"), default="constant")
    ap.add_argument("--worlds", type=int, default=0, help="also the batched environment with this many worlds")
    ap.add_argument("--device", default="cpu", help="Warp device of the batched environment")
    ap.add_argument("--matrix", action="store_true", help="both plants at 1 ms and 10 ms control periods")
    ap.add_argument("--vector", type=int, default=0, help="the CPU-vectorised environment with this many worlds")
    ap.add_argument("--threads", type=int, default=1, help="threads of --vector and of mujoco.rollout")
    ap.add_argument("--pin", action="store_true", help="--vector: each thread pinned to a CPU (vector_env's pin)")
    a = ap.parse_args()
    if a.vector:
        vector(a)
        return
    cases = [(p, dt) for p in ("mujoco", "ideal") for dt in (0.001, 0.01)] if a.matrix else [(a.plant, a.control_dt)]
    for plant, dt in cases:
        e, r, n = single(a.scenario, plant, dt, a.duration, a.repeat, a.policy)
        print(
            f"scenario {a.scenario}, plant {plant}, n = {n}, control_dt {dt:g} s, {a.duration:g} s, policy {a.policy}: "
            f"environment {e:,.0f} steps/s ({e * n:,.0f} agent-steps/s); bioform run (compiled) {r:,.0f} steps/s; "
            f"ratio {e / r:.2f}"
        )
    if a.worlds:
        ov = [f"sim.duration={a.duration}", f"sim.control_dt={a.control_dt}", f"plant.kind={a.plant}"]
        batch(a, ov, load(a.scenario, ov))


def single(scenario: str, plant: str, control_dt: float, duration: float, repeat: int, policy: str):
    """Medians of ``repeat`` alternating episodes: environment steps/s, ``simulate`` steps/s, followers."""
    ov = [f"sim.duration={duration}", f"sim.control_dt={control_dt}", f"plant.kind={plant}"]
    env = parallel_env(scenario, action="torque" if policy == "controller" else "velocity", overrides=ov)
    sc = load(scenario, ov)
    simulate(sc)  # compile / load kernels outside the timing
    env_rates, run_rates = [], []
    for _ in range(repeat + 1):
        env.reset(seed=0)
        act = {ag: np.array([0.2, 0.1]) for ag in env.agents}
        pol = None
        if policy == "controller":
            pol = ControllerPolicy(env)
            pol.reset()
        t0 = time.perf_counter()
        steps = 0
        while env.agents:
            env.step(act if pol is None else pol())
            steps += 1
        env_rates.append(steps / (time.perf_counter() - t0))
        r = simulate(sc)
        run_rates.append(r.summary["steps"] / r.summary["wall_time_s"])
    # the first round loads the fast period's kernels: left out
    return statistics.median(env_rates[1:]), statistics.median(run_rates[1:]), sc.n


def vector(a) -> None:
    """The CPU-vectorised environment against ``mujoco.rollout`` of the same worlds, steps and threads."""
    import mujoco
    from mujoco import rollout

    from bioform_mj.envs import vector_env

    ov = [f"sim.duration={a.duration}", f"sim.control_dt={a.control_dt}", "plant.kind=mujoco"]
    ve = vector_env(a.scenario, a.vector, a.threads, overrides=ov, pin=a.pin)
    cold = vector_env(a.scenario, a.vector, a.threads, overrides=ov, warm=False, pin=a.pin)
    W, n, N = ve.nworld, ve.n, ve.N
    act = np.tile(np.array([0.2, 0.1]), (W, n, 1))
    ve.reset(seed=0)  # builds every world's plant
    own = [e._plant.model for e in ve.envs]
    models = [ve._model if ve.shared[w] else own[w] for w in range(W)]  # what the environment steps with
    n_sub = int(ve.envs[0]._plant.n_substeps)
    datas = [mujoco.MjData(models[0]) for _ in range(a.threads)]
    pool = a.threads > 1
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    cspec = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED
    nc = mujoco.mj_stateSize(models[0], cspec)
    # the environment's inputs of every period, recorded in an untimed episode (the same seed and actions
    # give the same episode), then replayed by mujoco.rollout: the same physics steps, open loop
    ve.reset(seed=0)
    x0 = np.empty((W, mujoco.mj_stateSize(models[0], spec)))
    for w, e in enumerate(ve.envs):
        mujoco.mj_getState(e._plant.model, e._plant.data, x0[w], spec)
    if pool:  # rollout's threads started before --pin pins this thread (a new thread takes its creator's CPUs)
        rollout.rollout(models, datas, x0, nstep=1, persistent_pool=True)
    ctrl = np.empty((W, N * n_sub, nc))
    for k in range(N):
        ve.step(act)
        for w in range(W):
            ctrl[w, k * n_sub] = ve.world_state(w, cspec)
        ctrl[:, k * n_sub : (k + 1) * n_sub] = ctrl[:, k * n_sub : k * n_sub + 1]
    state = np.empty((W, n_sub, x0.shape[1]))
    # mujoco.rollout's outputs (every step's state and sensors), allocated and touched once, outside the timing:
    # left to rollout, each call allocated and page-faulted 53 MB (1 ms, 4 s) to 133 MB (10 ms, 10 s) of fresh
    # memory, which its time then counted (medians of 5 alternated calls, load ~5: 1.10x the time of a call given
    # its outputs at 1 ms on 1 thread, 1.42x at 10 ms on 2 threads; issue 30)
    traj = np.full((W, N * n_sub, x0.shape[1]), 0.0)
    sens = np.full((W, N * n_sub, models[0].nsensordata), 0.0)

    def per_period() -> None:  # mujoco.rollout called once per period, the state carried (a closed loop's visits)
        x = x0.copy()
        for k in range(N):
            rollout.rollout(models, datas, x, ctrl[:, k * n_sub : (k + 1) * n_sub], control_spec=cspec, nstep=n_sub,
                            persistent_pool=pool, state=state)  # fmt: skip
            x[:] = state[:, -1]

    rates: dict[str, list[float]] = {"env": [], "cold": [], "rollout": [], "own": [], "period": []}
    cpu: dict[str, list[float]] = {k: [] for k in rates}  # thread CPU s of each (one thread: all the work)

    def timed(key: str, fn) -> None:
        t0, c0 = time.perf_counter(), time.thread_time()
        fn()
        rates[key].append(N * W / (time.perf_counter() - t0))
        cpu[key].append(time.thread_time() - c0)

    def episode(env) -> None:
        for _k in range(N):
            env.step(act)

    for _ in range(a.repeat + 1):
        for key, env in (("env", ve), ("cold", cold)):
            env.reset(seed=0)
            timed(key, lambda env=env: episode(env))
        for key, ms in (("rollout", models), ("own", own)):
            timed(key, lambda ms=ms: rollout.rollout(ms, datas, x0, ctrl, control_spec=cspec, nstep=N * n_sub,
                                                     persistent_pool=pool, state=traj, sensordata=sens))  # fmt: skip
        timed("period", per_period)
    e, c, r, o, p = (statistics.median(rates[k][1:]) for k in ("env", "cold", "rollout", "own", "period"))
    us = {k: 1e6 * statistics.median(v[1:]) / (N * W) for k, v in cpu.items()}
    print(
        f"CPU-vectorised environment, {W} worlds x {n} followers ({int(ve.shared.sum())} on the shared model), "
        f"{a.threads} thread(s){' pinned' if a.pin else ''}, "
        f"control_dt {a.control_dt:g} s ({n_sub} physics steps a period), {N} periods: "
        f"{e:,.0f} world-steps/s ({e * n:,.0f} agent-steps/s); mujoco.rollout of the same worlds and physics "
        f"steps, open loop: {r:,.0f} world-steps/s; ratio {e / r:.2f} (rollout of the worlds' own models: "
        f"{o:,.0f}, ratio {e / o:.2f}; rollout called once per period: {p:,.0f}, ratio {e / p:.2f}); "
        f"warm=False (each world its own MjData): {c:,.0f} world-steps/s, ratio {c / r:.2f} (warm/cold {e / c:.2f})"
    )
    if a.threads == 1:
        print(
            f"  thread CPU time a world-step: environment {us['env']:.1f} us, warm=False {us['cold']:.1f} us, "
            f"mujoco.rollout {us['rollout']:.1f} us (own models {us['own']:.1f}, once per period "
            f"{us['period']:.1f}); ratio {us['rollout'] / us['env']:.2f}, warm=False {us['rollout'] / us['cold']:.2f}"
        )
    ve.close()
    cold.close()
    if a.threads > 1:
        rollout.shutdown_persistent_pool()


def batch(a, ov, sc) -> None:
    """The batched environment against the batch engine's own closed loop (``BatchRun.run``), same worlds."""
    import warp as wp

    from bioform_mj.envs import batch_env

    be = batch_env(a.scenario, worlds=a.worlds, device=a.device, overrides=ov)
    act = np.tile(np.array([0.2, 0.1]), (a.worlds, sc.n, 1))
    be.reset()
    be.step(act)  # kernels loaded
    env_rates, run_rates = [], []
    for _ in range(a.repeat):
        be.reset()
        wp.synchronize_device(be.run.device)
        t0 = time.perf_counter()
        for _k in range(be.N):
            be.step(act)
        wp.synchronize_device(be.run.device)
        env_rates.append(be.N / (time.perf_counter() - t0))
        wall = be.run.run()
        run_rates.append(be.N / wall)
    e, r = statistics.median(env_rates), statistics.median(run_rates)
    agents = a.worlds * sc.n
    print(f"batched environment, {a.worlds} worlds on {a.device}: {e:,.1f} steps/s ({e * agents:,.0f} agent-steps/s)")
    print(f"batch engine closed loop (BatchRun.run): {r:,.1f} steps/s; ratio {e / r:.2f}")


if __name__ == "__main__":
    main()
