"""The formation environment batched on MuJoCo Warp: ``W`` worlds stepped together (design §20).

The same observation and action layout as ``envs.parallel.FormationParallelEnv``, per world and
agent, on the device: :func:`_env_act` turns the agents' actions into wheel torques (the
paper's torque law with the learner for ``action = "velocity"``, or the torques themselves),
advances the estimator and applies torques and the disturbance; then ``n_substeps`` ×
``mjw.step``; then :func:`_env_sense` observes, runs the learner and the consensus, the
tracking errors, the guards, and writes observations, rewards and done flags. Each world has
its own step counter; ``reset(worlds)`` puts the chosen worlds back at their initial state.

Every equation is the Warp translation (``batch/samesource.py``) of ``core/equations.py``, and
the stack's steps (observe, reset, learner, consensus, tracking error, command derivative, torque law,
estimator advance) are the device functions of ``batch/stack.py`` that the closed loop
(``batch/step.py``) calls too; the structures (``BatchGains``, ``BatchState``) and set-up
(``BatchRun``: model, data, per-world gains, initial poses) are the batch engine's.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

import mujoco_warp as mjw
import numpy as np
import warp as wp

from bioform_mj.batch import stack
from bioform_mj.batch.device import (
    BIO,
    DT,
    LEARN,
    LFRAME,
    STEER,
    TILT,
    USED,
    BatchGains,
    BatchState,
    CommFaults,
    F,
    check_world,
    wrap,
)
from bioform_mj.batch.runner import BatchRun


@wp.func
def _rel(
    px: F,
    py: F,
    pth: F,
    vv: F,
    vw: F,
    ox: F,
    oy: F,
    oth: F,
    ov: F,
    ow: F,
    c: F,
    sn: F,
    obs: Any,
    w: int,
    i: int,
    o: int,
):
    dx = px - ox
    dy = py - oy
    obs[w, i, o] = F(1.0)
    obs[w, i, o + 1] = c * dx + sn * dy
    obs[w, i, o + 2] = -sn * dx + c * dy
    obs[w, i, o + 3] = wrap(pth - oth)
    obs[w, i, o + 4] = vv - ov
    obs[w, i, o + 5] = vw - ow


@wp.kernel
def _env_sense(
    g: BatchGains,
    s: BatchState,
    N: int,
    L_pose: wp.array2d(dtype=F),
    L_vel: wp.array2d(dtype=F),
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qadr: wp.array(dtype=int),
    dadr: wp.array(dtype=int),
    axle: wp.array2d(dtype=F),
    nbr: wp.array2d(dtype=int),  # (n, K) in-neighbour edge ids of each follower (−1: padding)
    w_form: F,
    w_effort: F,
    w_tip: F,
    w_term: F,
    obs: wp.array3d(dtype=F),  # (W, n, obs_size)
    reward: wp.array2d(dtype=F),  # (W, n)
    done: wp.array2d(dtype=int),  # (W, 2): [terminated, truncated]
    tipped: wp.array2d(dtype=int),  # (W, n) 1 once tipped (2 in the period it happened)
    active: wp.array(dtype=int),  # (W,) 1: this world is sensed now (0: a partial reset leaves it as it is)
    f: CommFaults,  # the run's network faults: none here (the consensus runs on the perfect network)
):
    """World ``w`` at its control step ``k``: observe (``mujoco_kernels.observe``), reset the stack at
    ``k = 0`` (``kernel.reset_state``), the learner over the last period, the consensus on the perfect
    network (``kernel.estimator_consensus``), tracking errors (``envs.kernels.sense_errors``), the guards
    (``engine.check``), the observation, the reward of the period just ended and the done flags."""
    w = wp.tid()
    if active[w] == 0:
        return
    k = s.k[w]
    n = s.pose.shape[1]
    dt = g.sc[w, DT]
    zero = F(0.0)
    fresh = wp.int32(0)  # typed: mutated in a dynamic loop
    for i in range(n):
        up = stack.observe(s, w, i, qpos, qvel, qadr, dadr, axle)
        for c in range(3):
            s.mpose[w, i, c] = s.pose[w, i, c]
        for c in range(2):
            s.mvel[w, i, c] = s.vel[w, i, c]
        if k == 0:
            tipped[w, i] = 0
        elif up < g.sc[w, TILT] and tipped[w, i] == 0:
            tipped[w, i] = 2  # tipped in this period (the reward's tip term), then 1
            fresh = fresh + 1
    if k == 0:  # kernel.reset_state
        stack.reset(g, s, w, n)
    elif g.sc[w, LEARN] != zero and s.first[w] == 0:  # kernel.learner_update
        stack.learn(g, s, w, n, dt)
    kl = wp.min(k, N)
    lp0 = L_pose[kl, 0]
    lp1 = L_pose[kl, 1]
    lp2 = L_pose[kl, 2]
    lv0 = L_vel[kl, 0]
    lv1 = L_vel[kl, 1]
    # kernel.estimator_consensus on the perfect network (no network faults here: batch_env_unsupported)
    stack.consensus(g, s, f, w, n, False, False, lp0, lp1, lp2, lv0, lv1)
    lframe = g.sc[w, LFRAME] != zero
    K = nbr.shape[1]
    for i in range(n):
        # tracking error (eqs. 27-28; the slot's own pose for leader-frame offsets, design §4)
        e0, e1, e2, vr, wr = stack.follower_error(g, s, w, i, lframe)
        stack.formation_error(g, s, w, i, lp0, lp1, lp2, lframe)  # against the true leader (engine.record)
    bad = wp.int32(0)
    if k > 0:
        bad = check_world(g, s, w, n)
    term = wp.int32(0)
    if bad != 0 or fresh > 0:
        term = 1
    for i in range(n):
        # observation (envs.parallel.OBS_FIELDS)
        obs[w, i, 0] = s.mvel[w, i, 0]
        obs[w, i, 1] = s.mvel[w, i, 1]
        obs[w, i, 2] = s.err[w, i, 0]
        obs[w, i, 3] = s.err[w, i, 1]
        obs[w, i, 4] = s.err[w, i, 2]
        obs[w, i, 5] = s.est_vel[w, i, 0]
        obs[w, i, 6] = s.est_vel[w, i, 1]
        for o in range(7, obs.shape[2]):
            obs[w, i, o] = zero
        ch = wp.cos(s.mpose[w, i, 2])
        sn = wp.sin(s.mpose[w, i, 2])
        ox0 = s.est_pose[w, i, 0]
        ox1 = s.est_pose[w, i, 1]
        ox2 = s.est_pose[w, i, 2]
        ov0 = s.est_vel[w, i, 0]
        ov1 = s.est_vel[w, i, 1]
        for q in range(K):
            e = nbr[i, q]
            if e >= 0:
                j = g.dst[e]
                _rel(
                    s.est_pose[w, j, 0], s.est_pose[w, j, 1], s.est_pose[w, j, 2], s.est_vel[w, j, 0],
                    s.est_vel[w, j, 1], ox0, ox1, ox2, ov0, ov1, ch, sn, obs, w, i, 7 + 6 * q,
                )  # fmt: skip
        if g.lacc[w, i] > zero:
            _rel(lp0, lp1, lp2, lv0, lv1, ox0, ox1, ox2, ov0, ov1, ch, sn, obs, w, i, 7 + 6 * K)
        # reward of the period that ended here (envs.parallel.FormationParallelEnv.step)
        r = zero
        if k > 0:
            tl = s.tau[w, i, 0] / g.lim[w, i]
            tr = s.tau[w, i, 1] / g.lim[w, i]
            fe = s.ferr[w, i]
            if not wp.isfinite(fe):
                fe = zero
            r = -dt * (w_form * fe + w_effort * F(0.5) * (tl * tl + tr * tr))
            if tipped[w, i] == 2:
                r = r - w_tip
                tipped[w, i] = 1
            if term != 0:
                r = r - w_term * wp.max(zero, F(N - k) * dt)
        reward[w, i] = r
    done[w, 0] = term
    trunc = wp.int32(0)
    if term == 0 and k >= N:
        trunc = 1
    done[w, 1] = trunc
    if bad != 0:
        s.status[w] = 1


@wp.kernel
def _env_act(
    g: BatchGains,
    s: BatchState,
    mode: int,  # 0: velocity action, 1: torque action
    action: wp.array3d(dtype=F),  # (W, n, 2)
    xmat: wp.array2d(dtype=wp.mat33),
    base: wp.array(dtype=int),
    act: wp.array2d(dtype=int),
    cscale: wp.array2d(dtype=F),
    ctrl: wp.array2d(dtype=float),
    xfrc: wp.array2d(dtype=wp.spatial_vector),
):
    """World ``w`` at its control step ``k``: the agents' actions into torques (``envs.kernels.track_velocity``
    or ``direct_torque``), the estimator's Euler step and the neuron (``kernel.estimator_advance``), the
    torques and ``d(k dt)`` applied to the plant (``mujoco_kernels.apply_inputs``); then ``k += 1``."""
    w = wp.tid()
    k = s.k[w]
    n = s.pose.shape[1]
    dt = g.sc[w, DT]
    zero = F(0.0)
    first = s.first[w] == 1
    steer = g.sc[w, STEER] != zero
    for i in range(n):
        r0 = action[w, i, 0]
        r1 = action[w, i, 1]
        if mode == 0:
            for c in range(2):
                s.cmd[w, i, c] = action[w, i, c]
                stack.follower_derivative(g, s, w, i, c, first, dt)
            r0, r1 = stack.torque_law(g, s, w, i, action[w, i, 0], action[w, i, 1])
        stack.apply_torque(s, w, i, r0, r1, g.lim[w, i], steer)
    s.first[w] = 0
    bio = g.sc[w, BIO] != zero
    stack.advance(g, s, w, n, dt, bio)  # kernel.estimator_advance
    d0 = zero
    d1 = zero
    if g.sc[w, USED] != zero:
        d0, d1 = stack.disturbance(g, w, F(k) * dt)
    for i in range(n):
        ctrl[w, act[i, 0]] = wp.float32(cscale[i, 0] * s.tau[w, i, 0])
        ctrl[w, act[i, 1]] = wp.float32(cscale[i, 1] * s.tau[w, i, 1])
        if g.sc[w, USED] != zero:
            b = base[i]
            R = xmat[w, b]
            fa = g.m_eff[w, i] * d0
            xfrc[w, b] = wp.spatial_vector(
                wp.float32(F(R[0, 0]) * fa), wp.float32(F(R[1, 0]) * fa), 0.0, 0.0, 0.0, wp.float32(g.i_eff[w, i] * d1)
            )
    s.k[w] = k + 1


@wp.kernel
def _env_reset(
    mask: wp.array(dtype=int),
    qpos0: wp.array2d(dtype=float),
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    qacc_ws: wp.array2d(dtype=float),
    ctrl: wp.array2d(dtype=float),
    xfrc: wp.array2d(dtype=wp.spatial_vector),
    time: wp.array(dtype=float),
    k: wp.array(dtype=int),
):
    """The worlds with ``mask[w] = 1`` back at their initial state (``BatchRun.reset`` for one world)."""
    w = wp.tid()
    if mask[w] == 0:
        return
    for q in range(qpos.shape[1]):
        qpos[w, q] = qpos0[w, q]
    for q in range(qvel.shape[1]):
        qvel[w, q] = 0.0
        qacc_ws[w, q] = 0.0
    for a in range(ctrl.shape[1]):
        ctrl[w, a] = 0.0
    for b in range(xfrc.shape[1]):
        xfrc[w, b] = wp.spatial_vector(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    time[w] = 0.0
    k[w] = 0


@wp.kernel
def _env_check_actions(
    action: wp.array3d(dtype=F),
    low: wp.array2d(dtype=F),
    high: wp.array2d(dtype=F),
    acc_low: wp.array2d(dtype=F),
    acc_high: wp.array2d(dtype=F),
    bad: wp.array(dtype=int),
):
    """``bad[0]`` = 1 + the flat index (world·n + agent) of an action that is not finite or outside the space
    by more than float32 rounding of its bounds (``acc_low``, ``acc_high``: a float32 2π is above 2π); an
    accepted action is clipped onto ``[low, high]`` in place (the parallel environment's rule)."""
    w, i = wp.tid()
    for c in range(2):
        u = action[w, i, c]
        if not wp.isfinite(u) or u < acc_low[i, c] or u > acc_high[i, c]:
            wp.atomic_max(bad, 0, 1 + w * action.shape[1] + i)
        else:
            action[w, i, c] = wp.clamp(u, low[i, c], high[i, c])


#: the most bytes of calls :class:`BatchEnv` keeps for its copies (bytes); a trainer that resets ended worlds stays
#: far below it (one episode: ``T/dt`` periods of W·n·2 floats, 1,024 worlds of 4 followers over 20 s at 10 ms: 131 MB)
RECORD_CAP_BYTES = 512 * 2**20


class BatchEnv:
    """``W`` formations of one scenario, stepped together on a MuJoCo Warp device (``envs.batch_env``).

    Arrays per world and agent: :meth:`reset` and :meth:`step` return ``obs`` (W, n, obs_size),
    ``reward`` (W, n), ``terminated`` (W,), ``truncated`` (W,) as Warp arrays on the device
    (``.numpy()``; ``wp.to_torch``/``wp.to_jax`` or DLPack share them without a copy). Actions:
    (W, n, 2) float64, a numpy or Warp array, in the same space as the parallel environment.
    A world whose episode ended stays ended (its rows are stale) until :meth:`reset` names it. ``pickle`` and
    ``deepcopy`` rebuild it on the same device and replay its calls since the oldest current episode began
    (:meth:`__setstate__`).
    """

    def __init__(
        self,
        scenarios: list,
        device: str = "cpu",
        action: str = "velocity",
        reward: Mapping[str, float] | None = None,
        v_max: float | None = None,
        w_max: float | None = None,
        nconmax: int | None = None,
        njmax: int | None = None,
    ) -> None:
        from bioform_mj.envs.parallel import ACTIONS, REWARD_WEIGHTS

        if action not in ACTIONS:
            raise ValueError(f"unknown action mode {action!r} (expected one of: {', '.join(ACTIONS)})")
        for sc in scenarios:
            why = batch_env_unsupported(sc)
            if why:
                raise ValueError(f"the batched environment cannot run this scenario: {why}")
        weights = dict(REWARD_WEIGHTS)
        for key, val in (reward or {}).items():
            if key not in weights:
                raise ValueError(f"unknown reward term {key!r} (expected one of: {', '.join(weights)})")
            weights[key] = float(val)
        self.weights = weights
        self.run = run = BatchRun(scenarios, device, nconmax=nconmax, njmax=njmax)
        if run.feed_on:
            raise ValueError(
                "the batched environment cannot run this scenario: DC motors (the learner's delivered-torque feed)"
            )
        sc0 = scenarios[0]
        self.nworld, self.n, self.N, self.dt = run.nworld, run.n, run.N, run.dt
        self.action_mode = action
        src = np.asarray(run.src)
        nbrs = [np.flatnonzero(src == i).tolist() for i in range(self.n)]
        self.K = max(1, max(len(x) for x in nbrs))
        table = -np.ones((self.n, self.K), dtype=np.int32)
        for i, es in enumerate(nbrs):
            table[i, : len(es)] = es
        self.obs_size = 2 + 3 + 2 + 6 * self.K + 6
        tau_max = np.broadcast_to(np.asarray(run.plant.tau_max, dtype=float), (self.n,))
        if action == "velocity":
            vm = float(min(sc0.limits.speed, 2.0)) if v_max is None else float(v_max)
            wm = float(2 * math.pi) if w_max is None else float(w_max)
            hi = np.tile([vm, wm], (self.n, 1))
        else:
            hi = np.stack([tau_max, tau_max], axis=1)
        self.low, self.high = -hi, hi
        W, n = self.nworld, self.n
        with wp.ScopedDevice(run.device):
            self._nbr = wp.array(table, dtype=int)
            self.obs = wp.zeros((W, n, self.obs_size), dtype=F)
            self.reward = wp.zeros((W, n), dtype=F)
            self._done = wp.zeros((W, 2), dtype=int)
            self._tipped = wp.zeros((W, n), dtype=int)
            self._action = wp.zeros((W, n, 2), dtype=F)
            self._low = wp.array(self.low, dtype=F)
            self._high = wp.array(self.high, dtype=F)
            acc = np.maximum(hi, hi.astype(np.float32).astype(float))  # float32 rounding of a bound: taken
            self._acc_low, self._acc_high = wp.array(-acc, dtype=F), wp.array(acc, dtype=F)
            self._bad = wp.zeros(1, dtype=int)
            self._mask = wp.zeros(W, dtype=int)
            self._all = wp.ones(W, dtype=int)
        self._ended = np.ones(W, dtype=bool)
        #: what rebuilds it (pickle, deepcopy: :meth:`__getstate__`)
        self._init = (list(scenarios), device, dict(action=action, reward=reward, v_max=v_max, w_max=w_max,
                                                    nconmax=nconmax, njmax=njmax))  # fmt: skip
        #: the calls since the oldest current episode began, what a copy replays: ``("reset", mask (W,))`` and
        #: ``("step", actions (W, n, 2) as checked and clipped)``; :attr:`_ep_start` the index in it at which each
        #: world's current episode began (0 for a world never reset: every step since the build moved it)
        self._log: list[tuple[str, np.ndarray]] = []
        self._ep_start = np.zeros(W, dtype=np.int64)
        #: bytes the record holds, at most :data:`RECORD_CAP_BYTES`: past it (a world ended and never reset keeps
        #: the oldest episode open, W·n·2 floats a period) the record is emptied, a warning says so once, the
        #: worlds' episode starts become -1 (begun before the record) and pickling refuses until each is reset
        self._log_bytes = 0
        self._warned_cap = False

    # ------------------------------------------------------------------ device launches
    def _sense(self, active: wp.array) -> None:
        r, d, w = self.run, self.run.d, self.weights
        wp.launch(
            _env_sense,
            dim=self.nworld,
            inputs=[
                r.g, r.s, self.N, r.L_pose, r.L_vel, d.qpos, d.qvel, r.qadr, r.dadr, r.axle, self._nbr,
                F(w["formation"]), F(w["effort"]), F(w["tipped"]), F(w["terminal"]),
                self.obs, self.reward, self._done, self._tipped, active, r.f,
            ],
        )  # fmt: skip

    def reset(self, worlds: Any = None):
        """Put the worlds ``worlds`` (indices or a boolean mask; None: all) at their initial state and
        observe them; returns ``obs`` (W, n, obs_size) (the other worlds' rows unchanged)."""
        r = self.run
        mask = np.zeros(self.nworld, dtype=np.int32)
        if worlds is None:
            mask[:] = 1
        else:
            sel = np.asarray(worlds)
            if sel.dtype == bool:
                if sel.shape != (self.nworld,):
                    raise ValueError(f"a world mask must have shape ({self.nworld},), got {sel.shape}")
                mask[sel] = 1
            else:
                if sel.size and (sel.min() < 0 or sel.max() >= self.nworld):
                    raise ValueError(f"world index out of range 0..{self.nworld - 1}: {sel.tolist()}")
                mask[sel.astype(int)] = 1
        d = r.d
        with wp.ScopedDevice(r.device):
            self._mask.assign(mask)
            wp.launch(
                _env_reset,
                dim=self.nworld,
                inputs=[self._mask, r._qpos0, d.qpos, d.qvel, d.qacc_warmstart, d.ctrl, d.xfrc_applied, d.time,
                        r.s.k],
            )  # fmt: skip
            d.overflow.zero_()
            mjw.forward(r.m, d)
            self._sense(self._mask)
        sel = mask.astype(bool)
        self._ended[sel] = False
        self._ep_start[sel] = len(self._log)
        self._remember(("reset", sel))
        drop = int(self._ep_start.min())  # calls no current episode needs (-1: one began before the record)
        if drop > 0:
            self._log_bytes -= sum(a.nbytes for _, a in self._log[:drop])
            del self._log[:drop]
            self._ep_start -= drop
        return self.obs

    def _remember(self, call: tuple[str, np.ndarray]) -> None:
        """Append ``call`` to the record a copy replays, keeping it within :data:`RECORD_CAP_BYTES`."""
        if call[0] == "step" and self._ep_start.max() < 0:
            return  # every open episode began before the record: nothing a copy could replay
        if self._log_bytes + call[1].nbytes > RECORD_CAP_BYTES:
            if not self._warned_cap:
                # the user's line: _remember <- reset, or _remember <- _step <- step
                warnings.warn(f"batch_env: {self._cap_why()}", stacklevel=3 if call[0] == "reset" else 4)
                self._warned_cap = True
            if call[0] == "reset":  # the worlds it resets begin within the record again
                self._ep_start[~call[1]] = -1
                self._ep_start[call[1]] = 0
            else:
                self._ep_start[:] = -1
            self._log.clear()
            self._log_bytes = 0
            if call[0] == "step":
                return
        self._log.append(call)
        self._log_bytes += call[1].nbytes

    def _cap_why(self) -> str:
        return (
            f"the record a copy replays (every call since the oldest open episode began) passed "
            f"{RECORD_CAP_BYTES / 2**20:.3g} MiB: a world whose episode ended and is not reset keeps it open; the "
            "record was dropped, so this environment cannot be pickled or copied until every world has been reset"
        )

    # ------------------------------------------------------------------ pickling and copies
    def __getstate__(self) -> dict[str, Any]:
        """What rebuilds this environment (its Warp arrays live on the device, behind ctypes pointers, and do not
        pickle): its arguments and the calls since the oldest current episode began (each reset's worlds, each
        step's actions as checked and clipped), and which worlds' episodes ended. The copy replays them."""
        if self._ep_start.min() < 0:
            stale = np.flatnonzero(self._ep_start < 0).tolist()
            raise TypeError(f"cannot pickle or copy this batch_env: {self._cap_why()} (not since: worlds {stale})")
        return {
            "init": self._init, "log": [(kind, a.copy()) for kind, a in self._log],
            "ep_start": self._ep_start.copy(), "ended": self._ended.copy(),
        }  # fmt: skip

    def __setstate__(self, st: dict[str, Any]) -> None:
        """Rebuild on the same device from :meth:`__getstate__`, then replay the recorded resets and steps, so
        every world's current episode is the original's (design §20). A world is independent of the others and
        a reset restores all of its state, so the worlds whose episode began later are right from their reset
        on. Bit for bit where the device is (Warp's CPU device, tested); on a CUDA device MuJoCo Warp's contact
        order and float atomics are not run-to-run reproducible (``opt.deterministic`` off), so the copy is
        another run of the same seeds and actions, as close to the original as two runs on that device."""
        scenarios, device, kw = st["init"]
        self.__init__(scenarios, device, **kw)
        for kind, a in st["log"]:
            if kind == "reset":
                self.reset(a)
            else:
                self._step(a)
        self._ended[:] = st["ended"]
        if not np.array_equal(self._ep_start, st["ep_start"]):  # pragma: no cover - the replay's own invariant
            raise RuntimeError("BatchEnv copy: the replay did not rebuild the original's record of episodes")

    def step(self, actions: Any):
        """One control period of every world that is running; returns ``(obs, reward, terminated, truncated)``:
        Warp arrays (W, n, obs_size), (W, n) and numpy booleans (W,)."""
        if self._ended.all():
            raise RuntimeError("step() with every world's episode ended: call reset() first")
        return self._step(actions)

    def _step(self, actions: Any):
        """:meth:`step` without the check that a world runs (a copy's replay steps worlds that ran then)."""
        r = self.run
        with wp.ScopedDevice(r.device):
            if isinstance(actions, wp.array):
                if actions.shape != (self.nworld, self.n, 2):
                    raise ValueError(f"actions must have shape ({self.nworld}, {self.n}, 2), got {actions.shape}")
                wp.copy(self._action, actions)
            else:
                a = np.asarray(actions, dtype=float)
                if a.shape != (self.nworld, self.n, 2):
                    raise ValueError(f"actions must have shape ({self.nworld}, {self.n}, 2), got {a.shape}")
                self._action.assign(a)
            self._bad.zero_()
            chk = [self._action, self._low, self._high, self._acc_low, self._acc_high, self._bad]
            wp.launch(_env_check_actions, dim=(self.nworld, self.n), inputs=chk)
            bad = int(self._bad.numpy()[0])
            if bad:
                w, i = divmod(bad - 1, self.n)
                u = self._action.numpy()[w, i].tolist()
                raise ValueError(
                    f"action of world {w}, follower_{i + 1} {u} is not finite or outside the action space "
                    f"[{self.low[i].tolist()}, {self.high[i].tolist()}]"
                )
            d = r.d
            mode = 0 if self.action_mode == "velocity" else 1
            wp.launch(
                _env_act,
                dim=self.nworld,
                inputs=[r.g, r.s, mode, self._action, d.xmat, r.base, r.act, r.cscale, d.ctrl, d.xfrc_applied],
            )
            for _ in range(r.n_sub):
                mjw.step(r.m, d)
            self._sense(self._all)
            done = self._done.numpy()
            self._remember(("step", self._action.numpy().copy()))
        term, trunc = done[:, 0].astype(bool) | self._ended, done[:, 1].astype(bool)
        self._ended |= term | trunc
        return self.obs, self.reward, term, trunc


def batch_env_unsupported(sc: Any) -> str:
    """What of ``sc`` the batched environment does not run (empty: all of it)."""
    from bioform_mj.batch.support import unsupported

    why = unsupported(sc)
    if why:
        return why
    if sc.faults.per_step:
        return "per-step faults (the parallel environment runs them: bioform_mj.envs.parallel_env)"
    if sc.events:
        return "payload events"
    if sc.plant.sensing != "truth":
        return f"plant.sensing = '{sc.plant.sensing}'"
    return ""
