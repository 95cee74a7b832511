#!/usr/bin/env python3
"""The learner's opt-in options measured on zoo robots (docs/findings/learner-options.md, design §14.4).

Paper scale (default): the paper scenario (20 s, bioinspired-learning, MuJoCo) on the TurtleBot3 Burger (menagerie
MJCF), PAL TIAGo (menagerie MJCF) and PAL PMB2 (URDF) of ``tests/zoo/``, with and without
``learner.projection_band``, ``learner.kd_deadband`` and ``torque.resistance_margin``, and prints one markdown row
per run: ĉ's error against c_true per follower (%), the outcomes, the rms formation error over the last half (mm),
the share of steps at the torque limit.

Fair scale (``--fair``, issue 27 items 5-6): the same options on the zoo robots at their fair scale, as
``scripts/zoo_table.py`` runs them (``formation.scale = "auto"``, ``formation.time_scale = "auto"``, the paper's
20 s × σ, ``learner.gain_scaling = "c_hat0"``, each robot mapped as ``tests/zoo/reference.py`` maps it with its
torque limit and maker's top speed, the preset's seeds). Each row also gives σ, the hardware verdict, the least
``â / c_true`` of the run and when it first got there (s), and what ``learner_sizing`` did. ``--json`` keeps the
raw rows (merged by label, so robots can be run one at a time and a table rebuilt with ``--table-only``).

    .venv/bin/python scripts/learner_options.py            # every paper-scale row (a few minutes)
    .venv/bin/python scripts/learner_options.py --only burger
    .venv/bin/python scripts/learner_options.py --fair --json /tmp/fair.json                 # ~15 min
    .venv/bin/python scripts/learner_options.py --fair --robots pmb2_urdf --json /tmp/fair.json
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import warnings
from pathlib import Path

import numpy as np

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


#: the robots of ``--fair`` (``tests/zoo/reference.py`` names), in the order of the table
FAIR_ROBOTS = (
    "menagerie_tiago",
    "pmb2_urdf",
    "diffbot_urdf",
    "robotis_tb3_burger",
    "create3_urdf",
    "tb3_burger_urdf",
    "tb3_waffle_pi_urdf",
)
#: option label -> scenario overrides of ``--fair`` (the values of the paper-scale table; given in the paper's
#: units, the fair scale transforms each key by its unit as it does the preset's, design §21)
FAIR_OPTIONS = {
    "none (the paper's)": [],
    "projection_band = [0.5, 2]": ["learner.projection_band=[0.5, 2]"],
    "resistance_margin = 1.5": ["torque.resistance_margin=1.5"],
    "kd_deadband = [25, 50]": ["learner.kd_deadband=[25.0, 50.0]"],
    "band [0.5, 2] and resistance_margin = 1.5": ["learner.projection_band=[0.5, 2]", "torque.resistance_margin=1.5"],
    "band [0.5, 2] and kd_deadband = [25, 50]": [
        "learner.projection_band=[0.5, 2]",
        "learner.kd_deadband=[25.0, 50.0]",
    ],
}


def _reference():
    """``tests/zoo/reference.py`` as a module (it is no package), with ``ROS_PACKAGE_PATH`` set to the zoo."""
    spec = importlib.util.spec_from_file_location("zoo_reference", ZOO / "reference.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["zoo_reference"] = mod
    spec.loader.exec_module(mod)
    os.environ["ROS_PACKAGE_PATH"] = ":".join(str(ZOO / r.name) for r in mod.ROBOTS)
    return mod


def fair_overrides(r) -> list[str]:
    """The scenario overrides of robot ``r`` (a ``reference.Robot``) at its fair scale, as ``scripts/zoo_table.py``."""
    table = {"model": str(ZOO / r.file), "base": r.base, "left_wheel": r.left, "right_wheel": r.right}
    table["tau_max"] = r.tau_max
    if r.top_speed:
        table["top_speed"] = r.top_speed
    inline = "{" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in table.items()) + "}"
    return [
        *COMMON,
        "sim.duration=20.0",
        "formation.scale=auto",
        "formation.time_scale=auto",
        f"plant.robots=[{inline}]",
    ]


def fair_run(r, option: str) -> dict:
    """One fair-scale run of robot ``r`` with ``option`` (:data:`FAIR_OPTIONS`): the raw row."""
    import time

    sc = load("paper", overrides=[*fair_overrides(r), *FAIR_OPTIONS[option]])
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = simulate(sc)
    s = res.summary
    ch = np.asarray(res.log["c_hat"])  # (K, n, 2)
    t = np.asarray(res.log["t"])
    ct = np.array([f["c_true"] for f in s["followers"]])  # (n, 2)
    rel = ch / ct[None]
    amin = np.nanmin(rel[..., 0], axis=0)
    first = [float(t[np.argmax(rel[:, i, 0] <= amin[i] * 1.02)]) for i in range(rel.shape[1])]
    hw = s.get("hardware") or {}
    return {
        "robot": r.name,
        "option": option,
        "sigma": float(sc.formation.time_scale),
        "scale": float(sc.formation.scale),
        "duration_s": float(sc.sim.duration),
        "wall_s": round(time.perf_counter() - t0, 1),
        "c_hat_rel_error": [f["c_hat_rel_error"] for f in s["followers"]],
        "outcomes": [[o["kind"] for o in f["outcomes"]] or ["ok"] for f in s["followers"]],
        "outcome_details": [[str(o.get("detail", ""))[:300] for o in f["outcomes"]] for f in s["followers"]],
        "rms_last_half_m": [f["rms_formation_error_last_half_m"] for f in s["followers"]],
        "saturation": [f["saturation_fraction"] for f in s["followers"]],
        "a_min_rel": amin.tolist(),
        "a_min_first_t_s": first,
        "hardware": {k: hw.get(k) for k in ("verdict", "failed", "not_checked")},
        "learner_sizing": s.get("learner_sizing"),
        "warnings": [str(w.message)[:240] for w in caught][:12],
    }


def fair_markdown(rows: list[dict]) -> str:
    """The ``--fair`` table: one row per robot and option, per follower 1, 2, 3."""
    lines = [
        "| robot | option | σ | â − c_true (%) | b̂ − c_true (%) | outcomes | rms formation error, last half (mm) "
        "| saturated | least â/c_true (first at, s) | hardware |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for x in rows:
        a = ", ".join(f"{100 * c[0]:+.0f}" for c in x["c_hat_rel_error"])
        b = ", ".join(f"{100 * c[1]:+.0f}" for c in x["c_hat_rel_error"])
        outs = ", ".join("+".join(o) for o in x["outcomes"])
        rms = ", ".join(f"{1e3 * v:.0f}" for v in x["rms_last_half_m"])
        sat = ", ".join(f"{v:.2f}" for v in x["saturation"])
        amin = f"{min(x['a_min_rel']):.2f} ({min(x['a_min_first_t_s']):.2f})"
        hw = x["hardware"]
        hwv = (hw.get("verdict") or "—") + (f" ({', '.join(hw['failed'])})" if hw.get("failed") else "")
        opt = x["option"]
        if x.get("learner_sizing") and "no dead band identified" in (x["learner_sizing"].get("why") or ""):
            opt += " (no dead band identified: off)"
        lines.append(
            f"| {x['robot']} | {opt} | {x['sigma']:.3g} | {a} | {b} | {outs} | {rms} | {sat} | {amin} | {hwv} |"
        )
    return "\n".join(lines) + "\n"


def fair_main(args: argparse.Namespace) -> None:
    """``--fair``: run (or, with ``--table-only``, only tabulate) the fair-scale rows, merging into ``--json``."""
    ref = _reference()
    by_name = {r.name: r for r in ref.ROBOTS}
    robots = [n for n in args.robots.split(",") if n] or list(FAIR_ROBOTS)
    options = [o for o in FAIR_OPTIONS if o.startswith(args.only)]
    path = Path(args.json) if args.json else None
    old = json.loads(path.read_text()) if path and path.exists() else []
    rows = {(x["robot"], x["option"]): x for x in old}
    for name in [] if args.table_only else robots:
        for opt in options:
            if (name, opt) in rows and not args.rerun:
                continue
            rows[(name, opt)] = fair_run(by_name[name], opt)
            x = rows[(name, opt)]
            print(f"{name} / {opt}: σ {x['sigma']:.3g}, {x['wall_s']} s", file=sys.stderr, flush=True)
            if path:
                path.write_text(json.dumps(list(rows.values()), indent=1, default=str, ensure_ascii=False))
    order = {n: i for i, n in enumerate(FAIR_ROBOTS)}
    keyed = sorted(rows.values(), key=lambda x: (order.get(x["robot"], 99), list(FAIR_OPTIONS).index(x["option"])))
    print(fair_markdown(keyed))


def main() -> None:
    """Print the table (the rows whose label starts with ``--only``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run only the rows (--fair: the options) whose label starts with this")
    ap.add_argument("--fair", action="store_true", help="the zoo at its fair scale (module docstring)")
    ap.add_argument("--robots", default="", help="--fair: comma-separated zoo names (default: FAIR_ROBOTS)")
    ap.add_argument("--json", default="", help="--fair: the raw rows, merged by robot and option")
    ap.add_argument("--rerun", action="store_true", help="--fair: rerun rows already in --json")
    ap.add_argument("--table-only", action="store_true", help="--fair: print the table of --json, run nothing")
    args = ap.parse_args()
    if args.fair:
        fair_main(args)
        return
    print("| run | â − c_true (%) | b̂ − c_true (%) | outcomes | rms formation error, last half (mm) | saturated |")
    print("|---|---|---|---|---|---|")
    for label, ov in RUNS.items():
        if label.startswith(args.only):
            print(row(label, ov), flush=True)


if __name__ == "__main__":
    main()
