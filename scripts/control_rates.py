"""Control rates (issue 12, item 5): the four methods at 1 kHz, 200, 100 and 50 Hz in MuJoCo, paper
scenario and tb3, with ideal and DC motors; writes a markdown table.

    PYTHONPATH=src python scripts/control_rates.py [--duration 20] [--out runs/control_rates]
        [--sensing truth,odometry] [--cases tb3] [--rates 100]

Cell: final formation error (max over followers, m, on the truth), and the outcome when not ``ok``;
with odometry also the largest ``odometry_drift_m``. Sensing: ``truth`` or ``odometry`` (encoders
and gyro, design §8.3; gyro noise 0.004 rad/s and bias 0.001 rad/s, the tb3's IMU class).
Physics stays at 1 ms; the controller runs
every ``control_dt`` with zero-order hold over ``control_dt / 1 ms`` physics steps.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

from bioform_mj.cli.main import main

METHODS = ["backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning"]
RATES = [(0.001, "1 kHz"), (0.005, "200 Hz"), (0.01, "100 Hz"), (0.02, "50 Hz")]
CASES = [
    ("paper", "ideal", None),
    ("paper", "DC, voltage driver", '[{model="paper",motor="dc",driver="voltage"}]'),
    ("tb3", "DC, current driver (preset)", None),
    ("tb3", "ideal", '[{model="tb3",tau_max=0.05}]'),
]


SENSING = {"truth": [], "odometry": ['plant.sensing="odometry"', "plant.gyro_noise=0.004", "plant.gyro_bias=0.001"]}


def cell(out: Path) -> str:
    s = json.loads((out / "summary.json").read_text())
    err = max(f["final_formation_error_m"] for f in s["followers"])
    bad = sorted({f["outcome"] for f in s["followers"] if f["outcome"] != "ok"})
    drift = [f.get("odometry_drift_m") for f in s["followers"]]
    extra = f", drift {max(drift):.2g} m" if all(d is not None for d in drift) else ""
    return f"{err:.3g} m" + (f" ({', '.join(bad)})" if bad else "") + extra


def run(args: argparse.Namespace) -> str:
    rates = [r for r in RATES if not args.rates or str(int(round(1 / r[0]))) in args.rates.split(",")]
    cases = [c for c in CASES if not args.cases or c[0] in args.cases.split(",")]
    rows = [
        "| scenario | motors | sensing | method | " + " | ".join(r[1] for r in rates) + " |",
        "|---|---|---|---|" + "---|" * len(rates),
    ]
    for (scen, label, robots), sensing, meth in (
        (c, se, m) for c in cases for se in args.sensing.split(",") for m in METHODS
    ):
        if True:
            cells = []
            for dt, _ in rates:
                out = args.out / f"{scen}_{label.split(',')[0].split()[0]}_{sensing}_{meth}_{int(round(1 / dt))}"
                argv = [
                    "run",
                    scen,
                    "--plant",
                    "mujoco",
                    "--method",
                    meth,
                    "--duration",
                    str(args.duration),
                    "--set",
                    f"sim.control_dt={dt}",
                    "--set",
                    f"sim.log_dt={max(dt, 0.01)}",
                    "--quiet",
                    "--out",
                    str(out),
                ]
                if robots:
                    argv += ["--set", f"plant.robots={robots}"]
                for kv in SENSING[sensing]:
                    argv += ["--set", kv]
                with contextlib.redirect_stderr(io.StringIO()):
                    code = main(argv)
                cells.append(cell(out) if code in (0, 3) and (out / "summary.json").exists() else f"exit {code}")
                if code == 3:
                    cells[-1] += " diverged"
            rows.append(f"| {scen} | {label} | {sensing} | {meth} | " + " | ".join(cells) + " |")
            print(rows[-1], file=sys.stderr, flush=True)
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--out", type=Path, default=Path("runs/control_rates"))
    ap.add_argument("--sensing", default="truth,odometry", help="comma-separated: truth, odometry")
    ap.add_argument("--cases", default="", help="comma-separated scenarios (paper, tb3); default all")
    ap.add_argument("--rates", default="", help="comma-separated rates in Hz (1000, 200, 100, 50); default all")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    table = run(a)
    (a.out / "control_rates.md").write_text(table)
    print(table)
