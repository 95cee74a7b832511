"""The batch engine's device side, shared by its kernels: the Warp translation of ``core/equations.py``
(:mod:`.samesource`), the per-world columns (``SCALARS``, ``FAULT_SCALARS``) and their indices, the
device structs (:class:`BatchGains`, :class:`BatchState`, :class:`PlantFaults`, :class:`CommFaults`) and
the device functions of the network faults (:func:`_comm`) and the divergence guards (:func:`check_world`).

Precision: controller state, gains and metrics are float64 (the learner is stiff and ``ĉ`` must match
the CPU engine to 0.5 %); MuJoCo Warp's physics is float32, converted at the boundary.
"""

from __future__ import annotations

import mujoco_warp as mjw
import warp as wp

from bioform_mj.batch.samesource import warp_equations
from bioform_mj.control.kernel import DERIV_ANALYTIC, DERIV_DIFFERENCE
from bioform_mj.core import equations as _E
from bioform_mj.core.thresholds import SPIN_RAD_S
from bioform_mj.run.faults import counter

F = wp.float64
EQ = warp_equations(_E, F)
# module globals: Warp resolves a kernel's globals when it builds the kernel
wrap = EQ.wrap
estimator_euler = EQ.estimator_euler
tracking_error = EQ.tracking_error
slot_reference = EQ.slot_reference
slot_error = EQ.slot_error
command_derivative = EQ.command_derivative
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
#: the ``spinning`` outcome's |ω| threshold, rad/s: ``core/thresholds.py``'s, not typed again (design §0)
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
    """Per-world actuator faults and pushes (``faults.actuator``, ``faults.push``; ``run/faults.py``) as
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
    r0 = now  # this step's row of the ring; before the first step there is no history: every row
    r1 = now + 1
    if k == 0:
        r1 = R
    for r in range(r0, r1):
        for i in range(n):
            for c in range(3):
                f.ring_p[w, r, i, c] = s.est_pose[w, i, c]
            for c in range(2):
                f.ring_v[w, r, i, c] = s.est_vel[w, i, c]
        for c in range(3):
            f.ring_lp[w, r, c] = L_pose[k, c]
        for c in range(2):
            f.ring_lv[w, r, c] = L_vel[k, c]
    if k == 0:  # the initial values held and valid
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
def check_world(g: BatchGains, s: BatchState, w: int, n: int) -> int:
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
