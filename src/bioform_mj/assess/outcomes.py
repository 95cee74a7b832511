"""What each follower's run came to (design §9, §14): the formation slots and :func:`outcome_list`, the one
list of outcomes both engines give a follower (:func:`follower_outcomes` for the CPU loops, ``batch.runner``'s
``_outcome`` for the device), on the one table of thresholds, ``core/thresholds.py``. Below
:mod:`bioform_mj.run.simulate` and :mod:`bioform_mj.assess.check`, which both import it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bioform_mj.core.thresholds import (
    C_HAT_BOUND_BAND,
    C_HAT_OFF,
    LOST_AFTER_S,
    LOST_FRACTION,
    LOST_M,
    SLIP_RATIO,
    SLIP_TIME,
    SPIN_RAD_S,
    TIP_ANGLE_DEG,
)
from bioform_mj.plants.base import RobotModels, TipSlipWatch
from bioform_mj.scenario.config import Scenario


def slots_of(sc: Scenario, leader_pose: np.ndarray) -> np.ndarray:
    """Formation slots (n, 2) m of the true leader at ``leader_pose`` (3,): ``p_r − Δ_i``, with the
    offsets rotated by the leader's heading for ``formation.frame = "leader"`` (design §4)."""
    off = np.asarray(sc.formation.offsets, dtype=float).reshape(sc.n, 2)
    if sc.formation.frame == "leader":
        c, s = np.cos(leader_pose[2]), np.sin(leader_pose[2])
        off = np.column_stack([c * off[:, 0] - s * off[:, 1], s * off[:, 0] + c * off[:, 1]])
    return np.asarray(leader_pose[:2], dtype=float)[None, :] - off


def lost_threshold_m(sc: Scenario) -> float:
    """The ``lost`` outcome's threshold, m: ``LOST_FRACTION`` (``core/thresholds.py``) × the formation's extent, the
    largest distance between two points of the leader and the followers' slots (``p_r − Δ_i``), from
    the resolved offsets (design §9). 1 m for the paper's formation (offsets (3, 0), (4, ±5): 10 m), so
    it scales with the experiment: 0.15 m for the ``tb3`` preset (``formation.scale = 0.15``), 0.25 m for
    ``stretch``. The one place both engines take it from."""
    pts = np.vstack([np.zeros((1, 2)), np.asarray(sc.formation.offsets, dtype=float)])
    extent = float(np.max(np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)))
    return LOST_FRACTION * extent


#: outcome kinds, the most severe first: a follower's ``outcome`` is the first of its ``outcomes`` (design §14)
OUTCOME_ORDER = (
    "controller_nonfinite",
    "tipped",
    "collided",
    "slipping",
    "spinning",
    "lost",
    "too_close",
    "c_hat_at_bound",
    "c_hat_off",
)


def severity(outcome: dict[str, Any]) -> int:
    """Sort key of an outcome ``{"kind", …}``: its place in :data:`OUTCOME_ORDER` (unknown kinds last)."""
    k = outcome.get("kind")
    return OUTCOME_ORDER.index(k) if k in OUTCOME_ORDER else len(OUTCOME_ORDER)


def outcome_kinds(follower: dict[str, Any]) -> list[str]:
    """Every outcome kind of one follower's summary entry, the most severe first (``[]`` when ok); a
    summary from before the ``outcomes`` list has only ``outcome``."""
    kinds = list(dict.fromkeys(o["kind"] for o in follower.get("outcomes") or []))  # a kind once (two collisions)
    o = follower.get("outcome")
    return kinds if o in (None, "ok") or o in kinds else [str(o), *kinds]


#: s: an identified drag with a longer time constant is not named (``robot check`` warns below 5 s, design §14)
DRAG_NAMED_S = 5.0


def identified_resistances(report: dict[str, Any]) -> list[dict[str, Any]]:
    """The resistances ``robot check`` identified (design §14.2; ``report``: :func:`bioform_mj.assess.check.check`'s),
    as a run's ``c_hat_off`` names them: ``{"kind": "braking_caster", "geom", "braking_force_n" (N, μ × load),
    "torque_nm" (N·m of wheel torque, × r), "while_driving", "lever_m" (m from the axle midpoint; None: not
    known), "contact" ("chassis": the chassis itself drags, else "caster")}``,
    ``{"kind": "caster_resistance", "joints"}``,
    ``{"kind": "drag", "drag_rate_per_s": [k_υ, k_ω]}`` (1/s; the identified viscous drag of the ``damping``
    finding, 0 where its time constant is over :data:`DRAG_NAMED_S`) and ``{"kind": "dead_band",
    "deadband_torque_Nm": [on τ_a, on τ_b]}`` (N·m, ≥ 0). Only
    the findings the identification made (each above its own threshold, design §14), with positive numbers."""
    r = float(report.get("wheel_radius_m") or 0.0)
    out: list[dict[str, Any]] = []
    for fd in report.get("findings") or []:
        kind = fd.get("kind")
        if kind == "braking_caster" and fd.get("braking_force_n"):
            force = float(fd["braking_force_n"])
            out.append(
                {
                    "kind": kind,
                    "geom": str(fd.get("geom", "")),
                    "braking_force_n": force,
                    "torque_nm": force * r,
                    "while_driving": bool(fd.get("while_driving", False)),
                    "lever_m": None if fd.get("lever_m") is None else float(fd["lever_m"]),
                    "contact": str(fd.get("contact") or "caster"),  # "chassis": the chassis itself drags
                }
            )
        elif kind == "caster_resistance":  # the share of a's and b's gap the casters account for (design §14.3)
            gaps = {w: float(fd[w]["gap"]) for w in ("a", "b") if isinstance(fd.get(w), dict)}
            out.append({"kind": kind, "joints": [str(j) for j in fd.get("caster_joints") or []], "gap": gaps})
        elif kind == "damping":  # a drag slower than DRAG_NAMED_S is no warning of robot check's either
            k = [
                float(x) if x is not None and math.isfinite(x) and x * DRAG_NAMED_S > 1 else 0.0
                for x in fd["drag_rate_per_s"]
            ]
            if max(k) > 0:
                out.append({"kind": "drag", "drag_rate_per_s": k})
        elif kind == "dead_band":
            db = [float(x) if x is not None and math.isfinite(x) and x > 0 else 0.0 for x in fd["deadband_torque_Nm"]]
            if max(db) > 0:
                out.append({"kind": kind, "deadband_torque_Nm": db})
    return out


def robot_check_resistances(robot_check: dict[str, Any] | None, n: int) -> list[list[dict[str, Any]]]:
    """Per follower (``n``) the :func:`identified_resistances` of its robot in a run's ``robot_check``
    (:func:`bioform_mj.assess.prerun.before_run`: its ``robots`` with their 1-based ``followers``); empty lists
    where the check was skipped, failed or found none."""
    out: list[list[dict[str, Any]]] = [[] for _ in range(n)]
    for rob in (robot_check or {}).get("robots") or []:
        for j in rob.get("followers") or []:
            if 1 <= int(j) <= n:
                out[int(j) - 1] = list(rob.get("resistances") or [])
    return out


def _drag_phrase(k: Sequence[float], drag_max: float, whose: str) -> str:
    """``wheel drag`` with its rates (1/s) and time constants, and whether the opt-in learner.drag reaches it."""
    rates = ", ".join(f"k_{w} = {x:.3g} 1/s" for x, w in zip(k, ("υ", "ω")) if x > 0)
    tcs = ", ".join(f"{1 / x:.3g} s" for x in k if x > 0)
    beyond = max(k) > drag_max
    return f"wheel drag ({whose}: drag rate {rates}, time constants {tcs}; " + (
        f"beyond the range of the opt-in learner.drag [0, learner.drag_max = {drag_max:g}] 1/s: it cannot "
        "estimate this one)"
        if beyond
        else "the opt-in learner.drag would estimate it)"
    )


def unmodelled_causes(
    params: Any,
    slipping: bool = False,
    casters: Sequence[str] = (),
    drag_max: float = 50.0,
    identified: Sequence[dict[str, Any]] = (),
) -> list[str]:
    """The terms a plant knows that the paper's model lacks and that bias ĉ (design §8, §14): wheel
    drag (damping, back-EMF; time constant), a dead band (frictionloss), slip, braking casters, a
    centre of mass off the axle (b̂). ``params``: the robot's
    :class:`~bioform_mj.robots.params.RobotParams` or None (ideal plant: none). ``drag_max``: the opt-in
    ``learner.drag``'s upper bound, 1/s: a drag rate beyond it is said to be beyond its range.
    ``identified``: what ``robot check`` identified of this robot (:func:`identified_resistances`, design §14.2):
    each named with its numbers (a braking caster's drag N and wheel torque N·m, a drag rate 1/s, a dead band
    N·m) in place of the model's own figure for the same term; ``casters``: those braking at the run's end."""
    out = []
    by = {x["kind"]: x for x in identified}
    brakes = [x for x in identified if x["kind"] == "braking_caster"]
    for x in brakes:
        chassis = x.get("contact") == "chassis"  # robot check's "the chassis drags" (assess.causes._contact_kind)
        what = f"'{x['geom']}' of the chassis braking" if chassis else f"caster '{x['geom']}' braking"
        out.append(
            f"{what} (robot check: {x['braking_force_n']:.3g} N of drag"
            + (" while it drives" if x.get("while_driving") else "")
            + f", {x['torque_nm']:.3g} N·m of wheel torque)"
        )
    um = params.unmodelled(0.0, 0.0) if params is not None else None
    if "drag" in by:
        model_k = um["drag_rate_per_s"] if um is not None else [0.0, 0.0]
        said = _drag_phrase(by["drag"]["drag_rate_per_s"], drag_max, "identified by robot check")
        if max(model_k) > 0:
            said = said[:-1] + f"; the wheels' damping/back-EMF: {', '.join(f'{x:.3g}' for x in model_k)} 1/s)"
        out.append(said)
    elif um is not None and max(um["drag_rate_per_s"]) > 0:
        out.append(_drag_phrase(um["drag_rate_per_s"], drag_max, "damping/back-EMF"))
    if "dead_band" in by:
        db = by["dead_band"]["deadband_torque_Nm"]
        f = params.wheel_frictionloss if params is not None else 0.0
        out.append(
            f"a dead band of {db[0]:.3g} N·m on τ_a, {db[1]:.3g} N·m on τ_b (robot check"
            + (f"; wheel frictionloss 2 f = {2 * f:.3g} N·m)" if f > 0 else ")")
        )
    elif params is not None and params.wheel_frictionloss > 0:
        out.append(f"a dead band of {2 * params.wheel_frictionloss:.3g} N·m (wheel frictionloss)")
    if "caster_resistance" in by:  # after the wheels' own terms: a share of identification's gap, not a torque
        cr = by["caster_resistance"]
        gaps = ", ".join(f"{w} {g:+.0%}" for w, g in (cr.get("gap") or {}).items())
        n_j = len(cr["joints"])
        out.append(
            f"the casters' resistance (robot check: {n_j} caster joint{'s' if n_j != 1 else ''}, identification "
            f"{gaps or 'off'} from the formula on their account)"
        )
    if params is not None and params.com_offset > 0.01:
        out.append(f"a centre of mass {1e3 * params.com_offset:.0f} mm off the axle (b̂ biased, design §8.1)")
    if slipping:
        out.append("wheel slip")
    named = {x["geom"] for x in brakes}
    out += [f"caster '{c}' braking" for c in casters if c not in named]
    return out


def injected_causes(sc: Any, i: int) -> list[str]:
    """The faults and events the scenario itself injects into follower ``i`` (0-based) that bias what the learner
    sees (design §9, issue 28): a ``c_hat_off`` names them as its likely cause before any physics. Network faults
    and a leader's path are left out: they change what the follower tracks, not the plant ĉ estimates."""
    fc, fid, out = sc.faults, i + 1, []
    for row in fc.actuator:
        if int(row[0]) == fid:
            known = "" if fc.actuator_known else ", unknown to the controller"
            out.append(f"the scenario's actuator fault (torque × {row[3]:g} from t = {row[1]:g} s{known})")
    for row in fc.push:
        if int(row[0]) == fid:
            out.append(f"the scenario's push at t = {row[1]:g} s ({row[3]:g}, {row[4]:g} N, {row[5]:g} N·m)")
    for ev in sc.events:
        if ev.kind == "payload" and ev.follower == fid:
            out.append(f"the scenario's payload event at t = {ev.time:g} s (+{ev.mass:g} kg, +{ev.inertia:g} kg·m²)")
    if len(fc.friction_patch) == 5:
        out.append(f"the scenario's friction patch (μ = {fc.friction_patch[4]:g})")
    if any(v > 0 for v in (*fc.noise_pose, *fc.noise_vel)):
        out.append("the scenario's sensor noise")
    return out


def outcome_list(
    *,
    tip_t: float | None,
    slip_t: float | None,
    spinning: bool,
    final: float,
    fe0: float,
    t_end: float,
    learning: bool,
    c_hat: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    c_true: np.ndarray,
    causes: Any = None,
    slip_ratio: float = SLIP_RATIO,
    slip_time: float = SLIP_TIME,
    lost_m: float = LOST_M,
) -> list[dict[str, Any]]:
    """Every outcome of one follower, the most severe first (:data:`OUTCOME_ORDER`), each
    ``{"kind", "detail", "t"}`` (``t``: s when it happened, None for an end-of-run outcome); empty
    when ok. Shared by both engines (:func:`follower_outcomes`, ``batch/runner.py``'s ``BatchRun._outcome``).
    ``causes``: a callable giving :func:`unmodelled_causes`' list (called only for ``c_hat_off``);
    ``lost_m``: the scenario's :func:`lost_threshold_m` (m)."""
    out: list[dict[str, Any]] = []
    if tip_t is not None:
        out.append({"kind": "tipped", "detail": f"tilt beyond {TIP_ANGLE_DEG:g} deg at t = {tip_t:.3f} s", "t": tip_t})
    if slip_t is not None:
        out.append(
            {
                "kind": "slipping",
                "detail": f"wheel slip ratio > {slip_ratio:g} for {slip_time:g} s, by t = {slip_t:.3f} s",
                "t": slip_t,
            }
        )
    if spinning:
        out.append(
            {"kind": "spinning", "detail": f"|omega| > {SPIN_RAD_S:g} rad/s over the last second", "t": t_end - 1.0}
        )
    if final > lost_m and (t_end >= LOST_AFTER_S - 1e-9 or final > 1.5 * fe0):
        out.append({"kind": "lost", "detail": f"final formation error {final:.3g} m > {lost_m:.3g} m", "t": None})
    if learning:
        at = [
            k
            for k in range(2)
            if c_hat[k] <= lo[k] + C_HAT_BOUND_BAND * abs(lo[k]) or c_hat[k] >= hi[k] - C_HAT_BOUND_BAND * abs(hi[k])
        ]
        if at:
            out.append(
                {
                    "kind": "c_hat_at_bound",
                    "detail": "learned "
                    + ", ".join("ab"[k] for k in at)
                    + f" at its bound (within {C_HAT_BOUND_BAND:.0%})",
                    "t": None,
                }
            )
        rel = [float(c_hat[k] / c_true[k] - 1.0) for k in range(2)]
        off = [k for k in range(2) if not abs(rel[k]) <= C_HAT_OFF]  # NaN counts as off
        if off:
            # a tipped robot learned on an overturned chassis: the tip is the cause, not what it then lies on
            why = (
                [f"the robot tipped at t = {tip_t:.3f} s"]
                if tip_t is not None
                else list(causes())
                if callable(causes)
                else list(causes or [])
            )
            out.append(
                {
                    "kind": "c_hat_off",
                    "detail": ", ".join(f"learned {'ab'[k]} {rel[k]:+.0%} from c_true" for k in off)
                    + f" (> {C_HAT_OFF:.0%}); likely cause: "
                    + ("; ".join(why) if why else "none the plant knows (too little excitation, or the learner gains)"),
                    "t": None,
                }
            )
    return out


def braking_casters(plant: Any, i: int, found: dict[str, Any] | None = None) -> list[str]:
    """Follower ``i``'s casters that brake on the floor now, labelled as ``robot check`` labels them
    (``contacts.floor_contacts``: a geom's name, or ``BODY#K``), by ``robot check``'s test
    (``contacts.brakes``: loaded, cannot roll, with friction; design §14.2). ``found``: a dict kept across the
    followers of one state, where every robot's contacts are sorted once (``contacts.robot_contacts``)."""
    if not isinstance(plant, RobotModels):
        return []
    try:
        from bioform_mj.robots.contacts import brakes, floor_contacts, robot_contacts

        mine = None
        if found is not None:
            if "contacts" not in found:
                found["contacts"] = robot_contacts(plant.model, plant.data, plant.layouts)
            mine = found["contacts"][i]
        floor = floor_contacts(plant.model, plant.data, plant.layouts[i], f"f{i + 1}/", mine)
        return [c["geom"] for c in floor if brakes(c)]
    except Exception:  # noqa: BLE001 - a cause is a hint; never fail a run's summary for it
        return []


def follower_outcomes(
    sc: Scenario,
    plant: Any,
    controller: Any,
    logd: dict[str, np.ndarray],
    final_form: np.ndarray,
    c_hat: np.ndarray,
    dt: float,
    resistances: Sequence[Sequence[dict[str, Any]]] | None = None,
) -> list[list[dict[str, Any]]]:
    """Per follower every outcome (:func:`outcome_list`; the thresholds are ``core/thresholds.py``'s:
    ``tipped`` (tilt beyond ``TIP_ANGLE_DEG``, with the time), ``slipping`` (a wheel's slip ratio beyond
    ``SLIP_RATIO`` for ``SLIP_TIME`` s), ``spinning`` (|ω| > ``SPIN_RAD_S`` over the last
    second), ``lost`` (final formation error > :func:`lost_threshold_m` after ``LOST_AFTER_S`` s, or
    grown by half over a shorter run), ``c_hat_at_bound`` (a learned parameter within
    ``C_HAT_BOUND_BAND`` of its projection bound at the end), ``c_hat_off`` (ĉ more than
    ``C_HAT_OFF`` from c_true, with the likely cause); empty when ok. ``resistances``: per follower what ``robot
    check`` identified (:func:`robot_check_resistances`), named in ``c_hat_off`` with its numbers."""
    n = sc.n
    out: list[list[dict[str, Any]]] = []
    watch = isinstance(plant, TipSlipWatch)
    tip = plant.tip_step if watch else None
    slip = plant.slip_step if watch else None
    p = getattr(controller, "p", None)
    t = logd["t"]
    last = t >= (t[-1] - 1.0) if len(t) else np.zeros(0, bool)
    c_true = plant.c_true() if plant is not None else np.full((n, 2), np.nan)
    params = plant.params if isinstance(plant, RobotModels) else None
    lost_m = lost_threshold_m(sc)
    found: dict[str, Any] = {}  # the robots' contacts, sorted once if a cause is asked for (braking_casters)
    for i in range(n):
        slipping = slip is not None and slip[i] >= 0
        learning = p is not None and p.learning
        out.append(
            outcome_list(
                tip_t=float(tip[i] * dt) if tip is not None and tip[i] >= 0 else None,
                slip_t=float(slip[i] * dt) if slipping else None,
                spinning=bool(len(t) and np.all(np.abs(logd["vel"][last, i, 1]) > SPIN_RAD_S)),
                final=float(final_form[i]),
                fe0=float(logd["formation_error"][0, i]) if len(t) else 0.0,
                t_end=float(t[-1]) if len(t) else 0.0,
                learning=learning,
                c_hat=c_hat[i],
                lo=np.broadcast_to(p.c_min, (n, 2))[i] if learning else np.zeros(2),
                hi=np.broadcast_to(p.c_max, (n, 2))[i] if learning else np.zeros(2),
                c_true=c_true[i],
                causes=lambda i=i, s=slipping: (
                    injected_causes(sc, i)
                    + unmodelled_causes(
                        params[i] if params is not None else None,
                        s,
                        braking_casters(plant, i, found),
                        sc.learner.drag_max,
                        resistances[i] if resistances is not None else (),
                    )
                ),
                slip_ratio=SLIP_RATIO,
                slip_time=SLIP_TIME,
                lost_m=lost_m,
            )
        )
    return out
