"""The physics probe: before a batch runs, one step at a time from the same state, how far MuJoCo Warp's
physics of the scene is from C MuJoCo's (:func:`physics_probe`); :func:`check_physics` refuses a scene
beyond :data:`PROBE_TOL`.
"""

from __future__ import annotations

from typing import Any

import mujoco_warp as mjw
import numpy as np
import warp as wp

from bioform_mj.batch.support import default_capacity
from bioform_mj.scenario.config import Scenario

#: :func:`physics_probe`'s limit on the one-step velocity difference (relative to |qvel|). Measured
#: (60 steps, Warp CPU device): bare floor 1.9e-4 (paper), 2.3e-4 (paper, DC motors), 1.4e-3
#: (stretch preset), 2.0e-3 (tb3 preset); on a friction patch, a box: 0.11 (paper, 6 m patch),
#: 0.86 (paper), 7.9 (tb3) (docs/warp_engine.md)
PROBE_TOL = 3e-2
#: s of physics :func:`physics_probe` lets C MuJoCo settle the scene before comparing
SETTLE_S = 0.05
_probed: dict[tuple[str, str], float] = {}


def physics_probe(plant: Any, device: str = "cpu", steps: int = 60, seed: int = 0) -> float:
    """How far MuJoCo Warp's physics of ``plant``'s scene is from C MuJoCo's, one step at a time.

    C MuJoCo first settles the scene (``SETTLE_S`` of physics at zero input: the robots land on the
    floor, where one engine may see a touching contact the other does not); then both engines step
    it from that state with the same wheel inputs (uniform random
    within ±80 % of each motor's limit, new every 20 steps, ``seed``); after each step the largest
    over robots of ``|qvel_warp − qvel_C| / (|qvel_C| + 1e-3)`` is taken and MuJoCo Warp is put back
    on C MuJoCo's state, so what is measured is each step's own difference (float32 rounding:
    2e-4 … 2e-3 on our robots; another contact model: ≳ 1e-1). Returns the largest over ``steps``
    (dimensionless). One world; ~2 × ``steps`` physics steps of host time on Warp's CPU device."""
    import mujoco

    m = plant.model
    d = mujoco.MjData(m)
    mujoco.mj_copyData(d, m, plant.data)
    mujoco.mj_resetData(m, d)
    for _ in range(max(1, int(round(SETTLE_S / m.opt.timestep)))):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    rng = np.random.default_rng(seed)
    ids = np.asarray(plant._ctrl).reshape(-1)
    lim = (np.asarray(plant.tau_max, dtype=float)[:, None] * np.asarray(plant._ctrl_scale, dtype=float)).reshape(-1)
    worst = 0.0
    with wp.ScopedDevice(device):
        mm = mjw.put_model(m)
        dd = mjw.put_data(m, d, nworld=1, nconmax=default_capacity(plant.n)[0], njmax=default_capacity(plant.n)[1])
        u = np.zeros(m.nu)
        for k in range(steps):
            if k % 20 == 0:
                u[:] = 0.0
                u[ids] = rng.uniform(-0.8, 0.8, ids.size) * np.abs(lim)
                dd.ctrl.assign(u[None].astype(np.float32))
                d.ctrl[:] = u
            mujoco.mj_step(m, d)
            mjw.step(mm, dd)
            qv = dd.qvel.numpy()[0].astype(float)
            for v6 in plant._v6:
                a, b = v6[0], v6[-1] + 1
                worst = max(worst, float(np.linalg.norm(qv[a:b] - d.qvel[a:b]) / (np.linalg.norm(d.qvel[a:b]) + 1e-3)))
            if not np.isfinite(worst):
                return float("inf")
            dd.qpos.assign(d.qpos[None].astype(np.float32))  # back on C MuJoCo's state
            dd.qvel.assign(d.qvel[None].astype(np.float32))
    return worst


def check_physics(sc: Scenario, device: str = "cpu", plant: Any = None) -> None:
    """ValueError if MuJoCo Warp's physics of ``sc``'s scene is not C MuJoCo's (:func:`physics_probe`
    beyond :data:`PROBE_TOL`); probed once per scene and device in a process."""
    import json

    scene = {"plant": sc.to_dict()["plant"], "patch": list(sc.faults.friction_patch), "dt": sc.sim.physics_dt}
    key = (json.dumps(scene, sort_keys=True, default=repr), str(device))  # what the composed scene is made of
    if key not in _probed:
        if plant is None:
            from bioform_mj.run.simulate import make_plant

            plant = make_plant(sc)
        _probed[key] = physics_probe(plant, device)
    err = _probed[key]
    if not err <= PROBE_TOL:
        raise ValueError(
            f"scenario '{sc.name}': MuJoCo Warp's physics of this scene differs from C MuJoCo's: one physics "
            f"step from the same state, the robots' velocities differ by up to {err:.3g} (relative; float32 "
            f"gives ~1e-3, the limit is {PROBE_TOL:g}): a contact pair the two engines model differently "
            "(e.g. wheel meshes or boxes); the batch engine would not reproduce the CPU engine"
        )
