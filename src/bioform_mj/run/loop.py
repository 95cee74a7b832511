"""The closed loop's driver (design §9), run by :func:`bioform_mj.run.simulate.simulate`.

- :class:`Stepper`: the Python side of a control step (measure, control, record) and a chunk of
  steps with the contract of a plant's compiled chunk, one Python call per step;
- :func:`warm_up`: control step 0 and a zero-length chunk (kernels load or compile there, outside
  the timed loop);
- :func:`run_loop`: chunks of control periods between the points where Python must act (events,
  observers, progress, interrupts), until the end, a divergence, an interrupt or an error;
- :func:`start_observers`, :func:`finish_observers`, :class:`ObserverClock`: the observers' calls;
  :class:`EventQueue`: the scenario's timed events.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from bioform_mj.control.kernel import StackState
from bioform_mj.core.engine import GUARD_FAILED, OK, Loop, after_control, describe, record_odometry
from bioform_mj.core.errors import ControllerError, Diverged
from bioform_mj.plants.base import DeliveredTorques
from bioform_mj.run.hooks import _checked_torques, _tag, read_only

__all__ = [
    "MAX_CHUNK_S",
    "MIN_CHUNK_WALL_S",
    "Stepper",
    "LoopEnd",
    "warm_up",
    "run_loop",
    "start_observers",
    "finish_observers",
    "ObserverClock",
    "EventQueue",
    "first_step_at",
]

#: longest stretch of simulated time between two visits to Python (s): bounds the delay of
#: progress reports and of interrupts, unless the chunk took less wall time than :data:`MIN_CHUNK_WALL_S`
MAX_CHUNK_S = 0.1
#: a chunk whose steps ran in less wall time than this (s) is lengthened for the next one to take about
#: this long: each visit to Python costs ~0.1 ms (the kernel's dispatch over its ~20 arguments, the plant's
#: contact-list check, this loop), which was 5 % of the paper scene's 0.1 s chunk (2 ms) and more of the
#: ideal plant's, and the physics after each call runs slower for a while (paper scene, kernel time only:
#: the compiled chunk costs 7 % more than the bare replay in 5 ms chunks, 3 % in 20 ms, 0 % in 80 ms;
#: docs/findings/performance.md, "The gap at n = 3"); the results do not depend on where chunks end (the
#: step-by-step loop is bit-identical). 0.1 s also bounds the delay of progress reports and interrupts.
MIN_CHUNK_WALL_S = 0.1


class Stepper:
    """The Python side of each control step, on the loop's shared arrays ``ctx``.

    ``n`` followers; ``faults``: a :class:`~bioform_mj.run.faults.Faults` (None: none per step); ``own_stack``: the
    controller is the package's (its torques are not checked); ``kernel``: the controller's
    compiled kernel (None: a user's controller, whose signals are copied into ``ctx.state`` each
    step, the missing ones named in ``missing``); ``c_true`` (n, 2) the plant's coefficients
    (updated in place by events); ``odometry``: the controllers get the plant's dead reckoning
    (design §8.3).
    """

    def __init__(
        self,
        ctx: Loop,
        n: int,
        plant: Any,
        controller: Any,
        faults: Any,
        own_stack: bool,
        kernel: Any,
        c_true: np.ndarray,
        odometry: bool,
        missing: set[str],
    ) -> None:
        self.ctx, self.n, self.plant, self.controller, self.faults = ctx, n, plant, controller, faults
        self.own_stack, self.kernel, self.c_true = own_stack, kernel, c_true
        self.odometry, self.missing = odometry, missing
        self.cname = type(controller).__name__
        self.nonfinite: dict[str, Any] = {}  # design §17: a user's controller returned NaN/inf torques
        self.applied = np.zeros((self.n, 2))  # the torques the plant applies over the next period
        self.feed = isinstance(plant, DeliveredTorques) and bool(plant.feed_delivered)
        self.at = [0, 0]  # (steps done, log rows) of the Python chunk so far: kept when a step raises

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """What the controllers get: the true pose and velocity, or the odometry's (design §8.3)."""
        ctx = self.ctx
        return self.plant.measurement(ctx.pose, ctx.vel) if self.odometry else (ctx.pose, ctx.vel)

    def control(self, k: int) -> np.ndarray:
        """Control step ``k`` on the current measurements; the torques to apply."""
        ctx, controller, cname, dt = self.ctx, self.controller, self.cname, self.ctx.dt
        L_pose, L_vel = ctx.L_pose, ctx.L_vel
        mp, mv = self.measure()
        lp, lv = L_pose[k], L_vel[k]
        if not self.own_stack:  # a user's controller reads the loop's arrays through read-only views
            lp, lv, mp, mv = read_only(lp), read_only(lv), read_only(mp), read_only(mv)
        try:
            if self.faults is None:
                tau = controller.step(lp, lv, mp, mv)
            else:  # noisy sensing, faulty network, weakened motors, pushes; tau = what reaches the plant
                tau = self.faults.step(k, k * dt, controller, self.plant, lp, lv, mp, mv)
        except Exception as exc:
            _tag(exc, f"controller {cname}.step", k, k * dt)
            raise
        if not self.own_stack:
            tau = _checked_torques(tau, self.n, cname, k, dt)
            bad = ~np.all(np.isfinite(tau), axis=1)
            if bad.any():
                self.nonfinite.update(k=k, rows=np.flatnonzero(bad), tau=tau.copy())
                i = int(self.nonfinite["rows"][0])
                raise Diverged(
                    f"follower {i + 1}: controller {cname}.step returned non-finite torques {tau[i].tolist()} "
                    f"at t = {k * dt:.4f} s (step {k})",
                    step=k,
                    time=k * dt,
                )
        if self.kernel is None:
            try:
                sig = controller.signals()
            except Exception as exc:
                _tag(exc, f"controller {cname}.signals", k, k * dt)
                raise
            try:
                _shadow(ctx.state, sig, tau, self.missing)
            except (ValueError, TypeError) as exc:  # a signal of the wrong shape
                err = ControllerError(f"controller {cname}.signals() at step {k}: {exc}")
                _tag(err, f"controller {cname}.signals", k, k * dt)
                raise err from exc
        return np.array(tau, dtype=float)

    def record(self, k: int, j: int) -> tuple[int, int]:
        """After the control step of ``k``: metrics, guards and the log row (``engine.after_control``)."""
        ctx = self.ctx
        return after_control(
            k,
            ctx.N,
            ctx.stride,
            ctx.state,
            ctx.pose,
            ctx.vel,
            ctx.met,
            ctx.acc,
            ctx.log,
            j,
            ctx.L_pose,
            ctx.L_vel,
            ctx.dt,
            self.c_true,
            ctx.form,
            ctx.bounds,
            ctx.diag,
        )

    def python_chunk(self, k0: int, k1: int, j: int) -> tuple[int, int, int]:
        """The same contract as a compiled chunk, one Python call per step."""
        ctx, plant, dt, N = self.ctx, self.plant, self.ctx.dt, self.ctx.N
        self.at[:] = k0, j
        for k in range(k0, k1):
            plant.step(self.applied, k * dt)  # may raise Diverged (MuJoCo warnings)
            if self.feed:  # DC motors: the learner gets the torque delivered over the period (design §8.2)
                plant.feed_delivered_torque(ctx.state.tau_body)
            p, v = plant.observe()
            ctx.pose[:] = p
            ctx.vel[:] = v
            if k + 1 < N:
                self.applied = self.control(k + 1)
                j1, status = self.record(k + 1, j)
                if self.odometry and j1 > j:
                    record_odometry(ctx.log, j, plant.odo.mpose, plant.odo.mvel)
                j = j1
                self.at[:] = k + 1, j
                if status != OK:
                    return k + 1 - k0, j, status
        return k1 - k0, j, OK


#: a user controller's ``signals()`` names and the :class:`StackState` field each is copied into
_SIGNALS = (
    ("est_pose", "est_pose"),
    ("est_vel", "est_vel"),
    ("cmd", "cmd"),
    ("dcmd", "dcmd"),
    ("tau_raw", "tau_raw"),
    ("c_hat", "c_hat"),
    ("z_hat", "z_hat"),
    ("vs", "vs"),
    ("tracking_error", "err"),
    ("saturated", "saturated"),
)


def _shadow(state: StackState, sig: Any, tau: np.ndarray, missing: set[str]) -> None:
    """Copy a user controller's signals into the shadow state the metrics, guards and log read."""
    for name, attr in _SIGNALS:
        v = sig.get(name)
        if v is None:
            missing.add(name)
            if name == "tau_raw":
                state.tau_raw[:] = tau
            continue
        getattr(state, attr)[:] = v
    state.tau[:] = tau


class Warm(NamedTuple):
    """After :func:`warm_up`: the log rows so far, the guard status, what stopped the run already."""

    j: int
    status: int
    diverged: Diverged | None
    raised: Exception | None  # what a user's controller raised (design §17)
    setup_s: float  # s from ``t_setup`` to the kernels loaded


def warm_up(step: Stepper, run_chunk: Any, progress: Any, t_setup: float) -> Warm:
    """Control step 0 and its row, then a zero-length chunk: kernels are loaded (or compiled) here,
    outside the timed loop."""
    if progress is not None and hasattr(progress, "phase"):
        progress.phase("loading compiled kernels (compiling them on the first run)")
    diverged: Diverged | None = None
    raised: Exception | None = None  # what a user's controller or observer raised (design §17)
    j, status = 0, OK
    try:
        step.applied = step.control(0)
        j, status = step.record(0, 0)
    except Diverged as e:  # non-finite torques of a user's controller at step 0
        diverged = e
    except Exception as exc:  # noqa: BLE001 - re-raised by simulate, with the log so far attached
        raised = exc
    if step.odometry and j > 0:
        record_odometry(step.ctx.log, 0, step.plant.odo.mpose, step.plant.odo.mvel)
    run_chunk(0, 0, j)
    setup_s = time.perf_counter() - t_setup
    if progress is not None and hasattr(progress, "phase"):
        progress.phase(None)
    return Warm(j, status, diverged, raised, setup_s)


def start_observers(observers: Sequence[Any], state_obs: Any, raised: Exception | None):
    """Each observer's ``start`` (none if the run failed already); returns ``(started, raised)``."""
    started: list[Any] = []
    if raised is None:
        try:
            for o in observers:
                try:
                    o.start(state_obs)
                except Exception as exc:
                    _tag(exc, f"observer {type(o).__name__}.start", 0, 0.0)
                    raise
                started.append(o)
        except Exception as exc:  # noqa: BLE001 - re-raised by simulate
            raised = exc
    return started, raised


class LoopEnd(NamedTuple):
    """How the loop ended: steps done, log rows, the final true state, the loop's wall time (s),
    its CPU time (s, ``time.process_time``) and what stopped it early (a divergence, an interrupt, an
    exception to re-raise)."""

    k_done: int
    j: int
    pose: np.ndarray  # (n, 3) copy
    vel: np.ndarray  # (n, 2) copy
    wall: float
    diverged: Diverged | None
    interrupted: KeyboardInterrupt | None
    raised: Exception | None
    cpu: float


def run_loop(
    sc: Any,
    step: Stepper,
    run_chunk: Any,
    compiled: bool,
    observers: Sequence[Any],
    state_obs: Any,
    warm: Warm,
    raised: Exception | None,
    progress: Any,
) -> LoopEnd:
    """Chunks of control periods up to ``ctx.N``, stopping at every event, due observer and
    :data:`MAX_CHUNK_S` (longer where that ran in under :data:`MIN_CHUNK_WALL_S`); a divergence, a
    ``KeyboardInterrupt`` or an exception stops it (the log so far is kept). ``compiled``: ``run_chunk`` is
    the plant's compiled chunk."""
    ctx, plant, c_true = step.ctx, step.plant, step.c_true
    N, dt, stride, lg, L_pose, L_vel = ctx.N, ctx.dt, ctx.stride, ctx.log, ctx.L_pose, ctx.L_vel
    j, status, diverged = warm.j, warm.status, warm.diverged
    obs = ObserverClock(observers, state_obs)
    evq = EventQueue(sc.events, dt)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    interrupted: KeyboardInterrupt | None = None
    k = 0
    if status != OK and diverged is None:
        diverged = Diverged(describe(ctx.diag, 0.0, ctx.bounds), step=0, time=0.0)
    try:
        base_chunk = max(1, int(round(MAX_CHUNK_S / dt)))
        max_chunk = base_chunk
        while k < N and diverged is None and raised is None:
            if evq.apply(k, plant):
                c_true[:] = plant.c_true()
                if k % stride == 0 and j > 0:
                    lg.c_true[j - 1] = c_true  # this step's row shows the new plant
            obs.sample(k * dt, L_pose[k], L_vel[k], ctx.pose, ctx.vel)
            k1 = _chunk_end(k, N, max_chunk, evq, obs, dt)
            t_chunk = time.perf_counter()
            try:
                done, j, status = run_chunk(k, k1, j)
            except Diverged as e:  # a MuJoCo warning, a user's non-finite torques: keep the log so far
                diverged = e
                if step.nonfinite:  # ours (a user's controller, stepwise): the rows of this chunk are kept
                    j = step.at[1]
                k = e.step
                break
            except Exception as exc:  # noqa: BLE001 - a user's controller raised: re-raised by simulate
                raised = exc
                if not compiled:  # the steps the plant made (the failing control step's index), the rows kept
                    k, j = int(getattr(exc, "_bioform_step", step.at[0])), step.at[1]
                break
            k += done
            max_chunk = _next_chunk(base_chunk, done, time.perf_counter() - t_chunk)
            if status == GUARD_FAILED:
                diverged = Diverged(describe(ctx.diag, k * dt, ctx.bounds), step=k, time=k * dt)
            if progress is not None:
                progress(k, N)
    except KeyboardInterrupt as exc:
        interrupted = exc
    except Exception as exc:  # noqa: BLE001 - an observer's sample raised: re-raised by simulate
        raised = exc
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    pose, vel = ctx.pose.copy(), ctx.vel.copy()
    k_done = min(k, N)
    if (
        diverged is None
        and not interrupted
        and raised is None
        and not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel)))
    ):
        diverged = Diverged(f"non-finite robot state at the end of the run (t = {N * dt:g} s)", step=N, time=N * dt)
    if progress is not None and diverged is None and not interrupted and raised is None:
        progress(N, N)
    return LoopEnd(k_done, j, pose, vel, wall, diverged, interrupted, raised, cpu)


def _next_chunk(base: int, done: int, wall: float) -> int:
    """Steps of the next chunk: ``base`` (:data:`MAX_CHUNK_S`), or as many as take about
    :data:`MIN_CHUNK_WALL_S` at the last chunk's pace (``done`` steps in ``wall`` s) when that is more."""
    if done <= 0:
        return base
    return max(base, int(done * MIN_CHUNK_WALL_S / max(wall, 1e-9)))


def _chunk_end(k: int, N: int, max_chunk: int, evq: EventQueue, obs: ObserverClock, dt: float) -> int:
    """Where the chunk from step ``k`` ends (exclusive): after at most ``max_chunk`` steps, at the next
    event and at the next observer due, and at least one step on."""
    k1 = min(N, k + max_chunk)
    nxt = evq.next_step()
    if nxt is not None:
        k1 = min(k1, max(k + 1, nxt))
    for tn in obs.next:
        k1 = min(k1, max(k + 1, first_step_at(tn, dt)))
    return k1


def finish_observers(started: Sequence[Any], state_obs: Any, step: Stepper, end: LoopEnd) -> Exception | None:
    """Each started observer's ``finish`` on the final state (not the one whose ``sample`` raised);
    returns what to re-raise (the first error)."""
    k_done, dt = end.k_done, step.ctx.dt
    state_obs.t, state_obs.pose, state_obs.vel = k_done * dt, end.pose, end.vel
    state_obs.leader_pose, state_obs.leader_vel = step.ctx.L_pose[k_done], step.ctx.L_vel[k_done]
    raised = end.raised
    culprit = getattr(raised, "_bioform_source", None)
    for o in started:
        if (
            culprit is not None
            and culprit == f"observer {type(o).__name__}.sample"
            and o is getattr(raised, "_bioform_obj", None)
        ):
            continue  # the observer that failed is not asked to finish
        try:
            o.finish(state_obs)
        except Exception as exc:
            if raised is not None:  # already failing: say it, keep the first error
                raised.add_note(f"(observer {type(o).__name__}.finish also raised {type(exc).__name__}: {exc})")
                continue
            _tag(exc, f"observer {type(o).__name__}.finish", k_done, k_done * dt)
            raised = exc
    return raised


class ObserverClock:
    """Calls each observer's ``sample`` once its period of simulated time has passed."""

    def __init__(self, observers: Sequence[Any], state: Any) -> None:
        self.observers = list(observers)
        self.state = state
        self.next = [0.0] * len(self.observers)  # s, next due time of each

    def sample(self, t: float, leader_pose, leader_vel, pose, vel) -> None:
        """At control time ``t`` (s), before the plant step: sample the observers that are due."""
        if not self.observers:
            return
        st = self.state
        st.t, st.leader_pose, st.leader_vel, st.pose, st.vel = t, leader_pose, leader_vel, pose, vel
        for i, o in enumerate(self.observers):
            if t >= self.next[i] - 1e-12:
                try:
                    o.sample(st)
                except Exception as exc:
                    _tag(exc, f"observer {type(o).__name__}.sample", int(round(t / st.scenario.sim.control_dt)), t)
                    exc._bioform_obj = o  # type: ignore[attr-defined]
                    raise
                self.next[i] += o.period


class EventQueue:
    """The scenario's timed events, applied to the plant at the first control step at or after their time."""

    def __init__(self, events: Sequence[Any], dt: float) -> None:
        self.events = sorted(events, key=lambda e: e.time)
        self.steps = [first_step_at(e.time, dt) for e in self.events]
        self.i = 0

    def next_step(self) -> int | None:
        """Control step of the next pending event (None: no more)."""
        return self.steps[self.i] if self.i < len(self.steps) else None

    def apply(self, k: int, plant: Any) -> bool:
        """Apply every event due at step ``k``; True if any was."""
        applied = False
        while self.i < len(self.events) and self.steps[self.i] <= k:
            ev = self.events[self.i]
            plant.add_payload(ev.follower - 1, ev.mass, ev.inertia)
            self.i += 1
            applied = True
        return applied


def first_step_at(t: float, dt: float) -> int:
    """The first control step ``k`` with ``k·dt ≥ t`` (to 1e-12 s)."""
    return max(0, int(math.ceil((t - 1e-12) / dt - 1e-9)))
