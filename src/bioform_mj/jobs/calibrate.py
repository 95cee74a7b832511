"""Calibration of the conditions the paper leaves unstated, against its Table I (issue 14).

``bioform calibrate table1 [--plant ideal|mujoco] [--budget N] --out DIR`` searches

* the followers' initial poses, each within ±3 m (x, y) of ``scenarios/paper.toml``'s and a
  heading in [−π/2, π/2];
* the scale of ``ĉ(0) = s · c_true`` (s ∈ [0.25, 2], log-uniform);
* the command derivative (``filter``, ``difference``, ``analytic``; design §6) and the filter's
  ``ω_n`` ∈ [10, 10⁴] rad/s (log-uniform);
* the wheel torque limit ∈ [2, 10⁴] N·m (log-uniform) and the saturation mode;
* the estimator gain assignment: eq. 13's simulation (``ka = 25, kb = 1``) or eq. 15's proof
  (``ka = 1, kb = 25``)

for the best fit to the paper's twelve Table I numbers and Fig. 4's "over 8 m/s" peak ``υ_cmd``
of conventional backstepping. The objective is the RMS of 13 log residuals: ``log(ours/paper)``
per cell, and for the peak ``log(peak/8)`` below 8 m/s, ``log(peak/10)`` above 10 m/s, 0 between
(we read "over 8" as 8–10 m/s); plus 1 when a method loses the formation (a final formation error
above 0.5 m: the paper's Figs. 5–6 show every method holding it) and 10 for a run that diverges.

The optimiser is scipy's differential evolution (integer dimensions for the categorical
conditions), seeded with the scenario's own conditions and a scrambled Sobol sample; a budget
smaller than two populations is spent on that sample alone (quasi-random search). Evaluations
run on worker processes forked after the kernels are loaded, by the sweep's runner
(``jobs.run_local``: workers ignore SIGINT and are terminated by this process on a signal).
Then every condition is moved alone from the best (``sensitivity``). Output:
``DIR/calibration.json`` and ``DIR/calibration.md``; while it runs, ``DIR/evaluations.jsonl``
(one line per evaluation, appended as each finishes: a rerun of the same command reuses them) and,
after SIGINT/SIGTERM, ``DIR/calibration.partial.json`` (the best so far). Design §16.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import signal
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import BioformError, InputError
from bioform_mj.jobs.table1 import PAPER_TABLE1
from bioform_mj.outputs.files import write_json, write_text

TARGETS = ("table1",)
DERIVS = ("filter", "difference", "analytic")
SATS = ("steer-priority", "wheel")
ESTS = ("eq13", "eq15")
#: eq. 13's simulation gains and eq. 15's (proof) assignment: (ka, kb)
EST_GAINS = {"eq13": (25.0, 1.0), "eq15": (1.0, 25.0)}
#: Fig. 4: backstepping's peak υ_cmd "over 8 m/s", read as this band (m/s)
PEAK_BAND = (8.0, 10.0)
#: the calibration's own penalty threshold (m; not the ``lost`` outcome's, ``core/thresholds.py``)
PENALTY_LOST_M = 0.5
DIVERGED_PENALTY = 10.0
LOST_PENALTY = 1.0
POSE_HALF_RANGE = 3.0
DEFAULT_BUDGET = {"ideal": 600, "mujoco": 90}

# the search vector: 9 pose numbers, then these
_LOG_C = (math.log10(0.25), math.log10(2.0))
_LOG_WN = (1.0, 4.0)
_LOG_TAU = (math.log10(2.0), 4.0)


def _bounds(base_poses: np.ndarray) -> list[tuple[float, float]]:
    b: list[tuple[float, float]] = []
    for x, y, _ in base_poses:
        b += [
            (x - POSE_HALF_RANGE, x + POSE_HALF_RANGE),
            (y - POSE_HALF_RANGE, y + POSE_HALF_RANGE),
            (-math.pi / 2, math.pi / 2),
        ]
    return b + [_LOG_C, (0, len(DERIVS) - 1), _LOG_WN, _LOG_TAU, (0, len(SATS) - 1), (0, len(ESTS) - 1)]


def _integrality(n_pose: int) -> np.ndarray:
    return np.array([False] * n_pose + [False, True, False, False, True, True])


def to_conditions(x: Sequence[float], n: int) -> dict[str, Any]:
    """The search vector ``x`` as named conditions (categorical entries rounded)."""
    x = list(map(float, x))
    k = 3 * n
    poses = [[round(x[3 * i], 4), round(x[3 * i + 1], 4), round(x[3 * i + 2], 4)] for i in range(n)]
    pick = lambda v, opts: opts[int(min(max(round(v), 0), len(opts) - 1))]  # noqa: E731
    return {
        "initial_poses": poses,
        "c_hat0_scale": round(10 ** x[k], 4),
        "derivative": pick(x[k + 1], DERIVS),
        "deriv_wn": round(10 ** x[k + 2], 2),
        "tau_max": round(10 ** x[k + 3], 3),
        "saturation": pick(x[k + 4], SATS),
        "estimator_gains": pick(x[k + 5], ESTS),
    }


def to_vector(c: dict[str, Any]) -> np.ndarray:
    """Inverse of :func:`to_conditions`."""
    v = [float(p) for pose in c["initial_poses"] for p in pose]
    v += [
        math.log10(c["c_hat0_scale"]),
        DERIVS.index(c["derivative"]),
        math.log10(c["deriv_wn"]),
        math.log10(c["tau_max"]),
        SATS.index(c["saturation"]),
        ESTS.index(c["estimator_gains"]),
    ]
    return np.array(v)


def scenario_conditions(sc) -> dict[str, Any]:
    """The conditions a scenario already has (the starting point and the comparison)."""
    ka, kb = sc.estimator.ka[0], sc.estimator.kb[0]
    est = "eq15" if ka < kb else "eq13"
    return {
        "initial_poses": [list(map(float, p)) for p in sc.formation.initial_poses],
        "c_hat0_scale": float(sc.learner.c_hat0_scale[0]),
        "derivative": sc.torque.derivative,
        "deriv_wn": float(sc.torque.deriv_wn),
        "tau_max": float(sc.torque.tau_max),
        "saturation": sc.torque.saturation,
        "estimator_gains": est,
    }


def build_scenario(source: str, plant: str, c: dict[str, Any], overrides: Sequence[str] = ()):
    """The scenario ``source`` under the conditions ``c`` on ``plant``."""
    from bioform_mj.robots.refs import RobotRef
    from bioform_mj.scenario.loader import load

    ka, kb = EST_GAINS[c["estimator_gains"]]
    s = c["c_hat0_scale"]
    poses = "[" + ",".join("[" + ",".join(repr(float(v)) for v in p) + "]" for p in c["initial_poses"]) + "]"
    ov = list(overrides) + [
        f"formation.initial_poses={poses}",
        f"learner.c_hat0_scale=[{s!r},{s!r}]",
        f'torque.derivative="{c["derivative"]}"',
        f"torque.deriv_wn={float(c['deriv_wn'])!r}",
        f'torque.saturation="{c["saturation"]}"',
        f"estimator.ka=[{ka},{ka}]",
        f"estimator.kb=[{kb},{kb}]",
    ]
    if c["tau_max"] is not None:
        ov.append(f"torque.tau_max={float(c['tau_max'])!r}")
    sc = load(source, ov, plant=plant)
    if plant == "mujoco" and c["tau_max"] is not None:  # the robots' motors get this limit (None: their own)
        robots = tuple(
            dataclasses.replace(r, tau_max=float(c["tau_max"]))
            if isinstance(r, RobotRef)
            else RobotRef(str(r), tau_max=float(c["tau_max"]))
            for r in sc.plant.robots
        )
        sc = dataclasses.replace(sc, plant=dataclasses.replace(sc.plant, robots=robots))
    return sc


def score(per: dict[str, list[float]], peak: float, lost: bool, diverged: bool) -> dict[str, float]:
    """Objective terms from Table I values ``per[method][follower]`` and backstepping's peak ``υ_cmd``."""
    cells = [math.log(max(per[m][i], 1e-12) / PAPER_TABLE1[m][i]) for m in PAPER_TABLE1 for i in range(3)]
    lo, hi = PEAK_BAND
    rp = math.log(peak / lo) if peak < lo else (math.log(peak / hi) if peak > hi else 0.0)
    rms = math.sqrt(sum(r * r for r in cells) / len(cells))
    fit = math.sqrt((sum(r * r for r in cells) + rp * rp) / (len(cells) + 1))
    obj = fit + (LOST_PENALTY if lost else 0.0) + (DIVERGED_PENALTY if diverged else 0.0)
    return {"objective": obj, "fit": fit, "rms_log_residual": rms, "peak_log_residual": rp}


# ----------------------------------------------------------------------------- evaluation
_CTX: dict[str, Any] = {}


def evaluate(
    c: dict[str, Any], source: str = "paper", plant: str = "ideal", overrides: Sequence[str] = ()
) -> dict[str, Any]:
    """One evaluation: Table I (four methods) under the conditions ``c``."""
    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.jobs.table1 import run_table1

    t0 = time.perf_counter()
    try:
        with quiet_outcomes():  # the objective scores lost and diverged runs (design §18.1)
            tab = run_table1(build_scenario(source, plant, c, overrides))
    except Exception as exc:  # noqa: BLE001 - a failed evaluation is a bad point, not the end of the search
        return {
            "conditions": c,
            "objective": DIVERGED_PENALTY * 2,
            "error": f"{type(exc).__name__}: {exc}",
            "wall_s": time.perf_counter() - t0,
        }
    ms = tab["methods"]
    per = {m: [float(f["total_velocity_error"]) for f in ms[m]["followers"]] for m in PAPER_TABLE1}
    peak = max(float(f["max_abs_v_cmd"]) for f in ms["backstepping"]["followers"])
    final = {m: max(float(f["final_formation_error_m"]) for f in ms[m]["followers"]) for m in PAPER_TABLE1}
    diverged = [m for m in PAPER_TABLE1 if ms[m].get("diverged")]
    lost = [m for m in PAPER_TABLE1 if not final[m] <= PENALTY_LOST_M]
    sat = {m: max(float(f["saturation_fraction"]) for f in ms[m]["followers"]) for m in PAPER_TABLE1}
    lim = [
        f.get("robot", {}).get("tau_max_nm") if isinstance(f.get("robot"), dict) else f.get("tau_max_nm")
        for f in ms["backstepping"]["followers"]
    ]
    out = {
        "conditions": c,
        **score(per, peak, bool(lost), bool(diverged)),
        "per": per,
        "robot_tau_max": max((x for x in lim if x is not None), default=None),
        "peak_v_cmd_backstepping": peak,
        "final_formation_error_m": final,
        "saturation_fraction": sat,
        "lost": lost,
        "diverged": diverged,
        "ordering_holds": bool(tab["ordering_holds"]),
        "stepping_s": sum(float(ms[m].get("wall_time_s") or 0.0) for m in ms),
        "wall_s": time.perf_counter() - t0,
    }
    return out


def _eval_in_worker(c: dict[str, Any]) -> dict[str, Any]:
    return evaluate(c, _CTX["source"], _CTX["plant"], _CTX["overrides"])


def _table_rows(ev: dict[str, Any]) -> list[dict[str, Any]]:
    rows = []
    for m, paper in PAPER_TABLE1.items():
        for i, p in enumerate(paper):
            ours = ev["per"][m][i] if "per" in ev else float("nan")
            rows.append(
                {
                    "method": m,
                    "follower": i + 1,
                    "ours": round(ours, 4),
                    "paper": p,
                    "log_residual": round(math.log(ours / p), 4) if ours > 0 else None,
                }
            )
    rows.append(
        {
            "method": "backstepping",
            "follower": "max",
            "quantity": "peak |v_cmd| (m/s), Fig. 4",
            "ours": round(ev.get("peak_v_cmd_backstepping", float("nan")), 3),
            "paper": "over 8 (read as 8-10)",
            "log_residual": round(ev.get("peak_log_residual", float("nan")), 4),
        }
    )
    return rows


def _sensitivity_points(best: dict[str, Any], default: dict[str, Any]) -> list[tuple[str, Any, dict[str, Any]]]:
    """(condition, value, conditions) with one condition moved from ``best``."""
    pts: list[tuple[str, Any, dict[str, Any]]] = []

    def alt(name: str, value: Any, **changes: Any) -> None:
        c = dict(best)
        c.update(changes)
        if c != best:
            pts.append((name, value, c))

    alt("initial_poses", "paper.toml's", initial_poses=default["initial_poses"])
    for s in (0.25, 0.5, 1.0, 2.0):
        alt("c_hat0_scale", s, c_hat0_scale=s)
    for d in DERIVS:
        alt("derivative", d, derivative=d)
    if best["derivative"] == "filter":
        for wn in (10.0, 50.0, 200.0, 1000.0, 10000.0):
            alt("deriv_wn", wn, deriv_wn=wn)
    for t in (5.0, 20.0, 100.0, 10000.0):
        alt("tau_max", t, tau_max=t)
    for s in SATS:
        alt("saturation", s, saturation=s)
    for e in ESTS:
        alt("estimator_gains", e, estimator_gains=e)
    return pts


#: most evaluations one calibration may ask (design §16): beyond, the estimate is refused (exit 2)
MAX_BUDGET = 100_000
#: estimated memory one kept evaluation takes (its record in the history, ~3 kB, with margin)
EVALUATION_BYTES = 10e3
EVALUATIONS_FILE = "evaluations.jsonl"
PARTIAL_FILE = "calibration.partial.json"
_HEADER_KIND = "bioform calibrate evaluations"


class CalibrationInterrupted(BioformError):
    """SIGINT/SIGTERM stopped the calibration; the evaluations done are kept in ``evaluations.jsonl``."""

    def __init__(self, signum: int, done: int, kept: str) -> None:
        self.signum, self.done, self.kept = signum, done, kept
        super().__init__(f"interrupted ({signal.Signals(signum).name}) after {done} evaluations; {kept}")


class _Stopped(Exception):
    """Raised through scipy's optimiser when a signal stopped the evaluations."""


def evaluation_seconds(sc: Any) -> float:
    """Estimated single-core seconds of one evaluation (Table I: four runs of ``sc``), from the sweep's cost model."""
    from bioform_mj.jobs.sweep import COST_SETUP_S, COST_US_PER_ROBOT_STEP

    kind = sc.plant.kind if sc.plant.kind in COST_SETUP_S else "mujoco"
    steps = sc.sim.duration / sc.sim.control_dt
    return 4 * (COST_SETUP_S[kind] + steps * sc.n * COST_US_PER_ROBOT_STEP[kind] * 1e-6)


def check_inputs(
    target: str,
    plant: str,
    budget: int | None,
    source: str,
    overrides: Sequence[str],
    workers: int | None,
) -> tuple[Any, int, int]:
    """Validate a calibration's input before any work (InputError, exit 2): returns
    ``(scenario, budget, workers)``. A budget above :data:`MAX_BUDGET`, or whose history does not fit
    in memory, is refused with its estimated duration."""
    from bioform_mj.core.budget import fmt_bytes, fmt_seconds, require
    from bioform_mj.scenario.config import PLANTS
    from bioform_mj.scenario.loader import load

    if target not in TARGETS:
        raise InputError(f"unknown calibration target '{target}' (expected one of: {', '.join(TARGETS)})")
    if plant not in PLANTS:
        raise InputError(f"--plant: unknown '{plant}' (expected one of: {', '.join(PLANTS)})")
    budget = DEFAULT_BUDGET[plant] if budget is None else int(budget)
    if budget < 1:
        raise InputError(f"--budget must be >= 1 evaluation, got {budget}")
    from bioform_mj.jobs.runner import check_workers

    check_workers(workers, local=True)  # forked on this machine: 1 to 8 per CPU
    workers = min(os.cpu_count() or 1, 2) if workers is None else int(workers)
    base = load(source, list(overrides), plant=plant)  # validates the scenario (exit 2 before any work)
    if base.n != 3:
        raise InputError(f"Table I has three followers; scenario '{source}' has {base.n}")
    each = evaluation_seconds(base)
    if budget > MAX_BUDGET:
        raise InputError(
            f"--budget {budget}: {budget:.3g} evaluations of ~{each:.2g} s each (estimated) on {workers} worker(s) "
            f"would take about {fmt_seconds(budget * each / workers)}; at most {MAX_BUDGET} evaluations"
        )
    require(budget * EVALUATION_BYTES, f"--budget {budget} ({fmt_bytes(EVALUATION_BYTES)} per evaluation kept)")
    return base, budget, workers


def _context(base: Any, target: str, plant: str, seed: int) -> dict[str, Any]:
    """What the evaluations of a calibration depend on besides their conditions (a resume checks it)."""
    from bioform_mj.jobs.provenance import provenance
    from bioform_mj.jobs.sweep import config_text

    return {
        "target": target,
        "plant": plant,
        "seed": seed,
        "scenario": hashlib.sha1(config_text(base).encode()).hexdigest()[:16],
        "provenance": provenance(base),
    }


def _ckey(c: dict[str, Any]) -> str:
    return json.dumps(c, sort_keys=True, separators=(",", ":"))


def load_evaluations(path: Path, context: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The evaluations kept in ``path`` by an earlier run with the same ``context``, by conditions;
    InputError when they belong to another calibration (other scenario, code, robot files, seed).
    A last line cut short (the process was killed mid-write) is ignored."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        return {}
    if not lines:
        return {}
    try:
        head = json.loads(lines[0])
    except ValueError:
        head = {}
    if head.get("kind") != _HEADER_KIND:
        raise InputError(f"'{path}' is not a calibration's evaluations file; use --overwrite or another --out")
    old = head.get("context", {})
    why = [k for k in ("target", "plant", "seed", "scenario") if old.get(k) != context[k]]
    from bioform_mj.jobs.provenance import differences

    why += differences(old.get("provenance"), context["provenance"])
    if why:
        raise InputError(
            f"'{path}' holds the evaluations of another calibration ({'; '.join(why[:3])}): they cannot be "
            "resumed; use --overwrite to start again, or another --out"
        )
    cache: dict[str, dict[str, Any]] = {}
    for ln in lines[1:]:
        try:
            ev = json.loads(ln)
        except ValueError:
            continue  # cut short
        if isinstance(ev, dict) and "conditions" in ev and "objective" in ev:
            cache[_ckey(ev["conditions"])] = ev
    return cache


def _eval_item(item: tuple[int, dict[str, Any]]) -> dict[str, Any]:
    return {"i": item[0], "ev": _eval_in_worker(item[1])}


def _died_item(item: tuple[int, dict[str, Any]], reason: str) -> dict[str, Any]:
    c = item[1]
    return {"i": item[0], "ev": {"conditions": c, "objective": DIVERGED_PENALTY * 2, "error": f"worker died: {reason}"}}


def calibrate(
    target: str = "table1",
    plant: str = "ideal",
    budget: int | None = None,
    source: str = "paper",
    overrides: Sequence[str] = (),
    workers: int | None = None,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    out: str | Path | None = None,
    note: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the search and the sensitivity analysis; returns the report (see module doc).

    With ``out``, every evaluation is appended to ``out/evaluations.jsonl`` as it finishes, and
    evaluations already there (same scenario, code, robot files and seed) are reused: the search is
    deterministic for a seed, so a rerun replays them and goes on where the last one stopped.
    SIGINT/SIGTERM stop the evaluations in seconds (workers terminated), write the best so far to
    ``out/calibration.partial.json`` and raise :class:`CalibrationInterrupted`. ``note(text)`` is
    told the evaluation count and an estimated duration once the first evaluation is timed.
    """
    from scipy.optimize import differential_evolution
    from scipy.stats import qmc

    from bioform_mj.core.budget import fmt_seconds
    from bioform_mj.jobs.runner import Signals, run_local

    base, budget, workers = check_inputs(target, plant, budget, source, overrides, workers)
    default = scenario_conditions(base)
    bounds = _bounds(np.array(default["initial_poses"]))
    n = base.n
    t_start = time.perf_counter()
    _CTX.update(source=source, plant=plant, overrides=list(overrides))

    ev_path = Path(out) / EVALUATIONS_FILE if out is not None else None
    cache: dict[str, dict[str, Any]] = {}
    fh = None
    if ev_path is not None:
        context = _context(base, target, plant, seed)
        cache = load_evaluations(ev_path, context)
        if not cache:
            with open(ev_path, "w", encoding="utf-8") as f0:
                f0.write(json.dumps({"kind": _HEADER_KIND, "context": context}) + "\n")
        fh = open(ev_path, "a", encoding="utf-8")  # noqa: SIM115 - closed in the finally below
    reused = [0]
    history: list[dict[str, Any]] = []
    done = [0]
    total = budget

    def keep(ev: dict[str, Any]) -> None:
        if fh is not None and not str(ev.get("error", "")).startswith("worker died"):
            fh.write(json.dumps(ev, default=float) + "\n")  # one line per evaluation, flushed: a resume reads it
            fh.flush()

    def run_many(conds: list[dict[str, Any]], sig: Signals, nworkers: int) -> list[dict[str, Any]]:
        res: list[dict[str, Any] | None] = [None] * len(conds)
        todo = []
        for i, c in enumerate(conds):
            hit = cache.get(_ckey(c))
            if hit is not None:
                res[i] = hit
                reused[0] += 1
            else:
                todo.append((i, c))

        def got(row: dict[str, Any]) -> None:
            res[row["i"]] = row["ev"]
            keep(row["ev"])

        if todo:
            run_local(todo, nworkers, sig, got, fn=_eval_item, died=_died_item)
        if sig.signum is not None:
            history.extend(r for r in res if r is not None)
            raise _Stopped()
        history.extend(res)  # type: ignore[arg-type]
        done[0] += len(res)
        if progress is not None:
            progress(min(done[0], total), total)
        return res  # type: ignore[return-value]

    d = len(bounds)
    pop = max(5, 2 * d)
    x0 = to_vector(default)
    lo, hi = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    method = "quasi-random search (scrambled Sobol)"
    sens_pts: list = []
    sens_res: list = []
    search_evals = 0
    try:
        with Signals() as sig:
            try:
                if plant == "mujoco":  # its own limit is the robots' motors' (torque.tau_max is the ideal plant's)
                    ev_default = run_many([dict(default, tau_max=None)], sig, 1)[0]
                    default["tau_max"] = float(ev_default.get("robot_tau_max") or default["tau_max"])
                    ev_default = dict(ev_default, conditions=default)
                    history[-1] = ev_default
                else:
                    ev_default = run_many([default], sig, 1)[0]  # in this process: loads the kernels before the fork
                if note is not None:
                    each = float(ev_default.get("wall_s") or evaluation_seconds(base))
                    n_sens = len(_sensitivity_points(default, scenario_conditions(base))) + 8
                    left = max(0, budget - 1 - len(cache)) + n_sens
                    was = f"; {len(cache)} kept in {ev_path} are reused" if cache else ""
                    note(
                        f"calibrate: {budget} evaluations in the search + ~{n_sens} for the sensitivity on {workers} "
                        f"worker(s), {each:.2g} s each (the first one, measured): estimated "
                        f"{fmt_seconds(left * each / workers)}{was}"
                    )

                def de_map(_func: Callable, xs: Any) -> list[float]:
                    return [r["objective"] for r in run_many([to_conditions(x, n) for x in xs], sig, workers)]

                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # Sobol balance warnings for sample sizes not a power of 2
                    sob = qmc.Sobol(d, scramble=True, seed=seed)
                    if budget < 2 * pop:
                        pts = qmc.scale(sob.random(max(budget - 1, 0)), lo, hi) if budget > 1 else np.zeros((0, d))
                        run_many([to_conditions(x, n) for x in pts], sig, workers)
                    else:
                        method = "differential evolution (scipy.optimize, rand1bin, integer categorical dimensions)"
                        init = np.vstack([x0, qmc.scale(sob.random(pop - 1), lo, hi)])
                        ints = _integrality(3 * n)
                        init[:, ints] = np.round(init[:, ints])
                        maxiter = max(budget // pop - 1, 0)
                        differential_evolution(
                            lambda x: 0.0,
                            bounds,
                            init=init,
                            maxiter=maxiter,
                            popsize=pop,
                            integrality=ints,
                            workers=de_map,
                            updating="deferred",
                            polish=False,
                            tol=0.0,
                            atol=0.0,
                            seed=seed,
                            mutation=(0.5, 1.0),
                            recombination=0.7,
                        )
                search_evals = len(history)
                good = [h for h in history if "per" in h]
                best = min(good or history, key=lambda h: h["objective"])
                sens_pts = _sensitivity_points(best["conditions"], default)
                sens_res = run_many([c for _, _, c in sens_pts], sig, workers)
            except _Stopped:
                signum = sig.signum or signal.SIGINT
                kept = _write_partial(history, out, signum)
                raise CalibrationInterrupted(signum, len(history), kept) from None
    finally:
        if fh is not None:
            fh.close()
    if out is not None:
        with contextlib.suppress(FileNotFoundError):
            (Path(out) / PARTIAL_FILE).unlink()

    sensitivity: dict[str, Any] = {}
    for (name, value, _), r in zip(sens_pts, sens_res):
        e = sensitivity.setdefault(
            name,
            {"best_value": best["conditions"][name] if name != "initial_poses" else "calibrated", "alternatives": []},
        )
        e["alternatives"].append(
            {
                "value": value,
                "objective": round(r["objective"], 4),
                "rms_log_residual": round(r.get("rms_log_residual", float("nan")), 4),
                "peak_v_cmd_backstepping": round(r.get("peak_v_cmd_backstepping", float("nan")), 3),
                "lost": r.get("lost", []),
                "ordering_holds": r.get("ordering_holds"),
            }
        )
    for e in sensitivity.values():
        e["max_objective_change"] = round(max(a["objective"] for a in e["alternatives"]) - best["objective"], 4)
    stepping = [h["stepping_s"] for h in history if "stepping_s" in h]
    report = {
        "target": target,
        "plant": plant,
        "scenario": source,
        "overrides": list(overrides),
        "seed": seed,
        "budget": budget,
        "evaluations": {
            "search": search_evals,
            "sensitivity": len(sens_res),
            "total": len(history),
            "reused": reused[0],
        },
        "optimiser": method,
        "workers": workers,
        "wall_s": round(time.perf_counter() - t_start, 2),
        "stepping_s_per_evaluation": {
            "median": round(float(np.median(stepping)), 4) if stepping else None,
            "max": round(float(np.max(stepping)), 4) if stepping else None,
        },
        "objective_definition": (
            "RMS of 13 log residuals: log(ours/paper) for the 12 Table I cells and, for "
            "backstepping's peak |v_cmd|, log(peak/8) below 8 m/s, log(peak/10) above 10, 0 "
            f"between; + {LOST_PENALTY} when a method ends > {PENALTY_LOST_M} m off the formation, "
            f"+ {DIVERGED_PENALTY} when a run diverges"
        ),
        "search_space": {
            "initial_poses": f"paper.toml's ±{POSE_HALF_RANGE} m in x and y, heading in [-pi/2, pi/2]",
            "c_hat0_scale": [0.25, 2.0],
            "derivative": list(DERIVS),
            "deriv_wn": [10.0, 1e4],
            "tau_max": [2.0, 1e4],
            "saturation": list(SATS),
            "estimator_gains": {k: {"ka": v[0], "kb": v[1]} for k, v in EST_GAINS.items()},
        },
        "best": best["conditions"],
        "objective": round(best["objective"], 4),
        "rms_log_residual": round(best["rms_log_residual"], 4),
        "peak_v_cmd_backstepping": round(best["peak_v_cmd_backstepping"], 3),
        "ordering_holds": best["ordering_holds"],
        "lost": best["lost"],
        "diverged": best["diverged"],
        "final_formation_error_m": {m: round(v, 4) for m, v in best["final_formation_error_m"].items()},
        "saturation_fraction": {m: round(v, 3) for m, v in best["saturation_fraction"].items()},
        "table": _table_rows(best),
        "default": {
            "conditions": default,
            "objective": round(ev_default["objective"], 4),
            "rms_log_residual": round(ev_default.get("rms_log_residual", float("nan")), 4),
            "peak_v_cmd_backstepping": round(ev_default.get("peak_v_cmd_backstepping", float("nan")), 3),
            "lost": ev_default.get("lost"),
            "table": _table_rows(ev_default),
        },
        "sensitivity": sensitivity,
        "top": [
            {
                "objective": round(h["objective"], 4),
                "rms_log_residual": round(h.get("rms_log_residual", 99), 4),
                "conditions": h["conditions"],
            }
            for h in sorted(history[:search_evals], key=lambda h: h["objective"])[:10]
        ],
    }
    return report


def _write_partial(history: list[dict[str, Any]], out: str | Path | None, signum: int) -> str:
    """The best evaluation so far as ``out/calibration.partial.json``; returns what was kept, in words."""
    if out is None:
        return f"{len(history)} evaluations done, nothing written (no output folder)"
    good = [h for h in history if "per" in h] or history
    ev_file = Path(out) / EVALUATIONS_FILE
    if not good:
        return f"nothing evaluated yet; rerun the same command to start ({ev_file})"
    best = min(good, key=lambda h: h["objective"])
    write_json(
        Path(out) / PARTIAL_FILE,
        {
            "interrupted": signal.Signals(signum).name,
            "evaluations_done": len(history),
            "objective": best["objective"],
            "rms_log_residual": best.get("rms_log_residual"),
            "best": best["conditions"],
            "resume": "rerun the same command: the evaluations kept in evaluations.jsonl are reused",
        },
    )
    return (
        f"{len(history)} evaluations kept in {ev_file}, the best so far (objective {best['objective']:.4g}) in "
        f"{Path(out) / PARTIAL_FILE}; rerun the same command to resume"
    )


def markdown(r: dict[str, Any]) -> str:
    """``calibration.md``: best conditions, the table beside the paper's, the sensitivity."""
    b = r["best"]
    lines = [
        f"# Calibration of Table I's unstated conditions ({r['plant']} plant, scenario '{r['scenario']}')",
        "",
        f"{r['optimiser']}; {r['evaluations']['search']} evaluations in the search + "
        f"{r['evaluations']['sensitivity']} for the sensitivity on {r['workers']} worker(s), {r['wall_s']:.0f} s; "
        f"median stepping per evaluation (4 methods × 20 s) {r['stepping_s_per_evaluation']['median']} s.",
        "",
        f"Objective: {r['objective_definition']}.",
        "",
        f"**Best: objective {r['objective']:.3f}, RMS log residual over the 12 cells {r['rms_log_residual']:.3f} "
        f"(×{math.exp(r['rms_log_residual']):.2f} typical factor); backstepping peak |υ_cmd| "
        f"{r['peak_v_cmd_backstepping']:.2f} m/s; ordering {'holds' if r['ordering_holds'] else 'does NOT hold'}"
        + (f"; lost formation: {', '.join(r['lost'])}" if r["lost"] else "")
        + ".** "
        f"The scenario's own conditions: objective {r['default']['objective']:.3f}, RMS "
        f"{r['default']['rms_log_residual']:.3f}, peak {r['default']['peak_v_cmd_backstepping']:.2f} m/s.",
        "",
        "## Best conditions",
        "",
        "| condition | value |",
        "|---|---|",
        "| initial poses (x, y, θ) | "
        + "; ".join(f"({p[0]:.2f}, {p[1]:.2f}, {p[2]:.2f})" for p in b["initial_poses"])
        + " |",
        f"| ĉ(0) scale | {b['c_hat0_scale']} |",
        f"| command derivative | {b['derivative']} |",
        f"| ω_n (filter only) | {b['deriv_wn']} rad/s |",
        f"| torque limit | {b['tau_max']} N·m |",
        f"| saturation | {b['saturation']} |",
        f"| estimator gains | {b['estimator_gains']} (ka, kb = {EST_GAINS[b['estimator_gains']]}) |",
        "",
        "## Table I, ours (best) beside the paper's",
        "",
        "| method | follower | ours | paper | log(ours/paper) | scenario's own |",
        "|---|---|---|---|---|---|",
    ]
    for row, d in zip(r["table"], r["default"]["table"]):
        lr = row["log_residual"]
        lines.append(
            f"| {row['method']} | {row['follower']} | {row['ours']} | {row['paper']} | "
            f"{'' if lr is None else f'{lr:+.3f}'} | {d['ours']} |"
        )
    lines += [
        "",
        "## Sensitivity (one condition moved from the best)",
        "",
        "| condition | best | moved to → objective (RMS of the 12) | largest increase |",
        "|---|---|---|---|",
    ]
    for name, e in sorted(r["sensitivity"].items(), key=lambda kv: -kv[1]["max_objective_change"]):
        alts = "; ".join(
            f"{a['value']} → {a['objective']:.2f} ({a['rms_log_residual']:.2f})" + (" lost" if a["lost"] else "")
            for a in e["alternatives"]
        )
        lines.append(f"| {name} | {e['best_value']} | {alts} | {e['max_objective_change']:+.2f} |")
    return "\n".join(lines) + "\n"


def write(report: dict[str, Any], out) -> None:
    """``calibration.json`` and ``calibration.md`` in ``out`` (atomic writes)."""
    from pathlib import Path

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "calibration.json", report)
    write_text(out / "calibration.md", markdown(report))
