"""What the contact and proximity watches cost per physics step (design §19), in compiled code.

For the ``paper`` (n = 3, 1 ms) and ``large256`` (n = 256, 4 ms) scenes on MuJoCo, numba loops time
``mj_step`` alone, the contact watch alone (after every physics step) and the proximity watch alone
(every ``PROXIMITY_DT``), each the best of ``--reps`` on the standing scene (zero torques: the
contact list holds the wheel and caster contacts, as in a run), and prints the watches' cost per
physics step as a share of ``mj_step``. Timed apart because on a shared machine the difference of
two whole loops (~1 %) drowns in the noise between them; ``bioform bench`` gives the loop's ratio.

    PYTHONPATH=src python scripts/contact_watch_cost.py [--reps 7]
"""

from __future__ import annotations

import argparse
import time

from bioform_mj.core.equations import njit
from bioform_mj.plants.mujoco.contacts import watch_contacts, watch_proximity
from bioform_mj.plants.mujoco.kernels import _mj_step
from bioform_mj.run.simulate import make_plant
from bioform_mj.scenario.loader import load


@njit
def _steps(mp, dp, k):
    for _ in range(k):
        _mj_step(mp, dp)


@njit
def _contacts(mp, dp, cl, k):
    ncon, con, meta, owner, ci, cf, f6, hdt = cl  # once, as run_chunk does
    for i in range(k):
        watch_contacts(mp, dp, ncon, con, meta, owner, ci, cf, f6, hdt, i * hdt)


@njit
def _proximity(mp, dp, px, pose, k):
    gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order = px
    for i in range(k):
        watch_proximity(mp, dp, gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order, pose, i * 1e-3)


def _best(fn, args, k, reps):
    fn(*args, 1)
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn(*args, k)
        best = min(best, (time.perf_counter() - t0) / k)
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=7)
    args = ap.parse_args()
    for name, k in (("paper", 20000), ("large256", 100)):
        p = make_plant(load(name, plant="mujoco"))
        m, d = p.model, p.data
        for _ in range(20):
            p.step(0 * p.initial_poses[:, :2], 0.0)  # settle on the floor
        pose, _ = p.observe()
        step = _best(_steps, (m._address, d._address), k, args.reps)
        p.reset()
        c = _best(_contacts, (m._address, d._address, p.contacts.contacts), 50 * k, args.reps)
        x = _best(_proximity, (m._address, d._address, p.contacts.proximity, pose), 50 * k, args.reps)
        every = p.contacts.every * p.n_substeps  # physics steps between two proximity looks
        per = c + x / every
        print(
            f"{name}: n = {p.n}, ncon = {d.ncon}: mj_step {step * 1e6:.1f} µs; contact watch {c * 1e9:.0f} ns "
            f"per physics step, proximity {x * 1e9:.0f} ns per look (every {every} physics steps): "
            f"{per * 1e9:.0f} ns per physics step = {per / step * 100:.2f} % of mj_step"
        )


if __name__ == "__main__":
    main()
