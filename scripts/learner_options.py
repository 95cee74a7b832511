#!/usr/bin/env python3
"""The learner's opt-in options measured on zoo robots (docs/findings/learner-options.md, design §14.4).

Runs the paper scenario (20 s, bioinspired-learning, MuJoCo) on the TurtleBot3 Burger (menagerie MJCF), PAL TIAGo
(menagerie MJCF) and PAL PMB2 (URDF) of ``tests/zoo/``, with and without ``learner.projection_band``,
``learner.kd_deadband`` and ``torque.resistance_margin``, and prints one markdown row per run: ĉ's error against
c_true per follower (%), the outcomes, the rms formation error over the last half (mm), the share of steps at
the torque limit.

    .venv/bin/python scripts/learner_options.py            # every row (a few minutes)
    .venv/bin/python scripts/learner_options.py --only burger
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

ZOO = Path(__file__).resolve().parent.parent / "tests" / "zoo"
BURGER = (
    f'{{model="{ZOO}/robotis_tb3_burger/turtlebot3_burger.xml", base="base", left_wheel="wheel_left", '
    'right_wheel="wheel_right", tau_max=0.3}'
)
TIAGO = (
    f'{{model="{ZOO}/menagerie_tiago/tiago.xml", base="base_link", left_wheel="wheel_left_joint", '
    'right_wheel="wheel_right_joint"TAU}'
)
PMB2 = (
    f'{{model="{ZOO}/pmb2_urdf/pmb2.urdf", base="base_footprint", left_wheel="wheel_left_joint", '
    f'right_wheel="wheel_right_joint", package_path={{pmb2_description="{ZOO}/pmb2_urdf/pmb2_description"}}}}'
)
COMMON = ["plant.kind=mujoco", 'learner.gain_scaling="c_hat0"']
#: label -> overrides
RUNS = {
    "burger": [f"plant.robots=[{BURGER}]", "formation.scale=0.4"],
    "burger, projection_band = [0.5, 2]": [
        f"plant.robots=[{BURGER}]",
        "formation.scale=0.4",
        "learner.projection_band=[0.5, 2]",
    ],
    "burger, kd_deadband = [5, 5]": [
        f"plant.robots=[{BURGER}]",
        "formation.scale=0.4",
        "learner.kd_deadband=[5.0, 5.0]",
    ],
    "burger, kd_deadband = [25, 50]": [
        f"plant.robots=[{BURGER}]",
        "formation.scale=0.4",
        "learner.kd_deadband=[25.0, 50.0]",
    ],
    "burger, band and kd_deadband = [25, 50]": [
        f"plant.robots=[{BURGER}]",
        "formation.scale=0.4",
        "learner.projection_band=[0.5, 2]",
        "learner.kd_deadband=[25.0, 50.0]",
    ],
    "burger, resistance_margin = 1.5": [
        f"plant.robots=[{BURGER}]",
        "formation.scale=0.4",
        "torque.resistance_margin=1.5",
    ],
    "burger, resistance_margin = 5": [f"plant.robots=[{BURGER}]", "formation.scale=0.4", "torque.resistance_margin=5"],
    "tiago, 100 N·m": [f"plant.robots=[{TIAGO.replace('TAU', '')}]"],
    "tiago, 100 N·m, projection_band = [0.5, 2]": [
        f"plant.robots=[{TIAGO.replace('TAU', '')}]",
        "learner.projection_band=[0.5, 2]",
    ],
    "tiago, 20 N·m": [f"plant.robots=[{TIAGO.replace('TAU', ', tau_max=20.0')}]"],
    "tiago, 20 N·m, projection_band = [0.5, 2]": [
        f"plant.robots=[{TIAGO.replace('TAU', ', tau_max=20.0')}]",
        "learner.projection_band=[0.5, 2]",
    ],
    "pmb2": [f"plant.robots=[{PMB2}]"],
    "pmb2, kd_deadband = [25, 50]": [f"plant.robots=[{PMB2}]", "learner.kd_deadband=[25.0, 50.0]"],
}


def row(label: str, overrides: list[str]) -> str:
    """One markdown row of the run ``label`` (its scenario: the paper's with ``overrides``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = simulate(load("paper", overrides=[*COMMON, *overrides])).summary
    f = s["followers"]
    a = ", ".join(f"{100 * x['c_hat_rel_error'][0]:+.0f}" for x in f)
    b = ", ".join(f"{100 * x['c_hat_rel_error'][1]:+.0f}" for x in f)
    out = ", ".join("+".join(o["kind"] for o in x["outcomes"]) or "ok" for x in f)
    rms = ", ".join(f"{1e3 * x['rms_formation_error_last_half_m']:.1f}" for x in f)
    sat = ", ".join(f"{x['saturation_fraction']:.2f}" for x in f)
    return f"| {label} | {a} | {b} | {out} | {rms} | {sat} |"


def main() -> None:
    """Print the table (the rows whose label starts with ``--only``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run only the rows whose label starts with this")
    args = ap.parse_args()
    print("| run | â − c_true (%) | b̂ − c_true (%) | outcomes | rms formation error, last half (mm) | saturated |")
    print("|---|---|---|---|---|---|")
    for label, ov in RUNS.items():
        if label.startswith(args.only):
            print(row(label, ov), flush=True)


if __name__ == "__main__":
    main()
