"""Table I of the paper: the four methods side by side (design §7).

Our metric is ``∫₀ᵀ (|υ_cmd − υ| + |ω_cmd − ω|) dt`` per follower (the paper gives
none); the claim to reproduce is the ordering, bioinspired-learning lowest.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from bioform_mj.control.stack import METHODS
from bioform_mj.run.simulate import RunResult, simulate
from bioform_mj.scenario.config import Scenario

#: The paper's Table I, "total velocity error", per follower 1..3.
PAPER_TABLE1: dict[str, tuple[float, float, float]] = {
    "backstepping": (20.6, 27.2, 33.5),
    "bioinspired": (5.3, 15.7, 18.9),
    "backstepping-learning": (8.9, 11.1, 12.8),
    "bioinspired-learning": (1.9, 1.1, 1.5),
}


def paper_differences(sc: Scenario) -> list[str]:
    """The keys in which ``sc`` is not the paper's experiment (empty: Table I's numbers are comparable).

    The experiment is the paper's leader, graph, three followers at the paper's offsets (world frame,
    scale 1), 20 s, the disturbance, the kinematic, torque-law (``c``) and learner gains (``k4, k5``, no
    ``kd``), no faults or events, and the paper's robot (``c_true = (0.4, 10)`` on the ideal plant, the
    ``paper`` robot on MuJoCo). What the paper leaves unstated may differ: initial poses, time steps,
    ``ĉ(0)``, torque limit and saturation, command derivative, boundary layers, estimator gains (eq. 13
    or eq. 15), the plant kind."""
    ref = Scenario()
    out = []
    for section, keys in (
        ("leader", None),
        ("graph", None),
        ("disturbance", None),
        ("kinematic", None),
        ("formation", ("offsets", "frame", "scale")),
        ("torque", ("c",)),
        ("learner", ("k4", "k5", "kd", "gain_scaling")),
        ("sim", ("duration",)),
    ):
        a, b = getattr(sc, section), getattr(ref, section)
        for f in dataclasses.fields(a):
            if (keys is None or f.name in keys) and getattr(a, f.name) != getattr(b, f.name):
                out.append(f"{section}.{f.name}")
    if sc.faults.configured:
        out.append("faults")
    if sc.events:
        out.append("events")
    if sc.plant.kind == "ideal" and tuple(sc.plant.c_true) != tuple(ref.plant.c_true):
        out.append("plant.c_true")
    if sc.plant.kind == "mujoco" and any(r.model != "paper" or r.mapped for r in sc.plant.robots):
        out.append("plant.robots")
    return out


def run_table1(
    sc: Scenario,
    on_result: Callable[[str, RunResult], None] | None = None,
    progress: Callable[[str], Callable[[int, int], None] | None] | None = None,
) -> dict[str, Any]:
    """Run the four methods on ``sc``; returns ``{"plant", "scenario", "methods": {METHOD: summary}}``.

    ``progress(method)``, if given, returns the ``progress(k, N)`` callback for that run.
    """
    differs = paper_differences(sc)
    out: dict[str, Any] = {
        "plant": sc.plant.kind,
        "scenario": sc.name,
        "paper_comparable": not differs,  # the paper's numbers are shown beside ours only then
        "differs_from_paper": differs,
        "methods": {},
    }
    for m in METHODS:
        res = simulate(dataclasses.replace(sc, method=m), progress=None if progress is None else progress(m))
        if getattr(res, "interrupted", None) is not None:  # SIGINT/SIGTERM: no further methods
            res.interrupted.result = res
            raise res.interrupted
        out["methods"][m] = res.summary
        if on_result is not None:
            on_result(m, res)
    out["ordering_holds"] = ordering_holds(out)
    return out


def ordering_holds(table: dict[str, Any]) -> bool:
    """True when bioinspired-learning has the lowest total velocity error for every follower."""
    per = {m: [f["total_velocity_error"] for f in s["followers"]] for m, s in table["methods"].items()}
    best = per["bioinspired-learning"]
    return all(best[i] <= min(v[i] for v in per.values()) for i in range(len(best)))


def _diverged(summary: dict[str, Any]) -> dict[str, Any] | None:
    return summary.get("diverged") or None


def _mark(summary: dict[str, Any], follower: dict[str, Any]) -> str:
    """`` [diverged]`` for a run that diverged, `` [tipped]`` etc. for a follower whose
    ``outcome`` is not ``ok`` (a summary without ``outcome`` is taken as ok); else ``""``."""
    if _diverged(summary):
        return " [diverged]"
    from bioform_mj.assess.outcomes import outcome_kinds

    kinds = outcome_kinds(follower)
    return f" [{', '.join(kinds)}]" if kinds else ""


def markdown(table: dict[str, Any]) -> str:
    """Table I as Markdown: our numbers, with the paper's beside them for followers 1–3.

    A method whose run diverged is marked ``[diverged]`` in every cell (its numbers cover
    the run up to the divergence), a follower whose ``outcome`` is not ``ok`` is marked with
    it (``[tipped]``, ``[slipping]``, …), and the notes under the table say what happened;
    the ordering claim is then qualified.
    """
    methods = list(table["methods"])
    comparable = table.get("paper_comparable", True)
    differs = table.get("differs_from_paper", [])
    paper_note = (
        "paper's value in brackets."
        if comparable
        else "the paper's values are not shown: they are not comparable, this scenario is not the paper's "
        f"experiment (it differs in {', '.join(differs)})."
    )
    lines = [
        f"# Table I: total velocity error ({table['plant']} plant, scenario '{table['scenario']}')",
        "",
        f"Metric: ∫(|υ_cmd − υ| + |ω_cmd − ω|) dt per follower; {paper_note}",
        "",
        "| follower | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    n = len(table["methods"][methods[0]]["followers"])
    for i in range(n):
        cells = []
        for m in methods:
            summ = table["methods"][m]
            f = summ["followers"][i]
            ours = f["total_velocity_error"]
            paper = PAPER_TABLE1.get(m) if comparable else None
            ref = f" ({paper[i]})" if paper and i < len(paper) and n == 3 else ""
            cells.append(f"{ours:.2f}{ref}{_mark(summ, f)}")
        lines.append(f"| {i + 1} | " + " | ".join(cells) + " |")
    notes = []
    for m in methods:
        summ = table["methods"][m]
        d = _diverged(summ)
        if d:
            when = d.get("time_s") if isinstance(d, dict) else None
            msg = d.get("message", "") if isinstance(d, dict) else str(d)
            notes.append(
                f"- **{m} diverged**"
                + (f" at t = {when:.3g} s" if isinstance(when, (int, float)) else "")
                + (f": {msg}" if msg else "")
                + "; its numbers cover the run up to then, not a result."
            )
        from bioform_mj.assess.outcomes import outcome_kinds

        bad = [(f["id"], " + ".join(outcome_kinds(f))) for f in summ["followers"] if outcome_kinds(f)]
        if bad and not d:
            notes.append(f"- **{m}**: " + ", ".join(f"follower {i} {o}" for i, o in bad) + ".")
    holds = "holds" if table.get("ordering_holds") else "does NOT hold"
    lines += [""]
    if notes:
        lines += ["Failed runs:", "", *notes, ""]
        holds += " (but see the failed runs above: the comparison is not valid for them)"
    lines += [f"Ordering (bioinspired-learning lowest for every follower): {holds}.", ""]
    lines += [
        "| method | final formation error (m) per follower | max abs v_cmd (m/s) | saturation fraction |",
        "|---|---|---|---|",
    ]
    for m in methods:
        summ = table["methods"][m]
        fs = summ["followers"]
        lines.append(
            f"| {m}{' [diverged]' if _diverged(summ) else ''} | "
            + ", ".join(f"{f['final_formation_error_m']:.3f}{_mark({}, f)}" for f in fs)
            + f" | {max(f['max_abs_v_cmd'] for f in fs):.2f} | "
            + ", ".join(f"{f['saturation_fraction']:.2f}" for f in fs)
            + " |"
        )
    return "\n".join(lines) + "\n"
