#!/usr/bin/env python3
"""Measured outcomes of every fault preset for the four methods (issue 6, README "Faults").

Runs the ``fault_*`` presets, harder variants of them (``SEVERE``: where the methods break) and
the fault-free paper scenario on the same plant and duration as a reference, for each method.
Writes ``OUT/fault_table.json`` (one row per run, see :func:`bioform_mj.run.faults.outcome`),
``OUT/fault_table.md`` (every number) and ``OUT/fault_table_compact.md`` (faults × methods, as in
the README); prints both.

    .venv/bin/python scripts/fault_table.py --out runs/fault_table --jobs 2
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from bioform_mj.control.stack import METHODS
from bioform_mj.outputs.files import write_json, write_text
from bioform_mj.run.faults import TOLERANCE, outcome
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load, preset_names

REFERENCE = "paper (no fault)"

#: Harder versions of the presets, to find where the methods break: label -> (preset, overrides).
SEVERE = {
    "leader link of 1 down 6–9 s (the whole team cut off)": ("fault_link", {"faults.link_fail": [[1, 0, 6.0, 9.0]]}),
    "99.9 % packet loss 6–9 s": ("fault_packet_loss", {"faults.packet_loss": 0.999}),
    "0.3 s delay 6–9 s": ("fault_delay", {"faults.delay": 0.3}),
    "noise ×5 (10 cm, 0.1 rad, 0.25 m/s, 0.25 rad/s) 6–9 s": (
        "fault_noise",
        {"faults.noise_pose": [0.1, 0.1, 0.1], "faults.noise_vel": [0.25, 0.25]},
    ),
    "follower 1 motors dead (scale 0) 6–9 s": ("fault_actuator", {"faults.actuator": [[1, 6.0, 9.0, 0.0]]}),
    "follower 1 motors at 20 %, known to the controller": ("fault_actuator", {"faults.actuator_known": True}),
    "μ = 0.01 patch": ("fault_friction", {"faults.friction_patch": [3.0, -10.0, 6.0, 10.0, 0.01]}),
    "push 400 N sideways, 0.2 s": ("fault_push", {"faults.push": [[2, 6.0, 0.2, 0.0, 400.0, 0.0]]}),
}


def run_one(job: tuple[str, str]) -> dict:
    label, method = job
    if label == REFERENCE:
        ref = load("fault_link")  # same plant and duration as the fault presets
        sc = load("paper", {"sim.duration": ref.sim.duration}, method=method, plant=ref.plant.kind)
    elif label in SEVERE:
        preset, overrides = SEVERE[label]
        sc = load(preset, overrides, method=method)
    else:
        sc = load(label, method=method)
    t0 = time.perf_counter()
    res = simulate(sc)
    row = outcome(res, interval=(6.0, 9.0) if label == REFERENCE else None)  # the presets' fault window
    row["scenario"] = label
    row["wall_s"] = time.perf_counter() - t0
    learning = method.endswith("-learning")
    row["c_hat_rel_error_max"] = (
        max(abs(v) for f in res.summary["followers"] for v in f["c_hat_rel_error"]) if learning else None
    )
    return row


def _m(v: float | None) -> str:
    return "–" if v is None else f"{v:.3f}"


def markdown(rows: list[dict]) -> str:
    head = (
        "| fault | method | peak before (m) | peak during (m) | peak after (m) | final (m) | back under "
        f"{TOLERANCE:g} m after (s) | recovered | max abs(ĉ/c − 1) at end |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        rec = "diverged" if r["diverged"] else ("yes" if r["recovered"] else "**no**")
        if r["tipped_over"]:
            rec += f" (tipped over: {', '.join(map(str, r['tipped_over']))})"
        if r["spinning"]:
            rec += f" (spinning: {', '.join(map(str, r['spinning']))})"
        chat = "–" if r["c_hat_rel_error_max"] is None else f"{r['c_hat_rel_error_max']:.2f}"
        back = "never" if r["recovery_s"] is None else f"{r['recovery_s']:.2f}"
        lines.append(
            f"| {r['scenario']} | {r['method']} | {_m(r['before'])} | {_m(r['peak_during'])} | "
            f"{_m(r['peak_after'])} | {_m(r['final'])} | {back} | {rec} | {chat} |"
        )
    return head + "\n".join(lines) + "\n"


#: Row labels of the compact table.
LABELS = {
    REFERENCE: "none (paper scenario)",
    "fault_link": "link 1–2 down 6–9 s (`fault_link`)",
    "fault_packet_loss": "95 % packet loss 6–9 s (`fault_packet_loss`)",
    "fault_delay": "0.1 s delay 6–9 s (`fault_delay`)",
    "fault_noise": "noise 2 cm, 0.02 rad, 0.05 m/s, 0.05 rad/s, 6–9 s (`fault_noise`)",
    "fault_actuator": "follower 1 motors at 20 %, unknown, 6–9 s (`fault_actuator`)",
    "fault_friction": "μ = 0.05 patch, crossed 6–10 s (`fault_friction`)",
    "fault_push": "push 200 N x, 200 N y, 5 N·m, 0.2 s (`fault_push`)",
}


def compact(rows: list[dict]) -> str:
    """Faults × methods; a cell is the peak formation error from the fault's start to the end (m) and
    the time after the fault until it stays under the tolerance, or what went wrong."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    out = "| fault | " + " | ".join(methods) + " |\n|---|" + "---|" * len(methods) + "\n"
    for label in dict.fromkeys(r["scenario"] for r in rows):
        cells = []
        for m in methods:
            r = next(x for x in rows if x["scenario"] == label and x["method"] == m)
            peak = max(v for v in (r["peak_during"], r["peak_after"]) if v is not None)
            if r["recovered"]:
                cells.append(f"{peak:.2f} m, {r['recovery_s']:.1f} s")
            else:
                why = ["diverged"] if r["diverged"] else []
                if r["tipped_over"]:
                    why.append("tipped over: " + ", ".join(map(str, r["tipped_over"])))
                if r["spinning"]:
                    why.append("spinning: " + ", ".join(map(str, r["spinning"])))
                cells.append(f"**lost** ({r['final']:.1f} m{'; ' + '; '.join(why) if why else ''})")
        out += f"| {LABELS.get(label, label)} | " + " | ".join(cells) + " |\n"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/fault_table", help="output directory")
    ap.add_argument("--jobs", type=int, default=2, help="parallel processes")
    ap.add_argument("--presets", nargs="*", default=None, help="fault presets (default: every fault_* preset)")
    ap.add_argument("--methods", nargs="*", default=list(METHODS))
    ap.add_argument("--no-severe", action="store_true", help="skip the harder variants (SEVERE)")
    a = ap.parse_args()
    shipped = [p for p in preset_names() if p.startswith("fault_")]
    ordered = [p for p in LABELS if p in shipped] + [p for p in shipped if p not in LABELS]
    presets = a.presets or ([REFERENCE] + ordered + ([] if a.no_severe else list(SEVERE)))
    jobs = [(p, m) for p in presets for m in a.methods]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(a.jobs) as pool:
        rows = list(pool.map(run_one, jobs))
    write_json(out / "fault_table.json", {"tolerance_m": TOLERANCE, "rows": rows})
    md = markdown(rows)
    write_text(out / "fault_table.md", md)
    cmd = compact(rows)
    write_text(out / "fault_table_compact.md", cmd)
    print(md)
    print(cmd)
    print(f"wall time per run: {sum(r['wall_s'] for r in rows) / len(rows):.1f} s; outputs in {out}")


if __name__ == "__main__":
    main()
