"""A run's ``summary.json`` (design §9): per follower the metrics, the outcomes and the robot that
was used; versions, timing, divergence or interrupt, the resolved configuration. Built by
:func:`bioform_mj.run.simulate.simulate` at the end of the loop."""

from __future__ import annotations

import platform
from typing import Any, NamedTuple

import numpy as np

from bioform_mj._version import __version__
from bioform_mj.assess.outcomes import follower_outcomes, robot_check_resistances, severity, slots_of
from bioform_mj.core.engine import CHANNELS, MEAN_CHANNELS
from bioform_mj.plants.base import ContactWatch, LumpedBodies, RobotModels, TipSlipWatch
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.record import resolved_config


class RunEnd(NamedTuple):
    """How a run ended, as :func:`_summary` reads it (built by :func:`bioform_mj.run.simulate.simulate`)."""

    state: Any  # the controller's StackState (a user's controller: the shadow of its signals)
    met: Any  # engine.Metrics, per follower
    logd: dict[str, np.ndarray]  # the run's log
    lp_end: np.ndarray  # (3,) the leader's pose at the last step done
    pose: np.ndarray  # (n, 3) the followers' final true poses
    k_done: int  # control steps done
    dt: float  # control period, s
    wall: float  # s, the loop
    setup_s: float  # s, before the loop
    diverged: Any  # Diverged or None
    interrupted: Any  # KeyboardInterrupt or None
    missing: set[str]  # the signals a user's controller did not give
    engine: str  # "compiled" or "stepwise"


def _summary(
    sc: Scenario, plant: Any, controller: Any, run: RunEnd, robot_check: dict[str, Any] | None = None
) -> dict[str, Any]:
    """summary.json of a run (design §9): per follower the metrics, outcomes and the robot used; the run's
    scenario, engine, timing, how it ended, the log's channels, versions and resolved configuration.
    ``robot_check``: the run's ``prerun.before_run`` (its identified resistances name ``c_hat_off``'s cause)."""
    state, met, logd, lp_end, pose = run.state, run.met, run.logd, run.lp_end, run.pose
    k_done, dt, missing = run.k_done, run.dt, run.missing
    n = sc.n
    final_form = np.linalg.norm(pose[:, :2] - slots_of(sc, lp_end), axis=1)
    est = state.est_pose if "est_pose" not in missing else np.full((n, 3), np.nan)
    final_est = np.linalg.norm(est[:, :2] - lp_end[None, :2], axis=1)
    fe = logd["formation_error"]
    half = fe[len(fe) // 2 :] if len(fe) else fe
    c_true = plant.c_true()
    c_hat = state.c_hat if "c_hat" not in missing else np.full((n, 2), np.nan)
    nan_if = lambda name, v: float("nan") if name in missing else float(v)  # noqa: E731
    found = robot_check_resistances(robot_check, n)  # design §14.2: what robot check identified, per follower
    outcomes = follower_outcomes(sc, plant, controller, logd, final_form, c_hat, dt, found)
    contact = contact_outcomes(plant, n, dt)  # design §19: contacts and distances (MuJoCo)
    followers = []
    for i in range(n):
        every = sorted(outcomes[i] + contact[i][1], key=severity)  # every outcome, the most severe first
        followers.append(
            {
                "id": i + 1,
                "outcome": every[0]["kind"] if every else "ok",
                "outcome_detail": every[0]["detail"] if every else "",
                "outcomes": every,
                **contact[i][0],
                "total_velocity_error": nan_if("cmd", met.verr[i] * dt),
                "final_formation_error_m": float(final_form[i]),
                "rms_formation_error_m": float(np.sqrt(np.mean(fe[:, i] ** 2))) if len(fe) else float("nan"),
                "rms_formation_error_last_half_m": float(np.sqrt(np.mean(half[:, i] ** 2)))
                if len(half)
                else float("nan"),
                "final_estimation_error_m": float(final_est[i]),
                "max_abs_v_cmd": nan_if("cmd", met.vmax[i]),
                "peak_abs_torque": float(met.tau[i]),
                "peak_abs_torque_commanded": float(met.tau_raw[i]),
                "saturation_fraction": nan_if("saturated", met.sat[i] / max(1, k_done)),
                "c_hat": [float(v) for v in c_hat[i]],
                "c_true": [float(v) for v in c_true[i]],
                "c_hat_rel_error": [float(v) for v in (c_hat[i] / c_true[i] - 1.0)],
                # opt-in learner.drag (design §14): the learned drag rates k̂ [1/s] of υ, ω; None when off
                "drag_hat_per_s": [float(v) for v in state.k_hat[i]] if sc.learner.drag else None,
                **_robot_used(sc, plant, controller, i),
            }
        )
    return {
        "scenario": sc.name,
        "plant": sc.plant.kind,
        "method": sc.method if getattr(controller, "p", None) is not None else type(controller).__name__,
        "controller": type(controller).__name__,
        "engine": run.engine,
        "seed": sc.sim.seed,
        "sim_time_s": k_done * dt,
        "wall_time_s": run.wall,
        "setup_time_s": run.setup_s,
        "steps": k_done,
        "diverged": None
        if run.diverged is None
        else {"message": str(run.diverged), "time_s": run.diverged.time, "step": run.diverged.step},
        "interrupted": None
        if run.interrupted is None
        else {"signal": _signal_name(getattr(run.interrupted, "signum", 2)), "time_s": k_done * dt},
        "log_channels": {name: CHANNELS[name][1] for name in CHANNELS},
        "log_interval_means": list(MEAN_CHANNELS),
        "versions": _versions(),
        "formation_scale": sc.formation.scale,  # applied: config holds the scaled values with scale = 1
        "time_scale": sc.formation.time_scale,  # design §21: applied likewise (config: time_scale = 1)
        "scale_note": sc.formation.scale_note,  # why ("auto": from what, which limit set σ)
        # design §21: the slip ratio's speed floor (m/s) and where it came from; None: the plant watches no slip
        "slip_floor": dict(plant.slip_floor_entry) if isinstance(plant, TipSlipWatch) else None,
        "config": resolved_config(sc),  # the run's own record: load() takes it back unchanged
        # opt-in (design §14, learner_sizing): the c and kd sized to the identified resistance; None: off
        "learner_sizing": getattr(getattr(controller, "p", None), "sizing", None),
        "followers": followers,
    }


def _robot_used(sc: Scenario, plant: Any, controller: Any, i: int) -> dict[str, Any]:
    """What follower ``i``'s robot really was: torque limit, mass, yaw inertia (design §9)."""
    p = getattr(controller, "p", None)
    out: dict[str, Any] = {"tau_max_nm": float(np.broadcast_to(p.tau_max, (sc.n,))[i]) if p is not None else None}
    if isinstance(plant, RobotModels):
        rp = plant.params[i]
        out["mass_kg"] = float(rp.mass)
        out["yaw_inertia_kgm2"] = float(rp.yaw_inertia)
    else:
        mass, inertia = (plant.mass, plant.inertia) if isinstance(plant, LumpedBodies) else (None, None)
        out["mass_kg"] = None if mass is None else float(mass[i])
        out["yaw_inertia_kgm2"] = None if inertia is None else float(inertia[i])
    return out


def _signal_name(signum: int) -> str:
    import signal

    try:
        return signal.Signals(signum).name
    except ValueError:
        return str(signum)


def _versions() -> dict[str, str]:
    out = {"bioform_mj": __version__, "numpy": np.__version__, "python": platform.python_version()}
    try:
        import mujoco

        out["mujoco"] = mujoco.__version__
    except ImportError:  # pragma: no cover - mujoco is a dependency
        out["mujoco"] = "not installed"
    return out


def contact_outcomes(plant: Any, n: int, dt: float) -> list[tuple[dict[str, Any], list[dict]]]:
    """Per follower the contact/proximity fields and outcomes (``collided``, ``too_close``) of a
    plant that watches them (:func:`bioform_mj.formation.safety.follower_fields`); none for the others."""
    if not isinstance(plant, ContactWatch):
        return [({}, []) for _ in range(n)]
    watch = plant.contact_watch()
    from bioform_mj.formation.safety import follower_fields

    names = [o.name for o in plant.obstacles]
    return [follower_fields(watch, i, dt, names) for i in range(n)]
