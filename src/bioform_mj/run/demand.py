"""The scenario's demand against the robot's limits, before the run (design §21).

The demand is the same scenario on the paper's ideal plant (eq. 34) with the robot's ``c_true`` and
no torque limit: what the controller asks of a robot that can give everything. From its log:

- ``wheel_speed`` m/s: the largest wheel ground speed ``max |υ ± l ω|`` (``l`` the robot's half track)
  against the top speed (:func:`~bioform_mj.robots.limits.top_speed`);
- ``accel`` m/s²: the largest ``|dυ/dt|`` (log differences) against the acceleration the torque,
  traction and tip-over allow (:func:`~bioform_mj.robots.limits.limits_of`);
- ``yaw_accel`` rad/s²: the largest ``|dω/dt|`` against ``2 b min(τ_max, τ_traction)``;
- ``lateral_accel`` m/s²: the largest ``|υ ω|`` against the lateral tip-over margin;
- ``sign_torque`` N·m: the sliding-mode sign terms' torque amplitude per wheel, ``c_a / (2 â) +
  c_b / (2 b̂)`` (eqs. 38–39 with the least ``ĉ`` of the run), against ``min(τ_max, τ_traction)``;
- ``torque_vs_traction`` N·m: the motor limit against the traction limit (above it the wheels skid).
- ``wheel_torque`` N·m (where the wheel's own resistance is known): the largest torque a wheel needs over the
  twin's run, ``|(υ̇/a ± ω̇/b)/2 + c φ̇ + f sgn φ̇ + (τ_brake/2) sgn υ|`` with ``φ̇ = (υ ± l ω)/r`` (joint
  damping ``c`` N·m·s/rad, frictionloss ``f`` N·m, a braking caster's drag ``τ_brake = F r`` N·m on ``τ_a`` as
  robot check identifies it), against ``τ_max``: the acceleration limits count all of ``τ_max`` as available,
  this item what the wheel's own resistance leaves of it (design §21);
- ``accel_at_c_bound`` m/s² (where the method learns): ``2 a min(τ_bound, τ_max)``, the sign terms' torque at the
  learner's lower projection bound (eq. 38 divides by ĉ) as the motors deliver it, against the acceleration limit:
  the start-up a plant that drives ĉ to its bound makes (the ideal twin's ĉ stays near c_true and cannot show it);
- ``sliding_gain_v`` / ``_w`` (where the robot has a wheel dead band or damping): its resistance,
  ``2 a f + k_υ |υ|max`` m/s² (resp. ``2 b f + k_ω |ω|max`` rad/s²), against the sliding gain
  ``torque.c`` that must dominate it (eqs. 38–39); the gain scales × 1/σ², the resistance not. A braking
  caster robot check identifies adds ``a τ_brake`` (its drag force over the mass, m/s²) to ``_v`` and, with its
  lever ``d`` (its contact's distance from the axle midpoint, the turning centre), ``b Σ F r d / l`` to ``_w``
  (its moment ``F d`` as the wheel-torque difference ``F d r / l`` it takes, rad/s²; the most it can be: turning
  in place the drag is across the lever, otherwise less); without a lever ``_w`` leaves it out (said in the item).

Each is ``{"value", "limit", "ratio", "unit", "limit_by"}`` (``limit`` None and ``missing`` where the
robot does not say); a ``warning:`` line per ratio above 1. The ideal run is cached per scenario and
robot (memory and :func:`bioform_mj.assess.prerun.cache_dir`'s sibling ``demand``): ≤ 2 s once, nothing again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: cache entries of another format are recomputed
CACHE_FORMAT = 5
_MEMO: dict[str, dict[str, Any]] = {}
#: the twin's log (t, vel) per key, this process only: a wheel not yet asked about costs no second twin
_LOGS: dict[str, tuple[np.ndarray, np.ndarray]] = {}
#: the loop that runs the ideal twin, :func:`bioform_mj.run.simulate.simulate`: it registers itself when imported
#: (it calls this module before a run, so this module cannot import it: design §0), and importing the run package
#: imports it; every caller of the demand (a run's check, the batch engine's, the "auto" time scale) asks this one
_LOOP: list[Callable[..., Any]] = []


def register_loop(run: Callable[..., Any]) -> None:
    """Register the loop that runs the demand's ideal twin (``run(scenario, engine="auto") -> RunResult``).

    Parameters
    ----------
    run : callable
        :func:`bioform_mj.run.simulate.simulate`, registered by its module when imported.
    """
    _LOOP[:] = [run]


def _loop() -> Callable[..., Any]:
    if not _LOOP:
        raise RuntimeError("the demand's ideal twin needs the loop: import bioform_mj.run (it registers simulate)")
    return _LOOP[-1]


def ideal_twin(sc: Any, c_true: tuple[float, float]) -> Any:
    """``sc`` on the paper's ideal plant with ``c_true`` and no torque limit (the demand's run): what
    needs MuJoCo left out — a friction patch, the odometry sensing, the obstacles and the safety filter
    (the formation's own demand; an avoidance manoeuvre asks more). A scenario slowed by σ > 1 is
    stepped × σ (control, physics and log steps): the twin of a similar scenario is then the σ = 1
    twin with every time × σ (design §21), and costs what it costs, ≤ 2 s."""
    from bioform_mj.formation.obstacles import ObstacleFieldCfg
    from bioform_mj.formation.safety import SafetyCfg
    from bioform_mj.robots.refs import RobotRef

    plant = dataclasses.replace(
        sc.plant,
        kind="ideal",
        c_true=(float(c_true[0]), float(c_true[1])),
        robots=(RobotRef("paper"),),
        sensing="truth",
    )
    faults = dataclasses.replace(sc.faults, friction_patch=())
    sim = sc.sim
    sigma = float(sc.formation.time_scale_applied)
    if sigma > 1:  # stepped × σ: it costs what the unscaled scenario costs (similar; the sign terms chatter more)
        sim = dataclasses.replace(
            sim, control_dt=sim.control_dt * sigma, physics_dt=sim.physics_dt * sigma, log_dt=sim.log_dt * sigma
        )
    torque = dataclasses.replace(sc.torque, tau_max=1e5)
    limits = dataclasses.replace(sc.limits, torque=max(sc.limits.torque, 1e7))
    return dataclasses.replace(
        sc,
        sim=sim,
        plant=plant,
        faults=faults,
        torque=torque,
        limits=limits,
        obstacles=(),
        obstacle_field=ObstacleFieldCfg(),
        safety=SafetyCfg(),
    )


def _key(sc: Any, c_true: tuple[float, float], half_track: float) -> str:
    from bioform_mj.assess.prerun import code_digest

    h = hashlib.sha256(code_digest())
    h.update(json.dumps(ideal_twin(sc, c_true).to_dict(), sort_keys=True, default=str).encode())
    h.update(repr(float(half_track)).encode())
    return h.hexdigest()[:32]


def wheel_key(wheel: dict[str, float] | None) -> str:
    """``wheel``'s numbers as a cache key (9 significant digits)."""
    if not wheel:
        return ""
    return json.dumps({k: float(f"{float(v):.9g}") for k, v in sorted(wheel.items())})


def wheel_need(
    t: np.ndarray, vel: np.ndarray, c_true: tuple[float, float], half_track: float, wheel: dict[str, float]
) -> dict[str, float]:
    """The torque per wheel the motion ``vel`` (K, n, 2: υ m/s, ω rad/s at times ``t`` s) needs of a robot of
    ``c_true = (a, b)``, half track ``half_track`` m and ``wheel`` = ``{"radius_m", "damping_nms",
    "frictionloss_nm", "brake_torque_nm"}``, its own resistance included (module docstring, ``wheel_torque``):
    ``{"wheel_torque_nm", "wheel_inertial_nm", "wheel_resistance_nm", "wheel_rate_radps"}``, each the largest
    absolute value over the log's intervals, both wheels and every robot (N·m, rad/s)."""
    a, b = float(c_true[0]), float(c_true[1])
    r, c = float(wheel["radius_m"]), float(wheel["damping_nms"])
    f, brake = float(wheel["frictionloss_nm"]), float(wheel.get("brake_torque_nm", 0.0))
    if len(t) < 2:
        return {"wheel_torque_nm": 0.0, "wheel_inertial_nm": 0.0, "wheel_resistance_nm": 0.0, "wheel_rate_radps": 0.0}
    dt = np.diff(t)[:, None]
    vd, wd = np.diff(vel[..., 0], axis=0) / dt, np.diff(vel[..., 1], axis=0) / dt
    vm, wm = 0.5 * (vel[1:, :, 0] + vel[:-1, :, 0]), 0.5 * (vel[1:, :, 1] + vel[:-1, :, 1])
    out = dict.fromkeys(("wheel_torque_nm", "wheel_inertial_nm", "wheel_resistance_nm", "wheel_rate_radps"), 0.0)
    for sgn in (1.0, -1.0):  # right, left
        inert = 0.5 * (vd / a + sgn * wd / b)
        phid = (vm + sgn * half_track * wm) / r
        resist = c * phid + f * np.sign(phid) + 0.5 * brake * np.sign(vm)
        for k, x in (
            ("wheel_torque_nm", inert + resist),
            ("wheel_inertial_nm", inert),
            ("wheel_resistance_nm", resist),
            ("wheel_rate_radps", phid),
        ):
            out[k] = max(out[k], float(np.max(np.abs(x))))
    return out


def peaks(
    sc: Any, c_true: tuple[float, float], half_track: float, *, wheel: dict[str, float] | None = None
) -> dict[str, Any]:
    """The demand's peaks (module docstring) of ``sc`` on the ideal plant with ``c_true`` and a robot of
    half track ``half_track`` m, run by the registered loop (:func:`register_loop`); cached.
    ``{"wheel_speed_mps", "accel_mps2", "yaw_accel_radps2",
    "lateral_accel_mps2", "c_hat_min", "seconds", "from"}``; with ``wheel`` (:func:`wheel_need`'s) also its
    ``wheel_torque_nm``, ``wheel_inertial_nm``, ``wheel_resistance_nm``, ``wheel_rate_radps`` (cached with the
    entry, one per distinct wheel)."""
    key = _key(sc, c_true, half_track)
    wk = wheel_key(wheel)

    def _done(entry: dict[str, Any], where: str) -> dict[str, Any] | None:
        if wk and wk not in entry.get("wheels", {}):
            return None
        return {
            **{k: v for k, v in entry.items() if k != "wheels"},
            **entry.get("wheels", {}).get(wk, {}),
            "from": where,
        }

    if key in _MEMO and (hit := _done(_MEMO[key], "memory")) is not None:
        return hit
    from bioform_mj.assess.prerun import cache_dir

    path = cache_dir().parent / "demand" / f"{key}.json"
    if key not in _MEMO:
        try:
            entry = json.loads(path.read_text(encoding="utf-8"))
            if isinstance(entry, dict) and entry.get("format") == CACHE_FORMAT:
                _MEMO[key] = entry
                if (hit := _done(entry, "disk")) is not None:
                    return hit
        except (OSError, ValueError):
            pass
    t0 = time.perf_counter()
    entry = _MEMO.get(key)
    if entry is None or key not in _LOGS:
        with warnings.catch_warnings():  # the twin's outcomes are not the run's
            warnings.simplefilter("ignore")
            res = _loop()(ideal_twin(sc, c_true), engine="auto")
        t = np.asarray(res.log["t"])
        vel = np.asarray(res.log["vel"])  # (K, n, 2) υ m/s, ω rad/s
        _LOGS.clear()  # one twin's log kept: the wheel asked right after the σ search's last twin
        _LOGS[key] = (t, vel)
        if entry is None:
            v, w = vel[:, :, 0], vel[:, :, 1]
            dt = np.diff(t)[:, None] if len(t) > 1 else np.ones((0, 1))
            ch = np.asarray(res.log.get("c_hat", np.full((1, 1, 2), np.nan)))
            entry = {
                "format": CACHE_FORMAT,
                "wheel_speed_mps": float(np.max(np.abs(v) + half_track * np.abs(w))) if len(t) else 0.0,
                "accel_mps2": float(np.max(np.abs(np.diff(v, axis=0)) / dt)) if len(t) > 1 else 0.0,
                "yaw_accel_radps2": float(np.max(np.abs(np.diff(w, axis=0)) / dt)) if len(t) > 1 else 0.0,
                "lateral_accel_mps2": float(np.max(np.abs(v * w))) if len(t) else 0.0,
                "speed_mps": float(np.max(np.abs(v))) if len(t) else 0.0,
                "yaw_rate_radps": float(np.max(np.abs(w))) if len(t) else 0.0,
                "c_hat_min": [float(np.nanmin(ch[..., 0])), float(np.nanmin(ch[..., 1]))],
                # per follower, the twin's ĉ at its end against c_true: the method's own share (twin_share)
                "c_hat_end_rel": [
                    [float(x / c - 1.0) if np.isfinite(x) else None for x, c in zip(row, c_true)] for row in ch[-1]
                ],
                "duration_s": float(sc.sim.duration),
                "seconds": 0.0,
                "wheels": {},
            }
    t, vel = _LOGS[key]
    entry = {**entry, "wheels": dict(entry.get("wheels", {}))}
    if wk:
        entry["wheels"][wk] = wheel_need(t, vel, c_true, half_track, wheel or {})
    entry["seconds"] = time.perf_counter() - t0
    _MEMO[key] = entry
    try:
        from bioform_mj.outputs.files import write_json

        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, entry)
    except Exception:  # noqa: BLE001 - a cache that cannot be written costs time, not the run
        pass
    done = _done(entry, "computed")
    assert done is not None  # the wheel's entry was just added
    return done


def _item(value: float, limit: float | None, unit: str, by: str) -> dict[str, Any]:
    out: dict[str, Any] = {"value": float(value), "limit": None if limit is None else float(limit), "unit": unit}
    out["ratio"] = None if limit is None or limit <= 0 else float(value) / float(limit)
    out["limit_by"] = by
    return out


def c_lower_bound(sc: Any, c_true: tuple[float, float]) -> tuple[float, float] | None:
    """The learner's lower projection bound ``(â_lo, b̂_lo)`` for a robot of ``c_true`` (as ``control.params`` sets
    it: ``learner.projection_band[0] × c_true``, else ``learner.c_bounds[0] × c_hat0_scale × c_true``); None where
    the method does not learn (or is a user's controller: its bounds are its own)."""
    from bioform_mj.control.stack import parse_method

    try:
        if not parse_method(sc.method)[1]:
            return None
    except ValueError:
        return None
    band = sc.learner.projection_band
    lo = [band[0], band[0]] if band else [sc.learner.c_bounds[0] * k for k in sc.learner.c_hat0_scale]
    return (float(lo[0] * c_true[0]), float(lo[1] * c_true[1]))


def compare(
    sc: Any,
    pk: dict[str, Any],
    lim: dict[str, Any],
    resist: dict[str, Any] | None = None,
    c_true: tuple[float, float] | None = None,
    brake_torque_nm: float = 0.0,
    brake_yaw_nm: float | None = None,
) -> dict[str, dict[str, Any]]:
    """The demand ``pk`` (:func:`peaks`) of ``sc`` against the robot's limits ``lim``
    (:func:`~bioform_mj.robots.limits.limits_of`), one item per quantity (module docstring).
    ``resist``: the robot's unmodelled resistance (:meth:`~bioform_mj.robots.params.RobotParams.unmodelled`:
    ``deadband_accel``, ``drag_rate_per_s``); where it has one, ``sliding_gain_v`` / ``_w`` put it, at
    the demand's peak speed, against the sliding gain ``torque.c`` that must dominate it (eqs. 38–39).
    ``c_true``: the robot's ``(a, b)``; with it, where the method learns, ``accel_at_c_bound``: the forward
    acceleration ``2 a min(τ_bound, τ_max)`` (m/s²) of the sign terms' torque at the learner's lower projection bound
    (:func:`c_lower_bound`; eq. 38 divides by ĉ) against the acceleration limit — the start-up a plant the paper's
    model does not fit can drive ĉ to (TIAGo in MuJoCo, design §21), which the ideal twin, whose ĉ stays near
    c_true, does not show. ``brake_torque_nm``: the braking casters' drag ``F r`` (N·m on ``τ_a``) robot check
    identified, added as ``a F r`` (m/s², with ``c_true``) to ``sliding_gain_v``; ``brake_yaw_nm``: their moment
    on ω as a wheel-torque difference ``Σ F r d / l`` (N·m, :func:`brake_yaw_torques`), added as ``b Σ F r d / l``
    (rad/s²) to ``sliding_gain_w`` (None: the lever is not known, said in the item). Where ``pk`` has
    ``wheel_torque_nm`` (:func:`peaks` with a ``wheel``): ``wheel_torque`` against ``τ_max``."""
    grip = min(lim["torque_nm"], lim["traction_torque_nm"])
    ca, cb = (float(x) for x in sc.torque.c)
    a_min, b_min = pk["c_hat_min"]
    sign = ca / (2 * a_min) + cb / (2 * b_min) if a_min > 0 and b_min > 0 else float("inf")
    out = {
        "wheel_speed": _item(
            pk["wheel_speed_mps"], lim["top_speed_mps"], "m/s", f"top speed ({lim['top_speed_source'] or 'unknown'})"
        ),
        "accel": _item(pk["accel_mps2"], lim["accel_mps2"], "m/s²", lim["accel_limited_by"]),
        "yaw_accel": _item(pk["yaw_accel_radps2"], lim["yaw_accel_radps2"], "rad/s²", lim["yaw_accel_limited_by"]),
        "lateral_accel": _item(pk["lateral_accel_mps2"], lim["lateral_accel_mps2"], "m/s²", "tip lateral"),
        "sign_torque": _item(
            sign, grip, "N·m", "torque" if lim["torque_nm"] <= lim["traction_torque_nm"] else "traction"
        ),
        "torque_vs_traction": _item(lim["torque_nm"], lim["traction_torque_nm"], "N·m", "traction"),
    }
    if "wheel_torque_nm" in pk:  # design §21: the motion's torque and the wheel's own resistance, against τ_max
        out["wheel_torque"] = _item(pk["wheel_torque_nm"], lim["torque_nm"], "N·m", "torque limit τ_max")
        out["wheel_torque"].update(
            inertial_nm=float(pk["wheel_inertial_nm"]),
            resistance_nm=float(pk["wheel_resistance_nm"]),
            wheel_rate_radps=float(pk["wheel_rate_radps"]),
        )
    bound = c_lower_bound(sc, c_true) if c_true is not None else None
    if bound is not None and bound[0] > 0 and bound[1] > 0:
        tau_bound = ca / (2 * bound[0]) + cb / (2 * bound[1])  # N·m per wheel, eqs. 38–39 with ĉ at its bound
        given = min(tau_bound, lim["torque_nm"])  # what the motors deliver of it
        out["accel_at_c_bound"] = _item(2 * c_true[0] * given, lim["accel_mps2"], "m/s²", lim["accel_limited_by"])
        out["accel_at_c_bound"].update(
            torque_at_bound_nm=float(tau_bound), c_bound=[float(bound[0]), float(bound[1])], torque_given_nm=given
        )
    brake_acc = float(c_true[0]) * float(brake_torque_nm) if c_true is not None and brake_torque_nm > 0 else 0.0
    brake_yaw = float(c_true[1]) * float(brake_yaw_nm or 0.0) if c_true is not None and brake_acc > 0 else 0.0
    if resist is not None or brake_acc > 0:
        dead = resist["deadband_accel"] if resist is not None else (0.0, 0.0)
        drag = resist["drag_rate_per_s"] if resist is not None else (0.0, 0.0)
        for k, j, speed, gain, unit in (
            ("sliding_gain_v", 0, pk.get("speed_mps", 0.0), ca, "m/s²"),
            ("sliding_gain_w", 1, pk.get("yaw_rate_radps", 0.0), cb, "rad/s²"),
        ):
            brk = brake_acc if j == 0 else brake_yaw  # on ω: the caster's moment F d, the most it can be
            r = float(dead[j]) + float(drag[j]) * float(speed) + brk
            if r > 0:
                out[k] = _item(r, gain, unit, f"torque.c[{j}], the sliding gain")
                out[k].update(deadband=float(dead[j]), drag=float(drag[j]) * float(speed), braking_caster=brk)
                if j == 1 and brake_acc > 0 and brake_yaw_nm is None:
                    out[k]["braking_caster_note"] = "a braking caster's moment on ω is not included (lever unknown)"
    return out


_WHAT = {
    "wheel_speed": "peak wheel ground speed",
    "accel": "peak acceleration",
    "yaw_accel": "peak yaw acceleration",
    "lateral_accel": "peak centripetal acceleration",
    "sign_torque": "sliding-mode sign terms' torque amplitude",
    "torque_vs_traction": "the torque limit",
    "sliding_gain_v": "the robot's resistance (dead band, drag at peak speed, braking caster) on υ",
    "sliding_gain_w": "the robot's resistance (dead band, drag at peak yaw rate, braking caster's moment) on ω",
    "accel_at_c_bound": "the acceleration of the sign terms at ĉ's projection bound",
    "wheel_torque": "peak wheel torque (the motion's and the wheel's own resistance)",
}


#: how the demand scales with the time factor σ (design §21): speeds 1/σ, accelerations and the sign terms 1/σ²
_POWER = {"wheel_speed": 1.0, "accel": 2.0, "yaw_accel": 2.0, "lateral_accel": 2.0, "sign_torque": 2.0}


def warning_lines(who: str, items: dict[str, dict[str, Any]], sigma: float = 1.0) -> list[str]:
    """One line per exceeded limit, with the ratio and, where slowing the scenario helps, the
    ``formation.time_scale`` that would bring it to the limit (similarity: the ratio × σ^(1/power))."""
    out = []
    for k, it in items.items():
        if it["ratio"] is not None and it["ratio"] > 1:
            u = it["unit"]
            if k == "accel_at_c_bound":  # design §21: what ĉ at its projection bound makes the torque law ask
                lo = it["c_bound"]
                out.append(
                    f"{who}: if the learned ĉ falls to its projection bound (â = {lo[0]:.3g}, b̂ = {lo[1]:.3g}), eq. "
                    f"38's sign terms ask {it['torque_at_bound_nm']:.3g} N·m per wheel and the motors give "
                    f"{it['torque_given_nm']:.3g} N·m: an acceleration of {it['value']:.3g} {u}, "
                    f"{it['ratio']:.2g}x the robot's limit {it['limit']:.3g} {u} ({it['limit_by']}); a plant the "
                    "paper's model does not fit drives ĉ there at the start (design §21); learner.projection_band "
                    "narrows the bound (design §14.4)"
                )
                continue
            if k == "wheel_torque":  # design §21: the wheel's own resistance is the motor's to give
                out.append(
                    f"{who}: {_WHAT[k]} {it['value']:.3g} {u} is {it['ratio']:.2g}x the robot's limit "
                    f"{it['limit']:.3g} {u} (the torque limit τ_max): the motion needs {it['inertial_nm']:.3g} {u}, "
                    "the wheel's own damping, frictionloss and braking casters take up to "
                    f"{it['resistance_nm']:.3g} {u} (at "
                    f"{it['wheel_rate_radps']:.3g} rad/s); the robot cannot follow the scenario's motion (design §21)"
                )
                continue
            if k.startswith("sliding_gain"):  # the gain must dominate the resistance; slowing makes it worse
                out.append(
                    f"{who}: {_WHAT[k]} {it['value']:.3g} {u} is {it['ratio']:.2g}x the sliding gain "
                    f"{it['limit_by'].split(',')[0]} = {it['limit']:.3g} {u}: the sign terms cannot hold it and "
                    "the learner reads it as a smaller ĉ (design §21)"
                )
                continue
            hint = ""
            if k in _POWER:
                hint = f'; formation.time_scale >= {sigma * it["ratio"] ** (1 / _POWER[k]):.3g} or "auto" slows it'
            out.append(
                f"{who}: {_WHAT[k]} {it['value']:.3g} {u} is {it['ratio']:.2g}x the robot's limit "
                f"{it['limit']:.3g} {u} ({it['limit_by']}{hint})"
            )
    return out


def _rounded(x: Any) -> Any:
    """``x`` with every float at 9 significant digits (the same robot built twice differs in the last bits)."""
    if isinstance(x, float):
        return float(f"{x:.9g}")
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_rounded(v) for v in x]
    return x


def run_limits(sc: Any, plant: Any) -> list[dict[str, Any]]:
    """Per follower of a built MuJoCo ``plant``: its limits (:func:`~bioform_mj.robots.limits.limits_of`)."""
    import mujoco

    from bioform_mj.assess.check import tip_margins
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.limits import limits_of

    scratch = mujoco.MjData(plant.model)
    mujoco.mj_kinematics(plant.model, scratch)
    loads = plant.settled_wheel_loads()
    entries = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    out = []
    for i in range(plant.n):
        tips = tip_margins(plant.model, scratch, f"f{i + 1}/")["tip_accel_mps2"]
        out.append(limits_of(plant, i, resolve_robot(entries[i]), loads[i], tips))
    return out


def brake_torques(robot_check: dict[str, Any] | None, n: int) -> list[float]:
    """Per follower (``n``) the braking casters' drag ``Σ F r`` (N·m on ``τ_a``) that ``robot check`` identified
    (``robot_check``: :func:`bioform_mj.assess.prerun.before_run`'s; 0 where it found none or was skipped)."""
    from bioform_mj.assess.outcomes import robot_check_resistances

    return [
        float(sum(float(x.get("torque_nm") or 0.0) for x in found if x.get("kind") == "braking_caster"))
        for found in robot_check_resistances(robot_check, n)
    ]


def brake_yaw_torques(robot_check: dict[str, Any] | None, half_tracks: list[float]) -> list[float | None]:
    """Per follower (half track ``half_tracks[i]`` m) the braking casters' moment on ω that ``robot check``
    identified, as the wheel-torque difference it takes: ``Σ F r d / l`` (N·m on ``τ_b``; ``F r`` the caster's
    ``torque_nm``, ``d`` its ``lever_m``); None where a braking caster's lever is not known (an older check)."""
    from bioform_mj.assess.outcomes import robot_check_resistances

    out: list[float | None] = []
    for found, l_half in zip(robot_check_resistances(robot_check, len(half_tracks)), half_tracks):
        brakes = [x for x in found if x.get("kind") == "braking_caster"]
        if any(x.get("lever_m") is None for x in brakes):
            out.append(None)
            continue
        out.append(float(sum(float(x.get("torque_nm") or 0.0) * float(x["lever_m"]) for x in brakes)) / l_half)
    return out


def before_run(sc: Any, plant: Any, robot_check: dict[str, Any] | None = None) -> dict[str, Any]:
    """summary.json's ``demand`` for a MuJoCo run (the ideal twin run by the registered loop, :func:`peaks`):
    ``{"robots": [{"followers", "model", "c_true",
    "limits", "demand", "ideal_run"}], "warnings", "seconds"}`` (one entry per distinct robot).
    ``robot_check``: the run's robot check (:func:`bioform_mj.assess.prerun.before_run`): its braking casters
    count in ``wheel_torque`` and ``sliding_gain_v`` (:func:`brake_torques`), and with their lever in
    ``sliding_gain_w`` (:func:`brake_yaw_torques`)."""
    t0 = time.perf_counter()
    lims = run_limits(sc, plant)
    brakes = brake_torques(robot_check, plant.n)
    yaws = brake_yaw_torques(robot_check, [float(p.half_track) for p in plant.params])
    groups: dict[str, list[int]] = {}
    for i, p in enumerate(plant.params):
        k = json.dumps(
            _rounded([p.a_eff, p.b_eff, p.half_track, lims[i], brakes[i], yaws[i]]), sort_keys=True, default=str
        )
        groups.setdefault(k, []).append(i)
    robots, lines = [], []
    for idx in groups.values():
        i = idx[0]
        p = plant.params[i]
        who = f"follower{'s' if len(idx) > 1 else ''} {', '.join(str(j + 1) for j in idx)}"
        try:
            wheel = {
                "radius_m": p.wheel_radius,
                "damping_nms": p.wheel_damping + p.motor_damping,
                "frictionloss_nm": p.wheel_frictionloss,
                "brake_torque_nm": brakes[i],
            }
            pk = peaks(sc, (p.a_eff, p.b_eff), p.half_track, wheel=wheel)
        except Exception as exc:  # noqa: BLE001 - a demand that cannot be computed is said, the run goes ahead
            why = f"{type(exc).__name__}: {exc}"
            lines.append(f"{who}: the scenario's demand could not be computed on the ideal plant ({why})")
            robots.append({"followers": [j + 1 for j in idx], "limits": lims[i], "demand": None, "error": why})
            continue
        items = compare(sc, pk, lims[i], p.unmodelled(1.0, 1.0), (p.a_eff, p.b_eff), brakes[i], yaws[i])
        twin_end = pk.get("c_hat_end_rel") or []
        sigma = sc.formation.time_scale if isinstance(sc.formation.time_scale, float) else 1.0
        lines += warning_lines(who, items, sigma)
        robots.append(
            {
                "followers": [j + 1 for j in idx],
                "model": Path(plant.robot_files[i]).name,
                "c_true": [p.a_eff, p.b_eff],
                "limits": lims[i],
                "demand": items,
                # the ideal twin's ĉ error at its end for these followers (a, b; twin_share)
                "twin_c_hat_rel_error": [twin_end[j] if j < len(twin_end) else None for j in idx],
                "ideal_run": {k: pk[k] for k in ("seconds", "from") if k in pk},
            }
        )
    return {"robots": robots, "warnings": lines, "seconds": time.perf_counter() - t0}


def twin_share(summary: dict[str, Any]) -> None:
    """In ``summary`` (a run's, with its ``demand``): each follower's ``c_hat_off`` whose ideal twin (the same
    scenario on the paper's plant with the robot's c_true, :func:`before_run`) ended as far off, the same way, on a
    component (within ±:data:`~bioform_mj.core.thresholds.C_HAT_OFF` of the run's error, itself beyond it) says so:
    that share is the method's at this scale (too little excitation, the learner's gains), not the plant's physics,
    whatever else the cause list names (design §21)."""
    from bioform_mj.core.thresholds import C_HAT_OFF

    twin: dict[int, list[float]] = {}
    for r in (summary.get("demand") or {}).get("robots", []):
        for fid, rel in zip(r.get("followers", []), r.get("twin_c_hat_rel_error") or []):
            if rel is not None and None not in rel:
                twin[int(fid)] = [float(x) for x in rel]
    for f in summary.get("followers", []):
        t, run = twin.get(int(f["id"])), f.get("c_hat_rel_error")
        if t is None or run is None:
            continue
        same = [
            k
            for k in range(2)
            if abs(run[k]) > C_HAT_OFF
            and abs(t[k]) > C_HAT_OFF
            and t[k] * run[k] > 0
            and abs(t[k] - run[k]) <= C_HAT_OFF
        ]
        if not same:
            continue
        add = (
            "; the ideal twin (the paper's plant, the same scenario, c_true) learned "
            + ", ".join(f"{'ab'[k]} {t[k]:+.0%}" for k in same)
            + " too: the method's share at this scale (excitation, learner gains), not the plant's"
        )
        for o in f.get("outcomes", []):
            if o.get("kind") == "c_hat_off":
                if f.get("outcome_detail") == o["detail"]:
                    f["outcome_detail"] = o["detail"] + add
                o["detail"] += add


#: what :func:`before_run` measures of itself: said on a run's log, not kept in its summary (same bits per seed)
VOLATILE = ("seconds", "from", "ideal_run")


def for_summary(d: dict[str, Any]) -> dict[str, Any]:
    """:func:`before_run`'s result without its times and cache provenance."""
    return {
        **{k: v for k, v in d.items() if k not in VOLATILE},
        "robots": [{k: v for k, v in r.items() if k not in VOLATILE} for r in d.get("robots", [])],
    }
