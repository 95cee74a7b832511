"""The zoo table of the README and docs/zoo.md: each published robot of ``tests/zoo`` checked and run at its fair scale.

Per robot (issue 27 item 6, design §21): ``robot check``'s verdict (and cause); the paper scenario at the
robot's fair scale (``formation.scale = "auto"``: s from its half track; ``formation.time_scale =
"auto"``: σ from its limits, the maker's top speed given as the mapping's ``top_speed`` from
``tests/zoo/reference.py``), ``learner.gain_scaling = "c_hat0"``, its own torque limit, on

- the paper's ideal plant (eq. 34) with the robot's ``c_true`` and torque limit: the method's share;
- MuJoCo with the robot as published: the method and the physics the paper's model lacks;

and records ``s``, ``σ`` and what set it, the worst demand/limit ratio of the run's ``demand``, the
hardware verdict, ``ĉ`` against ``c_true`` per follower on both plants, the final formation error, every
outcome with its detail. ``--duration`` is the paper's duration (s, before × σ; default the paper's
20 s). ``--map KEY=JSON`` / ``--set KEY=VALUE`` run a counterfactual (one mapping or scenario key
changed; said in the row). Writes ``--json`` (one row per robot, merged into an existing file so robots
can be measured one at a time), ``--out`` (the Markdown table of every row, per follower) and beside it
``*_compact.md`` (the README's). The whole zoo takes about 6 minutes on a 2-core machine (the DiffBot,
σ 58, the longest)::

    .venv/bin/python scripts/zoo_table.py
    .venv/bin/python scripts/zoo_table.py --robots create3_urdf --map caster_friction=0 \\
        --map 'casters=["front_caster_link"]' --json runs/zoo/cf.json --out runs/zoo/cf.md
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import re
import sys
import time
import warnings
from pathlib import Path

ZOO = Path(__file__).resolve().parent.parent / "tests" / "zoo"


def toml_table(d: dict) -> str:
    """``{key = value, ...}`` as TOML writes an inline table (strings quoted by JSON, numbers as they are)."""
    return "{" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in d.items()) + "}"


def _outcomes(f: dict) -> list[dict]:
    """A follower's outcomes as ``[{"kind", "detail"}]`` (``ok`` when none)."""
    out = [{"kind": o.get("kind"), "detail": str(o.get("detail", ""))[:240]} for o in f.get("outcomes") or []]
    return out or [{"kind": "ok", "detail": ""}]


#: demand items that compare the robot's resistance with the sliding gain (the method), not a demand with a limit
GAIN_ITEMS = ("sliding_gain_v", "sliding_gain_w")
#: the mapping's torque limit against traction: a property of the robot, not of the scenario's demand; the sign terms
#: at ĉ's projection bound: the method's worst case, not the scenario's demand (design §21)
MAPPING_ITEMS = ("torque_vs_traction", "accel_at_c_bound")


def _worst_ratio(summary: dict) -> dict | None:
    """The largest demand/limit ratio of ``summary["demand"]`` (``{"name", "ratio", "value", "limit", "unit",
    "limit_by"}``) of the scenario's demand over the robot's limits (not :data:`GAIN_ITEMS`,
    :data:`MAPPING_ITEMS`), None without a demand."""
    return _worst_of([r.get("demand") for r in (summary.get("demand") or {}).get("robots", [])])


def _worst_of(demands: list) -> dict | None:
    """:func:`_worst_ratio` of the ``demand`` dicts of the robots."""
    worst = None
    for d in demands:
        for name, it in (d or {}).items():
            skip = GAIN_ITEMS + MAPPING_ITEMS
            ratio = it.get("ratio") if isinstance(it, dict) and name not in skip else None
            if ratio is not None and (worst is None or ratio > worst["ratio"]):
                worst = {"name": name, **{k: it.get(k) for k in ("ratio", "value", "limit", "unit", "limit_by")}}
    return worst


def _followers(summary: dict) -> dict:
    fol = summary["followers"]
    return {
        "c_hat_rel_error": [f.get("c_hat_rel_error") for f in fol],
        "outcomes": [_outcomes(f) for f in fol],
        "final_formation_error_m": [f.get("final_formation_error_m") for f in fol],
        "diverged": (summary.get("diverged") or {}).get("message"),
    }


def measure(r, a, paper_l: float) -> dict:
    """One robot's row (module docstring)."""
    from bioform_mj.assess.check import check
    from bioform_mj.robots.refs import RobotRef
    from bioform_mj.run.demand import ideal_twin
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    ref = RobotRef(
        model=str(ZOO / r.file),
        base=r.base,
        left_wheel=r.left,
        right_wheel=r.right,
        tau_max=r.tau_max,
        top_speed=r.top_speed,
        control_rate=r.control_rate,  # the maker's controller's rate where it publishes one (design §19)
    )
    extra = {k: tuple(v) if isinstance(v, list) else v for k, v in (a.map or {}).items()}
    ref = dataclasses.replace(ref, **extra)  # a counterfactual mapping (--map), said in the row
    row: dict = {
        "robot": r.name,
        "maker": r.maker,
        "expected_verdict": r.expected_verdict,  # the independent reference's (tests/zoo/reference.py)
        "format": r.format,
        "source": r.source,
        "tau_max_nm": r.tau_max,
        "top_speed_mps": r.top_speed or None,
        "top_speed_source": r.top_speed_source,
        "paper_duration_s": a.duration,
        "counterfactual": {"map": a.map, "set": a.set} if (a.map or a.set) else None,
    }
    rep = check(ref)
    row.update(
        verdict=rep["verdict"],
        cause=(rep.get("cause") or {}).get("kind"),
        a_formula=rep["a_eff"],
        b_formula=rep["b_eff"],
        rel_error=rep.get("relative_error"),
        limits=rep.get("limits"),
        lengths_only_scale=rep["half_track_m"] / paper_l,
    )
    keys = ("model", "base", "left_wheel", "right_wheel", "tau_max", "top_speed", "control_rate", *extra)
    default = {f.name: f.default for f in dataclasses.fields(RobotRef)}
    table = {  # the keys that differ from RobotRef's defaults (caster_friction = 0 is not its default -1)
        k: list(getattr(ref, k)) if isinstance(getattr(ref, k), tuple) else getattr(ref, k)
        for k in keys
        if k == "model" or getattr(ref, k) != default.get(k)
    }
    ov = [
        "plant.kind=mujoco",
        f"sim.duration={a.duration}",
        "formation.scale=auto",
        "formation.time_scale=auto",
        "learner.gain_scaling=c_hat0",
        "plant.robots=[" + toml_table(table) + "]",
        *a.set,
    ]
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sc = load("paper", ov)
    except Exception as exc:  # a refusal (exit 2 in the CLI) is the row's result
        row["run_error"] = f"{type(exc).__name__}: {exc}".replace(f"{ZOO.parent.parent}/", "")[:300]
        return row
    f = sc.formation
    row.update(
        scale=float(f.scale),
        time_scale=float(f.time_scale),
        scale_note=f.scale_note,
        duration_s=float(sc.sim.duration),
        load_warnings=[str(w.message)[:240] for w in caught][:5],
    )
    # the method's share: the same scenario on the paper's plant with the robot's c_true and torque limit
    c_true = (rep["a_eff"], rep["b_eff"])
    twin = ideal_twin(sc, c_true)
    twin = dataclasses.replace(
        twin,
        sim=sc.sim,  # the run's own steps
        torque=dataclasses.replace(twin.torque, tau_max=r.tau_max),
        limits=sc.limits,
    )
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ideal = simulate(twin, engine="auto")
    row["ideal"] = {**_followers(ideal.summary), "seconds": round(time.perf_counter() - t0, 1)}
    print(
        f"{r.name}: ideal plant done in {row['ideal']['seconds']} s (s {row['scale']:.3g}, σ {row['time_scale']:.3g})"
    )
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = simulate(sc)
    except Exception as exc:  # a refusal (exit 2 in the CLI) is the row's result
        row["run_error"] = f"{type(exc).__name__}: {exc}".replace(f"{ZOO.parent.parent}/", "")[:300]
        return row
    s = res.summary
    hw = s.get("hardware") or {}
    row["mujoco"] = {
        **_followers(s),
        "seconds": round(time.perf_counter() - t0, 1),
        "c_true": [d.get("c_true") for d in (s.get("demand") or {}).get("robots", [])],
        "worst_demand": _worst_ratio(s),
        "demand": [d.get("demand") for d in (s.get("demand") or {}).get("robots", [])],
        "demand_warnings": (s.get("demand") or {}).get("warnings", []),
        "hardware": {k: hw.get(k) for k in ("verdict", "failed", "not_checked")},
        "hardware_checks": hw.get("checks"),
        "warnings": [str(w.message)[:240] for w in caught][:8],
    }
    return row


def _pct(c: list | None) -> str:
    if not c or c[0] is None:
        return "—"
    return f"{100 * c[0]:+.0f} %, {100 * c[1]:+.0f} %"


def _outs(ff: list[list[dict]]) -> str:
    """``kind ×n`` over the followers (each kind once per follower)."""
    counts: dict[str, int] = {}
    for fo in ff:
        for k in dict.fromkeys(o["kind"] for o in fo):
            counts[k] = counts.get(k, 0) + 1
    kinds = ", ".join(f"{k} ×{n}" if n > 1 else k for k, n in counts.items())
    causes = dict.fromkeys(
        o["detail"].split("likely cause: ", 1)[1] for fo in ff for o in fo if "likely cause: " in o.get("detail", "")
    )
    return kinds + (f" (likely cause: {'; '.join(causes)})" if causes else "")


def _gain(mj: dict) -> str:
    """The robot's resistance against the sliding gain, υ and ω channels (``×`` the gain), or ``—``."""
    d = (mj.get("demand") or [None])[0] or {}
    r = [(d.get(k) or {}).get("ratio") for k in GAIN_ITEMS]
    return ", ".join("—" if x is None else f"{x:.2g}" for x in r) if any(x is not None for x in r) else "—"


def _mm(mj: dict) -> str:
    """The followers' final formation errors in mm, or ``—``."""
    e = [x for x in (mj or {}).get("final_formation_error_m") or [] if x is not None]
    return ", ".join(f"{1000 * x:.0f}" for x in e) if e else "—"


def _traction(mj: dict) -> str:
    """The mapped torque limit against the traction limit, or ``—``."""
    d = ((mj.get("demand") or [None])[0] or {}).get("torque_vs_traction") or {}
    return f"{d['ratio']:.2g}" if d.get("ratio") is not None else "—"


def _set_by(note: str) -> str:
    """What set σ, from the summary's ``scale_note`` (e.g. ``wheel speed 0.158 m/s``)."""
    m = re.search(r"time_scale = [^(]*\(auto: set by the '[^']+' (.+?) against (.+?) at σ", note or "")
    return f"{m.group(1)} vs {m.group(2)}" if m else (note or "")[:80]


def _expected(row: dict) -> str:
    """``; VERDICT``: the verdict the independent reference expects (``tests/zoo/reference.py``), or ``""``."""
    return f"; {row['expected_verdict']}" if row.get("expected_verdict") else ""


def markdown(rows: list[dict]) -> str:
    lines = [
        "| robot (maker) | `robot check` (ours; the reference expects) | top speed m/s (maker's) | s | σ (set by) "
        "| run s (paper s × σ) | worst demand/limit | τ_max/traction | resistance/sliding gain υ, ω | hardware "
        "| ĉ − c_true, ideal plant (a, b per follower) | outcomes, ideal | ĉ − c_true, MuJoCo | final formation error "
        "mm, MuJoCo | outcomes, MuJoCo |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        if "verdict" not in row:
            lines.append(f"| {row['robot']} ({row['maker']}) | not measured this round |" + " |" * 13)
            continue
        cause = f" ({row['cause']})" if row.get("cause") else ""
        top = f"{row['top_speed_mps']:g} (datasheet)" if row.get("top_speed_mps") else "— (file's limit)"
        cf = row.get("counterfactual") or {}
        what = [f"{k}={json.dumps(v)}" for k, v in (cf.get("map") or {}).items()] + list(cf.get("set") or [])
        name = row["robot"] + (f" [{', '.join(what)}]" if what else "")
        head = f"| {name} ({row['maker']}) | {row['verdict']}{cause}{_expected(row)} | {top} | "
        if "scale" not in row:
            lines.append(head + f"— | — | — | — | — | — | — | refused: {row.get('run_error', '')[:160]} | | | | |")
            continue
        note = _set_by(row.get("scale_note"))
        ideal, mj = row.get("ideal") or {}, row.get("mujoco") or {}
        w = _worst_of(mj.get("demand") or [])
        worst = f"{w['ratio']:.2f} ({w['name']})" if w else "—"
        hw = mj.get("hardware") or {}
        hwv = hw.get("verdict") or "—"
        if hw.get("failed"):
            hwv += f" ({', '.join(hw['failed'])})"
        elif hw.get("not_checked"):
            hwv += f" (not checked: {', '.join(hw['not_checked'])})"
        mjc = "; ".join(_pct(c) for c in mj.get("c_hat_rel_error", [])) if mj else "—"
        mjo = _outs(mj["outcomes"]) if mj else f"run refused: {row.get('run_error', '')[:160]}"
        lines.append(
            head + f"{row['scale']:.3g} | {row['time_scale']:.3g} ({note}) | {row['duration_s']:.0f} "
            f"({row['paper_duration_s']:g} × σ) | {worst} | {_traction(mj)} | {_gain(mj)} | {hwv} | "
            + "; ".join(_pct(c) for c in ideal.get("c_hat_rel_error", []))
            + f" | {_outs(ideal.get('outcomes', []))} | {mjc} | {_mm(mj)} | {mjo} |"
        )
    return "\n".join(lines) + "\n"


def _span(cs: list, j: int) -> str:
    """Follower ``ĉ`` errors of channel ``j`` as ``mean %`` or, spread over 10 points, ``lo…hi %``."""
    v = [100 * c[j] for c in cs if c and c[j] is not None]
    if not v:
        return "—"
    return f"{min(v):+.0f}…{max(v):+.0f} %" if max(v) - min(v) > 10 else f"{sum(v) / len(v):+.0f} %"


def compact(rows: list[dict]) -> str:
    """The README's table: one line per robot, ``ĉ`` over the three followers (mean, or the range)."""
    lines = [
        "| robot (maker) | `robot check` (ours; the reference expects) | top speed m/s (maker's) | s | σ "
        "| worst demand/limit | hardware | ĉ − c_true, ideal plant: a, b | ĉ − c_true, MuJoCo: a, b "
        "| formation error mm | outcomes, MuJoCo |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        if "verdict" not in row:
            lines.append(f"| {row['robot']} ({row['maker']}) | not measured this round |" + " |" * 9)
            continue
        link = f"[{row['robot']}]({row['source']}) ({row['maker']}, {row['format'].upper()})"
        cause = f" ({row['cause']})" if row.get("cause") else ""
        top = f"{row['top_speed_mps']:g}" if row.get("top_speed_mps") else "0.015 (URDF)"
        if "scale" not in row:
            lines.append(f"| {link} | {row['verdict']}{cause}{_expected(row)} | {top} |" + " — |" * 7 + " refused |")
            continue
        ideal, mj = row.get("ideal") or {}, row.get("mujoco") or {}
        w = _worst_of(mj.get("demand") or [])
        hw = mj.get("hardware") or {}
        hwv = (hw.get("verdict") or "—") + (f" ({', '.join(hw['failed'])})" if hw.get("failed") else "")
        ci, cm = ideal.get("c_hat_rel_error", []), mj.get("c_hat_rel_error", [])
        outs = _outs(mj["outcomes"]).split(" (likely cause")[0] if mj else "refused (robot check)"
        lines.append(
            f"| {link} | {row['verdict']}{cause}{_expected(row)} | {top} | {row['scale']:.3g} | "
            f"{row['time_scale']:.3g} | "
            + (f"{w['ratio']:.2f} ({w['name']})" if w else "—")
            + f" | {hwv if mj else '—'} | {_span(ci, 0)}, {_span(ci, 1)} | "
            + (f"{_span(cm, 0)}, {_span(cm, 1)}" if mj else "—")
            + f" | {_mm(mj)} | {outs} |"
        )
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="the paper's duration, s (the run's is × σ)")
    ap.add_argument("--robots", default="", help="comma-separated names (default: all)")
    ap.add_argument("--out", type=Path, default=Path("runs/zoo/zoo_table.md"))
    ap.add_argument("--json", type=Path, default=Path("runs/zoo/zoo_table.json"))
    ap.add_argument("--set", action="append", default=[], help="a further scenario override KEY=VALUE (repeatable)")
    ap.add_argument(
        "--map", action="append", default=[], help="a counterfactual mapping key KEY=JSON, e.g. caster_friction=0"
    )
    ap.add_argument("--table-only", action="store_true", help="write --out from --json, run nothing")
    a = ap.parse_args()
    a.map = {k: json.loads(v) for k, v in (m.split("=", 1) for m in a.map)}
    spec = importlib.util.spec_from_file_location("zoo_reference", ZOO / "reference.py")
    ref_mod = importlib.util.module_from_spec(spec)
    sys.modules["zoo_reference"] = ref_mod
    spec.loader.exec_module(ref_mod)
    os.environ["ROS_PACKAGE_PATH"] = ":".join(str(ZOO / r.name) for r in ref_mod.ROBOTS)

    from bioform_mj.assess.check import check

    names = [n for n in a.robots.split(",") if n] or [r.name for r in ref_mod.ROBOTS]
    if a.table_only:
        names = []
    old = json.loads(a.json.read_text()) if a.json.exists() else []
    rows = {row["robot"]: row for row in old}
    a.json.parent.mkdir(parents=True, exist_ok=True)
    by_name = {r.name: r for r in ref_mod.ROBOTS}
    for name in names:  # in the order given
        r = by_name[name]
        rows[r.name] = measure(r, a, check("paper", identify_=False)["half_track_m"])
        order = [x.name for x in ref_mod.ROBOTS if x.name in rows]
        a.json.write_text(json.dumps([rows[n] for n in order], indent=1, default=str, ensure_ascii=False) + "\n")
        print(json.dumps({k: rows[r.name].get(k) for k in ("robot", "scale", "time_scale", "run_error")}))
    md = markdown([rows.get(x.name, {"robot": x.name, "maker": x.maker}) for x in ref_mod.ROBOTS])
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(md)
    a.out.with_name(a.out.stem + "_compact.md").write_text(
        compact([rows.get(x.name, {"robot": x.name, "maker": x.maker}) for x in ref_mod.ROBOTS])
    )
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
