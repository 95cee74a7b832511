"""Control rates (issue 12, item 5): the four methods at 1 kHz, 200, 100 and 50 Hz in MuJoCo, paper
scenario and tb3, with ideal and DC motors; writes a markdown table.

    PYTHONPATH=src python scripts/control_rates.py [--duration 20] [--out runs/control_rates]

Cell: final formation error (max over followers, m), and the outcome when not ``ok``. Sensing is
the truth (odometry sensing is not implemented yet, see README). Physics stays at 1 ms; the controller runs
every ``control_dt`` with zero-order hold over ``control_dt / 1 ms`` physics steps.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

from bioform_mj.cli import main

METHODS = ["backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning"]
RATES = [(0.001, "1 kHz"), (0.005, "200 Hz"), (0.01, "100 Hz"), (0.02, "50 Hz")]
CASES = [
    ("paper", "ideal", None),
    ("paper", "DC, voltage driver", '[{model="paper",motor="dc",driver="voltage"}]'),
    ("tb3", "DC, current driver (preset)", None),
    ("tb3", "ideal", '[{model="tb3",tau_max=0.05}]'),
]


def cell(out: Path) -> str:
    s = json.loads((out / "summary.json").read_text())
    err = max(f["final_formation_error_m"] for f in s["followers"])
    bad = sorted({f["outcome"] for f in s["followers"] if f["outcome"] != "ok"})
    return f"{err:.3g} m" + (f" ({', '.join(bad)})" if bad else "")


def run(args: argparse.Namespace) -> str:
    rows = ["| scenario | motors | method | " + " | ".join(r[1] for r in RATES) + " |",
            "|---|---|---|" + "---|" * len(RATES)]
    for scen, label, robots in CASES:
        for meth in METHODS:
            cells = []
            for dt, _ in RATES:
                out = args.out / f"{scen}_{label.split(',')[0].split()[0]}_{meth}_{int(round(1 / dt))}"
                argv = ["run", scen, "--plant", "mujoco", "--method", meth, "--duration", str(args.duration),
                        "--set", f"sim.control_dt={dt}", "--set", f"sim.log_dt={max(dt, 0.01)}", "--quiet", "--out", str(out)]
                if robots:
                    argv += ["--set", f"plant.robots={robots}"]
                with contextlib.redirect_stderr(io.StringIO()):
                    code = main(argv)
                cells.append(cell(out) if code in (0, 3) and (out / "summary.json").exists() else f"exit {code}")
                if code == 3:
                    cells[-1] += " diverged"
            rows.append(f"| {scen} | {label} | {meth} | " + " | ".join(cells) + " |")
            print(rows[-1], file=sys.stderr, flush=True)
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--out", type=Path, default=Path("runs/control_rates"))
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    table = run(a)
    (a.out / "control_rates.md").write_text(table)
    print(table)
