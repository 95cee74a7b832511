"""Would this run work on the robot as specified? The hardware-feasibility verdict of a run (design §19).

After every run :func:`verdict` compares what the run asked of the robots with what they can
give, each check a number, its limit and pass/fail (``None`` with a ``reason`` where the
robot does not say: a check that cannot be made is skipped, never passed silently):

* ``wheel_speed`` rad/s: the largest wheel rate ``|υ ± l ω| / r`` of the log against the motor's
  no-load wheel speed ``V_max / (K g)`` (a ``<dcmotor>``; a torque source has none: skipped);
* ``torque`` N·m: the largest torque applied against the motor limit; ``torque_saturation``: the
  fraction of control steps at the limit against :data:`SATURATION_LIMIT` (a run that lives on
  the limit depends on a saturation model more than on the controller);
* ``tip_over`` / ``tip_over_lateral`` m/s²: the largest tangential ``|dυ/dt|`` and centripetal
  ``|υ ω|`` acceleration of the log against the chassis' static margins
  (:func:`~bioform_mj.assess.check.tip_margins`), and no follower ``tipped``;
* ``separation`` m: the least chassis-to-chassis distance (``min_separation_m``) against 0
  (touching) or ``safety.distance`` if set; no contact with a robot or an obstacle;
* ``control_rate`` Hz: the scenario's control rate against the robot's own: the mapping's ``control_rate`` (the
  maker's figure; ``--control-rate``), else its shipped preset's (``tb3`` for the TurtleBot3 model …), else
  skipped with :data:`NO_CONTROL_RATE`, which says how to give it;
* ``slip`` s: the time followers spent slipping (outcome ``slipping``) against 0.

The verdict is ``fail`` if any check failed, else ``incomplete`` if one could not be made
(``not_checked`` names them; never ``pass`` with a check skipped, design §21), else ``pass``. The
ideal plant has no robot model: only the checks its numbers allow run, the others are skipped with
the reason. ``wheel_speed`` of torque-source motors is checked against the robot's top speed
(:mod:`bioform_mj.robots.limits`: the mapping's ``top_speed``, the URDF's ``<limit velocity>``).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from bioform_mj.plants.base import RobotModels, TipSlipWatch

#: largest fraction of control steps at the torque limit that still counts as feasible: beyond it
#: the run depends more on the saturation model than on the controller (the shipped presets, 20 s:
#: paper 0.09, stretch 0.15, tb3 0.01)
SATURATION_LIMIT = 0.25


def _check(value: Any, limit: Any, ok: bool | None, reason: str = "") -> dict[str, Any]:
    f = lambda x: None if x is None else float(x)  # noqa: E731 - plain JSON numbers, not numpy's
    out = {"value": f(value), "limit": f(limit), "pass": None if ok is None else bool(ok)}
    if reason:
        out["reason"] = reason
    return out


def _skip(reason: str) -> dict[str, Any]:
    return _check(None, None, None, reason)


def preset_control_rate(model_path: str) -> tuple[float | None, str]:
    """The control rate (Hz) the shipped presets run the robot file ``model_path`` at, and the
    preset: the one named as the robot (``paper``, ``tb3``, ``stretch``) if it drives that robot
    alone, else the fastest of those that do; ``(None, "")`` if none does."""
    from pathlib import Path

    want = str(Path(model_path).resolve())
    mine = [(rate, name) for rate, name, path in _preset_rates() if path == want]
    own = Path(model_path).stem.removesuffix("_robot")  # models/tb3_robot.xml: the 'tb3' preset
    for rate, name in mine:
        if name == own:
            return rate, name
    return max(mine) if mine else (None, "")


@functools.lru_cache(maxsize=1)
def _preset_rates() -> list[tuple[float, str, str]]:
    """(control rate Hz, preset, robot file) of every shipped MuJoCo preset with one robot model,
    slowest first (the TOML files read, not loaded: no validation per run)."""
    import tomllib
    from importlib import resources
    from pathlib import Path

    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.refs import as_ref
    from bioform_mj.scenario.config import SimCfg
    from bioform_mj.scenario.loader import preset_names

    out = []
    for name in preset_names():
        try:
            raw = tomllib.loads(
                (resources.files("bioform_mj.scenario") / "presets" / f"{name}.toml").read_text("utf-8")
            )
            robots = raw.get("plant", {}).get("robots", ["paper"])
            paths = {str(Path(resolve_robot(as_ref(r, "plant.robots")).model).resolve()) for r in robots}
        except Exception:  # noqa: BLE001 - a preset that does not read here says nothing of a robot
            continue
        if raw.get("plant", {}).get("kind") == "mujoco" and len(paths) == 1:
            dt = float(raw.get("sim", {}).get("control_dt", SimCfg.control_dt))
            out.append((1.0 / dt, name, paths.pop()))
    return sorted(out)


#: the ``control_rate`` check's reason where no rate is known: how to give it (design §19)
NO_CONTROL_RATE = (
    "the robot's control rate is not known: give the rate its maker's controller commands the wheels at as the "
    "robot mapping's control_rate (Hz; e.g. plant.robots = [{model = ..., control_rate = 30}]) or --control-rate HZ "
    "(bioform run, robot check, identify); no shipped preset drives this robot"
)


def robot_control_rates(sc: Any, plant: Any) -> list[tuple[float | None, str]]:
    """Per distinct robot of a MuJoCo run: ``(Hz, where it comes from)`` — the mapping's ``control_rate`` ("the
    mapping's"), else :func:`preset_control_rate` ("the 'NAME' preset's rate"), else ``(None, "")``."""
    from bioform_mj.robots.entries import resolve_robot

    entries = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    out: dict[Any, tuple[float | None, str]] = {}
    for i, path in enumerate(plant.robot_files):
        ref = resolve_robot(entries[i]) if i < len(entries) else None
        key = (path, getattr(ref, "control_rate", 0.0))
        if key in out:
            continue
        if ref is not None and ref.control_rate > 0:
            out[key] = (float(ref.control_rate), "the mapping's")
        else:
            r, name = preset_control_rate(path)
            out[key] = (r, f"the '{name}' preset's rate") if r is not None else (None, "")
    return list(out.values())


def verdict(sc: Any, plant: Any, summary: dict[str, Any], logd: dict[str, np.ndarray]) -> dict[str, Any]:
    """``{"verdict": "pass"|"fail"|"incomplete", "failed", "not_checked", "checks": {name: {"value", "limit",
    "pass"[, "reason"]}}}``
    for a finished run (``summary``: its ``summary.json`` dict, ``logd``: its log)."""
    fs = summary["followers"]
    checks: dict[str, dict[str, Any]] = {}
    params = plant.params if isinstance(plant, RobotModels) else None
    vel = np.asarray(logd.get("vel", np.zeros((0, len(fs), 2))))
    t = np.asarray(logd.get("t", np.zeros(0)))

    # wheel speed against the motors' no-load speed
    if params is None:
        checks["wheel_speed"] = _skip("the ideal plant has no motor model")
    else:
        import mujoco

        from bioform_mj.robots.layout import dc_constants

        m = plant.model
        limits = []
        for i in range(len(fs)):
            nl = []
            for a in plant._ctrl[i]:
                if int(m.actuator_dyntype[a]) == int(mujoco.mjtDyn.mjDYN_DCMOTOR):
                    R, K, g, vmax = dc_constants(m, int(a))
                    if K > 0 and g > 0 and vmax > 0:
                        nl.append(vmax / (K * g))
            limits.append(min(nl) if nl else None)
        tops = _top_speeds(summary, len(fs))  # design §21: m/s at the tyre, for torque-source motors
        for i, p in enumerate(params):
            if limits[i] is None and tops[i] is not None:
                limits[i] = tops[i] / p.wheel_radius
        if all(v is None for v in limits):
            checks["wheel_speed"] = _skip(
                "no top speed known: torque-source motors have no no-load speed (no <dcmotor> in the model) and "
                "the robot gives none (map top_speed, m/s at the tyre; design §21)"
            )
        elif len(vel):
            worst, lim_w = 0.0, None
            for i, p in enumerate(params):
                if limits[i] is None:
                    continue
                w = np.abs(vel[:, i, 0][:, None] + np.array([-1.0, 1.0]) * p.half_track * vel[:, i, 1][:, None])
                rate = float(np.max(w)) / p.wheel_radius
                if lim_w is None or rate / limits[i] > worst / lim_w:
                    worst, lim_w = rate, limits[i]
            checks["wheel_speed"] = _check(worst, lim_w, worst <= lim_w)
        else:
            checks["wheel_speed"] = _skip("the run logged no step")

    # torque against the motor limit, and how often the controller lived on it
    tmax = [f.get("tau_max_nm") for f in fs]
    if any(v is None for v in tmax):
        checks["torque"] = _skip("a user's controller: no torque limit known")
    else:
        worst = max(range(len(fs)), key=lambda i: fs[i]["peak_abs_torque"] / tmax[i])
        checks["torque"] = _check(
            float(fs[worst]["peak_abs_torque"]),
            float(tmax[worst]),
            fs[worst]["peak_abs_torque"] <= tmax[worst] * (1 + 1e-9),
        )
    sat = [f["saturation_fraction"] for f in fs if f.get("saturation_fraction") == f.get("saturation_fraction")]
    if sat:
        checks["torque_saturation"] = _check(float(max(sat)), SATURATION_LIMIT, max(sat) <= SATURATION_LIMIT)
    else:
        checks["torque_saturation"] = _skip("the controller reports no saturation")

    # tip-over margins
    if params is None:
        checks["tip_over"] = _skip("the ideal plant has no chassis")
        checks["tip_over_lateral"] = _skip("the ideal plant has no chassis")
    elif len(t) >= 2:
        import mujoco

        from bioform_mj.assess.check import tip_margins

        scratch = mujoco.MjData(plant.model)
        mujoco.mj_kinematics(plant.model, scratch)
        dt = np.diff(t)
        acc = np.abs(np.diff(vel[:, :, 0], axis=0)) / dt[:, None]  # (K − 1, n) m/s²
        cen = np.abs(vel[:, :, 0] * vel[:, :, 1])
        tipped = [f["id"] for f in fs if any(o["kind"] == "tipped" for o in f.get("outcomes", []))]
        best_t = best_l = None
        for i in range(len(fs)):
            tips = tip_margins(plant.model, scratch, f"f{i + 1}/")["tip_accel_mps2"]
            lim_t = min(tips["forward"], tips["backward"])
            rt = (float(acc[:, i].max()), float(lim_t))
            rl = (float(cen[:, i].max()), float(tips["lateral"]))
            if best_t is None or rt[0] / max(rt[1], 1e-12) > best_t[0] / max(best_t[1], 1e-12):
                best_t = rt
            if best_l is None or rl[0] / max(rl[1], 1e-12) > best_l[0] / max(best_l[1], 1e-12):
                best_l = rl
        why = f"followers {', '.join(map(str, tipped))} tipped" if tipped else ""
        checks["tip_over"] = _check(best_t[0], best_t[1], best_t[0] <= best_t[1] and not tipped, why)
        checks["tip_over_lateral"] = _check(best_l[0], best_l[1], best_l[0] <= best_l[1] and not tipped, why)
    else:
        checks["tip_over"] = _skip("the run logged fewer than two steps")
        checks["tip_over_lateral"] = _skip("the run logged fewer than two steps")

    # separation against the footprint (or the safety distance)
    if fs and "min_separation_m" in fs[0]:
        limit = float(sc.safety.distance)
        seps = [f["min_separation_m"] for f in fs if f["min_separation_m"] is not None]
        touched = sum(f["robot_contacts"] + f["obstacle_contacts"] for f in fs)
        clear = [f["min_obstacle_clearance_m"] for f in fs if f.get("min_obstacle_clearance_m") is not None]
        least = min(seps + clear) if seps or clear else None
        if least is None:
            checks["separation"] = _check(None, limit, touched == 0, "no robot or obstacle came within range")
        else:
            why = f"{touched} contact events with robots or obstacles" if touched else ""
            checks["separation"] = _check(float(least), limit, least > limit and touched == 0, why)
    elif len(fs) > 1:
        checks["separation"] = _skip("the ideal plant's robots are points")

    # control rate against the robot's own: the mapping's control_rate, else its shipped preset's (design §19)
    if params is None:
        checks["control_rate"] = _skip("the ideal plant has no robot")
    else:
        rate = 1.0 / sc.sim.control_dt
        own = robot_control_rates(sc, plant)
        if any(r is None for r, _ in own):
            checks["control_rate"] = _skip(NO_CONTROL_RATE)
        else:
            lim_r, source = min(own, key=lambda x: x[0])
            checks["control_rate"] = _check(rate, lim_r, rate <= lim_r * (1 + 1e-9), source)

    # slip
    if not isinstance(plant, TipSlipWatch) or plant.slip_step is None:
        checks["slip"] = _skip("the ideal plant has no wheels")
    else:
        slips = [f["id"] for f in fs if any(o["kind"] == "slipping" for o in f.get("outcomes", []))]
        on = [float(s) * sc.sim.control_dt for s in plant.slip_step if s >= 0]
        checks["slip"] = _check(
            float(len(slips)),
            0.0,
            not slips,
            f"followers {', '.join(map(str, slips))} slipped from t = {min(on):.3f} s" if slips else "",
        )
        checks["slip"]["unit"] = "followers"

    failed = [k for k, c in checks.items() if c["pass"] is False]
    unchecked = [k for k, c in checks.items() if c["pass"] is None]  # never "pass" with a check skipped
    verdict_ = "fail" if failed else "incomplete" if unchecked else "pass"
    return {"verdict": verdict_, "failed": failed, "not_checked": unchecked, "checks": checks}


def _top_speeds(summary: dict[str, Any], n: int) -> list[float | None]:
    """Per follower, the top speed (m/s at the tyre) of the pre-run demand check's limits
    (``summary["demand"]``, :mod:`bioform_mj.run.demand`), None where unknown."""
    out: list[float | None] = [None] * n
    for r in (summary.get("demand") or {}).get("robots", []):
        for i in r.get("followers", []):
            if 1 <= i <= n:
                out[i - 1] = r.get("limits", {}).get("top_speed_mps")
    return out


def line(hw: dict[str, Any]) -> str:
    """One line for the end of a run: ``hardware: pass (7 checks passed)``, ``hardware: incomplete (…, not
    checked: wheel_speed (why))`` or the failures."""
    checks = hw["checks"]
    skipped = sum(1 for c in checks.values() if c["pass"] is None)
    ran = len(checks) - skipped
    if hw["verdict"] == "pass":
        return f"hardware: pass ({ran} checks passed)"
    if hw["verdict"] == "incomplete":
        why = "; ".join(f"{k} ({checks[k].get('reason', '')})" for k in hw.get("not_checked", []))
        return f"hardware: incomplete ({ran} checks passed, {skipped} not checked: {why})"
    bits = []
    for k in hw["failed"]:
        c = checks[k]
        v, lim = c["value"], c["limit"]
        txt = f"{k} {v:.3g} (limit {lim:.3g})" if isinstance(v, float) and isinstance(lim, float) else k
        bits.append(txt + (f" ({c['reason']})" if c.get("reason") else ""))
    rest = hw.get("not_checked", [])
    tail = f" (not checked: {', '.join(rest)})" if rest else ""
    return f"hardware: FAIL, would not run on the robot as specified: {'; '.join(bits)}{tail}"
