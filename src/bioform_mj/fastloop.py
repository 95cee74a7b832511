"""The closed loop in compiled chunks: Python only at log samples, observers and events.

:func:`bioform_mj.sim.simulate` uses this when the stack is a
:class:`~bioform_mj.control.fused.FusedControlStack`, the plant is the ideal or the
MuJoCo plant, and nothing needs a Python hook every control step (injected faults do).
Between two such points, :func:`~bioform_mj.control.fused.run_ideal_chunk` or
``run_mujoco_chunk`` advance plant and controller together. The order of operations
is that of the generic loop in ``sim.py``::

    control(k) → metrics → [events at t_k, log k, observers at t_k] → plant step k → observe

Events only change the plant's parameters, so applying them after the control step of
``k`` and before the plant step of ``k`` is the same as before it.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .control.fused import (
    LOG_ORDER,
    FusedControlStack,
    _accumulate,
    _after_control,
    control_step,
    HAVE_MJ_STEP,
    record_row,
    run_ideal_chunk,
    run_mujoco_chunk,
)
from .disturbance import Harmonic
from .errors import Diverged
from .plants.ideal import IdealPlant


def _dist_terms(plant: Any) -> np.ndarray | None:
    """The (2, 4) ``bias, amp, freq, phase`` of a harmonic disturbance, zeros if none, None if unknown."""
    d = getattr(plant, "disturbance", None)
    if d is None:
        return np.zeros((2, 4))
    if not isinstance(d, Harmonic):
        return None
    return np.array(d.terms, dtype=float).reshape(2, 4)


def supported(plant: Any, stack: Any) -> bool:
    """Whether the compiled loop can drive this plant and stack."""
    if not isinstance(stack, FusedControlStack) or _dist_terms(plant) is None:
        return False
    if type(plant) is IdealPlant:
        return True
    from .plants.mujoco_plant import MujocoPlant

    return type(plant) is MujocoPlant and HAVE_MJ_STEP


#: longest stretch of simulated time between two visits to Python (s): bounds the delay of
#: progress reports and of MuJoCo-warning checks
MAX_CHUNK_S = 0.1


def run(sc, plant, stack: FusedControlStack, L_pose: np.ndarray, L_vel: np.ndarray, N: int, stride: int,
        evq: Any, obs: Any, progress: Callable | None,
        logd: dict[str, np.ndarray], guard: Callable[..., Diverged | None],
        record_inputs: tuple[np.ndarray, np.ndarray] | None = None,
        ) -> tuple[int, int, Diverged | None, np.ndarray, np.ndarray, np.ndarray]:
    """Run the closed loop from the state after ``plant.reset`` and ``stack.reset``.

    ``evq`` and ``obs`` are the run's ``sim.EventQueue`` and ``sim.ObserverClock``.
    Log samples go into the preallocated ``logd`` (``sim.CHANNELS``); the kernels check
    each one, and on a failed check ``guard(logd, j, t, k, limits)`` writes the diagnosis.
    ``record_inputs = (ctrl (N, nu), xfrc (N, n, 6))`` (MuJoCo only) receives every step's
    actuator and chassis-force inputs, for a bare-physics replay (``bioform bench``).
    Returns ``(steps done, log rows written, divergence, pose, vel, metrics (n, 5))``.
    """
    n = plant.n
    dt = float(sc.sim.control_dt)
    lim = sc.limits
    lim3 = np.array([lim.position, lim.speed, lim.torque], dtype=float)
    lg = tuple(logd[name] for name in LOG_ORDER)
    pose, vel = plant.observe()
    pose = np.ascontiguousarray(pose, dtype=float)
    vel = np.ascontiguousarray(vel, dtype=float)
    met = np.zeros((n, 5))
    ew, lw, rp, rv = stack.no_comm
    Lp = np.ascontiguousarray(L_pose, dtype=float)
    Lv = np.ascontiguousarray(L_vel, dtype=float)
    dist = _dist_terms(plant)
    if type(plant) is IdealPlant:
        x = np.ascontiguousarray(plant.x, dtype=float)
        plant.x = x  # the plant object sees the state the kernel advances

        def chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
            return run_ideal_chunk(stack.st, k0, k1, N, dt, plant.n_substeps, Lp, Lv, np.ascontiguousarray(plant._c),
                                   dist, x, pose, vel, met, ew, lw, rp, rv, lg, j, stride, lim3)

        def check(k: int) -> None:
            return None
    else:
        m, d = plant.model, plant.data
        q7 = np.ascontiguousarray(plant._q7, dtype=np.int64)
        v6 = np.ascontiguousarray(plant._v6, dtype=np.int64)
        ctrl_id = np.ascontiguousarray(plant._ctrl, dtype=np.int64)
        base = np.ascontiguousarray(plant._base, dtype=np.int64)
        arrays = (d.qpos, d.qvel, d.ctrl, d.xfrc_applied, d.xmat)
        warnings = plant._warnings
        rec = record_inputs if record_inputs is not None else (np.zeros((0, m.nu)), np.zeros((0, n, 6)))

        def chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
            qpos, qvel, ctrl, xfrc, xmat = arrays
            return run_mujoco_chunk(stack.st, k0, k1, N, dt, plant.n_substeps, Lp, Lv, m._address, d._address,
                        qpos, qvel, q7, v6, ctrl, ctrl_id, xfrc, xmat, base,
                        np.ascontiguousarray(plant._m_eff), np.ascontiguousarray(plant._i_eff), dist,
                        pose, vel, met, ew, lw, rp, rv, lg, j, stride, lim3,
                        np.ascontiguousarray(plant._c), rec[0], rec[1])

        def check(k: int) -> None:
            plant._step_count = k
            for i, w in enumerate(warnings):
                if w.number:
                    plant._raise_warning(i, w)  # raises Diverged

    def diagnose(j: int) -> Diverged:
        t_ = float(logd["t"][j - 1])
        k_ = int(round(t_ / dt))
        return guard(logd, j - 1, t_, k_, lim) or Diverged(f"the run failed its checks at t = {t_:.4f} s", step=k_, time=t_)

    # control step 0 and its log sample
    diverged: Diverged | None = None
    control_step(stack.st, Lp[0], Lv[0], pose, vel, False, ew, lw, rp, rv)
    _accumulate(stack.st, vel, met)
    j, ok = _after_control(0, N, stride, lg, 0, lim3, Lp, Lv, dt, pose, vel, stack.st, np.ascontiguousarray(plant._c))
    if not ok:
        return 0, j, diagnose(j), pose, vel, met
    from .sim import first_step_at

    max_chunk = max(1, int(round(MAX_CHUNK_S / dt)))
    k = 0
    while k < N:
        t = k * dt
        if evq.apply(k, plant) and k % stride == 0:
            logd["c_true"][j - 1] = plant.c_true()  # this step's sample shows the new plant, as stepwise
        obs.sample(t, L_pose[k], L_vel[k], pose, vel)
        # the next step at which Python must act
        k1 = min(N, k + max_chunk)
        if evq.next_step() is not None:
            k1 = min(k1, max(k + 1, evq.next_step()))
        for tn in obs.next:
            k1 = min(k1, max(k + 1, first_step_at(tn, dt)))
        done, j, status = chunk(k, k1, j)
        k += done
        try:
            check(k)
        except Diverged as e:
            diverged = e
            break
        if progress is not None:
            progress(k, N)
        if status == 1:
            diverged = diagnose(j)
            break
        if status == 2:  # non-finite plant state: log it and stop
            record_row(lg, j, k * dt, Lp[k], Lv[k], pose, vel, stack.st, np.ascontiguousarray(plant._c))
            j += 1
            diverged = diagnose(j)
            break
    return k, j, diverged, pose, vel, met
