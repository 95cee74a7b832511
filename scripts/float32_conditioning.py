#!/usr/bin/env python3
"""Reproduces the float32 measurements behind the batch engine's agreement criterion (design §11).

Four measurements on the paper scenario in MuJoCo (``--seed`` jittered start, ``--set`` overrides):

``local``   one control period from the same state, MuJoCo Warp (``--device``) against C MuJoCo, every
            100 steps along the CPU engine's closed loop: relative |Δqvel|, |Δqpos| (median, largest).
            (docs/warp_engine.md: qvel median 1.2e-6 … 2.9e-5, qpos 3e-8 … 7e-8 on the floor; on a
            friction patch qvel up to 35.)
``initial`` the CPU engine from a float32-rounded initial state nudged by one unit, ``--realisations``
            times: final formation error spread (≤ 3e-6 m: the loop forgets its start).
``noise``   the CPU engine with ``qpos``/``qvel`` × (1 + ε N(0,1)) after every period
            (``agreement.float32_spread``; ``--eps``, ``--eps-qpos`` for positions alone): per follower
            spread (ε = 1e-6: 2.9–8.0 mm for follower 2; ε = 2⁻²⁴ with 16 realisations, seed 2: 0.98 mm).
``trace``   the batch engine (one world) and the CPU engine step by step: per follower position gap
            (seed 2: 1.6e-6 m at step 400, 4.7e-5 at 450, 7.1e-4 at 550).
``probe``   ``control.physics_probe`` on our robots and on friction patches (the numbers beside
            ``PROBE_TOL``: floor 1.9e-4 … 2.0e-3, patches 0.11 … 7.9).

    python scripts/float32_conditioning.py local --seed 2 [--set faults.friction_patch=[-50,-50,50,50,1.0]]
    python scripts/float32_conditioning.py noise --seed 2 --eps 5.96e-8 --realisations 16 --duration 2
"""

from __future__ import annotations

import argparse

import numpy as np


def _scenario(a):
    from bioform_mj.scenario.loader import load

    ov = ["plant.kind=mujoco", f"sim.duration={a.duration}", "formation.init_jitter=0.05", f"sim.seed={a.seed}"]
    return load("paper", overrides=[*ov, *a.set])


def local(a) -> None:
    import mujoco
    import mujoco_warp as mjw
    import warp as wp

    from bioform_mj.run.simulate import make_plant, simulate

    sc = _scenario(a)
    p = make_plant(sc)
    m, d = p.model, p.data
    N = int(round(sc.sim.duration / sc.sim.control_dt))
    ctrl, xf = np.zeros((N, m.nu)), np.zeros((N, sc.n, 6))
    simulate(sc, record_inputs=(ctrl, xf))  # the closed loop's inputs, replayed below
    p.reset()
    with wp.ScopedDevice(a.device):
        mm = mjw.put_model(m)
        for k in range(N):
            if k % 100 == 50:
                dd = mjw.put_data(m, d, nworld=1, nconmax=64, njmax=256)
                d2 = mujoco.MjData(m)
                mujoco.mj_copyData(d2, m, d)
                d2.ctrl[:] = ctrl[k]
                d2.xfrc_applied[p._base] = xf[k]
                dd.ctrl.assign(ctrl[k][None].astype(np.float32))
                xa = dd.xfrc_applied.numpy()
                xa[0, p._base] = xf[k]
                dd.xfrc_applied.assign(xa)
                for _ in range(p.n_substeps):
                    mujoco.mj_step(m, d2)
                    mjw.step(mm, dd)
                rv = np.abs(dd.qvel.numpy()[0] - d2.qvel) / (np.abs(d2.qvel) + 1e-3)
                rp = np.abs(dd.qpos.numpy()[0] - d2.qpos) / (np.abs(d2.qpos) + 1e-3)
                print(
                    f"step {k}: qvel rel. diff median {np.median(rv):.2e} largest {rv.max():.2e}; "
                    f"qpos median {np.median(rp):.2e} largest {rp.max():.2e}"
                )
            d.ctrl[:] = ctrl[k]
            d.xfrc_applied[p._base] = xf[k]
            for _ in range(p.n_substeps):
                mujoco.mj_step(m, d)


def initial(a) -> None:
    import mujoco  # noqa: F401  (the plant's model)

    from bioform_mj.run.simulate import make_plant, simulate

    sc = _scenario(a)
    base = simulate(sc).summary["followers"]
    rng = np.random.default_rng(0)
    worst = np.zeros(sc.n)
    for _ in range(a.realisations):
        p = make_plant(sc)
        q = p.model.qpos0.astype(np.float32)
        up = rng.random(q.shape) < 0.5
        q = np.where(up, np.nextafter(q, np.float32(np.inf)), np.nextafter(q, np.float32(-np.inf)))
        p.model.qpos0[:] = q.astype(float)  # reset() starts from qpos0
        run = simulate(sc, plant=p).summary["followers"]
        worst = np.maximum(
            worst, [abs(r["final_formation_error_m"] - b["final_formation_error_m"]) for r, b in zip(run, base)]
        )
    for i, w in enumerate(worst):
        print(f"follower {i + 1}: final formation error spread {w:.3g} m (initial state only)")


def noise(a) -> None:
    from bioform_mj.batch import agreement

    sc = _scenario(a)
    if a.eps_qpos is None:
        _, spread = agreement.float32_spread(sc, a.realisations, a.eps)
    else:  # positions and velocities at their own levels
        orig = agreement._perturbed

        def both(plant, eps, rng):
            step = plant.step

            def noisy(u, t):
                step(u, t)
                plant.data.qpos[:] *= 1.0 + a.eps_qpos * rng.standard_normal(plant.data.qpos.shape)
                plant.data.qvel[:] *= 1.0 + eps * rng.standard_normal(plant.data.qvel.shape)

            plant.step = noisy
            return plant

        agreement._perturbed = both
        try:
            _, spread = agreement.float32_spread(sc, a.realisations, a.eps)
        finally:
            agreement._perturbed = orig
    for i, s in enumerate(spread):
        print(f"follower {i + 1}: " + "  ".join(f"{k} {v:.3g}" for k, v in s.items()))


def trace(a) -> None:
    import warp as wp

    from bioform_mj.batch.runner import BatchRun
    from bioform_mj.run.simulate import simulate

    wp.config.quiet = True
    sc = _scenario(a)

    class Obs:
        period = 0.0
        rows: list = []

        def start(self, run):
            pass

        def sample(self, run):
            self.rows.append(run.pose.copy())

        def finish(self, run):
            pass

    o = Obs()
    simulate(sc, [o])
    b = BatchRun([sc], a.device)
    b.reset()
    dev = [b.s.pose.numpy()[0].copy()]
    for _ in range(b.N - 1):
        b._steps(1)
        dev.append(b.s.pose.numpy()[0].copy())
    cpu, dev = np.array(o.rows), np.array(dev)
    m = min(len(cpu), len(dev))
    gap = np.linalg.norm(cpu[:m, :, :2] - dev[:m, :, :2], axis=2)
    for k in range(0, m, 50):
        print(f"step {k}: position gap per follower " + " ".join(f"{x:.2e}" for x in gap[k]))


PROBES = [
    ("paper", ["plant.kind=mujoco"]),
    ("paper", ["plant.kind=mujoco", 'plant.robots=[{model="paper", motor="dc", driver="voltage"}]']),
    ("stretch", []),
    ("tb3", []),
    ("paper", ["plant.kind=mujoco", "faults.friction_patch=[-3.0,-3.0,3.0,3.0,0.5]"]),
    ("paper", ["plant.kind=mujoco", "faults.friction_patch=[-50.0,-50.0,50.0,50.0,1.0]"]),
    ("tb3", ["faults.friction_patch=[-50.0,-50.0,50.0,50.0,1.0]"]),
]


def probe(a) -> None:
    import warp as wp

    from bioform_mj.batch.probe import PROBE_TOL, physics_probe
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    wp.config.quiet = True
    for name, ov in PROBES:
        err = physics_probe(make_plant(load(name, overrides=ov)), a.device)
        print(f"{name} {' '.join(ov[1:] if name == 'paper' else ov)}: {err:.3g} (limit {PROBE_TOL:g})")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("local", "initial", "noise", "trace", "probe"))
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--realisations", type=int, default=8)
    ap.add_argument("--eps", type=float, default=1e-6)
    ap.add_argument("--eps-qpos", type=float, default=None)
    ap.add_argument("--set", action="append", default=[])
    a = ap.parse_args()
    {"local": local, "initial": initial, "noise": noise, "trace": trace, "probe": probe}[a.what](a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
