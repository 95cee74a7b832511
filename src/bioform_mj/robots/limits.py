"""A robot's limits in one place (design §21): top speed, torque, traction, tip-over, acceleration.

:func:`limits_of` gathers, for one robot of a built :class:`~bioform_mj.plants.mujoco.plant.MujocoPlant`:

- ``top_speed_mps`` (m/s at the tyre) and where it came from, first found of: the mapping's
  ``top_speed`` (the maker's datasheet figure); the top wheel speed the robot file states × r (its
  format's ``wheel_speed``; URDF: the wheel joints' ``<limit velocity>``; the source is the format's
  name; a value ≥ :data:`PLACEHOLDER_RADPS` rad/s is named a placeholder and not used); a
  ``<dcmotor>``'s no-load wheel speed ``V_max / (K g)`` × r. None (``missing`` says so) otherwise;
- ``torque_nm`` (the motor limit per wheel) and ``traction_torque_nm`` (``μ N r / f``, design §13);
- ``accel_mps2``: the largest forward acceleration, ``min(2 a τ_max, 2 a τ_traction, tip forward,
  tip backward)`` and which one sets it; ``yaw_accel_radps2``: ``2 b min(τ_max, τ_traction)``;
- ``tip_accel_mps2`` (forward, backward, lateral; :func:`~bioform_mj.assess.check.tip_margins`);
- ``control_rate_hz``: the mapping's ``control_rate`` (Hz, the maker's controller's rate; design §19), else None.

``robot check`` prints them as one block and keeps them in its JSON (``limits``); the demand check
(:mod:`bioform_mj.run.demand`) and ``formation.time_scale = "auto"`` compare a scenario with them.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.robots.refs import RobotRef

#: a wheel joint's URDF ``<limit velocity>`` at or above this (rad/s) is a placeholder, not a motor's
#: figure (50 rad/s on a 0.1 m wheel is 5 m/s; files copy 100 or 1000 from templates)
PLACEHOLDER_RADPS = 50.0


def file_wheel_speed(model_file: str, wheel_joints: list[str], ref: Any = None) -> tuple[float | None, str, Any]:
    """``(the least top speed (rad/s) the robot file states for the named wheel joints, why none, its format)``,
    asked of the file's format (its ``wheel_speed``, :mod:`bioform_mj.robots.formats`; URDF: the wheel joints'
    ``<limit velocity>``): None with ``""`` if the format states none or a wheel has none, None with the reason if
    the file cannot be read again. The file is read as the robot's import read it: ``ref``'s package path, xacro flag
    and arguments and ``asset_roots`` (a mesh let in only through ``asset_roots`` must not hide the top speed;
    issue 28). The format is None where none reads the file."""
    from bioform_mj.robots.formats import format_of

    fmt = None
    try:
        fmt = format_of(model_file)
        if fmt.wheel_speed is None:
            return None, "", fmt
        r = replace(ref, model=model_file) if isinstance(ref, RobotRef) else RobotRef(model_file)
        w = fmt.wheel_speed(r, Path(model_file), wheel_joints)
    except Exception as exc:  # noqa: BLE001 - said in the top speed's note, never silently dropped
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        what = fmt.wheel_speed_what if fmt is not None else "the file's wheel speed limit"
        return None, f"{what} not read ({why})", fmt
    if w is None or not w > 0:
        return None, "", fmt
    return float(w), "", fmt


def dc_no_load_speed(plant: Any, i: int) -> float | None:
    """The least no-load wheel speed ``V_max / (K g)`` (rad/s) of follower ``i``'s ``<dcmotor>``
    actuators, None if its motors are torque sources."""
    import mujoco

    from bioform_mj.robots.layout import dc_constants

    m = plant.model
    nl = []
    for a in plant._ctrl[i]:
        if int(m.actuator_dyntype[a]) == int(mujoco.mjtDyn.mjDYN_DCMOTOR):
            _r, k, g, vmax = dc_constants(m, int(a))
            if k > 0 and g > 0 and vmax > 0:
                nl.append(vmax / (k * g))
    return float(min(nl)) if nl else None


def top_speed(ref: Any, plant: Any, i: int) -> tuple[float | None, str, str]:
    """``(m/s at the tyre, source, note)`` of follower ``i``: the mapping's ``top_speed``, else the
    top wheel speed its file states × r (:func:`file_wheel_speed`; a placeholder ≥ 50 rad/s is said and not used), else
    the ``<dcmotor>`` no-load speed × r; ``(None, "", why)`` when none is known."""
    p = plant.params[i]
    r = float(p.wheel_radius)
    notes = []
    if ref is not None and getattr(ref, "top_speed", 0.0) > 0:
        return float(ref.top_speed), "mapping", "the robot mapping's top_speed (the maker's figure)"
    lay = plant.layouts[i]
    wheels = [j.split("/", 1)[1] if "/" in j else j for j in lay.wheel_joints]
    model_file = str(getattr(ref, "model", "") or lay.file)
    w, unread, fmt = file_wheel_speed(model_file, wheels, ref=ref)
    if unread:
        notes.append(unread)
    if w is not None:
        what = fmt.wheel_speed_what
        if w < PLACEHOLDER_RADPS:
            return w * r, fmt.name, f"{what} {w:g} rad/s × r (the file's, not a datasheet's)"
        notes.append(f"{what} {w:g} rad/s ({w * r:.3g} m/s) looks like a placeholder")
    nl = dc_no_load_speed(plant, i)
    if nl is not None:
        return nl * r, "dcmotor", "; ".join([*notes, f"the <dcmotor> no-load speed {nl:.4g} rad/s × r"])
    notes.append(
        "no top speed known: give the maker's figure as the robot mapping's top_speed (m/s at the tyre), "
        "e.g. plant.robots = [{model = ..., top_speed = 0.22}]"
    )
    return None, "", "; ".join(notes)


def limits_of(plant: Any, i: int, ref: Any, loads: np.ndarray, tips: dict[str, float]) -> dict[str, Any]:
    """The limits of follower ``i`` (module docstring): ``loads`` its settled wheel loads (N), ``tips``
    its static tip margins (m/s², forward / backward / lateral)."""
    p = plant.params[i]
    mu = plant._wheel_friction(i)
    traction = float(p.traction_torque(mu, float(np.min(loads))))
    motor = float(np.min(p.tau_max))
    v_top, source, note = top_speed(ref, plant, i)
    cand = {
        "torque": 2 * p.a_eff * motor,
        "traction": 2 * p.a_eff * traction,
        "tip forward": float(tips["forward"]),
        "tip backward": float(tips["backward"]),
    }
    acc_by = min(cand, key=lambda k: cand[k])
    yaw_by = "torque" if motor <= traction else "traction"
    missing = [] if v_top is not None else ["top_speed"]
    return {
        "top_speed_mps": v_top,
        "top_speed_source": source or None,
        "top_speed_note": note,
        "wheel_speed_radps": None if v_top is None else v_top / p.wheel_radius,
        "torque_nm": motor,
        "traction_torque_nm": traction,
        "friction_mu": float(mu),
        "accel_mps2": float(cand[acc_by]),
        "accel_limited_by": acc_by,
        "yaw_accel_radps2": float(2 * p.b_eff * min(motor, traction)),
        "yaw_accel_limited_by": yaw_by,
        "tip_accel_mps2": {k: float(v) for k, v in tips.items()},
        "lateral_accel_mps2": float(tips["lateral"]),
        # design §19: the rate the robot's own controller runs at (the mapping's; else the hardware verdict's preset)
        "control_rate_hz": float(ref.control_rate) if ref is not None and getattr(ref, "control_rate", 0) > 0 else None,
        "control_rate_source": "mapping" if ref is not None and getattr(ref, "control_rate", 0) > 0 else None,
        "missing": missing,
    }


def block(lim: dict[str, Any]) -> list[str]:
    """The limits as lines of ``robot check``'s report (one block)."""
    v = lim["top_speed_mps"]
    ta = lim["tip_accel_mps2"]
    speed = f"{v:.3g} m/s at the tyre ({lim['top_speed_source']})" if v is not None else "unknown"
    return [
        "  limits:",
        f"    top speed {speed}" + (f"; {lim['top_speed_note']}" if lim["top_speed_note"] else ""),
        f"    torque {lim['torque_nm']:.3g} N·m per wheel, traction {lim['traction_torque_nm']:.3g} N·m "
        f"(μ = {lim['friction_mu']:g})",
        f"    acceleration {lim['accel_mps2']:.3g} m/s² (set by {lim['accel_limited_by']}), yaw acceleration "
        f"{lim['yaw_accel_radps2']:.3g} rad/s² (set by {lim['yaw_accel_limited_by']})",
        f"    tip-over forward {ta['forward']:.3g}, backward {ta['backward']:.3g}, lateral {ta['lateral']:.3g} m/s²",
        f"    control rate {lim['control_rate_hz']:.4g} Hz (the mapping's)"
        if lim.get("control_rate_hz")
        else "    control rate: not given (the mapping's control_rate, Hz; a shipped preset's where one drives it)",
    ]
