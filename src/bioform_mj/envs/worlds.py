"""The CPU-vectorised environment's compiled step: every world's period on threads (design §20; issue 30, item 6).

:class:`~.vector.VectorEnv` keeps its worlds' arrays in one :class:`VecArgs`; a step is :func:`dispatch` on the
calling thread and :func:`serve` on the others (``envs.team``: they stay in compiled code between periods).

The worlds are split into ``T`` blocks, one a thread, as ``mujoco.rollout`` splits its batch, but a block is not
tied to its thread: each thread claims the worlds of its own block one at a time from the block's counter (an
atomic add), and when its block is done it claims the rest of the others' blocks. Where a thread is held up (the
other processes of a shared machine, a slower world) the others step its worlds instead of waiting at the
period's end: ``mujoco.rollout`` gets the same from its pool's queue of small chunks. The calling thread waits
for the count of worlds done, not for each thread: a thread that has not woken up yet by the time the others
took its worlds holds nothing up. Any thread can step any world: each world's period has one
:class:`~.fast.PeriodArgs` per thread (``args[t·W + w]``), pointing at that thread's warm ``MjData`` where the
world steps warm (its MuJoCo state is copied in and out each period, ``envs/vector.py``), so which thread
stepped a world does not change its bits (``tests/test_envs_vector.py``).

Counters (int32, one 64-byte line each, :data:`~.team.SLOT` entries): ``claim[SLOT·u]`` the next world of block
``u``; ``claim[SLOT·(T + t)]`` the worlds thread ``t`` finished this period. A period's counters are set by the
calling thread before it releases the others (sequentially consistent stores, then the "go" bump), so a thread
that claims a world sees the period's actions and states; a world's results are seen by the calling thread
once it has read the finished counts.
"""

from __future__ import annotations

import numpy as np

from bioform_mj.core.equations import njit
from bioform_mj.envs.fast import BAD_ACTION, FAST, GUARD, TIPPED, WARNED, period
from bioform_mj.envs.kernels import actions_within
from bioform_mj.envs.team import GO, SLOT, STOP, atomic_add, atomic_load, atomic_store, bump, wait_change
from bioform_mj.plants.mujoco.kernels import copy_data, state_in, state_out

#: the control array's index of the "a thread finished its claims" counter (the calling thread sleeps on it;
#: ``ALL + 1``: its sleepers), in slot 1 (slot 0 holds "go", :data:`~.team.GO`)
ALL = SLOT


@njit
def first_bad(U, running, lo, hi):
    """The first ``running`` world whose actions ``U[w]`` (n, 2) are not all finite within ``[lo, hi]``
    (the float32-rounded bounds), or −1."""
    for w in range(U.shape[0]):
        if running[w] and not actions_within(U[w], lo, hi):
            return w
    return -1


@njit
def periods(args, claim, t, blocks, wd, wx, ww, own, warm, X, sig, U, pose, vel, new_pose, new_vel, O, O_out, R, k,
            step_count, status, running, term, trunc, N, dt, w_terminal):  # fmt: skip
    """Thread ``t``'s share of a period: the worlds it claims (``claim``, ``blocks`` (T, 2) ``lo, hi``: its own
    block first, then the others'), each one :func:`~.fast.mujoco_period` if ``running`` (``args`` the typed list
    of the worlds' :class:`~.fast.PeriodArgs`, thread ``t``'s at ``t·W + w``; ``U`` (W, n, 2) the actions); a
    world's new state is copied into ``pose``, ``vel`` (unless MuJoCo warned: the plant is not observed then)
    and its step counters ``k`` (control) and ``step_count`` (the plant's) advance. ``status`` (W,): the
    period's bits; then the step's ends, as the single environment's step sets them: ``term`` (W,) (the guards,
    a tip-over, a MuJoCo warning), the terminal reward ``w_terminal·max(0, (N − k)·dt)`` taken from the rewards
    ``R`` (W, n) (not for a warning: its tail runs in Python), the observations ``O`` zeroed where the guards
    failed or MuJoCo warned, ``trunc`` (W,) at step ``N``, ``running`` cleared where either; ``O_out`` (the
    observations in the environment's dtype) written from ``O``.

    A world with ``warm[w]`` steps this thread's ``MjData`` (address ``wd``; its ``xmat`` view ``wx`` and
    warning counters ``ww``): its MuJoCo state ``X[w]`` (``mj_getState``'s layout for ``sig``,
    ``mjSTATE_INTEGRATION``) is copied in before the period and out after it, with the chassis' rows of ``xmat``
    (the disturbance's heading of the next period) into the world's own array; where its episode ends or MuJoCo
    warns, the whole ``MjData`` is copied into the world's own (address ``own[w]``), which then holds what
    stepping it would have left, and the counters are cleared."""
    T, W = blocks.shape[0], U.shape[0]
    for j in range(T):
        b = (t + j) % T
        hi = blocks[b, 1]
        while True:
            w = atomic_add(claim, SLOT * b, np.int32(1))
            if w >= hi:
                break
            term[w] = False
            trunc[w] = False
            status[w] = 0
            if running[w]:
                a = args[t * W + w]
                if warm[w]:
                    state_in(a.mptr, wd, X[w], sig)
                st = period(a, U[w], pose[w], vel[w], new_pose[w], new_vel[w], O[w], k[w], step_count[w])
                status[w] = st
                if not st & BAD_ACTION:
                    _world_end(a, w, st, wd, wx, ww, own, warm, X, sig, pose, vel, new_pose, new_vel, O, O_out, R,
                               k, step_count, running, term, trunc, N, dt, w_terminal)  # fmt: skip
            atomic_add(claim, SLOT * (T + t), np.int32(1))


@njit(inline=True)
def _world_end(a, w, st, wd, wx, ww, own, warm, X, sig, pose, vel, new_pose, new_vel, O, O_out, R, k, step_count,
               running, term, trunc, N, dt, w_terminal):  # fmt: skip
    """World ``w``'s bookkeeping after its period of status ``st`` (see :func:`periods`)."""
    if warm[w]:
        state_out(a.mptr, wd, X[w], sig)
        xm, base = a.io.xmat, a.io.base
        for i in range(base.shape[0]):
            for c in range(9):
                xm[base[i], c] = wx[base[i], c]
    step_count[w] += 1
    if not st & WARNED:
        k[w] += 1
        pose[w, :, :] = new_pose[w]
        vel[w, :, :] = new_vel[w]
    if st & (GUARD | TIPPED | WARNED):
        term[w] = True
        if not st & WARNED:
            c = w_terminal * max(0.0, (N - k[w]) * dt)
            for i in range(R.shape[1]):
                R[w, i] = R[w, i] - c
        if st & (GUARD | WARNED):
            O[w, :, :] = 0.0
    elif k[w] >= N:
        trunc[w] = True
    running[w] = not (term[w] or trunc[w])
    if warm[w] and not running[w]:  # ended or warned
        copy_data(own[w], a.mptr, wd)
        for j in range(ww.shape[0]):
            ww[j] = 0
    for i in range(O.shape[1]):
        for j in range(O.shape[2]):
            O_out[w, i, j] = O[w, i, j]


#: the fields of :class:`VecArgs`: :func:`periods`' arguments, the threads' blocks (``blocks`` (T, 2): ``lo, hi``),
#: the claim counters ``claim`` (int32 (2·T·SLOT,)), the warm ``MjData`` (``wd`` (T,) addresses, ``wx``/``ww`` typed
#: lists of their ``xmat`` and warning counters), the actions' bounds for :func:`first_bad`
VFIELDS = (
    "args", "blocks", "claim", "wd", "wx", "ww", "own", "warm", "X", "sig", "U", "pose", "vel", "new_pose", "new_vel",
    "O", "O_out", "R", "k", "step_count", "status", "running", "term", "trunc", "N", "dt", "w_terminal", "acc_low",
    "acc_high",
)  # fmt: skip

if FAST:
    from numba.experimental import structref

    from bioform_mj.envs.fast import ArgsStructType

    @structref.register
    class VecArgsType(ArgsStructType):
        """numba's type of :class:`VecArgs`."""

    class VecArgs(structref.StructRefProxy):
        """:data:`VFIELDS`, the same arrays through the environment's life, held by one compiled object: a
        period's call unboxes one argument, not ~20 arrays (~0.3 µs each, with the GIL held)."""

    structref.define_proxy(VecArgs, VecArgsType, list(VFIELDS))

    @njit
    def make_vargs(*fields):
        """A :class:`VecArgs` of ``fields`` (in :data:`VFIELDS`' order), built in compiled code (cached)."""
        return VecArgs(*fields)

else:  # pragma: no cover - the vector environment needs numba's JIT
    VecArgs = make_vargs = None


def claims(threads: int) -> np.ndarray:
    """Zeroed claim counters for ``threads`` threads (see the module docstring)."""
    return np.zeros(2 * SLOT * max(threads, 1), dtype=np.int32)


@njit
def block(v, t):
    """Thread ``t``'s claims of a period: :func:`periods` with ``v`` (:class:`VecArgs`) on its warm ``MjData``."""
    periods(v.args, v.claim, t, v.blocks, v.wd[t], v.wx[t], v.ww[t], v.own, v.warm, v.X, v.sig, v.U, v.pose,
            v.vel, v.new_pose, v.new_vel, v.O, v.O_out, v.R, v.k, v.step_count, v.status, v.running, v.term, v.trunc,
            v.N, v.dt, v.w_terminal)  # fmt: skip


@njit
def check(v):
    """:func:`first_bad` of the actions ``v.U``."""
    return first_bad(v.U, v.running, v.acc_low, v.acc_high)


@njit
def start(v):
    """A period's counters: every thread's finished count 0, then each block's next world its first."""
    T = v.blocks.shape[0]
    for t in range(T):
        atomic_store(v.claim, SLOT * (T + t), np.int32(0))
    for b in range(T):
        atomic_store(v.claim, SLOT * b, np.int32(v.blocks[b, 0]))


@njit
def finished(v):
    """The worlds the threads have finished this period (the sum of their counts)."""
    T, s = v.blocks.shape[0], 0
    for t in range(T):
        s += atomic_load(v.claim, SLOT * (T + t))
    return s


@njit
def count_warned(v):
    """The number of worlds whose period MuJoCo warned in."""
    c = 0
    for w in range(v.status.shape[0]):
        if v.status[w] & WARNED:
            c += 1
    return c


@njit
def dispatch(v, ctl, spin_ns):
    """One period of every world: the actions checked (a bad one: ``-(w + 1)`` for the first bad world ``w``,
    nothing stepped), the counters set (:func:`start`), the other threads released (a new "go" generation in
    ``ctl``), the calling thread's claims (:func:`block` 0), then, until every world is finished, a wait on the
    threads' "finished its claims" counter (:data:`ALL`; spinning up to ``spin_ns`` ns, then asleep). Returns
    the number of worlds that warned."""
    bad = first_bad(v.U, v.running, v.acc_low, v.acc_high)
    if bad >= 0:
        return -(bad + 1)
    T, W = v.blocks.shape[0], v.U.shape[0]
    start(v)
    if T > 1:
        bump(ctl, GO)
    block(v, 0)
    if T > 1:
        ts = np.empty(2, dtype=np.int64)
        while True:
            g = atomic_load(ctl, ALL)
            if finished(v) >= W:
                break
            wait_change(ctl, ALL, g, spin_ns, ts)
    return count_warned(v)


@njit
def serve(v, ctl, t, gen, spin_ns):
    """Worker ``t``'s life: wait for the next "go" generation after ``gen`` (spinning up to ``spin_ns`` ns,
    then asleep), claim and step worlds (:func:`block`), tell the calling thread (:data:`ALL`); return at the
    stop flag."""
    ts = np.empty(2, dtype=np.int64)
    while True:
        gen = wait_change(ctl, GO, gen, spin_ns, ts)
        if atomic_load(ctl, STOP):
            return
        block(v, t)
        bump(ctl, ALL)
