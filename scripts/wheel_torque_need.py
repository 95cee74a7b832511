#!/usr/bin/env python3
"""The wheel torque a zoo robot needs for the scenario's demand at its fair scale, its own resistance included
(docs/findings/learner-options.md, PMB-2).

The demand's run (``run/demand.py: ideal_twin``: eq. 34 with the robot's ``c_true``, no torque limit) of the
paper scenario at the robot's fair scale, as ``scripts/learner_options.py --fair`` maps it; per wheel, from its
log: the inertial torque ``(υ̇/a ± ω̇/b)/2`` and the wheel joint's own resistance ``c φ̇ + f sgn φ̇`` (damping
``c`` N·m·s/rad, frictionloss ``f`` N·m, ``φ̇ = (υ ± l ω)/r``), their sum, and the share of the run each is
above the mapped torque limit. Prints one JSON object.

    .venv/bin/python scripts/wheel_torque_need.py pmb2_urdf
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import learner_options as lo  # noqa: E402  (the fair-scale mapping, one definition)

from bioform_mj.robots.entries import resolve_robot  # noqa: E402
from bioform_mj.robots.params import robot_truth  # noqa: E402
from bioform_mj.run.demand import ideal_twin  # noqa: E402
from bioform_mj.run.simulate import simulate  # noqa: E402
from bioform_mj.scenario.loader import load  # noqa: E402


def main() -> None:
    """Print the need per wheel (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("robot", help="a tests/zoo/reference.py name, e.g. pmb2_urdf")
    a = ap.parse_args()
    by_name = {r.name: r for r in lo._reference().ROBOTS}
    if a.robot not in by_name:
        ap.error(f"unknown robot {a.robot!r}; one of {', '.join(by_name)}")
    r = by_name[a.robot]
    sc = load("paper", lo.fair_overrides(r))
    p = robot_truth(resolve_robot(sc.plant.robots[0]))
    ca, cb, l, rad = p.a_eff, p.b_eff, p.half_track, p.wheel_radius
    c, f = p.wheel_damping + p.motor_damping, p.wheel_frictionloss
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(ideal_twin(sc, (ca, cb)), engine="auto")
    t, vel = np.asarray(res.log["t"]), np.asarray(res.log["vel"])
    dt = np.diff(t)[:, None]
    vd, wd = np.diff(vel[..., 0], axis=0) / dt, np.diff(vel[..., 1], axis=0) / dt
    vm, wm = 0.5 * (vel[1:, :, 0] + vel[:-1, :, 0]), 0.5 * (vel[1:, :, 1] + vel[:-1, :, 1])
    out: dict = {"robot": r.name, "sigma": float(sc.formation.time_scale), "tau_max_nm": r.tau_max}
    out.update(a=ca, b=cb, half_track_m=l, wheel_radius_m=rad, damping_nms=c, frictionloss_nm=f)
    for side, sgn in (("right", 1.0), ("left", -1.0)):
        inert = 0.5 * (vd / ca + sgn * wd / cb)
        phid = (vm + sgn * l * wm) / rad
        resist = c * phid + f * np.sign(phid)
        need = inert + resist
        out[side] = {
            "inertial_max_nm": float(np.abs(inert).max()),
            "wheel_speed_max_radps": float(np.abs(phid).max()),
            "resistance_max_nm": float(np.abs(resist).max()),
            "need_max_nm": float(np.abs(need).max()),
            "need_median_nm": float(np.median(np.abs(need))),
            "share_need_above_tau_max": float(np.mean(np.abs(need) > r.tau_max)),
            "share_resistance_above_tau_max": float(np.mean(np.abs(resist) > r.tau_max)),
        }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
