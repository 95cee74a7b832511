"""The zoo table of the README and docs/zoo.md: each published robot of ``tests/zoo`` checked and run.

Per robot: ``robot check``'s verdict (and cause), the formula's ``a_eff``/``b_eff`` against the
project's identification, and the paper scenario at the robot's scale (``formation.scale`` = the
robot's half track / the paper robot's, ``learner.gain_scaling = "c_hat0"``, the robot's own torque
limit, MuJoCo plant, ``--duration``) with the learned ``ĉ`` against ``c_true`` and every outcome.
Writes ``--out`` (Markdown) and ``--json``; about a minute per robot on a 2-core machine::

    .venv/bin/python scripts/zoo_table.py --out runs/zoo/zoo_table.md --json runs/zoo/zoo_table.json
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import warnings
from pathlib import Path

ZOO = Path(__file__).resolve().parent.parent / "tests" / "zoo"


def toml_table(d: dict) -> str:
    """``{key = value, ...}`` as TOML writes an inline table (strings quoted by JSON, numbers as they are)."""
    return "{" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in d.items() if v not in ("", None)) + "}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--robots", default="", help="comma-separated names (default: all)")
    ap.add_argument("--out", type=Path, default=Path("runs/zoo/zoo_table.md"))
    ap.add_argument("--json", type=Path, default=Path("runs/zoo/zoo_table.json"))
    a = ap.parse_args()
    spec = importlib.util.spec_from_file_location("zoo_reference", ZOO / "reference.py")
    ref_mod = importlib.util.module_from_spec(spec)
    sys.modules["zoo_reference"] = ref_mod
    spec.loader.exec_module(ref_mod)
    expect = json.loads((ZOO / "expectations.json").read_text())
    os.environ["ROS_PACKAGE_PATH"] = ":".join(str(ZOO / r.name) for r in ref_mod.ROBOTS)

    from bioform_mj.assess.check import check
    from bioform_mj.robots.refs import RobotRef
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    paper_l = check("paper", identify_=False)["half_track_m"]
    names = [n for n in a.robots.split(",") if n] or [r.name for r in ref_mod.ROBOTS]
    rows = []
    for r in ref_mod.ROBOTS:
        if r.name not in names:
            continue
        ref = RobotRef(model=str(ZOO / r.file), base=r.base, left_wheel=r.left, right_wheel=r.right, tau_max=r.tau_max)
        row = {
            "robot": r.name,
            "maker": expect[r.name]["maker"],
            "format": r.format,
            "source": expect[r.name]["source"],
        }
        rep = check(ref)
        row.update(
            verdict=rep["verdict"],
            cause=(rep.get("cause") or {}).get("kind"),
            a_formula=rep["a_eff"],
            b_formula=rep["b_eff"],
            rel_error=rep.get("relative_error"),
        )
        scale = rep["half_track_m"] / paper_l
        table = {"model": ref.model, "base": ref.base, "left_wheel": ref.left_wheel, "right_wheel": ref.right_wheel}
        if ref.tau_max:
            table["tau_max"] = ref.tau_max
        ov = [
            "plant.kind=mujoco",
            f"sim.duration={a.duration}",
            f"formation.scale={scale:.6g}",
            "learner.gain_scaling=c_hat0",
            "plant.robots=[" + toml_table(table) + "]",
        ]
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                sc = load("paper", ov)
                res = simulate(sc)
            fol = res.summary["followers"]
            row.update(
                scale=scale,
                c_hat_rel_error=[f["c_hat_rel_error"] for f in fol],
                outcomes=[[o["kind"] for o in f.get("outcomes", [])] or ["ok"] for f in fol],
                final_formation_error_m=[f["final_formation_error_m"] for f in fol],
                diverged=(res.summary.get("diverged") or {}).get("message"),
                warnings=[str(w.message)[:200] for w in caught][:5],
            )
        except Exception as exc:  # a refusal (exit 2 in the CLI) is the row's result
            row.update(scale=scale, run_error=f"{type(exc).__name__}: {exc}"[:300])
        rows.append(row)
        print(json.dumps({k: row.get(k) for k in ("robot", "verdict", "cause", "c_hat_rel_error", "outcomes")}))
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(rows, indent=1, default=str))
    lines = [
        "| robot | maker | format | verdict (cause) | identified vs formula a, b | scale | learned ĉ vs c_true (a, b), "
        "per follower | outcomes |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        re_ = row.get("rel_error") or {}
        ident = (
            f"{100 * re_['a']:+.1f} %, {100 * re_['b']:+.1f} %"
            if re_ and re_.get("a") is not None
            else "not identified"
        )
        if "run_error" in row:
            chat, outc = "—", f"refused: {row['run_error'][:120]}"
        else:
            chat = "; ".join(f"{100 * c[0]:+.0f} %, {100 * c[1]:+.0f} %" for c in row["c_hat_rel_error"])
            outc = "; ".join("+".join(o) for o in row["outcomes"])
        cause = f" ({row['cause']})" if row.get("cause") else ""
        lines.append(
            f"| {row['robot']} | {row['maker']} | {row['format'].upper()} | {row['verdict']}{cause} | {ident} | "
            f"{row['scale']:.3g} | {chat} | {outc} |"
        )
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
