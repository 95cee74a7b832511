"""The control step of many formations on MuJoCo Warp: one thread per world.

:func:`_control` is ``control/kernel.py``'s ``control_step`` (learner, estimator consensus,
command and torques with the world's ``torque.derivative`` mode, estimator advance) plus the loop
bookkeeping of ``engine.py`` (run metrics, divergence guards)
and the plant glue of ``plants/mujoco_kernels.py`` (observe, wheel torques and the
eq. 34 disturbance as chassis ``xfrc_applied``; ``ctrl = scale · τ``, the DC motors' driver
input per N·m, design §8.2; the plant faults of ``faults.py``, actuator limits and pushes, from
per-world tables, :class:`PlantFaults`), for one world per thread, looping over
its followers and graph edges in the same order as the CPU kernels; with each world's network
faults and sensor noise (``faults.Faults.sense``/``comm``: :class:`CommFaults`, :func:`_comm`).
Every equation is
the Warp translation (:mod:`.samesource`) of ``control/equations.py``: only loops,
indexing and bookkeeping are written here.

Precision: controller state, gains and metrics are float64 (the learner is stiff and
``ĉ`` must match the CPU engine to 0.5 %); MuJoCo Warp's physics is float32, converted at
the boundary (``qpos``/``qvel`` in, ``ctrl``/``xfrc_applied`` out).

:func:`run_batch` runs a list of scenarios (one world each) of one composed scene. The
step loop (``n_substeps`` × ``mjw.step``, each followed with ``plant.sensing = "odometry"`` by
:func:`_sense`, the encoders, gyro and dead reckoning of design §8.3, and for DC motors by
:func:`_delivered`, which feeds the learner the torque delivered over the period, design §8.2,
+ one ``_control`` launch per control step) reads nothing back to the host; the step counter lives on the device,
so on CUDA a chunk of control steps is captured once as a CUDA graph and replayed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import mujoco_warp as mjw
import numpy as np
import warp as wp

from ..control import equations as _E
from ..control.kernel import DERIV_ANALYTIC, DERIV_DIFFERENCE
from ..control.stack import ControlStack
from ..disturbance import Harmonic
from ..engine import GUARDS
from ..faults import Faults, counter
from ..plants.mujoco_plant import TIP_ANGLE_DEG
from ..scenario import Scenario
from ..sim import LOST_AFTER_S, SPIN_RAD_S, lost_threshold_m
from .backend import default_capacity, unsupported
from .samesource import warp_equations

__all__ = ["run_batch", "BatchRun", "SCALARS"]

F = wp.float64
EQ = warp_equations(_E, F)
# module globals: Warp resolves a kernel's globals when it builds the kernel
wrap = EQ.wrap
estimator_euler = EQ.estimator_euler
tracking_error = EQ.tracking_error
slot_reference = EQ.slot_reference
formation_offset = EQ.formation_offset
velocity_command = EQ.velocity_command
neuron_step = EQ.neuron_step
filter_derivative = EQ.filter_derivative
backward_difference = EQ.backward_difference
estimator_rates = EQ.estimator_rates
error_rate = EQ.error_rate
neuron_rate = EQ.neuron_rate
command_rate = EQ.command_rate
sliding_mode = EQ.sliding_mode
saturate = EQ.saturate
learner_step = EQ.learner_step
harmonic = EQ.harmonic
planar_state = EQ.planar_state
slip_ratio = EQ.slip_ratio
encoder_angle = EQ.encoder_angle
gyro_reading = EQ.gyro_reading
odometry_step = EQ.odometry_step
clip = EQ.clip
noisy_reading = EQ.noisy_reading
packet_received = EQ.packet_received

#: per-world scalar gains, columns of ``BatchGains.sc``: the scalar fields of ``control.kernel.Gains``
#: (``deriv`` the ``DERIV_*`` code, the flags as 0/1), then ``scenario.limits``, then the
#: disturbance rows of eq. 34, then the loop's own numbers
GAIN_SCALARS = (
    "k1",
    "k2",
    "k3",
    "A",
    "B",
    "D",
    "kx",
    "ky",
    "kth",
    "ka0",
    "ka1",
    "kb0",
    "kb1",
    "ephi0",
    "ephi1",
    "ca",
    "cb",
    "tphi",
    "f00",
    "f01",
    "f10",
    "f11",
    "g0",
    "g1",
    "deriv",
    "k5a",
    "k5b",
    "kda",
    "kdb",
    "dt",
    "bio",
    "learning",
    "steer",
    "leader_frame",
)
SCALARS = (
    *GAIN_SCALARS,
    "lim_position",
    "lim_speed",
    "lim_torque",
    "d0",
    "d1",
    "d2",
    "d3",
    "e0",
    "e1",
    "e2",
    "e3",
    "use_dist",
    "stride",
    "t_spin",
    "tilt_cos",
    "slip_max",
    "slip_floor",
    "slip_need",
    "odometry",
    "odo_seed",
    "gyro_bias",
    "gyro_sigma",
)
_I = {name: wp.constant(i) for i, name in enumerate(SCALARS)}
K1, K2, K3, A_, B_, D_ = (_I[x] for x in ("k1", "k2", "k3", "A", "B", "D"))
KX, KY, KTH, KA0, KA1, KB0, KB1, EPHI0, EPHI1 = (
    _I[x] for x in ("kx", "ky", "kth", "ka0", "ka1", "kb0", "kb1", "ephi0", "ephi1")
)
CA, CB, TPHI, F00, F01, F10, F11, G0, G1 = (_I[x] for x in ("ca", "cb", "tphi", "f00", "f01", "f10", "f11", "g0", "g1"))
K5A, K5B, KDA, KDB, DT, BIO, LEARN, STEER = (
    _I[x] for x in ("k5a", "k5b", "kda", "kdb", "dt", "bio", "learning", "steer")
)
DERIV = _I["deriv"]
assert K5B == K5A + 1 and KDB == KDA + 1  # the learner's per-component loop indexes K5A + c, KDA + c
LFRAME = _I["leader_frame"]  # 1: offsets in the leader's frame (design §4)
DERIV_A = wp.constant(F(DERIV_ANALYTIC))
DERIV_D = wp.constant(F(DERIV_DIFFERENCE))
LPOS, LSPD, LTRQ = _I["lim_position"], _I["lim_speed"], _I["lim_torque"]
DD0, DE0, USED = _I["d0"], _I["e0"], _I["use_dist"]
STRIDE, TSPIN, TILT = _I["stride"], _I["t_spin"], _I["tilt_cos"]
SLIPMAX, SLIPFLOOR, SLIPNEED = _I["slip_max"], _I["slip_floor"], _I["slip_need"]
# plant.sensing = "odometry" (design §8.3): 1 = the controller is fed the dead reckoning; the gyro
# noise seed (sim.seed mod 2^31 − 1, as MujocoPlant), bias and standard deviation per sample, rad/s
ODO, OSEED, GBIAS, GSIGMA = _I["odometry"], _I["odo_seed"], _I["gyro_bias"], _I["gyro_sigma"]
#: MuJoCo Warp's ``Data.overflow`` bits that mean dropped contacts or constraint rows (capacity), not
#: the solver's iteration limits: a world with one of them is stopped as the CPU stops on MuJoCo's
#: ``mjWARN_CONTACTFULL``/``CNSTRFULL`` warnings (``engine.PLANT_FAILED``)
CAPACITY_BITS = (
    mjw.OverflowType.NEFC
    | mjw.OverflowType.NJMAX_NNZ
    | mjw.OverflowType.BROADPHASE
    | mjw.OverflowType.NARROWPHASE
    | mjw.OverflowType.CCD
    | mjw.OverflowType.HFIELD
    | mjw.OverflowType.NVMAX
)
CAPACITY = wp.constant(int(CAPACITY_BITS))
#: ``BatchState.status`` codes: running, a guard failed (``diag`` = guard), the physics overflowed
#: MuJoCo Warp's capacities (``diag[w, 0]`` = the ``Data.overflow`` bits)
RUNNING, GUARD_FAILED, CAPACITY_EXCEEDED = 0, 1, 2
ST_CAP = wp.constant(CAPACITY_EXCEEDED)
SPIN = wp.constant(F(SPIN_RAD_S))

#: per-world network and sensor faults (``faults.Faults``), columns of ``CommFaults.sc``: the counter
#: hash's seed (``sim.seed mod 2^31 − 1``); flags (0/1) ``comm`` (any link failure, loss or delay),
#: ``recv`` (loss or delay: received values differ from the current ones), ``noise``; the packet loss
#: probability, the delay in control steps, the window ``[w0, w1)`` s of loss, delay and noise (±inf:
#: the whole run), the noise standard deviations ``[σx m, σy m, σθ rad]``, ``[συ m/s, σω rad/s]``
FAULT_SCALARS = (
    "seed",
    "comm",
    "recv",
    "noise",
    "loss",
    "delay",
    "w0",
    "w1",
    "np0",
    "np1",
    "np2",
    "nv0",
    "nv1",
)
_J = {name: wp.constant(i) for i, name in enumerate(FAULT_SCALARS)}
FSEED, FCOMM, FRECV, FNOISE, FLOSS, FDELAY, FW0, FW1, FNP0, FNV0 = (
    _J[x] for x in ("seed", "comm", "recv", "noise", "loss", "delay", "w0", "w1", "np0", "nv0")
)
#: first counter-hash index of each random stream (``faults.counter``)
LOSS0 = wp.constant(counter("packet_loss", 0))
NPOSE0 = wp.constant(counter("noise_pose", 0))
NVEL0 = wp.constant(counter("noise_vel", 0))


@wp.struct
class BatchGains:
    """Per-world numbers (``W`` worlds, ``n`` followers, ``m`` edges)."""

    sc: wp.array2d(dtype=F)  # (W, len(SCALARS))
    k4: wp.array3d(dtype=F)  # (W, n, 2)
    c_min: wp.array3d(dtype=F)
    c_max: wp.array3d(dtype=F)
    offsets: wp.array3d(dtype=F)  # (W, n, 2)
    lim: wp.array2d(dtype=F)  # (W, n) wheel torque limit
    lacc: wp.array2d(dtype=F)  # (W, n) leader access a_ir
    c_hat0: wp.array3d(dtype=F)  # (W, n, 2)
    est0: wp.array3d(dtype=F)  # (W, n, 3) P_ir(0)
    m_eff: wp.array2d(dtype=F)  # (W, n)
    i_eff: wp.array2d(dtype=F)
    src: wp.array(dtype=int)  # (m,) graph edges src ← dst, shared by all worlds
    dst: wp.array(dtype=int)


@wp.struct
class BatchState:
    """``control.kernel.StackState`` with a leading world axis, plus the loop's own state."""

    pose: wp.array3d(dtype=F)  # (W, n, 3) the true pose at the last observation (the controller's: mpose)
    vel: wp.array3d(dtype=F)  # (W, n, 2) the true [υ, ω] (the controller's: mvel)
    est_pose: wp.array3d(dtype=F)
    est_vel: wp.array3d(dtype=F)
    z_hat: wp.array3d(dtype=F)
    e_int: wp.array3d(dtype=F)
    c_hat: wp.array3d(dtype=F)
    d_hat: wp.array3d(dtype=F)
    fy: wp.array3d(dtype=F)
    fdy: wp.array3d(dtype=F)
    vs: wp.array2d(dtype=F)
    err: wp.array3d(dtype=F)
    cmd: wp.array3d(dtype=F)
    dcmd: wp.array3d(dtype=F)
    tau: wp.array3d(dtype=F)
    tau_raw: wp.array3d(dtype=F)
    tau_body: wp.array3d(dtype=F)
    saturated: wp.array2d(dtype=int)
    p_err: wp.array3d(dtype=F)
    v_err: wp.array3d(dtype=F)
    est_rate: wp.array3d(dtype=F)  # (W, n, 5) the estimator's rates of this step (kernel.StackState)
    first: wp.array(dtype=int)  # (W,)
    k: wp.array(dtype=int)  # (W,) the control step this world computes next
    status: wp.array(dtype=int)  # (W,) RUNNING, GUARD_FAILED or CAPACITY_EXCEEDED
    k_done: wp.array(dtype=int)  # (W,) control steps done (N, or the step whose guard failed)
    diag: wp.array2d(dtype=F)  # (W, 3) guard code (engine.GUARDS index + 1), follower, value
    # metrics (engine.Metrics), per world and follower
    verr: wp.array2d(dtype=F)
    nsat: wp.array2d(dtype=F)
    vmax: wp.array2d(dtype=F)
    taumax: wp.array2d(dtype=F)
    tauraw_max: wp.array2d(dtype=F)
    ferr: wp.array2d(dtype=F)  # (W, n) formation error at the last observation
    # the log rows' share of the summary (rows at k % stride == 0, k < N, as sim.simulate logs them):
    fsq: wp.array2d(dtype=F)  # (W, n) Σ formation error² over the rows
    fe0: wp.array2d(dtype=F)  # (W, n) formation error of row 0
    spin_ok: wp.array2d(dtype=F)  # (W, n) rows with t ≥ t_spin and |ω| ≤ SPIN_RAD_S
    nrow: wp.array(dtype=int)  # (W,) rows
    tip_step: wp.array2d(dtype=int)  # (W, n) first observation k with the chassis tilted (−1: never)
    slip_run: wp.array2d(dtype=int)  # (W, n) consecutive observations with a wheel slipping
    slip_step: wp.array2d(dtype=int)  # (W, n) observation k at which a slip first lasted slip_need (−1: never)
    dacc: wp.array3d(dtype=F)  # (W, n, 2) DC motors: delivered wheel torque [τ_L, τ_R], N·m, summed over the period
    # what the controller is given (design §8.3): the truth (pose, vel) or the odometry's reading
    mpose: wp.array3d(dtype=F)  # (W, n, 3) [x, y, θ], m, rad
    mvel: wp.array3d(dtype=F)  # (W, n, 2) [υ, ω], m/s, rad/s (odometry: the period's mean)
    # plant.sensing = "odometry": each robot's dead reckoning (mujoco_kernels.Odometry), per world
    odo_pose: wp.array3d(dtype=F)  # (W, n, 3) [x, y, θ], m, rad
    odo_q: wp.array3d(dtype=F)  # (W, n, 2) last quantised forward wheel angles [q_L, q_R], rad
    odo_dist: wp.array2d(dtype=F)  # (W, n) distance since the last control step, m
    odo_turn: wp.array2d(dtype=F)  # (W, n) heading change since the last control step, rad
    odo_count: wp.array(dtype=int)  # (W,) physics steps since reset


@wp.struct
class PlantFaults:
    """Per-world actuator faults and pushes (``faults.actuator``, ``faults.push``; ``faults.py``) as
    padded tables of rows (``W`` worlds; ``Ra``, ``Rp`` the most rows of a world, at least 1; padding
    rows have follower −1). Times are control steps, resolved on the host exactly as ``Faults.step``
    compares ``t = k dt`` (:func:`plant_fault_tables`)."""

    act_i: wp.array2d(dtype=int)  # (W, Ra) follower (0-based), −1: padding
    act_k0: wp.array2d(dtype=int)  # (W, Ra) first control step with t ≥ t_start
    act_k1: wp.array2d(dtype=int)  # (W, Ra) first control step with t ≥ t_end (active in [k0, k1))
    act_s: wp.array2d(dtype=F)  # (W, Ra) scale of the wheel torque limit, in [0, 1]
    act_known: wp.array(dtype=int)  # (W,) 1: faults.actuator_known (the stack's own limit follows)
    push_i: wp.array2d(dtype=int)  # (W, Rp) follower (0-based), −1: padding; rows sorted by t (stable)
    push_k0: wp.array2d(dtype=int)  # (W, Rp) control step at which Faults.step starts the push
    push_k1: wp.array2d(dtype=int)  # (W, Rp) first control step at which it no longer acts
    push_w: wp.array3d(dtype=F)  # (W, Rp, 3) world-frame force fx, fy (N) and yaw torque tz (N·m)


@wp.func
def _act_scale(pf: PlantFaults, w: int, i: int, k: int) -> F:
    """Follower ``i``'s torque-limit scale at control step ``k``: the minimum over its active rows, 1
    without one (``Faults.actuate``: ``np.minimum.at`` on ones)."""
    sc = F(1.0)
    for r in range(pf.act_i.shape[1]):
        if pf.act_i[w, r] == i and pf.act_k0[w, r] <= k and k < pf.act_k1[w, r]:
            sc = wp.min(sc, pf.act_s[w, r])
    return sc


@wp.func
def _push_row(pf: PlantFaults, w: int, i: int, k: int) -> int:
    """The push acting on follower ``i`` in the period of control step ``k`` (−1: none): the last row
    started by then (``Faults.step`` starts rows in time order, a new one replacing the old one in
    ``MujocoPlant.push``), if it has not ended (``_apply_push``: ``t0 + duration > t + 1e-12``)."""
    last = wp.int32(-1)  # typed: mutated in a dynamic loop
    for r in range(pf.push_i.shape[1]):
        if pf.push_i[w, r] == i and pf.push_k0[w, r] <= k:
            last = r
    if last >= 0 and k >= pf.push_k1[w, last]:
        last = -1
    return last


@wp.struct
class CommFaults:
    """Per-world network and sensor faults (``faults.Faults``: link failure, packet loss, delay, noise)
    and their state (``W`` worlds, ``n`` followers, ``m`` graph edges, ``R`` ring rows: the batch's
    largest delay in control steps + 1)."""

    sc: wp.array2d(dtype=F)  # (W, len(FAULT_SCALARS))
    fe: wp.array3d(dtype=F)  # (W, Fe, 3) edge failures [edge, t_fail s, t_recover s]; edge −1: padding
    fl: wp.array3d(dtype=F)  # (W, Fl, 3) leader-link failures [follower (0-based), t_fail, t_recover]
    ring_p: wp.array4d(dtype=F)  # (W, R, n, 3) the estimates P_ir of the last R steps, m, m, rad
    ring_v: wp.array4d(dtype=F)  # (W, R, n, 2) [υ_ir, ω_ir], m/s, rad/s
    ring_lp: wp.array3d(dtype=F)  # (W, R, 3) the leader's pose
    ring_lv: wp.array3d(dtype=F)  # (W, R, 2) the leader's [υ_r, ω_r]
    hp: wp.array3d(dtype=F)  # (W, m, 3) dst's estimate as src last received it
    hv: wp.array3d(dtype=F)  # (W, m, 2)
    hlp: wp.array2d(dtype=F)  # (W, 3) the leader's state as last received
    hlv: wp.array2d(dtype=F)  # (W, 2)
    valid_e: wp.array2d(dtype=int)  # (W, m) 1: the edge counts (up, and a packet since it came up)
    valid_l: wp.array2d(dtype=int)  # (W, n) the same for each leader link
    ew: wp.array2d(dtype=F)  # (W, m) this step's edge weights (Comm.edge_w)
    lw: wp.array2d(dtype=F)  # (W, n) this step's leader-link weights (Comm.leader_w)


@wp.func
def _link_up(tab: wp.array3d(dtype=F), w: int, idx: int, t: F) -> F:
    """1 unless a row ``[idx, t_fail, t_recover]`` of world ``w``'s failure table holds ``t`` (then 0)."""
    for r in range(tab.shape[1]):
        if int(tab[w, r, 0]) == idx and t >= tab[w, r, 1] and t < tab[w, r, 2]:
            return F(0.0)
    return F(1.0)


@wp.func
def _comm(
    f: CommFaults,
    g: BatchGains,
    s: BatchState,
    w: int,
    k: int,
    t: F,
    L_pose: wp.array2d(dtype=F),
    L_vel: wp.array2d(dtype=F),
):
    """``faults.Faults.comm`` for world ``w`` at control step ``k`` (``t = k dt``): the link weights
    into ``f.ew``/``f.lw``; with loss or delay (``recv``) the ring of estimates (and of the leader's
    true state ``L_pose[k]``, ``L_vel[k]``), the held values ``f.hp``, ``f.hv``, ``f.hlp``, ``f.hlv`` (zero-order
    hold of what arrived) and the ``valid`` flags (a link that was down counts from its first packet).
    Loop glue; the draws are ``packet_received`` of the counter hash, as on the CPU."""
    m = g.src.shape[0]
    n = s.est_pose.shape[1]
    for e in range(m):
        f.ew[w, e] = _link_up(f.fe, w, e, t)
    for i in range(n):
        f.lw[w, i] = _link_up(f.fl, w, i, t)
    if f.sc[w, FRECV] == F(0.0):
        return  # link failures only: the links that are up carry current values
    D = int(f.sc[w, FDELAY])
    R = D + 1
    now = k % R
    for i in range(n):
        for c in range(3):
            f.ring_p[w, now, i, c] = s.est_pose[w, i, c]
        for c in range(2):
            f.ring_v[w, now, i, c] = s.est_vel[w, i, c]
    for c in range(3):
        f.ring_lp[w, now, c] = L_pose[k, c]
    for c in range(2):
        f.ring_lv[w, now, c] = L_vel[k, c]
    if k == 0:  # before the first step there is no history: the initial values
        for r in range(R):
            for i in range(n):
                for c in range(3):
                    f.ring_p[w, r, i, c] = s.est_pose[w, i, c]
                for c in range(2):
                    f.ring_v[w, r, i, c] = s.est_vel[w, i, c]
            for c in range(3):
                f.ring_lp[w, r, c] = L_pose[k, c]
            for c in range(2):
                f.ring_lv[w, r, c] = L_vel[k, c]
        for e in range(m):
            j = g.dst[e]
            for c in range(3):
                f.hp[w, e, c] = s.est_pose[w, j, c]
            for c in range(2):
                f.hv[w, e, c] = s.est_vel[w, j, c]
            f.valid_e[w, e] = 1
        for c in range(3):
            f.hlp[w, c] = L_pose[k, c]
        for c in range(2):
            f.hlv[w, c] = L_vel[k, c]
        for i in range(n):
            f.valid_l[w, i] = 1
    on = t >= f.sc[w, FW0] and t < f.sc[w, FW1]
    old = now
    if on:
        old = ((k - D) % R + R) % R  # Python's floored modulo (Warp's % is C's)
    loss = f.sc[w, FLOSS]
    draw = on and loss > F(0.0)
    seed = f.sc[w, FSEED]
    kf = F(k)
    for e in range(m):
        up = f.ew[w, e] != F(0.0)
        got = up
        if draw and up:
            got = packet_received(loss, seed, F(LOSS0 + e), kf) != F(0.0)
        if got:
            j = g.dst[e]
            for c in range(3):
                f.hp[w, e, c] = f.ring_p[w, old, j, c]
            for c in range(2):
                f.hv[w, e, c] = f.ring_v[w, old, j, c]
        v = 0
        if up and (got or f.valid_e[w, e] != 0):
            v = 1
        f.valid_e[w, e] = v
        f.ew[w, e] = F(v)
    lead = True  # the leader's broadcast arrives for all leader-connected followers or for none
    if draw:
        lead = packet_received(loss, seed, F(LOSS0 + m), kf) != F(0.0)
    nl = wp.int32(0)  # (a dynamic variable: mutated in the loop)
    for i in range(n):
        up = f.lw[w, i] != F(0.0)
        got = up and lead
        if got:
            nl = nl + 1
        v = 0
        if up and (got or f.valid_l[w, i] != 0):
            v = 1
        f.valid_l[w, i] = v
        f.lw[w, i] = F(v)
    if nl > 0:
        for c in range(3):
            f.hlp[w, c] = f.ring_lp[w, old, c]
        for c in range(2):
            f.hlv[w, c] = f.ring_lv[w, old, c]


@wp.func
def _finite3(a: wp.array3d(dtype=F), w: int, i: int, nc: int) -> bool:
    for c in range(nc):  # (no flag mutated in the loop: Warp 1.19 refuses to mutate a constant there)
        if not wp.isfinite(a[w, i, c]):
            return False
    return True


@wp.func
def _check(g: BatchGains, s: BatchState, w: int, n: int) -> int:
    """``engine.check`` for world ``w``: 0 if all guards pass, else writes ``s.diag[w]``."""
    for i in range(n):
        bad = 0
        if not _finite3(s.pose, w, i, 3):
            bad = 1
        elif not _finite3(s.vel, w, i, 2):
            bad = 2
        elif not _finite3(s.est_pose, w, i, 3):
            bad = 3
        elif not _finite3(s.est_vel, w, i, 2):
            bad = 4
        elif not _finite3(s.cmd, w, i, 2):
            bad = 5
        elif not _finite3(s.tau_raw, w, i, 2):
            bad = 6
        elif not _finite3(s.c_hat, w, i, 2):
            bad = 7
        elif not wp.isfinite(s.vs[w, i]):
            bad = 8
        if bad != 0:
            s.diag[w, 0] = F(bad)
            s.diag[w, 1] = F(i)
            s.diag[w, 2] = F(0.0)
            return bad
    for i in range(n):
        val = F(0.0)
        bad = 0
        pmag = wp.max(wp.abs(s.pose[w, i, 0]), wp.abs(s.pose[w, i, 1]))
        emag = wp.max(wp.abs(s.est_pose[w, i, 0]), wp.abs(s.est_pose[w, i, 1]))
        tmag = wp.max(wp.abs(s.tau_raw[w, i, 0]), wp.abs(s.tau_raw[w, i, 1]))
        if pmag > g.sc[w, LPOS]:
            bad = 9
            val = pmag
        elif emag > g.sc[w, LPOS]:
            bad = 10
            val = emag
        elif wp.abs(s.vel[w, i, 0]) > g.sc[w, LSPD]:
            bad = 11
            val = wp.abs(s.vel[w, i, 0])
        elif wp.abs(s.cmd[w, i, 0]) > g.sc[w, LSPD]:
            bad = 12
            val = wp.abs(s.cmd[w, i, 0])
        elif wp.abs(s.est_vel[w, i, 0]) > g.sc[w, LSPD]:
            bad = 13
            val = wp.abs(s.est_vel[w, i, 0])
        elif tmag > g.sc[w, LTRQ]:
            bad = 14
            val = tmag
        if bad != 0:
            s.diag[w, 0] = F(bad)
            s.diag[w, 1] = F(i)
            s.diag[w, 2] = val
            return bad
    return 0


@wp.kernel
def _control(
    g: BatchGains,
    s: BatchState,
    N: int,
    L_pose: wp.array2d(dtype=F),  # (N + 1, 3) the leader, shared by all worlds
    L_vel: wp.array2d(dtype=F),  # (N + 1, 2)
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    xmat: wp.array2d(dtype=wp.mat33),
    qadr: wp.array(dtype=int),
    dadr: wp.array(dtype=int),
    base: wp.array(dtype=int),
    act: wp.array2d(dtype=int),
    cscale: wp.array2d(dtype=F),  # (n, 2) ctrl per N·m (1: torque motor; DC driver's input, design §8.2)
    axle: wp.array2d(dtype=F),  # (n, 3) reference point in the base frame
    wdof: wp.array2d(dtype=int),  # (n, 2) qvel addresses of the [left, right] wheel joints
    wsign: wp.array2d(dtype=F),  # (n, 2) ±1: sign · qvel is the forward wheel rate
    wrad: wp.array(dtype=F),  # (n,) wheel radius, m
    htrack: wp.array(dtype=F),  # (n,) half track, m
    overflow: wp.array(dtype=int),  # (W,) MuJoCo Warp's Data.overflow bits (sticky until reset)
    ctrl: wp.array2d(dtype=float),
    xfrc: wp.array2d(dtype=wp.spatial_vector),
    sensordata: wp.array2d(dtype=float),  # (W, nsensordata) MuJoCo Warp's Data.sensordata
    enc: wp.array2d(dtype=int),  # (n, 2) sensordata addresses of the [left, right] wheel encoders
    osign: wp.array2d(dtype=F),  # (n, 2) ±1: forward wheel direction of each encoder
    cpr: wp.array(dtype=F),  # (n,) encoder counts per revolution
    pf: PlantFaults,  # actuator faults and pushes (faults.py), per world
    f: CommFaults,  # network and sensor faults (faults.Faults.comm, .sense)
):
    """World ``w``: observe; at ``k = 0`` reset the stack (``kernel.reset_state``) and, with the
    world's ``odometry`` flag, the dead reckoning at the true pose (``mujoco_kernels.odometry_reset``);
    for ``k < N`` give the controller its measurement (the truth, or ``odometry_read``: the
    odometry's pose and ``[Δs, Δθ]/dt``; design §8.3; metrics, guards, the formation error and the
    watches stay on the truth) with the world's sensor noise (``faults.Faults.sense``), the network
    of step ``k`` (:func:`_comm`, ``faults.Faults.comm``: link weights, held or delayed values),
    run control step ``k`` (``kernel.control_step``), the metrics and guards
    (``engine.accumulate``/``check``) and apply its torques (``ctrl = cscale · τ``) and ``d(k dt)``
    to the plant (``mujoco_kernels.apply_inputs``); then ``k += 1``. The command derivative is
    the world's ``deriv`` code (``kernel.DERIV_*``): filter, backward difference or analytic. With
    the world's ``leader_frame`` flag the offsets are in the leader's frame (design §4): the command
    step tracks ``slot_reference`` and the formation error rotates them (``formation_offset``).
    Plant faults (``faults.Faults.step``, the world's rows in ``pf``): ``faults.actuator`` scales the
    limit of the stack's own saturation when ``actuator_known``, and, while any follower's limit is
    reduced, clips every wheel torque reaching the plant to its follower's reduced limit (``s.tau``
    stays as commanded, as the CPU's stack state); ``faults.push`` adds the acting push's force and
    yaw torque to the disturbance's ``xfrc_applied`` (``MujocoPlant._apply_push``)."""
    w = wp.tid()
    k = s.k[w]
    n = s.pose.shape[1]
    dt = g.sc[w, DT]
    zero = F(0.0)
    # ---- MuJoCo Warp dropped contacts or constraint rows in the last period: stop this world
    # (the CPU loop stops on MuJoCo's warnings: engine.PLANT_FAILED), never silently
    if k >= 1 and s.status[w] == 0 and (overflow[w] & CAPACITY) != 0:
        s.status[w] = ST_CAP
        s.diag[w, 0] = F(overflow[w] & CAPACITY)
        s.diag[w, 1] = F(-1.0)
        s.diag[w, 2] = F(k) * dt  # the end of the period that overflowed
        s.k_done[w] = k - 1
    # ---- observe (mujoco_kernels.observe)
    for i in range(n):
        qa = qadr[i]
        qb = dadr[i]
        x, y, th, v, om, up = planar_state(
            F(qpos[w, qa]),
            F(qpos[w, qa + 1]),
            F(qpos[w, qa + 3]),
            F(qpos[w, qa + 4]),
            F(qpos[w, qa + 5]),
            F(qpos[w, qa + 6]),
            F(qvel[w, qb]),
            F(qvel[w, qb + 1]),
            F(qvel[w, qb + 2]),
            F(qvel[w, qb + 3]),
            F(qvel[w, qb + 4]),
            F(qvel[w, qb + 5]),
            axle[i, 0],
            axle[i, 1],
            axle[i, 2],
        )
        s.pose[w, i, 0] = x
        s.pose[w, i, 1] = y
        s.pose[w, i, 2] = th
        s.vel[w, i, 0] = v
        s.vel[w, i, 1] = om
        # mujoco_kernels.watch_tilt and watch_slip after each plant step (k ≥ 1) until the loop stops
        if k >= 1 and s.status[w] == 0:
            if s.tip_step[w, i] < 0 and up < g.sc[w, TILT]:
                s.tip_step[w, i] = k
            worst = F(0.0)
            for c in range(2):
                sl = slip_ratio(
                    F(qvel[w, wdof[i, c]]) * wsign[i, c],
                    wrad[i],
                    v,
                    om,
                    F(2 * c - 1) * htrack[i],
                    g.sc[w, SLIPFLOOR],
                )
                worst = wp.max(worst, sl)
            if worst > g.sc[w, SLIPMAX]:
                s.slip_run[w, i] = s.slip_run[w, i] + 1
                if s.slip_run[w, i] >= int(g.sc[w, SLIPNEED]) and s.slip_step[w, i] < 0:
                    s.slip_step[w, i] = k
            else:
                s.slip_run[w, i] = 0
    kl = wp.min(k, N)
    lframe = g.sc[w, LFRAME] != zero
    for i in range(n):  # formation error against the true leader at this observation (engine.record)
        ox, oy = formation_offset(g.offsets[w, i, 0], g.offsets[w, i, 1], L_pose[kl, 2], lframe)
        dx = s.pose[w, i, 0] - (L_pose[kl, 0] - ox)
        dy = s.pose[w, i, 1] - (L_pose[kl, 1] - oy)
        s.ferr[w, i] = wp.sqrt(dx * dx + dy * dy)
    # ---- reset (kernel.reset_state)
    if k == 0:
        for i in range(n):
            s.est_pose[w, i, 0] = g.est0[w, i, 0]
            s.est_pose[w, i, 1] = g.est0[w, i, 1]
            s.est_pose[w, i, 2] = wrap(g.est0[w, i, 2])
            for c in range(2):
                s.est_vel[w, i, c] = zero
                s.z_hat[w, i, c] = s.vel[w, i, c]
                s.e_int[w, i, c] = zero
                s.c_hat[w, i, c] = wp.min(wp.max(g.c_hat0[w, i, c], g.c_min[w, i, c]), g.c_max[w, i, c])
                s.d_hat[w, i, c] = zero
                s.fy[w, i, c] = zero
                s.fdy[w, i, c] = zero
                s.cmd[w, i, c] = zero
                s.dcmd[w, i, c] = zero
                s.tau[w, i, c] = zero
                s.tau_raw[w, i, c] = zero
                s.tau_body[w, i, c] = zero
            for c in range(3):
                s.err[w, i, c] = zero
            s.vs[w, i] = zero
            s.saturated[w, i] = 0
            s.verr[w, i] = zero
            s.nsat[w, i] = zero
            s.vmax[w, i] = zero
            s.taumax[w, i] = zero
            s.tauraw_max[w, i] = zero
            s.fsq[w, i] = zero
            s.fe0[w, i] = zero
            s.spin_ok[w, i] = zero
            s.tip_step[w, i] = -1
            s.slip_run[w, i] = 0
            s.slip_step[w, i] = -1
        s.nrow[w] = 0
        s.first[w] = 1
        s.status[w] = 0
        s.k_done[w] = 0
        if g.sc[w, ODO] != zero:  # mujoco_kernels.odometry_reset: the true pose, the sensordata of mjw.forward
            s.odo_count[w] = 0
            for i in range(n):
                for c in range(3):
                    s.odo_pose[w, i, c] = s.pose[w, i, c]
                for c in range(2):
                    s.odo_q[w, i, c] = encoder_angle(osign[i, c] * F(sensordata[w, enc[i, c]]), cpr[i])
                s.odo_dist[w, i] = zero
                s.odo_turn[w, i] = zero
    running = s.status[w] == 0 and k < N
    if running:
        # ---- the measurement (sim.simulate's measure(): plant.measurement, mujoco_kernels.odometry_read)
        for i in range(n):
            if g.sc[w, ODO] != zero:
                for c in range(3):
                    s.mpose[w, i, c] = s.odo_pose[w, i, c]
                s.mvel[w, i, 0] = s.odo_dist[w, i] / dt
                s.mvel[w, i, 1] = s.odo_turn[w, i] / dt
                s.odo_dist[w, i] = zero
                s.odo_turn[w, i] = zero
            else:
                for c in range(3):
                    s.mpose[w, i, c] = s.pose[w, i, c]
                for c in range(2):
                    s.mvel[w, i, c] = s.vel[w, i, c]
        # ---- faults.Faults.sense: Gaussian noise on what the controller measures, inside the window
        tk = F(k) * dt
        if f.sc[w, FNOISE] != zero and tk >= f.sc[w, FW0] and tk < f.sc[w, FW1]:
            seed = f.sc[w, FSEED]
            for i in range(n):
                for c in range(3):
                    s.mpose[w, i, c] = noisy_reading(
                        s.mpose[w, i, c], f.sc[w, FNP0 + c], seed, F(NPOSE0 + 3 * i + c), F(k)
                    )
                s.mpose[w, i, 2] = wrap(s.mpose[w, i, 2])
                for c in range(2):
                    s.mvel[w, i, c] = noisy_reading(
                        s.mvel[w, i, c], f.sc[w, FNV0 + c], seed, F(NVEL0 + 2 * i + c), F(k)
                    )
        # ---- learner_update
        if g.sc[w, LEARN] != zero and s.first[w] == 0:
            for i in range(n):
                for c in range(2):  # a (k5a, kda), then b (k5b, kdb): adjacent columns of SCALARS
                    zn, en, cn, dn = learner_step(
                        s.z_hat[w, i, c],
                        s.e_int[w, i, c],
                        s.c_hat[w, i, c],
                        s.d_hat[w, i, c],
                        s.tau_body[w, i, c],
                        s.mvel[w, i, c],
                        g.k4[w, i, c],
                        g.sc[w, K5A + c],
                        g.sc[w, KDA + c],
                        g.c_min[w, i, c],
                        g.c_max[w, i, c],
                        dt,
                    )
                    s.z_hat[w, i, c] = zn
                    s.e_int[w, i, c] = en
                    s.c_hat[w, i, c] = cn
                    s.d_hat[w, i, c] = dn
        # ---- the network (faults.Faults.comm): link weights, and with loss or delay the values received
        comm = f.sc[w, FCOMM] != zero
        recv = comm and f.sc[w, FRECV] != zero
        if comm:
            _comm(f, g, s, w, k, tk, L_pose, L_vel)
        # the leader's state as received (held or delayed with recv; else the true one now)
        lp0 = L_pose[k, 0]
        lp1 = L_pose[k, 1]
        lp2 = L_pose[k, 2]
        lv0 = L_vel[k, 0]
        lv1 = L_vel[k, 1]
        if recv:
            lp0 = f.hlp[w, 0]
            lp1 = f.hlp[w, 1]
            lp2 = f.hlp[w, 2]
            lv0 = f.hlv[w, 0]
            lv1 = f.hlv[w, 1]
        # ---- estimator_consensus: p_err, v_err of this step, leader term included (weights 1 and the
        # neighbours' current estimates on a perfect network; else Comm's weights and received values)
        for i in range(n):
            for c in range(3):
                s.p_err[w, i, c] = zero
            for c in range(2):
                s.v_err[w, i, c] = zero
        for e in range(g.src.shape[0]):
            i = g.src[e]
            j = g.dst[e]
            we = F(1.0)
            if comm:
                we = f.ew[w, e]
            for c in range(3):
                xj = s.est_pose[w, j, c]
                if recv:
                    xj = f.hp[w, e, c]
                d = s.est_pose[w, i, c] - xj
                if c == 2:
                    d = wrap(d)
                s.p_err[w, i, c] = s.p_err[w, i, c] + d * we
            for c in range(2):
                xj = s.est_vel[w, j, c]
                if recv:
                    xj = f.hv[w, e, c]
                s.v_err[w, i, c] = s.v_err[w, i, c] + (s.est_vel[w, i, c] - xj) * we
        for i in range(n):
            ai = g.lacc[w, i]
            if comm:
                ai = ai * f.lw[w, i]
            s.p_err[w, i, 0] = ai * (s.est_pose[w, i, 0] - lp0) + s.p_err[w, i, 0]
            s.p_err[w, i, 1] = ai * (s.est_pose[w, i, 1] - lp1) + s.p_err[w, i, 1]
            s.p_err[w, i, 2] = ai * wrap(s.est_pose[w, i, 2] - lp2) + s.p_err[w, i, 2]
            s.v_err[w, i, 0] = ai * (s.est_vel[w, i, 0] - lv0) + s.v_err[w, i, 0]
            s.v_err[w, i, 1] = ai * (s.est_vel[w, i, 1] - lv1) + s.v_err[w, i, 1]
            # the estimator's rates from them, once (kernel.estimator_consensus): the analytic
            # derivative and the Euler step below both read them
            q0, q1, q2, q3, q4 = estimator_rates(
                s.est_pose[w, i, 2],
                s.est_vel[w, i, 0],
                s.est_vel[w, i, 1],
                s.p_err[w, i, 0],
                s.p_err[w, i, 1],
                s.p_err[w, i, 2],
                s.v_err[w, i, 0],
                s.v_err[w, i, 1],
                g.sc[w, KX],
                g.sc[w, KY],
                g.sc[w, KTH],
                g.sc[w, KA0],
                g.sc[w, KA1],
                g.sc[w, KB0],
                g.sc[w, KB1],
                g.sc[w, EPHI0],
                g.sc[w, EPHI1],
            )
            s.est_rate[w, i, 0] = q0
            s.est_rate[w, i, 1] = q1
            s.est_rate[w, i, 2] = q2
            s.est_rate[w, i, 3] = q3
            s.est_rate[w, i, 4] = q4
        # ---- command_and_torques
        first = s.first[w] == 1
        steer = g.sc[w, STEER] != zero
        bio = g.sc[w, BIO] != zero
        deriv = g.sc[w, DERIV]
        for i in range(n):
            # the paper: world-frame offsets, the slot moves with the leader's velocity
            v_ref = s.est_vel[w, i, 0]
            w_ref = s.est_vel[w, i, 1]
            e0 = zero
            e1 = zero
            e2 = zero
            if lframe:  # the slot's own pose and velocity (design §4)
                xs, ys, ths, v_ref, w_ref = slot_reference(
                    s.est_pose[w, i, 0],
                    s.est_pose[w, i, 1],
                    s.est_pose[w, i, 2],
                    s.est_vel[w, i, 0],
                    s.est_vel[w, i, 1],
                    g.offsets[w, i, 0],
                    g.offsets[w, i, 1],
                )
                e0, e1, e2 = tracking_error(
                    xs, ys, ths, s.mpose[w, i, 0], s.mpose[w, i, 1], s.mpose[w, i, 2], zero, zero
                )
            else:
                e0, e1, e2 = tracking_error(
                    s.est_pose[w, i, 0],
                    s.est_pose[w, i, 1],
                    s.est_pose[w, i, 2],
                    s.mpose[w, i, 0],
                    s.mpose[w, i, 1],
                    s.mpose[w, i, 2],
                    g.offsets[w, i, 0],
                    g.offsets[w, i, 1],
                )
            s.err[w, i, 0] = e0
            s.err[w, i, 1] = e1
            s.err[w, i, 2] = e2
            u = e0
            if bio:
                u = s.vs[w, i]
            vc, wc = velocity_command(e1, e2, u, v_ref, w_ref, g.sc[w, K1], g.sc[w, K2], g.sc[w, K3])
            s.cmd[w, i, 0] = vc
            s.cmd[w, i, 1] = wc
            if deriv == DERIV_A:  # chain rule through the controller's own dynamics (design §6)
                dpx = s.est_rate[w, i, 0]  # this step's estimator rates (the consensus above)
                dpy = s.est_rate[w, i, 1]
                dpth = s.est_rate[w, i, 2]
                dv_ir = s.est_rate[w, i, 3]
                dw_ir = s.est_rate[w, i, 4]
                ch = wp.cos(s.mpose[w, i, 2])
                sh = wp.sin(s.mpose[w, i, 2])
                dex, dey, deth = error_rate(
                    e0,
                    e1,
                    s.mvel[w, i, 0],
                    s.mvel[w, i, 1],
                    s.est_vel[w, i, 0],
                    dpth,
                    e2,
                    ch * dpx + sh * dpy,
                    -sh * dpx + ch * dpy,
                )
                du = dex
                if bio:
                    du = neuron_rate(s.vs[w, i], e0, g.sc[w, A_], g.sc[w, B_], g.sc[w, D_])
                dvc, dwc = command_rate(
                    e1, e2, s.est_vel[w, i, 0], dv_ir, dw_ir, dey, deth, du, g.sc[w, K1], g.sc[w, K2], g.sc[w, K3]
                )
                s.dcmd[w, i, 0] = dvc
                s.dcmd[w, i, 1] = dwc
            else:
                for c in range(2):  # filter or backward difference (design §6)
                    if first:
                        s.fy[w, i, c] = s.cmd[w, i, c]
                        s.fdy[w, i, c] = zero
                    if deriv == DERIV_D:
                        s.dcmd[w, i, c] = backward_difference(s.cmd[w, i, c], s.fy[w, i, c], dt)
                        s.fy[w, i, c] = s.cmd[w, i, c]
                    else:
                        y, dy, dd = filter_derivative(
                            s.fy[w, i, c],
                            s.fdy[w, i, c],
                            s.cmd[w, i, c],
                            g.sc[w, F00],
                            g.sc[w, F01],
                            g.sc[w, F10],
                            g.sc[w, F11],
                            g.sc[w, G0],
                            g.sc[w, G1],
                            dt,
                        )
                        s.fy[w, i, c] = y
                        s.fdy[w, i, c] = dy
                        s.dcmd[w, i, c] = dd
            r0, r1 = sliding_mode(
                vc,
                wc,
                s.dcmd[w, i, 0],
                s.dcmd[w, i, 1],
                s.mvel[w, i, 0],
                s.mvel[w, i, 1],
                s.c_hat[w, i, 0],
                s.c_hat[w, i, 1],
                g.sc[w, CA],
                g.sc[w, CB],
                g.sc[w, TPHI],
            )
            s.tau_raw[w, i, 0] = r0
            s.tau_raw[w, i, 1] = r1
            L = g.lim[w, i]
            if pf.act_known[w] != 0:  # faults.actuator_known: the stack's own limit (ControlStack.set_tau_max)
                L = L * _act_scale(pf, w, i, k)
            sat = 0
            if wp.abs(r0) > L or wp.abs(r1) > L:
                sat = 1
            s.saturated[w, i] = sat
            t0, t1 = saturate(r0, r1, L, steer)
            s.tau[w, i, 0] = t0
            s.tau[w, i, 1] = t1
            s.tau_body[w, i, 0] = t0 + t1
            s.tau_body[w, i, 1] = t1 - t0
        s.first[w] = 0
        # ---- estimator_advance: one Euler step with this step's rates; the neuron (eq. 32)
        for i in range(n):
            px, py, pth, v, om = estimator_euler(
                s.est_pose[w, i, 0],
                s.est_pose[w, i, 1],
                s.est_pose[w, i, 2],
                s.est_vel[w, i, 0],
                s.est_vel[w, i, 1],
                s.est_rate[w, i, 0],
                s.est_rate[w, i, 1],
                s.est_rate[w, i, 2],
                s.est_rate[w, i, 3],
                s.est_rate[w, i, 4],
                dt,
            )
            s.est_pose[w, i, 0] = px
            s.est_pose[w, i, 1] = py
            s.est_pose[w, i, 2] = pth
            s.est_vel[w, i, 0] = v
            s.est_vel[w, i, 1] = om
            if bio:
                s.vs[w, i] = neuron_step(s.vs[w, i], s.err[w, i, 0], g.sc[w, A_], g.sc[w, B_], g.sc[w, D_], dt)
        # ---- engine.accumulate (metrics) and engine.check (guards)
        for i in range(n):
            s.verr[w, i] = (
                s.verr[w, i] + wp.abs(s.cmd[w, i, 0] - s.vel[w, i, 0]) + wp.abs(s.cmd[w, i, 1] - s.vel[w, i, 1])
            )
            if s.saturated[w, i] != 0:
                s.nsat[w, i] = s.nsat[w, i] + F(1.0)
            s.vmax[w, i] = wp.max(s.vmax[w, i], wp.abs(s.cmd[w, i, 0]))
            s.taumax[w, i] = wp.max(s.taumax[w, i], wp.max(wp.abs(s.tau[w, i, 0]), wp.abs(s.tau[w, i, 1])))
            s.tauraw_max[w, i] = wp.max(
                s.tauraw_max[w, i], wp.max(wp.abs(s.tau_raw[w, i, 0]), wp.abs(s.tau_raw[w, i, 1]))
            )
        s.k_done[w] = k
        if _check(g, s, w, n) != 0:
            s.status[w] = 1  # GUARD_FAILED
            running = False
        elif k % int(g.sc[w, STRIDE]) == 0:  # engine.record's row (formation error, vel) for the summary
            for i in range(n):
                s.fsq[w, i] = s.fsq[w, i] + s.ferr[w, i] * s.ferr[w, i]
                if k == 0:
                    s.fe0[w, i] = s.ferr[w, i]
                if F(k) * dt >= g.sc[w, TSPIN] and wp.abs(s.vel[w, i, 1]) <= SPIN:
                    s.spin_ok[w, i] = s.spin_ok[w, i] + F(1.0)
            s.nrow[w] = s.nrow[w] + 1
    # ---- apply_inputs: this step's torques and d(k dt), held over the period (zero once stopped)
    d0 = zero
    d1 = zero
    if running and g.sc[w, USED] != zero:
        t = F(k) * dt
        d0 = harmonic(g.sc[w, DD0], g.sc[w, DD0 + 1], g.sc[w, DD0 + 2], g.sc[w, DD0 + 3], t)
        d1 = harmonic(g.sc[w, DE0], g.sc[w, DE0 + 1], g.sc[w, DE0 + 2], g.sc[w, DE0 + 3], t)
    # faults.actuator (Faults.step): while any follower's limit is reduced, every wheel's torque
    # reaching the plant is clipped to its follower's limit × scale (s.tau stays as commanded: the
    # log, the metrics and, unless a DC motor feeds back what it delivered, the learner see that)
    weak = wp.int32(0)  # typed: mutated in a dynamic loop
    pushed = pf.push_i[w, 0] >= 0  # this world has pushes: xfrc_applied is written with them
    if running:
        for r in range(pf.act_i.shape[1]):
            if pf.act_i[w, r] >= 0 and pf.act_k0[w, r] <= k and k < pf.act_k1[w, r] and pf.act_s[w, r] < F(1.0):
                weak = 1
    for i in range(n):
        t0 = zero
        t1 = zero
        if running:
            t0 = s.tau[w, i, 0]
            t1 = s.tau[w, i, 1]
            if weak != 0:
                Lf = g.lim[w, i] * _act_scale(pf, w, i, k)
                t0 = clip(t0, -Lf, Lf)
                t1 = clip(t1, -Lf, Lf)
        ctrl[w, act[i, 0]] = wp.float32(cscale[i, 0] * t0)
        ctrl[w, act[i, 1]] = wp.float32(cscale[i, 1] * t1)
        if g.sc[w, USED] != zero or pushed:
            b = base[i]
            R = xmat[w, b]
            fa = g.m_eff[w, i] * d0
            fx = F(R[0, 0]) * fa
            fy = F(R[1, 0]) * fa
            tz = g.i_eff[w, i] * d1
            if running:  # faults.push (MujocoPlant._apply_push): added to the disturbance
                p = _push_row(pf, w, i, k)
                if p >= 0:
                    fx = fx + pf.push_w[w, p, 0]
                    fy = fy + pf.push_w[w, p, 1]
                    tz = tz + pf.push_w[w, p, 2]
            xfrc[w, b] = wp.spatial_vector(wp.float32(fx), wp.float32(fy), 0.0, 0.0, 0.0, wp.float32(tz))
    if running and k == N - 1:
        s.k_done[w] = N
    s.k[w] = k + 1


@wp.kernel
def _delivered(
    force: wp.array2d(dtype=float),  # (W, nu) MuJoCo Warp's Data.actuator_force of the step just taken
    act: wp.array2d(dtype=int),  # (n, 2) actuator ids of the [left, right] wheel motors
    to_wheel: wp.array2d(dtype=F),  # (n, 2) forward wheel torque per unit actuator force (gear × sign; 0: not fed)
    feed: wp.array(dtype=int),  # (n,) 1: the robot's learner is fed the delivered torque (DC motors)
    n_sub: int,  # physics steps per control period
    last: int,  # 1 after the period's last physics step
    dacc: wp.array3d(dtype=F),  # (W, n, 2) delivered [τ_L, τ_R] summed over the period so far, N·m
    tau_body: wp.array3d(dtype=F),  # (W, n, 2) the learner's input [τ_a, τ_b], N·m
):
    """DC motors (design §8.2), after each ``mjw.step`` of world ``w``: add each wheel motor's
    delivered torque ``to_wheel · actuator_force`` to ``dacc`` (``mujoco_kernels.delivered_add``);
    after the period's ``last`` step write the period mean as ``[τ_L + τ_R, τ_R − τ_L]`` into
    ``tau_body`` of the fed robots and clear ``dacc`` (``mujoco_kernels.delivered_feed``), so the
    next ``_control`` launch's learner sees the delivered, not the commanded, torque: the CPU
    loop's order (physics steps, feed, observe, control step). Loop glue only, no equation."""
    w = wp.tid()
    for i in range(act.shape[0]):
        for c in range(2):
            dacc[w, i, c] = dacc[w, i, c] + to_wheel[i, c] * F(force[w, act[i, c]])
        if last != 0:
            if feed[i] != 0:
                tl = dacc[w, i, 0] / F(n_sub)
                tr = dacc[w, i, 1] / F(n_sub)
                tau_body[w, i, 0] = tl + tr  # τ_a = τ_L + τ_R
                tau_body[w, i, 1] = tr - tl  # τ_b = τ_R − τ_L (design §5)
            dacc[w, i, 0] = F(0.0)
            dacc[w, i, 1] = F(0.0)


#: MuJoCo Warp ``Model`` fields a payload event changes (``MujocoPlant.add_payload``: the base body's
#: inertial, then ``mj_setConst``'s derived constants; measured against C MuJoCo's ``mj_setConst`` on
#: the paper scene: these, plus ``dof_M0`` and ``light_poscom0`` which MuJoCo Warp does not hold or
#: uses for rendering only). With events in a batch they get a leading world axis
#: (``mjw.put_model(..., batch_sizes=...)``) and :func:`_events` writes them per world.
EVENT_FIELDS = (
    "body_mass",
    "body_ipos",
    "body_iquat",
    "body_inertia",
    "body_subtreemass",
    "body_invweight0",
    "dof_invweight0",
    "actuator_acc0",
)


@wp.kernel
def _events(
    k: wp.array(dtype=int),  # (W,) the control step (period) about to be computed and stepped
    status: wp.array(dtype=int),  # (W,) BatchState.status: a stopped world takes no more events
    N: int,  # control steps of the run
    ev_step: wp.array2d(dtype=int),  # (W, E) each world's event steps, ascending, padded with -1
    t_mass: wp.array3d(dtype=float),  # (W, E + 1, nbody) row 0: initial model; row e + 1: after events 0..e
    t_ipos: wp.array3d(dtype=wp.vec3),
    t_iquat: wp.array3d(dtype=wp.quat),
    t_inertia: wp.array3d(dtype=wp.vec3),
    t_subtree: wp.array3d(dtype=float),
    t_biw: wp.array3d(dtype=wp.vec2),
    t_diw: wp.array3d(dtype=float),  # (W, E + 1, nv)
    t_acc0: wp.array3d(dtype=float),  # (W, E + 1, nu)
    t_meff: wp.array3d(dtype=F),  # (W, E + 1, n) kg
    t_ieff: wp.array3d(dtype=F),  # (W, E + 1, n) kg·m²
    body_mass: wp.array2d(dtype=float),  # (W, nbody) MuJoCo Warp's batched Model fields (EVENT_FIELDS)
    body_ipos: wp.array2d(dtype=wp.vec3),
    body_iquat: wp.array2d(dtype=wp.quat),
    body_inertia: wp.array2d(dtype=wp.vec3),
    body_subtreemass: wp.array2d(dtype=float),
    body_invweight0: wp.array2d(dtype=wp.vec2),
    dof_invweight0: wp.array2d(dtype=float),
    actuator_acc0: wp.array2d(dtype=float),
    m_eff: wp.array2d(dtype=F),  # (W, n) BatchGains.m_eff, i_eff (eq. 34's force scale)
    i_eff: wp.array2d(dtype=F),
):
    """Timed payload events (``sim.EventQueue``), before control step ``k`` of world ``w``: at
    ``k = 0`` the world's initial model, then at the step of each of its events (``sim.first_step_at``)
    the model after it: the precomputed rows (C MuJoCo's ``add_payload`` + ``mj_setConst``) copied
    into the batched ``Model`` fields and the chassis' effective mass and inertia. As on the CPU the
    event lands after control step ``k`` is computed from the observation and before its inputs
    are applied (``_control`` writes ``xfrc = m_eff · d0`` next) and the period's physics steps;
    several events at one step all land (the row is cumulative); none once the world stopped or
    at ``k ≥ N``. Loop glue only, no equation."""
    w = wp.tid()
    kw = k[w]
    if kw >= N or (kw > 0 and status[w] != 0):
        return
    row = -1
    if kw == 0:
        row = 0
    for e in range(ev_step.shape[1]):
        if ev_step[w, e] == kw:
            row = e + 1
    if row < 0:
        return
    for b in range(body_mass.shape[1]):
        body_mass[w, b] = t_mass[w, row, b]
        body_ipos[w, b] = t_ipos[w, row, b]
        body_iquat[w, b] = t_iquat[w, row, b]
        body_inertia[w, b] = t_inertia[w, row, b]
        body_subtreemass[w, b] = t_subtree[w, row, b]
        body_invweight0[w, b] = t_biw[w, row, b]
    for j in range(dof_invweight0.shape[1]):
        dof_invweight0[w, j] = t_diw[w, row, j]
    for a in range(actuator_acc0.shape[1]):
        actuator_acc0[w, a] = t_acc0[w, row, a]
    for i in range(m_eff.shape[1]):
        m_eff[w, i] = t_meff[w, row, i]
        i_eff[w, i] = t_ieff[w, row, i]


@wp.kernel
def _sense(
    sc: wp.array2d(dtype=F),  # (W, len(SCALARS)) BatchGains.sc: the odometry flag, noise seed, gyro bias, sigma
    sensordata: wp.array2d(dtype=float),  # (W, nsensordata) MuJoCo Warp's Data.sensordata of the step just taken
    enc: wp.array2d(dtype=int),  # (n, 2) sensordata addresses of the [left, right] wheel encoders (jointpos)
    gyro: wp.array(dtype=int),  # (n,) sensordata address of each gyro (3 values, IMU site frame; z used)
    osign: wp.array2d(dtype=F),  # (n, 2) ±1: forward wheel direction
    orad: wp.array(dtype=F),  # (n,) wheel radius, m
    cpr: wp.array(dtype=F),  # (n,) encoder counts per revolution
    every: int,  # physics steps per sensor sample
    ts: F,  # the sensor period, s
    count: wp.array(dtype=int),  # (W,) physics steps since reset
    pose: wp.array3d(dtype=F),  # (W, n, 3) the odometry's [x, y, θ], m, rad
    q: wp.array3d(dtype=F),  # (W, n, 2) last quantised forward wheel angles, rad
    dist: wp.array2d(dtype=F),  # (W, n) distance since the last control step, m
    turn: wp.array2d(dtype=F),  # (W, n) heading change since the last control step, rad
):
    """``mujoco_kernels.sense`` for world ``w`` (with its ``odometry`` flag), after each ``mjw.step``:
    count the step, and every ``every`` steps sample the encoders (``encoder_angle``) and the gyro
    (``gyro_reading``: bias, and noise from the counter hash of ``(seed, robot, sample)``) and
    advance each robot's dead reckoning (``odometry_step``), design §8.3. MuJoCo Warp computes the
    ``jointpos`` and ``gyro`` sensors in the forward pass at the start of ``mjw.step``, as C MuJoCo
    does in ``mj_step``: the reading after a step is the state it started from."""
    w = wp.tid()
    if sc[w, ODO] == F(0.0):
        return
    c = count[w] + 1
    count[w] = c
    if c % every != 0:
        return
    ks = F(c // every)  # the sample's counter, 1, 2, … (mujoco_kernels.sense)
    for i in range(pose.shape[1]):
        ql = encoder_angle(osign[i, 0] * F(sensordata[w, enc[i, 0]]), cpr[i])
        qr = encoder_angle(osign[i, 1] * F(sensordata[w, enc[i, 1]]), cpr[i])
        wz = gyro_reading(F(sensordata[w, gyro[i] + 2]), sc[w, GBIAS], sc[w, GSIGMA], sc[w, OSEED], F(i), ks)
        x, y, th, ds, dth = odometry_step(
            pose[w, i, 0], pose[w, i, 1], pose[w, i, 2], q[w, i, 0], q[w, i, 1], ql, qr, wz, orad[i], ts
        )
        pose[w, i, 0] = x
        pose[w, i, 1] = y
        pose[w, i, 2] = th
        q[w, i, 0] = ql
        q[w, i, 1] = qr
        dist[w, i] = dist[w, i] + ds
        turn[w, i] = turn[w, i] + dth


@wp.kernel
def _record(
    k: wp.array(dtype=int),
    ctrl: wp.array2d(dtype=float),
    xfrc: wp.array2d(dtype=wp.spatial_vector),
    base: wp.array(dtype=int),
    rec_ctrl: wp.array3d(dtype=float),
    rec_xfrc: wp.array3d(dtype=wp.spatial_vector),
):
    """After a ``_control`` launch: the inputs it wrote (for control step ``k − 1``) into the recording."""
    w = wp.tid()
    j = k[w] - 1
    if j < rec_ctrl.shape[0]:
        for a in range(ctrl.shape[1]):
            rec_ctrl[j, w, a] = ctrl[w, a]
        for i in range(base.shape[0]):
            rec_xfrc[j, w, i] = xfrc[w, base[i]]


@wp.kernel
def _replay(
    j: wp.array(dtype=int),
    rec_ctrl: wp.array3d(dtype=float),
    rec_xfrc: wp.array3d(dtype=wp.spatial_vector),
    base: wp.array(dtype=int),
    ctrl: wp.array2d(dtype=float),
    xfrc: wp.array2d(dtype=wp.spatial_vector),
):
    """Before a control period of the physics-alone replay: that period's recorded inputs (counter on the device)."""
    w = wp.tid()
    r = j[w]
    for a in range(ctrl.shape[1]):
        ctrl[w, a] = rec_ctrl[r, w, a]
    for i in range(base.shape[0]):
        xfrc[w, base[i]] = rec_xfrc[r, w, i]
    j[w] = r + 1


# ------------------------------------------------------------------------------ host side
def _check_compatible(scs: Sequence[Scenario]) -> None:
    """All worlds share one composed scene and one leader: say what differs if not."""
    sc0 = scs[0]
    if sc0.plant.kind != "mujoco":
        raise ValueError("the batch engine runs the MuJoCo plant only (plant.kind = 'mujoco')")
    for sc in scs:
        what = unsupported(sc)  # the same list the sweep refuses up front (exit 2): never run it silently
        if what is not None:
            raise ValueError(f"scenario '{sc.name}': {what} is not supported by the batch engine yet")
        for what, a, b in (
            ("plant", sc.plant, sc0.plant),
            ("faults.friction_patch", sc.faults.friction_patch, sc0.faults.friction_patch),  # part of the scene
            ("sim.control_dt", sc.sim.control_dt, sc0.sim.control_dt),
            ("sim.physics_dt", sc.sim.physics_dt, sc0.sim.physics_dt),
            ("sim.duration", sc.sim.duration, sc0.sim.duration),
            ("leader", sc.leader, sc0.leader),
            ("graph", sc.graph, sc0.graph),
            ("n", sc.n, sc0.n),
        ):
            if a != b:
                raise ValueError(
                    f"scenario '{sc.name}': {what} differs from the first world's; the batch engine "
                    "needs one scene, one leader and one graph for all worlds (not supported yet)"
                )


def _yaw_quat(q0: np.ndarray, dth: float) -> np.ndarray:
    """``q_z(dth) ⊗ q0`` (w, x, y, z)."""
    c, s = math.cos(dth / 2), math.sin(dth / 2)
    w0, x0, y0, z0 = q0
    return np.array([c * w0 - s * z0, c * x0 - s * y0, c * y0 + s * x0, c * z0 + s * w0])


def event_tables(sc0: Scenario, scs: Sequence[Scenario], N: int, dt: float) -> dict[str, np.ndarray] | None:
    """Each world's model after each of its payload events, from C MuJoCo (None: no world has one).

    One CPU plant of the shared scene (``sim.make_plant(sc0)``) replays every world's events in
    ``sim.EventQueue``'s order (sorted by time, stable): ``add_payload`` (the base body's inertial,
    then ``mj_setConst``) and, after each, the :data:`EVENT_FIELDS` and ``_m_eff``, ``_i_eff``,
    ``c_true()``; ``reset()`` restores the nominal model between worlds (equal payload sequences
    are computed once). Returns, with ``W`` worlds and ``E`` the most events of a world:
    ``step`` (W, E) int, each event's control step (``sim.first_step_at``), ascending, padded with
    −1; per field of :data:`EVENT_FIELDS` an array (W, E + 1, *the field's C shape*): row 0 the
    initial model, row ``e + 1`` the model after events ``0..e`` (padding rows repeat the last);
    ``m_eff`` (W, E + 1, n) kg, ``i_eff`` (W, E + 1, n) kg·m², ``c_true`` (W, E + 1, n, 2)."""
    from ..sim import first_step_at, make_plant

    if not any(sc.events for sc in scs):
        return None
    plant = make_plant(sc0)
    m = plant.model
    W, E = len(scs), max(len(sc.events) for sc in scs)

    def snap() -> dict[str, np.ndarray]:
        out = {f: np.array(getattr(m, f), dtype=float) for f in EVENT_FIELDS}
        out.update(m_eff=plant._m_eff.copy(), i_eff=plant._i_eff.copy(), c_true=plant.c_true())
        return out

    first = snap()
    tab = {k: np.empty((W, E + 1, *v.shape)) for k, v in first.items()}
    tab["step"] = np.full((W, E), -1, dtype=np.int32)
    cache: dict[tuple, dict[str, np.ndarray]] = {(): first}
    cur: tuple = ()  # the events the plant's model holds now
    for w, sc in enumerate(scs):
        evs = sorted(sc.events, key=lambda e: e.time)  # sim.EventQueue's order
        rows = [first]
        for e in range(len(evs)):
            key = tuple((ev.follower, ev.mass, ev.inertia) for ev in evs[: e + 1])
            if key not in cache:
                if cur != key[:-1]:  # else the plant holds this prefix's model already
                    plant.reset()  # the nominal model
                    cur = ()
                for ev in evs[len(cur) : e + 1]:
                    if ev.kind != "payload":
                        raise ValueError(f"scenario '{sc.name}': event kind '{ev.kind}' is not supported")
                    plant.add_payload(ev.follower - 1, ev.mass, ev.inertia)
                cur = key
                cache[key] = snap()
            rows.append(cache[key])
            tab["step"][w, e] = first_step_at(evs[e].time, dt)
        rows += [rows[-1]] * (E + 1 - len(rows))
        for k in first:
            tab[k][w] = [r[k] for r in rows]
    return tab


def _first_step(ok: np.ndarray) -> int:
    """The first index where ``ok`` (monotone, False then True) holds; ``len(ok)`` if none."""
    return int(np.argmax(ok)) if ok.any() else len(ok)


def plant_fault_tables(scs: Sequence[Scenario], N: int, dt: float) -> dict[str, np.ndarray]:
    """Each world's ``faults.actuator`` and ``faults.push`` rows as :class:`PlantFaults`' padded tables.

    Row times become control steps by ``Faults.step``'s own float64 comparisons at ``t = k dt``
    (``k`` = 0..N): an actuator row acts at the steps with ``t_start ≤ t < t_end``; a push row
    starts at the first step with ``t ≤ t_k + 1e-12`` (``Faults.step``) and acts while
    ``t + duration > t_k + 1e-12`` (``MujocoPlant._apply_push``). Push rows are sorted by ``t``
    (stable, as ``Faults``) so that the last started row of a follower is the one acting. Steps
    ``N + 1`` mean never. Returns ``act_i`` (W, Ra) int32, ``act_k0``, ``act_k1`` (W, Ra) int32,
    ``act_s`` (W, Ra), ``act_known`` (W,) int32, ``push_i``, ``push_k0``, ``push_k1`` (W, Rp) int32,
    ``push_w`` (W, Rp, 3) [fx N, fy N, tz N·m]; ``Ra``, ``Rp`` ≥ 1, padding rows with follower −1."""
    W = len(scs)
    tk = np.arange(N + 1) * dt  # t = k * dt, as sim.simulate passes it
    Ra = max(1, *(len(sc.faults.actuator) for sc in scs))
    Rp = max(1, *(len(sc.faults.push) for sc in scs))
    never = N + 1
    out = {
        "act_i": np.full((W, Ra), -1, dtype=np.int32),
        "act_k0": np.full((W, Ra), never, dtype=np.int32),
        "act_k1": np.full((W, Ra), never, dtype=np.int32),
        "act_s": np.ones((W, Ra)),
        "act_known": np.zeros(W, dtype=np.int32),
        "push_i": np.full((W, Rp), -1, dtype=np.int32),
        "push_k0": np.full((W, Rp), never, dtype=np.int32),
        "push_k1": np.full((W, Rp), never, dtype=np.int32),
        "push_w": np.zeros((W, Rp, 3)),
    }
    for w, sc in enumerate(scs):
        fc = sc.faults
        out["act_known"][w] = int(bool(fc.actuator_known))
        for r, (i, t0, t1, scale) in enumerate(fc.actuator):
            out["act_i"][w, r] = int(i) - 1
            out["act_k0"][w, r] = _first_step(tk >= t0)
            out["act_k1"][w, r] = _first_step(~(tk < t1))
            out["act_s"][w, r] = float(scale)
        for r, (i, t0, dur, fx, fy, tz) in enumerate(sorted(fc.push, key=lambda row: row[1])):
            out["push_i"][w, r] = int(i) - 1
            out["push_k0"][w, r] = _first_step(t0 <= tk + 1e-12)
            out["push_k1"][w, r] = _first_step(~(t0 + dur > tk + 1e-12))
            out["push_w"][w, r] = (fx, fy, tz)
    return out


class BatchRun:
    """One batch of worlds on a device: built once, :meth:`run` steps them all.

    Holds the MuJoCo Warp model/data, the per-world gains and state (device arrays), the
    leader trajectory, and the launch arguments of :func:`_control`. ``probe`` (default): refuse a
    scene whose physics MuJoCo Warp does not model as C MuJoCo does (:func:`check_physics`, once per
    scene and device in a process). ValueError for anything the batch engine does not run.
    """

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        device: str = "cpu",
        *,
        nconmax: int | None = None,
        njmax: int | None = None,
        probe: bool = True,
    ) -> None:
        from ..sim import initial_estimates, make_plant, stack_params

        scs = list(scenarios)
        if not scs:
            raise ValueError("no scenarios")
        _check_compatible(scs)
        sc0 = scs[0]
        W = self.nworld = len(scs)
        self.scenarios = scs
        self.device = wp.get_device(device)
        plant = make_plant(sc0)
        self.plant = plant
        if probe:
            check_physics(sc0, device, plant)  # the scene's physics is C MuJoCo's on this engine
        # DC motors (design §8.2): the learner is fed the torque delivered over each period (_delivered)
        self.feed_on = bool(getattr(plant, "feed_delivered", False))
        # plant.sensing = "odometry" (design §8.3; the plant, so the scene's sensors, is one per batch)
        sen = plant.sensors
        self.sense_on = bool(sen.on)
        mjm = plant.model
        self.mjm = mjm
        n = self.n = sc0.n
        dt = self.dt = sc0.sim.control_dt
        self.n_sub = plant.n_substeps
        N = self.N = max(1, int(round(sc0.sim.duration / dt)))
        L_pose, L_vel, _ = sc0.build_leader().states(np.arange(N + 1) * dt)
        graph = sc0.build_graph()
        c_true = plant.c_true()
        self.c_true = c_true

        sc_rows = np.zeros((W, len(SCALARS)))
        arr = {k: np.zeros((W, n, 2)) for k in ("k4", "c_min", "c_max", "offsets", "c_hat0")}
        lim = np.zeros((W, n))
        lacc = np.zeros((W, n))
        est0 = np.zeros((W, n, 3))
        # network and sensor faults (faults.Faults, parsed by it, per world)
        frows = np.zeros((W, len(FAULT_SCALARS)))
        fe_rows: list[list[list[float]]] = []
        fl_rows: list[list[list[float]]] = []
        qpos = np.tile(plant.data.qpos, (W, 1))
        q7 = plant._q7[:, 0]  # the plant's own ids (the robots' mapping, design §8)
        p0 = plant.initial_poses
        for w, sc in enumerate(scs):
            stack = ControlStack(graph if sc is sc0 else sc.build_graph(), stack_params(sc, c_true, plant.tau_max))
            gn = stack.gains
            row = {f: float(getattr(gn, f)) for f in GAIN_SCALARS}
            lm = sc.limits
            row.update(lim_position=lm.position, lim_speed=lm.speed, lim_torque=lm.torque)
            terms = np.array(
                Harmonic(n, sc.disturbance.bias, sc.disturbance.amp, sc.disturbance.freq, sc.disturbance.phase).terms,
                dtype=float,
            )  # (2, 4)
            for c, name in enumerate(("d0", "d1", "d2", "d3")):
                row[name] = terms[0, c]
            for c, name in enumerate(("e0", "e1", "e2", "e3")):
                row[name] = terms[1, c]
            row["use_dist"] = 1.0
            stride = max(1, int(round(sc.sim.log_dt / dt)))
            row["stride"] = float(stride)
            row["t_spin"] = ((N - 1) // stride) * stride * dt - 1.0  # sim.follower_outcomes: the last second of rows
            row["tilt_cos"] = math.cos(math.radians(TIP_ANGLE_DEG))
            row["slip_max"] = plant.SLIP_RATIO  # mujoco_plant's watch_slip thresholds
            row["slip_floor"] = plant.SLIP_V_FLOOR
            row["slip_need"] = float(plant._slip_need)
            row["odometry"] = 1.0 if sen.on else 0.0
            row["odo_seed"] = float(sc.sim.seed % 2147483647)  # as MujocoPlant: the seed of the gyro noise
            row["gyro_bias"] = float(sc.plant.gyro_bias) if sen.on else 0.0
            row["gyro_sigma"] = float(sc.plant.gyro_noise) if sen.on else 0.0
            sc_rows[w] = [row[f] for f in SCALARS]
            arr["k4"][w], arr["c_min"][w], arr["c_max"][w] = gn.k4, gn.c_min, gn.c_max
            arr["offsets"][w] = gn.offsets
            arr["c_hat0"][w] = np.broadcast_to(stack.p.c_hat0, (n, 2))
            lim[w], lacc[w] = gn.lim, gn.lacc
            poses = sc.initial_poses()
            for i in range(n):  # move each base by the planar motion from the scene's pose to this world's
                a = q7[i]
                dth = poses[i, 2] - p0[i, 2]
                qpos[w, a : a + 2] = poses[i, :2]
                qpos[w, a + 3 : a + 7] = _yaw_quat(plant.data.qpos[a + 3 : a + 7], dth)
            est0[w] = initial_estimates(sc, poses, L_pose[0])
            fr = dict.fromkeys(FAULT_SCALARS, 0.0)
            fr.update(w0=-math.inf, w1=math.inf)
            fe_rows.append([])
            fl_rows.append([])
            if sc.faults.per_step:
                fa = Faults(sc, graph, np.asarray(plant.tau_max, dtype=float))
                fr.update(seed=fa.seed, comm=float(fa.has_comm), recv=float(fa.has_recv), noise=float(fa.has_noise))
                fr.update(loss=fa.loss, delay=float(fa.delay_steps), w0=fa.w0, w1=fa.w1)
                for c in range(3):
                    fr[f"np{c}"] = float(fa.noise_pose[c])
                for c in range(2):
                    fr[f"nv{c}"] = float(fa.noise_vel[c])
                fe_rows[w] = [[float(e), t0, t1] for e, t0, t1 in zip(*fa._e_fail)]
                fl_rows[w] = [[float(i), t0, t1] for i, t0, t1 in zip(*fa._l_fail)]
            frows[w] = [fr[x] for x in FAULT_SCALARS]
        self.src, self.dst = graph.src, graph.dst

        dc, dj = default_capacity(n)
        nconmax = dc if nconmax is None else nconmax
        njmax = dj if njmax is None else njmax
        if nconmax < 1 or njmax < 1:  # njmax = 0 makes MuJoCo Warp skip every constraint, unflagged
            raise ValueError(f"nconmax and njmax must be >= 1 per world, got {nconmax}, {njmax}")
        # payload events (sim.EventQueue): each world's model after each of its events, from C MuJoCo
        self.events = event_tables(sc0, scs, N, dt)
        batched = None if self.events is None else dict.fromkeys(EVENT_FIELDS, W)
        with wp.ScopedDevice(self.device):
            self.m = mjw.put_model(mjm, batch_sizes=batched)  # events: per-world inertial fields
            self.d = mjw.put_data(mjm, plant.data, nworld=W, nconmax=nconmax, njmax=njmax)
            self.d.qpos.assign(qpos.astype(np.float32))
            self._qpos0 = wp.clone(self.d.qpos)
            A = lambda x, dtype=F: wp.array(np.ascontiguousarray(x), dtype=dtype)  # noqa: E731
            g = BatchGains()
            g.sc = A(sc_rows)
            g.k4, g.c_min, g.c_max, g.offsets = A(arr["k4"]), A(arr["c_min"]), A(arr["c_max"]), A(arr["offsets"])
            g.lim, g.lacc, g.c_hat0, g.est0 = A(lim), A(lacc), A(arr["c_hat0"]), A(est0)
            g.m_eff = A(np.tile(plant._m_eff, (W, 1)))
            g.i_eff = A(np.tile(plant._i_eff, (W, 1)))
            g.src = A(graph.src.astype(np.int32), int)
            g.dst = A(graph.dst.astype(np.int32), int)
            self.g = g
            s = BatchState()
            z3 = lambda: wp.zeros((W, n, 3), dtype=F)  # noqa: E731
            z2 = lambda: wp.zeros((W, n, 2), dtype=F)  # noqa: E731
            z1 = lambda: wp.zeros((W, n), dtype=F)  # noqa: E731
            s.pose, s.vel, s.est_pose, s.est_vel = z3(), z2(), z3(), z2()
            s.z_hat, s.e_int, s.c_hat, s.d_hat, s.fy, s.fdy = z2(), z2(), z2(), z2(), z2(), z2()
            s.vs, s.err, s.cmd, s.dcmd, s.tau, s.tau_raw, s.tau_body = z1(), z3(), z2(), z2(), z2(), z2(), z2()
            s.saturated = wp.zeros((W, n), dtype=int)
            s.p_err, s.v_err = z3(), z2()
            s.est_rate = wp.zeros((W, n, 5), dtype=F)
            s.first, s.k, s.status, s.k_done = (wp.zeros(W, dtype=int) for _ in range(4))
            s.diag = wp.zeros((W, 3), dtype=F)
            s.verr, s.nsat, s.vmax, s.taumax, s.tauraw_max, s.ferr = z1(), z1(), z1(), z1(), z1(), z1()
            s.fsq, s.fe0, s.spin_ok = z1(), z1(), z1()
            s.nrow = wp.zeros(W, dtype=int)
            s.tip_step = wp.full((W, n), -1, dtype=int)
            s.slip_run = wp.zeros((W, n), dtype=int)
            s.slip_step = wp.full((W, n), -1, dtype=int)
            s.dacc = z2()
            s.mpose, s.mvel = z3(), z2()
            s.odo_pose, s.odo_q, s.odo_dist, s.odo_turn = z3(), z2(), z1(), z1()
            s.odo_count = wp.zeros(W, dtype=int)
            self.s = s
            self.f = self._comm_faults(frows, fe_rows, fl_rows, len(graph.src))
            self.ev_args = None  # _events' table arguments (None: no events in this batch)
            if self.events is not None:
                ev = self.events
                f32 = lambda f: wp.array(  # noqa: E731
                    np.ascontiguousarray(ev[f], dtype=np.float32), dtype=getattr(self.m, f).dtype
                )
                self.ev_args = [A(ev["step"], int), *(f32(f) for f in EVENT_FIELDS), A(ev["m_eff"]), A(ev["i_eff"])]
            pft = plant_fault_tables(scs, N, dt)  # faults.actuator and faults.push, per world
            pf = PlantFaults()
            for f, v in pft.items():
                setattr(pf, f, A(v, int) if v.dtype == np.int32 else A(v))
            self.pf = pf
            self.L_pose = A(L_pose)
            self.L_vel = A(L_vel)
            self.qadr = A(plant._q7[:, 0].astype(np.int32), int)
            self.dadr = A(plant._v6[:, 0].astype(np.int32), int)
            self.base = A(plant._base.astype(np.int32), int)
            self.act = A(np.asarray(plant._ctrl).astype(np.int32), int)  # the plant's own motor ids
            self.cscale = A(np.asarray(plant._ctrl_scale, dtype=float))
            self.axle = A(plant._axle)
            self.wdof = A(np.asarray(plant._wdof).astype(np.int32), int)
            self.wsign = A(np.asarray(plant._wheel_sign, dtype=float))
            self.wrad = A(np.asarray(plant._wheel_radius, dtype=float))
            self.htrack = A(np.asarray(plant._half_track, dtype=float))
            self.to_wheel = A(np.asarray(plant._to_wheel, dtype=float))  # (n, 2) gear × sign, 0: not fed
            self.feed = A(np.asarray(plant._feed).astype(np.int32), int)  # (n,)
            # the odometry's sensors (mujoco_kernels.Sensors): sensordata addresses, sign, radius, cpr
            self.enc = A(np.asarray(sen.enc).astype(np.int32), int)  # (n, 2)
            self.gyro = A(np.asarray(sen.gyro).astype(np.int32), int)  # (n,)
            self.osign = A(np.asarray(sen.sign, dtype=float))  # (n, 2)
            self.orad = A(np.asarray(sen.radius, dtype=float))  # (n,)
            self.cpr = A(np.asarray(sen.cpr, dtype=float))  # (n,)
            self.sense_every, self.sense_ts = int(sen.every), float(sen.ts)
        self.L_pose_host = L_pose
        self.nconmax, self.njmax = nconmax, njmax
        self.graph = None

    def _comm_faults(self, rows: np.ndarray, fe: list, fl: list, m: int) -> CommFaults:
        """The device's :class:`CommFaults` from each world's :data:`FAULT_SCALARS` row ``rows`` (W, ·)
        and failure rows ``fe[w]``, ``fl[w]`` (lists of ``[edge or follower, t_fail, t_recover]``),
        padded to the batch's longest (edge −1); the ring holds the batch's largest delay + 1 steps."""
        W, n = self.nworld, self.n
        R = int(rows[:, FAULT_SCALARS.index("delay")].max()) + 1

        def table(rs: list) -> np.ndarray:
            out = np.full((W, max(1, *(len(r) for r in rs)), 3), -1.0)
            for w, r in enumerate(rs):
                if r:
                    out[w, : len(r)] = r
            return out

        A = lambda x, dtype=F: wp.array(np.ascontiguousarray(x), dtype=dtype)  # noqa: E731
        f = CommFaults()
        f.sc, f.fe, f.fl = A(rows), A(table(fe)), A(table(fl))
        f.ring_p = wp.zeros((W, R, n, 3), dtype=F)
        f.ring_v = wp.zeros((W, R, n, 2), dtype=F)
        f.ring_lp = wp.zeros((W, R, 3), dtype=F)
        f.ring_lv = wp.zeros((W, R, 2), dtype=F)
        f.hp, f.hv = wp.zeros((W, m, 3), dtype=F), wp.zeros((W, m, 2), dtype=F)
        f.hlp, f.hlv = wp.zeros((W, 3), dtype=F), wp.zeros((W, 2), dtype=F)
        f.valid_e, f.valid_l = wp.ones((W, m), dtype=int), wp.ones((W, n), dtype=int)
        f.ew, f.lw = wp.ones((W, m), dtype=F), wp.ones((W, n), dtype=F)
        return f

    # -- the step loop (device-side only)
    def _launch_control(self) -> None:
        d = self.d
        wp.launch(
            _control,
            dim=self.nworld,
            inputs=[
                self.g,
                self.s,
                self.N,
                self.L_pose,
                self.L_vel,
                d.qpos,
                d.qvel,
                d.xmat,
                self.qadr,
                self.dadr,
                self.base,
                self.act,
                self.cscale,
                self.axle,
                self.wdof,
                self.wsign,
                self.wrad,
                self.htrack,
                d.overflow,
                d.ctrl,
                d.xfrc_applied,
                d.sensordata,
                self.enc,
                self.osign,
                self.cpr,
                self.pf,
                self.f,
            ],
        )

    def _launch_events(self, k: wp.array | None = None) -> None:
        """:func:`_events` before the control step (or replayed period) ``k`` (W,) (default the
        worlds' step counters ``BatchState.k``); nothing when no world has events."""
        if self.ev_args is None:
            return
        m = self.m
        wp.launch(
            _events,
            dim=self.nworld,
            inputs=[
                self.s.k if k is None else k,
                self.s.status,
                self.N,
                *self.ev_args,
                *(getattr(m, f) for f in EVENT_FIELDS),
                self.g.m_eff,
                self.g.i_eff,
            ],
        )

    def _period(self) -> None:
        """One control period of physics: ``n_substeps`` × ``mjw.step``, each followed (sensing =
        odometry, design §8.3) by the sensors' sample and dead reckoning (:func:`_sense`) and (DC motors,
        design §8.2) by the delivered-torque accumulation, the last also by the feed (:func:`_delivered`)."""
        d, W, s = self.d, self.nworld, self.s
        for j in range(self.n_sub):
            mjw.step(self.m, d)
            if self.sense_on:
                wp.launch(
                    _sense,
                    dim=W,
                    inputs=[
                        self.g.sc,
                        d.sensordata,
                        self.enc,
                        self.gyro,
                        self.osign,
                        self.orad,
                        self.cpr,
                        self.sense_every,
                        F(self.sense_ts),
                        s.odo_count,
                        s.odo_pose,
                        s.odo_q,
                        s.odo_dist,
                        s.odo_turn,
                    ],
                )
            if self.feed_on:
                last = int(j == self.n_sub - 1)
                wp.launch(
                    _delivered,
                    dim=W,
                    inputs=[d.actuator_force, self.act, self.to_wheel, self.feed, self.n_sub, last, s.dacc, s.tau_body],
                )

    def _steps(self, nsteps: int) -> None:
        """``nsteps`` × [``n_substeps`` physics steps, control step]: no host reads."""
        for _ in range(nsteps):
            self._period()
            self._launch_events()  # payload events due at this control step (before its inputs)
            self._launch_control()

    def reset(self) -> None:
        """Physics back to the initial state of every world, then control step 0 (on the device)."""
        d = self.d
        with wp.ScopedDevice(self.device):
            wp.copy(d.qpos, self._qpos0)
            d.qvel.zero_()
            d.time.zero_()
            d.ctrl.zero_()
            d.xfrc_applied.zero_()
            d.qacc_warmstart.zero_()
            d.overflow.zero_()  # MuJoCo Warp ORs its overflow bits in and never clears them
            self.s.k.zero_()
            self._launch_events()  # each world's initial model (and its events at step 0)
            mjw.forward(self.m, d)
            self.s.dacc.zero_()
            self.s.odo_count.zero_()
            self._launch_control()  # k = 0: observe, reset, control step 0, torques

    def _timed(self, steps, start, total: int, chunk: int, capture: bool | None, graph=None):
        """``start()`` then ``steps(total)``; returns ``(wall seconds of the stepping, graph)``.
        On CUDA (``capture`` None or True) ``chunk`` steps are captured once as a CUDA graph (after
        one eager warm-up step that loads every kernel; ``graph`` reuses an earlier capture) and
        replayed ``total // chunk`` times, the rest launched eagerly."""
        use_graph = self.device.is_cuda if capture is None else capture
        full, rest = divmod(total, chunk)
        with wp.ScopedDevice(self.device):
            if use_graph and full and graph is None:
                start()
                steps(1)
                wp.synchronize_device(self.device)
                with wp.ScopedCapture() as cap:
                    steps(chunk)
                graph = cap.graph
            start()
            wp.synchronize_device(self.device)
            t0 = time.perf_counter()
            if use_graph and full:
                for _ in range(full):
                    wp.capture_launch(graph)
                steps(rest)
            else:
                steps(total)
            wp.synchronize_device(self.device)
            return time.perf_counter() - t0, graph

    def run(self, chunk: int = 100, capture: bool | None = None) -> float:
        """Reset and run all ``N`` control periods; returns the wall seconds of the step loop
        (CUDA: ``chunk`` periods as a captured graph, kept for later runs; :meth:`_timed`)."""
        wall, self.graph = self._timed(self._steps, self.reset, self.N, chunk, capture, self.graph)
        return wall

    def run_physics(self, nsteps: int, ctrl: np.ndarray, chunk: int = 100, capture: bool | None = None) -> float:
        """Physics alone on the same worlds (for the benchmark): from the initial state,
        ``nsteps`` physics steps with the constant inputs ``ctrl`` (nworld, nu), no disturbance;
        returns the wall seconds (CUDA: a captured chunk of ``chunk`` steps, replayed)."""
        d = self.d

        def steps(k):
            for _ in range(k):
                mjw.step(self.m, d)

        def start():
            self.reset()
            d.ctrl.assign(np.asarray(ctrl, dtype=np.float32))
            d.xfrc_applied.zero_()

        return self._timed(steps, start, nsteps, chunk, capture)[0]

    # -- physics alone on the closed loop's own inputs (benchmark)
    def record_bytes(self) -> int:
        """Device bytes :meth:`record` needs (ctrl and chassis forces of every control step)."""
        return self.N * self.nworld * (self.mjm.nu * 4 + self.n * 24)

    def record(self) -> None:
        """Run the closed loop once (untimed) recording every control step's ``ctrl`` and chassis
        ``xfrc_applied`` on the device, for :meth:`run_replay`."""
        W, N = self.nworld, self.N
        with wp.ScopedDevice(self.device):
            self.rec_ctrl = wp.zeros((N, W, self.mjm.nu), dtype=float)
            self.rec_xfrc = wp.zeros((N, W, self.n), dtype=wp.spatial_vector)
            self._rec_j = wp.zeros(W, dtype=int)
            d = self.d
            rec = lambda: wp.launch(
                _record,
                dim=W,
                inputs=[
                    self.s.k,
                    d.ctrl,
                    d.xfrc_applied,
                    self.base,  # noqa: E731
                    self.rec_ctrl,
                    self.rec_xfrc,
                ],
            )
            self.reset()
            rec()
            for _ in range(N - 1):
                self._period()
                self._launch_events()
                self._launch_control()
                rec()
            wp.synchronize_device(self.device)

    def run_replay(self, chunk: int = 100, capture: bool | None = None) -> float:
        """Physics alone, same worlds, same initial state: every control period's recorded inputs
        (:meth:`record`) then ``n_substeps`` × ``mjw.step``; the wall seconds of the loop (CUDA:
        ``chunk`` periods captured as a graph and replayed, as :meth:`run`)."""
        d, W = self.d, self.nworld

        def steps(k):
            for _ in range(k):
                self._launch_events(self._rec_j)  # the closed loop's model for this period
                wp.launch(
                    _replay,
                    dim=W,
                    inputs=[self._rec_j, self.rec_ctrl, self.rec_xfrc, self.base, d.ctrl, d.xfrc_applied],
                )
                for _ in range(self.n_sub):
                    mjw.step(self.m, d)

        def start():
            self.reset()  # the initial state (its control launch is overwritten by the first replay)
            self._rec_j.zero_()

        return self._timed(steps, start, self.N, chunk, capture)[0]

    # -- results
    def _outcome(self, w, i, diverged, final, fe0, t_end, nrow, spin_ok, tip, slip, learning, c_hat, lo, hi):
        """``sim.follower_outcomes`` from the device's counters (tilt and slip watched per world as
        ``mujoco_kernels.watch_tilt``/``watch_slip`` do); ``spinning`` is not checked in a world that
        diverged (its log would end earlier)."""
        if tip >= 0:
            return "tipped", f"tilt beyond {TIP_ANGLE_DEG:g} deg at t = {tip * self.dt:.3f} s"
        if slip >= 0:
            p = self.plant
            return (
                "slipping",
                f"wheel slip ratio > {p.SLIP_RATIO:g} for {p.SLIP_TIME:g} s, by t = {slip * self.dt:.3f} s",
            )
        if not diverged and nrow and spin_ok == 0:
            return "spinning", f"|omega| > {SPIN_RAD_S:g} rad/s over the last second"
        lost_m = lost_threshold_m(self.scenarios[w])
        if final > lost_m and (t_end >= LOST_AFTER_S - 1e-9 or final > 1.5 * fe0):
            return "lost", f"final formation error {final:.3g} m > {lost_m:.3g} m"
        if learning:
            at = [k for k in range(2) if c_hat[k] <= lo[k] * (1 + 1e-9) or c_hat[k] >= hi[k] * (1 - 1e-9)]
            if at:
                return "c_hat_at_bound", "learned " + ", ".join("ab"[k] for k in at) + " at its bound"
        return "ok", ("batch engine: spinning not checked (diverged)" if diverged else "")

    def _capacity_reason(self, bits: int, t: float) -> str:
        """The ``diverged_reason`` of a world whose physics overflowed MuJoCo Warp's capacities
        (``Data.overflow`` bits): what overflowed, which option raises it, and when."""
        O = mjw.OverflowType
        parts = []
        if bits & (O.BROADPHASE | O.NARROWPHASE | O.CCD | O.HFIELD):
            parts.append(f"contact capacity exceeded: raise --nconmax (now {self.nconmax} per world)")
        if bits & O.NEFC:
            parts.append(f"constraint capacity exceeded: raise --njmax (now {self.njmax} rows per world)")
        if bits & O.NJMAX_NNZ:
            parts.append("constraint Jacobian capacity (njmax_nnz) exceeded: raise --njmax")
        if bits & O.NVMAX:
            parts.append("active-DOF capacity (nvmax) exceeded")
        return (
            "; ".join(parts) + f"; MuJoCo Warp dropped what did not fit in the control period ending at t = {t:.4f} s "
            "(world stopped there: its physics is wrong from then on)"
        )

    def c_true_at_end(self, w: int, k_done: int) -> np.ndarray:
        """World ``w``'s ground truth ``[a_eff, b_eff]`` (n, 2) when its run stopped after ``k_done``
        control steps: with the events the CPU loop applied by then (``sim.simulate``: an event at
        step ``e`` lands at the top of loop iteration ``e``, reached only if no control step before
        or at ``e`` failed, and only for ``e < N``), i.e. those with step ``< k_done``."""
        if self.events is None:
            return self.c_true
        steps = self.events["step"][w]
        return self.events["c_true"][w, int(np.count_nonzero((steps >= 0) & (steps < k_done)))]

    def _odometry_drift(self) -> np.ndarray:
        """(W, n, 2): each robot's odometry error at the last observation, ``[|Δ(x, y)| m, |Δθ| rad]``
        against the true pose (``MujocoPlant.odometry_drift``; zeros in worlds without odometry).
        A world stopped early (guard, capacity) keeps stepping its physics and its odometry with zero
        torques, so its drift, like its other end values, is at the end of the run, not at the stop."""
        odo, pose = self.s.odo_pose.numpy(), self.s.pose.numpy()
        dth = np.angle(np.exp(1j * (odo[..., 2] - pose[..., 2])))
        return np.stack([np.hypot(*np.moveaxis(odo[..., :2] - pose[..., :2], -1, 0)), np.abs(dth)], axis=-1)

    def summaries(self, wall: float = float("nan")) -> list[dict[str, Any]]:
        s = self.s
        ferr, c_hat = s.ferr.numpy(), s.c_hat.numpy()
        verr, nsat, vmax = s.verr.numpy(), s.nsat.numpy(), s.vmax.numpy()
        taumax, tauraw = s.taumax.numpy(), s.tauraw_max.numpy()
        status, k_done, diag = s.status.numpy(), s.k_done.numpy(), s.diag.numpy()
        est = s.est_pose.numpy()
        pose = s.pose.numpy()
        fsq, fe0, spin_ok, nrow, tip = (
            s.fsq.numpy(),
            s.fe0.numpy(),
            s.spin_ok.numpy(),
            s.nrow.numpy(),
            s.tip_step.numpy(),
        )
        slip = s.slip_step.numpy()
        odo = self.g.sc.numpy()[:, ODO] != 0
        drift = self._odometry_drift()
        c_min, c_max = self.g.c_min.numpy(), self.g.c_max.numpy()
        learning = self.g.sc.numpy()[:, LEARN] != 0
        lp_end = self.L_pose_host[self.N]
        out = []
        for w, sc in enumerate(self.scenarios):
            kd = int(k_done[w])
            reason = None
            bad = not np.all(np.isfinite(pose[w]))
            if status[w] == CAPACITY_EXCEEDED:
                reason = self._capacity_reason(int(diag[w, 0]), float(diag[w, 2]))
            elif status[w]:
                code, i, val = int(diag[w, 0]), int(diag[w, 1]), float(diag[w, 2])
                signal, what, limit = GUARDS[code - 1]
                reason = (
                    f"follower {i + 1}: {what} '{signal}' "
                    + ("is not finite" if limit is None else f"= {val:.3g} exceeds limits.{limit}")
                    + f" at t = {kd * self.dt:.4f} s"
                )
            elif bad:
                reason = f"non-finite robot state at the end of the run (t = {self.N * self.dt:g} s)"
            c_true = self.c_true_at_end(w, kd)
            fol = []
            stride = max(1, int(round(sc.sim.log_dt / self.dt)))
            t_end = (int(nrow[w]) - 1) * stride * self.dt  # the last log row's time (sim.simulate's log)
            for i in range(self.n):
                outcome, detail = self._outcome(
                    w,
                    i,
                    reason is not None,
                    float(ferr[w, i]),
                    float(fe0[w, i]),
                    t_end,
                    int(nrow[w]),
                    float(spin_ok[w, i]),
                    int(tip[w, i]),
                    int(slip[w, i]),
                    bool(learning[w]),
                    c_hat[w, i],
                    c_min[w, i],
                    c_max[w, i],
                )
                fol.append(
                    {
                        "id": i + 1,
                        "outcome": outcome,
                        "outcome_detail": detail,
                        "rms_formation_error_m": float(np.sqrt(fsq[w, i] / nrow[w])) if nrow[w] else float("nan"),
                        "total_velocity_error": float(verr[w, i] * self.dt),
                        "final_formation_error_m": float(ferr[w, i]),
                        "final_estimation_error_m": float(np.hypot(*(est[w, i, :2] - lp_end[:2]))),
                        "max_abs_v_cmd": float(vmax[w, i]),
                        "peak_abs_torque": float(taumax[w, i]),
                        "peak_abs_torque_commanded": float(tauraw[w, i]),
                        "saturation_fraction": float(nsat[w, i] / max(1, kd)),
                        "c_hat": [float(v) for v in c_hat[w, i]],
                        "c_true": [float(v) for v in c_true[i]],
                        "c_hat_rel_error": [float(v) for v in (c_hat[w, i] / c_true[i] - 1.0)],
                        # sim.simulate: the odometry against the truth at the end (design §8.3), None on truth
                        "odometry_drift_m": float(drift[w, i, 0]) if odo[w] else None,
                        "odometry_heading_drift_rad": float(drift[w, i, 1]) if odo[w] else None,
                    }
                )
            out.append(
                {
                    "scenario": sc.name,
                    "seed": sc.sim.seed,
                    "world": w,
                    "backend": "warp",
                    "device": str(self.device),
                    "diverged": reason is not None,
                    "diverged_reason": reason,
                    "capacity_exceeded": bool(status[w] == CAPACITY_EXCEEDED),
                    "sensing": "odometry" if odo[w] else "truth",
                    "steps": kd,
                    "sim_time": kd * self.dt,
                    "wall_time_s": wall,
                    "followers": fol,
                }
            )
        return out


#: :func:`physics_probe`'s limit on the one-step velocity difference (relative to |qvel|). Measured
#: (60 steps, Warp CPU device): bare floor 1.9e-4 (paper), 2.3e-4 (paper, DC motors), 1.4e-3
#: (stretch preset), 2.0e-3 (tb3 preset); on a friction patch, a box: 0.11 (paper, 6 m patch),
#: 0.86 (paper), 7.9 (tb3) (docs/warp_engine.md)
PROBE_TOL = 3e-2
#: s of physics :func:`physics_probe` lets C MuJoCo settle the scene before comparing
SETTLE_S = 0.05
_probed: dict[tuple[str, str], float] = {}


def physics_probe(plant: Any, device: str = "cpu", steps: int = 60, seed: int = 0) -> float:
    """How far MuJoCo Warp's physics of ``plant``'s scene is from C MuJoCo's, one step at a time.

    C MuJoCo first settles the scene (``SETTLE_S`` of physics at zero input: the robots land on the
    floor, where one engine may see a touching contact the other does not); then both engines step
    it from that state with the same wheel inputs (uniform random
    within ±80 % of each motor's limit, new every 20 steps, ``seed``); after each step the largest
    over robots of ``|qvel_warp − qvel_C| / (|qvel_C| + 1e-3)`` is taken and MuJoCo Warp is put back
    on C MuJoCo's state, so what is measured is each step's own difference (float32 rounding:
    2e-4 … 2e-3 on our robots; another contact model: ≳ 1e-1). Returns the largest over ``steps``
    (dimensionless). One world; ~2 × ``steps`` physics steps of host time on Warp's CPU device."""
    import mujoco

    m = plant.model
    d = mujoco.MjData(m)
    mujoco.mj_copyData(d, m, plant.data)
    mujoco.mj_resetData(m, d)
    for _ in range(max(1, int(round(SETTLE_S / m.opt.timestep)))):
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    rng = np.random.default_rng(seed)
    ids = np.asarray(plant._ctrl).reshape(-1)
    lim = (np.asarray(plant.tau_max, dtype=float)[:, None] * np.asarray(plant._ctrl_scale, dtype=float)).reshape(-1)
    worst = 0.0
    with wp.ScopedDevice(device):
        mm = mjw.put_model(m)
        dd = mjw.put_data(m, d, nworld=1, nconmax=default_capacity(plant.n)[0], njmax=default_capacity(plant.n)[1])
        u = np.zeros(m.nu)
        for k in range(steps):
            if k % 20 == 0:
                u[:] = 0.0
                u[ids] = rng.uniform(-0.8, 0.8, ids.size) * np.abs(lim)
                dd.ctrl.assign(u[None].astype(np.float32))
                d.ctrl[:] = u
            mujoco.mj_step(m, d)
            mjw.step(mm, dd)
            qv = dd.qvel.numpy()[0].astype(float)
            for v6 in plant._v6:
                a, b = v6[0], v6[-1] + 1
                worst = max(worst, float(np.linalg.norm(qv[a:b] - d.qvel[a:b]) / (np.linalg.norm(d.qvel[a:b]) + 1e-3)))
            if not np.isfinite(worst):
                return float("inf")
            dd.qpos.assign(d.qpos[None].astype(np.float32))  # back on C MuJoCo's state
            dd.qvel.assign(d.qvel[None].astype(np.float32))
    return worst


def check_physics(sc: Scenario, device: str = "cpu", plant: Any = None) -> None:
    """ValueError if MuJoCo Warp's physics of ``sc``'s scene is not C MuJoCo's (:func:`physics_probe`
    beyond :data:`PROBE_TOL`); probed once per scene and device in a process."""
    import json

    scene = {"plant": sc.to_dict()["plant"], "patch": list(sc.faults.friction_patch), "dt": sc.sim.physics_dt}
    key = (json.dumps(scene, sort_keys=True, default=repr), str(device))  # what the composed scene is made of
    if key not in _probed:
        if plant is None:
            from ..sim import make_plant

            plant = make_plant(sc)
        _probed[key] = physics_probe(plant, device)
    err = _probed[key]
    if not err <= PROBE_TOL:
        raise ValueError(
            f"scenario '{sc.name}': MuJoCo Warp's physics of this scene differs from C MuJoCo's: one physics "
            f"step from the same state, the robots' velocities differ by up to {err:.3g} (relative; float32 "
            f"gives ~1e-3, the limit is {PROBE_TOL:g}): a contact pair the two engines model differently "
            "(e.g. wheel meshes or boxes); the batch engine would not reproduce the CPU engine"
        )


def run_batch(scenarios: Sequence[Scenario], device: str = "cpu", **kw) -> list[dict[str, Any]]:
    """Run every scenario as one world of a MuJoCo Warp batch on ``device``; one summary
    dict per scenario (the per-follower fields of ``sim.simulate``'s summary that the batch
    engine computes, plus ``diverged``/``diverged_reason``)."""
    b = BatchRun(scenarios, device, **kw)
    wall = b.run()
    return b.summaries(wall)
