"""The paper's idealised plant: unicycle kinematics with ``ż = diag(τ_a, τ_b) c + d`` (eq. 34).

The RK4 step is :func:`~bioform_mj.core.equations.unicycle_rk4` (written once); the
plant object and the compiled chunk kernel :func:`run_chunk` both call it, so the
step-by-step loop and the compiled loop compute the same bits.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from bioform_mj.control.kernel import knobs, safety_filter, stack_head, stack_tail
from bioform_mj.core.engine import OK, ROW, after_step, record
from bioform_mj.core.equations import njit, unicycle_rk4, wrap
from bioform_mj.formation.disturbance import harmonic_rows
from bioform_mj.plants.base import DisturbanceFn


@njit
def ideal_step(x, tau, c, extra, dist, t, dt, n_sub):
    """Advance ``x`` (n, 5) ``[x, y, θ, υ, ω]`` in place over one control period ``dt`` (s) from
    ``t``: ``n_sub`` RK4 steps with ``acc = diag(τ_a, τ_b) c + extra`` held, the harmonic
    disturbance rows ``dist`` (2, 4) ``bias, amp, freq, phase``; heading wrapped at the end."""
    h = dt / n_sub
    for i in range(x.shape[0]):
        tl = tau[i, 0]
        tr = tau[i, 1]
        av = (tl + tr) * c[i, 0] + extra[i, 0]
        aw = (tr - tl) * c[i, 1] + extra[i, 1]
        xi, yi, th, v, w = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4]
        for s in range(n_sub):
            xi, yi, th, v, w = unicycle_rk4(
                xi,
                yi,
                th,
                v,
                w,
                av,
                aw,
                dist[0, 0],
                dist[0, 1],
                dist[0, 2],
                dist[0, 3],
                dist[1, 0],
                dist[1, 1],
                dist[1, 2],
                dist[1, 3],
                t + s * h,
                h,
            )
        x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4] = xi, yi, wrap(th), v, w


@njit
def _observe(x, pose, vel):
    for i in range(x.shape[0]):
        pose[i, 0], pose[i, 1], pose[i, 2] = x[i, 0], x[i, 1], x[i, 2]
        vel[i, 0], vel[i, 1] = x[i, 3], x[i, 4]


@njit
def run_chunk(lp, k0, k1, n_sub, c, dist, x, extra, j0):
    """Plant steps ``k0 … k1−1`` of the closed loop (``lp``: :class:`~bioform_mj.core.engine.Loop`), each
    followed by the control step of ``k+1`` (the control step of ``k0`` must be done). ``c`` (n, 2)
    the true ``[a, b]``, ``dist`` (2, 4) the harmonic disturbance, ``x`` (n, 5) the state, ``extra``
    (n, 2) added accelerations. Returns ``(plant steps done, next log row, status)``."""
    # unpacked once, outside the step loop: numba takes a reference count on each array of a named tuple at
    # every read of a field and copy (control/kernel.py, issue 28)
    g, s, comm, N, dt, L_pose, L_vel, pose, vel, met, acc, lg, stride, form, lim, diag = lp
    kn = knobs(g)
    est_pose, est_vel, c_hat, vs, cmd, dcmd = s.est_pose, s.est_vel, s.c_hat, s.vs, s.cmd, s.dcmd
    tau, tau_raw, saturated = s.tau, s.tau_raw, s.saturated
    cbf_par, cbf_rad, cbf_obst, cbf_A, cbf_b, cbf_lam, cbf_bad = (
        g.cbf_par, g.cbf_rad, g.cbf_obst, g.cbf_A, g.cbf_b, g.cbf_lam, g.cbf_bad,
    )  # fmt: skip
    j = j0
    for k in range(k0, k1):
        ideal_step(x, tau, c, extra, dist, k * dt, dt, n_sub)
        _observe(x, pose, vel)
        if k + 1 < N:
            k_ = k + 1
            # kernel.stack_step's three lines (a copy, not a call of a shared helper: control/kernel.py says
            # why; tests/test_control_sequence.py keeps them alike), its safety filter on arrays bound above (a
            # call that could raise: nothing bound in the loop may live across it)
            stack_head(kn, g, s, comm, L_pose[k_, 0], L_pose[k_, 1], L_pose[k_, 2], L_vel[k_, 0], L_vel[k_, 1], pose,
                       vel)  # fmt: skip
            if kn.cbf:
                safety_filter(pose, cmd, cbf_par, cbf_rad, cbf_obst, cbf_A, cbf_b, cbf_lam, cbf_bad)
            stack_tail(kn, g, s, pose, vel)
            status = after_step(k_, N, stride, pose, vel, est_pose, est_vel, cmd, dcmd, tau, tau_raw, saturated, c_hat,
                                vs, met, acc, lim, diag)  # fmt: skip
            if status == ROW:
                record(lg, j, k_ * dt, L_pose[k_], L_vel[k_], pose, vel, s, c, form, acc)
                j += 1
            elif status != OK:
                return k_ - k0, j, status
    return k1 - k0, j, OK


class IdealPlant:
    """``n`` unicycles with first-order velocity dynamics, integrated by RK4.

    Parameters
    ----------
    c : (n, 2) true ``[a, b]`` (1/(kg·m), 1/(kg·m²)·m); the paper uses (0.4, 10).
    initial_poses : (n, 3) ``[x, y, θ]`` (m, m, rad).
    control_dt : control period (s); physics_dt : RK4 step (s), dividing it.
    disturbance : ``d(t)`` → (n, 2) accelerations.
    mass, inertia : (n,) only used by :meth:`add_payload`, to rescale ``c``.
    """

    def __init__(
        self,
        c: np.ndarray,
        initial_poses: np.ndarray,
        control_dt: float,
        physics_dt: float,
        disturbance: DisturbanceFn,
        mass: np.ndarray | None = None,
        inertia: np.ndarray | None = None,
    ) -> None:
        self.n = len(initial_poses)
        self.control_dt = control_dt
        self.n_substeps = max(1, round(control_dt / physics_dt))
        self.h = control_dt / self.n_substeps
        # C order: a broadcast (2,) would copy into Fortran order, and the compiled chunk would compile
        # engine.after_control for a second layout of c_true (8 s of a first run; issue 28)
        self._c = np.array(np.broadcast_to(c, (self.n, 2)), dtype=float, order="C")
        self.initial_poses = np.array(initial_poses, dtype=float)
        self.disturbance = disturbance
        self.mass = None if mass is None else np.array(np.broadcast_to(mass, (self.n,)), dtype=float)
        self.inertia = None if inertia is None else np.array(np.broadcast_to(inertia, (self.n,)), dtype=float)
        self.x = np.zeros((self.n, 5))  # [x, y, θ, υ, ω], updated in place
        self._zero_acc = np.zeros((self.n, 2))
        self._dist = self._dist_rows()
        self.reset()

    def reset(self) -> None:
        self.x[:, :3] = self.initial_poses
        for i in range(self.n):
            self.x[i, 2] = wrap(float(self.x[i, 2]))
        self.x[:, 3:] = 0.0
        self._push_until: np.ndarray | None = None  # pushes (faults): see push()

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x[:, :3].copy(), self.x[:, 3:].copy()

    def c_true(self) -> np.ndarray:
        return self._c.copy()

    def _dist_rows(self) -> np.ndarray | None:
        """Rows of a harmonic disturbance for the compiled loop
        (:func:`~bioform_mj.formation.disturbance.harmonic_rows`)."""
        return harmonic_rows(self.disturbance)

    def step(self, tau: np.ndarray, t: float) -> None:
        """Apply wheel torques (n, 2) ``[τ_L, τ_R]`` N·m for one control period from ``t`` (s)."""
        extra = self._push_acc(t) if self._push_until is not None else self._zero_acc  # faults: push()
        dist = self._dist
        if dist is None:  # a disturbance given as a function: fold it into `extra`, held over the period
            extra = extra + np.asarray(self.disturbance(t), dtype=float)
            dist = np.zeros((2, 4))
        ideal_step(
            self.x,
            np.ascontiguousarray(tau, dtype=float),
            self._c,
            np.ascontiguousarray(extra),
            dist,
            float(t),
            self.control_dt,
            self.n_substeps,
        )

    def compiled_chunk(self, ctx: Any) -> Callable[[int, int, int], tuple[int, int, int]] | None:
        """The compiled loop over this plant (see ``sim``), or None if a disturbance is not harmonic."""
        if self._dist is None:
            return None
        x = self.x

        def chunk(k0: int, k1: int, j: int) -> tuple[int, int, int]:
            return run_chunk(ctx, k0, k1, self.n_substeps, self._c, self._dist, x, self._zero_acc, j)

        return chunk

    def set_leader(self, pose: np.ndarray, slots: np.ndarray | None) -> None:
        """Nothing to show on the ideal plant."""

    def add_payload(self, i: int, mass_kg: float, inertia_kgm2: float) -> None:
        """Scale ``c_i`` as ``a ∝ 1/m``, ``b ∝ 1/I`` (needs ``mass`` and ``inertia``)."""
        if self.mass is None or self.inertia is None:
            raise ValueError("the ideal plant needs robot mass and inertia to add a payload")
        m0, i0 = self.mass[i], self.inertia[i]
        self.mass[i] += mass_kg
        self.inertia[i] += inertia_kgm2
        self._c[i, 0] *= m0 / self.mass[i]
        self._c[i, 1] *= i0 / self.inertia[i]

    # ------------------------------------------------------------------ faults
    def push(self, i: int, force_xy, torque_z: float, until_t: float) -> None:
        """Push follower ``i`` (0-based) with a world-frame force ``force_xy`` (N) and yaw torque
        ``torque_z`` (N·m) in every control step that starts before ``until_t`` (s).

        A unicycle cannot move sideways: only the force along the heading acts, as the
        acceleration ``F·h/m``, with ``ω̇ += τ_z/I`` (needs ``mass`` and ``inertia``). A new push on
        the same follower replaces the old one; ``reset()`` removes all.
        """
        if self.mass is None or self.inertia is None:
            raise ValueError("the ideal plant needs robot mass and inertia to be pushed")
        if not 0 <= i < self.n:
            raise IndexError(f"follower index {i} out of range 0..{self.n - 1}")
        if self._push_until is None:
            self._push_until = np.full(self.n, -np.inf)
            self._push_wrench = np.zeros((self.n, 3))
        self._push_wrench[i] = (force_xy[0], force_xy[1], torque_z)
        self._push_until[i] = until_t

    def _push_acc(self, t: float) -> np.ndarray:
        """(n, 2) accelerations of the active pushes, heading held over the control period."""
        active = self._push_until > t + 1e-12
        if not active.any():
            self._push_until = None
            return np.zeros((self.n, 2))
        w = self._push_wrench * active[:, None]
        th = self.x[:, 2]
        acc = np.empty((self.n, 2))
        acc[:, 0] = (w[:, 0] * np.cos(th) + w[:, 1] * np.sin(th)) / self.mass
        acc[:, 1] = w[:, 2] / self.inertia
        return acc
