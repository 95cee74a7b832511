#!/usr/bin/env python3
"""A zoo robot's start at its fair scale against eq. 34 (docs/findings/learner-options.md, TIAGo).

Runs the first ``--duration`` paper-seconds (× σ) of the paper scenario on one robot of ``tests/zoo`` exactly as
``scripts/learner_options.py --fair`` does (σ resolved over the whole run's 20 paper-seconds), and prints per
follower, over 0.015–0.15 s of the run: the measured υ̇ and ω̇ (log differences, m/s², rad/s²) against eq. 34's
``a τ_a`` and ``b τ_b`` with the robot's ``c_true``; the least ``â / c_true`` and when it first fell to 0.06; the
largest wheel torque (N·m); the outcomes.
``--map KEY=JSON`` changes one mapping key (e.g. frictionless casters), ``--set KEY=VALUE`` one scenario key.

    .venv/bin/python scripts/start_transient.py menagerie_tiago
    .venv/bin/python scripts/start_transient.py menagerie_tiago --map caster_friction=0 \\
        --map 'casters=["caster_front_right", "caster_front_left", "caster_back_right", "caster_back_left"]'
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

from bioform_mj.run.simulate import simulate  # noqa: E402
from bioform_mj.scenario.loader import load  # noqa: E402

#: the window of the run (s) over which the measured and modelled accelerations are averaged
WINDOW = (0.015, 0.15)


def main() -> None:
    """Print one JSON object per follower (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("robot", help="a tests/zoo/reference.py name, e.g. menagerie_tiago")
    ap.add_argument("--duration", type=float, default=0.3, help="paper seconds (the run's are × σ)")
    ap.add_argument("--map", action="append", default=[], help="a mapping key KEY=JSON (repeatable)")
    ap.add_argument("--set", action="append", default=[], help="a scenario override KEY=VALUE (repeatable)")
    a = ap.parse_args()
    ref = lo._reference()
    by_name = {r.name: r for r in ref.ROBOTS}
    if a.robot not in by_name:
        ap.error(f"unknown robot {a.robot!r}; one of {', '.join(by_name)}")
    extra = {k: json.loads(v) for k, v in (m.split("=", 1) for m in a.map)}
    ov = [o for o in lo.fair_overrides(by_name[a.robot]) if not o.startswith("sim.duration")]
    ov = [
        o[:-2] + "".join(f", {k} = {json.dumps(v)}" for k, v in extra.items()) + "}]"
        if o.startswith("plant.robots")
        else o
        for o in ov
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # σ of the whole run ("auto" resolved over the paper's 20 s), so this is that run's start
        sigma = load("paper", [*ov, "sim.duration=20.0", *a.set]).formation.time_scale
        ov = [f"formation.time_scale={sigma!r}" if o.startswith("formation.time_scale") else o for o in ov]
        sc = load("paper", [*ov, f"sim.duration={a.duration}", *a.set])
        res = simulate(sc)
    log = res.log
    t, vel, tau, ch = (np.asarray(log[k]) for k in ("t", "vel", "tau", "c_hat"))
    ct = np.array([f["c_true"] for f in res.summary["followers"]])
    acc = np.diff(vel, axis=0) / np.diff(t)[:, None, None]  # (K-1, n, 2)
    model = ct[None] * tau[1:]  # eq. 34 with the torque applied over each log step
    win = (t[1:] > WINDOW[0]) & (t[1:] <= WINDOW[1])
    rel = ch[..., 0] / ct[None, :, 0]
    for i, f in enumerate(res.summary["followers"]):
        low = rel[:, i] <= 0.06
        print(
            json.dumps(
                {
                    "follower": i + 1,
                    "sigma": round(float(sc.formation.time_scale), 3),
                    "vdot_measured": round(float(acc[win, i, 0].mean()), 3),
                    "vdot_eq34": round(float(model[win, i, 0].mean()), 3),
                    "wdot_measured": round(float(acc[win, i, 1].mean()), 3),
                    "wdot_eq34": round(float(model[win, i, 1].mean()), 3),
                    "a_hat_rel_least": round(float(rel[:, i].min()), 3),
                    "a_hat_first_at_0.06_s": float(t[np.argmax(low)]) if low.any() else None,
                    "max_abs_tau_nm": round(float(np.abs(tau[:, i]).max()), 1),
                    "outcomes": [o["kind"] for o in f["outcomes"]],
                }
            )
        )


if __name__ == "__main__":
    main()
