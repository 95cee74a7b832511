"""The environment's control period in one compiled call (design §20; issue 30, item 6).

At the preset's 1 ms control period a MuJoCo period is one physics step (~0.1 ms), and the step-by-step
:meth:`~.parallel.FormationParallelEnv._advance` spent ~6× that around it: seven compiled calls a period,
each resolving the types of the stack's ~70 arrays again (numba's dispatcher: 30-50 µs a call), and
numpy's small-array calls. :func:`mujoco_period` runs the same functions in the same order in one call
(the agents' actions checked, the control phase, the plant's inputs, ``n_sub`` ``mj_step`` with the
contact watch, the proximity watch, ``observe`` with the tilt and slip watches, the next step's
sensing, the guards, the formation error, tip-overs, contact events, rewards, observations), and
:class:`Compiled` calls its specialisation for the argument types of this episode directly, without
the per-call type resolution. The results are the step-by-step path's bits (``tests/test_envs_fast.py``).

On the ideal plant (eq. 34) :func:`ideal_period` does the same around ``IdealPlant.step``'s RK4
(``ideal_step``); both share the period's start (:func:`control_head`) and end (:func:`period_tail`).

The fast period runs where nothing per step needs Python: the MuJoCo plant with its compiled steps,
sensing = "truth", no DC-motor feed, a harmonic disturbance (or none), no per-step faults and no
pushes; the ideal plant with a harmonic disturbance (or none), no per-step faults and no pushes; an
event (a payload) runs its period step by step. Everything else stays on the step-by-step path, which
is the reference.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bioform_mj.control.kernel import control_step
from bioform_mj.core.engine import check
from bioform_mj.core.equations import HAVE_NUMBA, njit
from bioform_mj.core.thresholds import SLIP_RATIO, SLIP_V_FLOOR
from bioform_mj.envs.kernels import (
    actions_within,
    clip_into,
    control_phase,
    formation_error,
    observations,
    sense_errors,
    step_rewards,
)
from bioform_mj.plants.ideal import IdealPlant, ideal_step
from bioform_mj.plants.mujoco.contacts import EVENTS, watch_proximity
from bioform_mj.plants.mujoco.kernels import (
    apply_inputs,
    observe,
    physics_steps,
    watch_slip,
    watch_tilt,
)

#: bits of :func:`mujoco_period`'s status
BAD_ACTION, WARNED, GUARD, TIPPED, HIT = 1, 2, 4, 8, 16


@njit
def mujoco_period(a, u, pose, vel, new_pose, new_vel, O, k, step_count):
    """One control period ``k → k+1`` of the MuJoCo environment, the episode's arguments ``a``
    (:class:`PeriodArgs`: :data:`FIELDS`) read here, not passed on (numba takes a reference count on each
    array of a compiled function's arguments at every call: with ~110 arrays that was ~15 % of the vector
    environment's step at 1 ms, design §20), the step-by-step path's calls in its
    order (see the module docstring). ``u`` (n, 2): the agents' actions, checked against ``[alo, ahi]``
    (float32 rounding of the bounds) and clipped onto ``[lo, hi]``; ``pose``, ``vel``: the state at
    ``k`` (measured = true here); the state at ``k+1`` is written to ``new_pose``, ``new_vel``;
    ``fe`` (n,) m, ``newly``, ``hits`` (n,), ``r`` (n,) the rewards without the terminal term (weights
    ``w`` = [formation, effort, tipped, collision]) and, when the guards pass, the observations ``O``
    (n, obs) (zeroed here). Returns a status: 0, or the bits :data:`BAD_ACTION` (nothing done),
    :data:`WARNED` (a MuJoCo warning: stopped after the physics, as the plant raises there),
    :data:`GUARD` (the guards failed, ``diag`` says which), :data:`TIPPED` (a robot has tipped), :data:`HIT`
    (a new contact event)."""
    g, s, comm, io, wt, cl, px, mptr, dptr, n_sub = a.g, a.s, a.comm, a.io, a.wt, a.cl, a.px, a.mptr, a.dptr, a.n_sub
    k0_phys, plant_dt, lo, hi, alo, ahi = n_sub * step_count, a.plant_dt, a.lo, a.hi, a.alo, a.ahi
    velocity, verr, tau, tau_max, dt, L_pose, L_vel = a.velocity, a.verr, a.tau, a.tau_max, a.dt, a.L_pose, a.L_vel
    lim, diag, off, leader_frame, fe, tipped, newly = a.lim, a.diag, a.off, a.leader_frame, a.fe, a.tipped, a.newly
    events_seen, hits, w, r, slots, dst, ew = a.events_seen, a.hits, a.w, a.r, a.slots, a.dst, a.ew
    rp, rv, lacc, bound = a.rp, a.rv, a.lacc, a.bound
    if not control_head(g, s, u, lo, hi, alo, ahi, velocity, verr, vel, tau):
        return BAD_ACTION
    # the plant's step (MujocoPlant.step)
    apply_inputs(tau, k * dt, io.ctrl, io.ctrl_id, io.ctrl_scale, io.xfrc, io.xmat, io.base, io.m_eff, io.i_eff,
                 io.dist, io.use_dist)  # fmt: skip
    for i in range(io.dacc.shape[0]):
        io.dacc[i, 0] = 0.0
        io.dacc[i, 1] = 0.0
    ncon, con, meta, owner, ci, cf, f6, hdt = cl
    physics_steps(mptr, dptr, n_sub, k0_phys, ncon, con, meta, owner, ci, cf, f6, hdt)
    for j in range(io.warn.shape[0]):
        if io.warn[j] != 0:
            return WARNED
    gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order = px
    step_count += 1
    if step_count % int(ranges[3]) == 0:
        # MujocoPlant.step looks at the distances before observe(): the same positions (axle midpoints)
        observe(io.qpos, io.qvel, io.q7, io.v6, io.axle, new_pose, new_vel, io.up)
        watch_proximity(mptr, dptr, gstart, glist, ogeom, obst, rad, ranges, rf, ri, box, order, new_pose,
                        step_count * plant_dt)  # fmt: skip
    # MujocoPlant.observe
    observe(io.qpos, io.qvel, io.q7, io.v6, io.axle, new_pose, new_vel, io.up)
    watch_tilt(io.up, wt.tilt_cos, wt.tip_step, step_count)
    watch_slip(io.qvel, wt.wheel_dof, wt.wheel_sign, wt.radius, wt.half_track, new_vel, wt.slip_ratio, wt.v_floor,
               wt.slip_need, wt.slip_run, wt.slip_step, step_count)  # fmt: skip
    # tip-overs and contact events first: they read the watches alone, the tail does not touch them
    status = 0
    n = tau.shape[0]
    any_tipped = False
    for i in range(n):
        newly[i] = 0.0
        if wt.tip_step[i] >= 0 and not tipped[i]:
            newly[i] = 1.0
            tipped[i] = True
        if tipped[i]:
            any_tipped = True
    if any_tipped:
        status |= TIPPED
    for i in range(n):
        ev = float(ci[i, 0, EVENTS] + ci[i, 1, EVENTS])
        hits[i] = ev - events_seen[i]
        events_seen[i] = ev
        if hits[i] != 0.0:
            status |= HIT
    return period_tail(g, s, comm, new_pose, new_vel, k + 1, dt, L_pose, L_vel, lim, diag, off, leader_frame, fe,
                       newly, hits, tau, tau_max, w, r, O, slots, dst, ew, rp, rv, lacc, bound, status)  # fmt: skip


@njit(inline=True)
def control_head(g, s, u, lo, hi, alo, ahi, velocity, verr, vel, tau):
    """A period's start, the step-by-step path's ``_actions`` and ``control_phase``: ``u`` (n, 2) checked
    against ``[alo, ahi]`` (False: outside, nothing done) and clipped onto ``[lo, hi]``; the control
    phase (the torque law or the agents' torques, Table I's summand on the true ``vel``, the torques
    copied to ``tau`` (n, 2) N·m, the estimator's advance). Returns True when it ran."""
    if not actions_within(u, alo, ahi):
        return False
    clip_into(u, lo, hi)
    control_phase(g, s, vel, u, velocity, verr, vel, tau)
    return True


@njit(inline=True)
def period_tail(
    g, s, comm, new_pose, new_vel, k1, dt, L_pose, L_vel, lim, diag, off, leader_frame, fe, newly, hits, tau,
    tau_max, w, r, O, slots, dst, ew, rp, rv, lacc, bound, status,
):  # fmt: skip
    """A period's end after the plant, the step-by-step path's ``_advance_tail``: at step ``k1`` the
    sensing of the new state ``new_pose``, ``new_vel`` (truth), the guards (``status |=`` :data:`GUARD`),
    the formation error ``fe``, the rewards ``r`` of the tip-overs ``newly`` and contact events ``hits``,
    and, when the guards pass, the observations ``O``. Returns ``status``."""
    lp, lv = L_pose[k1], L_vel[k1]
    sense_errors(g, s, lp, lv, new_pose, new_vel, comm, True)
    if not check(s, new_pose, new_vel, lim, diag):
        status |= GUARD
    formation_error(new_pose, lp, off, leader_frame, fe)
    step_rewards(fe, tau, tau_max, newly, hits, w[0], w[1], w[2], w[3], dt, r)
    if status & GUARD == 0:
        for e in range(dst.shape[0]):
            for c in range(3):
                rp[e, c] = s.est_pose[dst[e], c]
            for c in range(2):
                rv[e, c] = s.est_vel[dst[e], c]
        for i in range(O.shape[0]):
            for j in range(O.shape[1]):
                O[i, j] = 0.0
        observations(O, new_pose, new_vel, s.err, s.est_pose, s.est_vel, slots, ew, rp, rv, lacc, lp, lv, bound)
    return status


@njit
def ideal_period(
    g, s, comm, x, c, extra, dist, plant_dt, n_sub, u, lo, hi, alo, ahi, velocity, verr, tau, tau_max, pose, vel,
    new_pose, new_vel, k, dt, L_pose, L_vel, lim, diag, off, leader_frame, fe, zeros, w, r, O, slots, dst, ew, rp, rv,
    lacc, bound,
):  # fmt: skip
    """One control period ``k → k+1`` of the environment on the ideal plant (eq. 34), the step-by-step
    path's calls in its order: :func:`control_head`, ``IdealPlant.step`` (``x`` (n, 5) the plant's state,
    ``c`` (n, 2) its true ``[a, b]``, ``extra`` (n, 2) zeros, ``dist`` (2, 4) the harmonic rows, ``n_sub``
    RK4 steps over ``plant_dt`` s), its ``observe`` into ``new_pose``, ``new_vel`` and :func:`period_tail`
    (no tip-overs, no contacts: ``zeros`` (n,)). Returns :func:`mujoco_period`'s status bits."""
    if not control_head(g, s, u, lo, hi, alo, ahi, velocity, verr, vel, tau):
        return BAD_ACTION
    ideal_step(x, tau, c, extra, dist, k * dt, plant_dt, n_sub)
    for i in range(x.shape[0]):
        new_pose[i, 0], new_pose[i, 1], new_pose[i, 2] = x[i, 0], x[i, 1], x[i, 2]
        new_vel[i, 0], new_vel[i, 1] = x[i, 3], x[i, 4]
    return period_tail(g, s, comm, new_pose, new_vel, k + 1, dt, L_pose, L_vel, lim, diag, off, leader_frame, fe,
                       zeros, zeros, tau, tau_max, w, r, O, slots, dst, ew, rp, rv, lacc, bound, 0)  # fmt: skip


@njit
def policy_period(g, s, lp, lv, pose, vel, comm, true_vel, verr, tau):
    """:class:`~.policy.ControllerPolicy`'s step of the paper's stack in one call: ``control_step`` from the
    measured ``pose`` (n, 3), ``vel`` (n, 2) and the leader ``lp``, ``lv`` as received, Table I's summand
    ``verr += |υ_cmd − υ| + |ω_cmd − ω|`` on the true velocities ``true_vel``, the torques copied to ``tau``."""
    control_step(g, s, lp, lv, pose, vel, comm)
    for i in range(verr.shape[0]):
        verr[i] += abs(s.cmd[i, 0] - true_vel[i, 0]) + abs(s.cmd[i, 1] - true_vel[i, 1])
        tau[i, 0] = s.tau[i, 0]
        tau[i, 1] = s.tau[i, 1]


class Compiled:
    """``fn`` (a numba dispatcher) specialised for the types of ``args`` and called directly: numba's
    dispatcher resolves every argument's type on every call (a named tuple of arrays: ~0.5 µs an array),
    which this skips. The caller passes arguments of the same types each call (the same arrays, or arrays
    of the same dtype, dimensions and layout); with numba's JIT off it is ``fn`` itself."""

    def __init__(self, fn: Any, args: tuple) -> None:
        if hasattr(fn, "typeof_pyval") and hasattr(fn, "compile"):
            sig = tuple(fn.typeof_pyval(a) for a in args)
            self.call = fn.compile(sig)
        else:  # pragma: no cover - NUMBA_DISABLE_JIT
            self.call = fn


def fast_plant(env: Any) -> bool:
    """True when the episode's period can run as :func:`mujoco_period` or :func:`ideal_period` (see the
    module docstring)."""
    p = env._plant
    if type(p) is IdealPlant:
        return FAST and p._dist is not None and env._faults is None and p._push_until is None
    return (
        FAST
        and hasattr(p, "model")
        and getattr(p, "_compiled_steps", False)
        and not p.sensors.on
        and not p.feed_delivered
        and (p.disturbance is None or p._dist is not None)
        and env._faults is None
        and p._push_until is None
        and hasattr(p, "contacts")
    )


#: the fields of :class:`IdealArgs`: :func:`ideal_period`'s arguments that stay the same through an episode
IDEAL_FIELDS = (
    "g", "s", "comm", "x", "c", "extra", "dist", "plant_dt", "n_sub", "lo", "hi", "alo", "ahi", "velocity", "verr",
    "tau", "tau_max", "dt", "L_pose", "L_vel", "lim", "diag", "off", "leader_frame", "fe", "zeros", "w", "r",
    "slots", "dst", "ew", "rp", "rv", "lacc", "bound",
)  # fmt: skip

#: the fields of :class:`PeriodArgs`: :func:`mujoco_period`'s arguments that stay the same through an episode
FIELDS = (
    "g", "s", "comm", "io", "wt", "cl", "px", "mptr", "dptr", "n_sub", "plant_dt", "lo", "hi", "alo", "ahi",
    "velocity", "verr", "tau", "tau_max", "dt", "L_pose", "L_vel", "lim", "diag", "off", "leader_frame", "fe",
    "tipped", "newly", "events_seen", "hits", "w", "r", "slots", "dst", "ew", "rp", "rv", "lacc", "bound",
)  # fmt: skip

if HAVE_NUMBA:
    import numba

#: the compiled period is available (numba, its JIT on)
FAST = HAVE_NUMBA and not numba.config.DISABLE_JIT

if FAST:
    from numba.core import types as _types
    from numba.experimental import structref

    class ArgsStructType(_types.StructRef):
        """The base of the episode's argument holders' numba types (:class:`PeriodArgs`, ``envs.worlds.VecArgs``
        …): each field typed as its value, never as a literal (an ``int`` field is ``int64``, not ``Literal[int](5)``:
        one specialisation whatever the numbers)."""

        def preprocess_fields(self, fields):
            return tuple((name, _types.unliteral(typ)) for name, typ in fields)

    @structref.register
    class PeriodArgsType(ArgsStructType):
        """numba's type of :class:`PeriodArgs`."""

    class PeriodArgs(structref.StructRefProxy):
        """:data:`FIELDS` held by one compiled object: passed to :func:`period` as one pointer, where
        ~110 arrays passed one by one cost numba ~0.3 µs each to unbox, every period."""

    structref.define_proxy(PeriodArgs, PeriodArgsType, list(FIELDS))

    @njit
    def make_args(*fields):
        """A :class:`PeriodArgs` of ``fields`` (in :data:`FIELDS`' order), built in compiled code (cached)."""
        return PeriodArgs(*fields)

    @structref.register
    class PolicyArgsType(ArgsStructType):
        """numba's type of :class:`PolicyArgs`."""

    class PolicyArgs(structref.StructRefProxy):
        """The paper's stack's ``(g, s, comm, verr)`` for :func:`policy_call` (see :class:`PeriodArgs`)."""

    structref.define_proxy(PolicyArgs, PolicyArgsType, ["g", "s", "comm", "verr"])

    @njit
    def make_policy_args(g, s, comm, verr):
        """A :class:`PolicyArgs` (built in compiled code, cached)."""
        return PolicyArgs(g, s, comm, verr)

    @njit
    def policy_call(a, lp, lv, pose, vel, true_vel, tau):
        """:func:`policy_period` with the stack's arguments ``a`` (:class:`PolicyArgs`)."""
        policy_period(a.g, a.s, lp, lv, pose, vel, a.comm, true_vel, a.verr, tau)

    #: :func:`mujoco_period` (its arguments ``a`` a :class:`PeriodArgs`)
    period = mujoco_period

    @structref.register
    class IdealArgsType(ArgsStructType):
        """numba's type of :class:`IdealArgs`."""

    class IdealArgs(structref.StructRefProxy):
        """:data:`IDEAL_FIELDS` held by one compiled object (see :class:`PeriodArgs`)."""

    structref.define_proxy(IdealArgs, IdealArgsType, list(IDEAL_FIELDS))

    @njit
    def make_ideal_args(*fields):
        """An :class:`IdealArgs` of ``fields`` (in :data:`IDEAL_FIELDS`' order), built in compiled code (cached)."""
        return IdealArgs(*fields)

    @njit
    def ideal_call(a, u, pose, vel, new_pose, new_vel, O, k, step_count):
        """:func:`ideal_period` with the episode's arguments ``a`` (:class:`IdealArgs`); ``step_count``
        unused (:func:`period`'s signature)."""
        return ideal_period(
            a.g, a.s, a.comm, a.x, a.c, a.extra, a.dist, a.plant_dt, a.n_sub, u, a.lo, a.hi, a.alo, a.ahi,
            a.velocity, a.verr, a.tau, a.tau_max, pose, vel, new_pose, new_vel, k, a.dt, a.L_pose, a.L_vel, a.lim,
            a.diag, a.off, a.leader_frame, a.fe, a.zeros, a.w, a.r, O, a.slots, a.dst, a.ew, a.rp, a.rv, a.lacc,
            a.bound,
        )  # fmt: skip


if not FAST:  # pragma: no cover - without numba or with its JIT off: the step-by-step path only
    PeriodArgs = PolicyArgs = make_args = make_policy_args = policy_call = period = None
    IdealArgs = make_ideal_args = ideal_call = None


class FastPeriod:
    """The arguments of :func:`mujoco_period` for the current episode of ``env`` (built after its reset,
    and again after an event changed the plant), and the scratch arrays it writes."""

    def __init__(
        self, env: Any, r: Any = None, fe: Any = None, hits: Any = None, model: Any = None, warm: Any = None
    ) -> None:
        """``r``, ``fe``, ``hits``: (n,) float64 arrays to write the rewards, formation errors and contact
        events into (views of a batch's arrays, ``envs.vector``); default: arrays of its own. ``model``: the
        ``MjModel`` the physics steps with (default: the plant's own; ``envs.vector`` passes one model that
        its worlds share where their physics is the same). ``warm``: ``(data, ncon, con, xmat)``, an
        ``MjData`` of the same sizes to step instead of the plant's own, its contact list's views (the
        :class:`~bioform_mj.plants.mujoco.contacts.ContactList` fields ``ncon``, ``con``) and the (nbody, 9)
        array the disturbance reads the chassis' orientation from (``envs.vector``: one ``MjData`` per
        thread, each world's state copied in and out; default: the plant's ``MjData``)."""
        p, n = env._plant, env.n
        st = env._stack
        w = env.weights
        self.tau = np.empty((n, 2))
        self.fe = np.empty(n) if fe is None else fe
        self.hits = np.zeros(n) if hits is None else hits
        self.r = np.empty(n) if r is None else r
        self.comm = st.comm_in(None)
        #: the MuJoCo plant (its step counter, warnings); False: the ideal plant
        self.mujoco = type(p) is not IdealPlant
        ne = len(env.graph.dst)
        pose, vel = env._pose, env._vel
        if not self.mujoco:
            fields = (
                env._g, env._s, self.comm, p.x, p._c, p._zero_acc, p._dist, float(p.control_dt), int(p.n_substeps),
                env._low, env._high, env._acc_low, env._acc_high, env.action_mode == "velocity", env._verr, self.tau,
                np.ascontiguousarray(env._tau_max), float(env.dt), env.L_pose, env.L_vel, env._lim, env._diag,
                env._off, bool(env._leader_frame), self.fe, self.hits,
                np.array([w["formation"], w["effort"], w["tipped"], w["collision"]]), self.r, env._slots,
                np.ascontiguousarray(env.graph.dst, dtype=np.int64), env._ones_e, np.empty((ne, 3)),
                np.empty((ne, 2)), env._lacc, float(env.obs_bound),
            )  # fmt: skip
            self.args = make_ideal_args(*fields)
            self.call = Compiled(ideal_call, (self.args, np.zeros((n, 2)), pose, vel, pose, vel,
                                              np.zeros((n, env.obs_size)), 0, 0)).call  # fmt: skip
            return
        self._plant = p
        m, d = p.model, p.data
        cl = p.contacts.contacts
        xmat = d.xmat
        if warm is not None:
            d, ncon, con, xmat = warm
            cl = cl._replace(ncon=ncon, con=con)
        from bioform_mj.plants.mujoco.kernels import Watch

        #: the plant's arrays of :class:`~bioform_mj.plants.mujoco.kernels.MjIO` that are not the ``MjData``'s
        self._io_own = (
            np.ascontiguousarray(p._q7[:, 0], dtype=np.int64), np.ascontiguousarray(p._v6[:, 0], dtype=np.int64),
            np.ascontiguousarray(p._ctrl, dtype=np.int64), np.ascontiguousarray(p._base, dtype=np.int64),
            np.zeros((2, 4)) if p._dist is None else p._dist,
        )  # fmt: skip
        io = self._io(d, xmat)
        wt = Watch(
            p.tilt_cos, p.tip_step, p._wdof, p._wheel_sign, p._wheel_radius, p._half_track, SLIP_RATIO,
            SLIP_V_FLOOR, p._slip_need, p.slip_run, p.slip_step,
        )  # fmt: skip
        fields = (
            env._g, env._s, self.comm, io, wt, cl, p.contacts.proximity,
            (m if model is None else model)._address, d._address,
            int(p.n_substeps), float(p.control_dt), env._low, env._high, env._acc_low, env._acc_high,
            env.action_mode == "velocity", env._verr, self.tau, np.ascontiguousarray(env._tau_max), float(env.dt),
            env.L_pose, env.L_vel, env._lim, env._diag, env._off, bool(env._leader_frame), self.fe, env._tipped,
            np.zeros(n), env._events_seen, self.hits,
            np.array([w["formation"], w["effort"], w["tipped"], w["collision"]]), self.r, env._slots,
            np.ascontiguousarray(env.graph.dst, dtype=np.int64), env._ones_e, np.empty((ne, 3)), np.empty((ne, 2)),
            env._lacc, float(env.obs_bound),
        )  # fmt: skip
        self._fields = fields
        self.args = make_args(*fields)  # fast_plant: numba's JIT is on
        self.call = Compiled(period, (self.args, np.zeros((n, 2)), pose, vel, pose, vel, np.zeros((n, env.obs_size)),
                                      0, 0)).call  # fmt: skip

    def _io(self, d: Any, xmat: np.ndarray) -> Any:
        """The :class:`~bioform_mj.plants.mujoco.kernels.MjIO` of the plant with ``MjData`` ``d``'s arrays and the
        chassis' orientation read from ``xmat``."""
        from bioform_mj.plants.mujoco.kernels import MjIO

        p = self._plant
        q7, v6, ctrl, base, dist = self._io_own
        return MjIO(
            d.qpos, d.qvel, q7, v6, p._axle, p._up, d.ctrl, ctrl, p._ctrl_scale, d.xfrc_applied, xmat, base, p._m_eff,
            p._i_eff, dist, p.disturbance is not None, d.warning.number, d.actuator_force, p._to_wheel, p._feed, False,
            p._dacc,
        )  # fmt: skip

    def args_on(self, warm: tuple) -> Any:
        """A :class:`PeriodArgs` of this episode that steps another ``MjData`` of the same sizes, ``warm`` as
        the constructor's (``envs.vector``: any thread's warm ``MjData`` may step a world); the episode's own
        arrays (the stack, the watches, the scratch and result arrays) are the same objects as :attr:`args`'."""
        d, ncon, con, xmat = warm
        f = list(self._fields)
        i = FIELDS.index
        f[i("io")] = self._io(d, xmat)
        f[i("cl")] = f[i("cl")]._replace(ncon=ncon, con=con)
        f[i("dptr")] = d._address
        return make_args(*f)


def fast_step(env: Any, actions: Any) -> tuple | None:
    """``env.step(actions)`` through :class:`FastPeriod`, or None where the step-by-step path must run it:
    the first period (the event queue is built there), an event's period, actions that are not a plain
    dict of every agent's two numbers within the space (that path names what is wrong; nothing was done)."""
    k = env.k
    if k == 0 or (env._ev_next is not None and k >= env._ev_next):
        env._fastp = None  # an event may replace the plant's arrays: the arguments are built again
        return None
    agents = env.agents
    if type(actions) is not dict or len(actions) != env.n or len(agents) != env.n:
        return None
    try:
        u = np.array([actions[a] for a in agents], dtype=float)  # every agent live: possible_agents' order
    except (KeyError, ValueError, TypeError):
        return None
    n = env.n
    if u.shape != (n, 2):
        return None
    fp = env._fastp
    if fp is None:
        fp = env._fastp = FastPeriod(env)
    p = env._plant
    pose, vel, O = np.empty((n, 3)), np.empty((n, 2)), np.empty((n, env.obs_size))
    status = fp.call(fp.args, u, env._pose, env._vel, pose, vel, O, k, p._step_count if fp.mujoco else 0)
    if status & BAD_ACTION:
        return None
    env._log.append(u)
    if fp.mujoco:
        p._step_count += 1
    if status & WARNED:  # as MujocoPlant.step: the warning raised, the state not observed
        return env._outputs(*env._advance_tail(fp.tau.copy(), warning_message(p)))
    env._pose, env._vel = pose, vel
    env.k = k = k + 1
    dt = env.dt
    env._mp, env._mv, env._lp_rx, env._lv_rx = pose, vel, env.L_pose[k], env.L_vel[k]
    env._comm, env._comm_in = None, fp.comm
    if k % env.stride == 0:
        env._stats_sample(k, fp.fe)
    if status == 0 and k < env.N:  # the usual period: no flag to name, nothing ends
        if env._dtype != O.dtype:
            O = O.astype(env._dtype)
        t = k * dt
        return (dict(zip(agents, O)), dict(zip(agents, fp.r.tolist())), dict.fromkeys(agents, False),
                dict.fromkeys(agents, False), {a: {"t": t} for a in agents})  # fmt: skip
    from bioform_mj.core.engine import describe

    diverged = describe(env._diag, k * dt, env._lim) if status & GUARD else None
    if status & TIPPED:
        env._any_tipped = True
    end = diverged is not None or env._any_tipped
    r = fp.r.copy()
    if end:
        r = r - env.weights["terminal"] * max(0.0, (env.N - k) * dt)
    trunc = k >= env.N and not end
    if end or trunc:
        env._done = True
        env._diverged = diverged
        env.agents = []
    return env._outputs(r, end, trunc, diverged, fp.hits.copy(), agents, None if diverged else O)


def warning_message(p: Any) -> str | None:
    """The message of the MuJoCo warning that stopped the period (``MujocoPlant.step`` raises it)."""
    from bioform_mj.core.errors import Diverged

    try:
        for i, w_ in enumerate(p._warnings):
            if w_.number:
                p._raise_warning(i, w_)
    except Diverged as e:
        return str(e)
    return None
