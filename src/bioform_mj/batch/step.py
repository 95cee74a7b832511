"""The control step of many formations on MuJoCo Warp, one thread per world: :func:`_control`.

``control/kernel.py``'s ``control_step`` (learner, estimator consensus, command and torques with the
world's ``torque.derivative`` mode, estimator advance) plus the loop bookkeeping of ``core/engine.py`` (run
metrics, divergence guards) and the plant glue of ``plants/mujoco/kernels.py`` (observe, wheel torques
and the eq. 34 disturbance as chassis ``xfrc_applied``; ``ctrl = scale · τ``, the DC motors' driver input
per N·m, design §8.2; actuator limits and pushes from :class:`~.device.PlantFaults`), looping over the
followers and graph edges in the same order as the CPU kernels, with each world's network faults and
sensor noise (:class:`~.device.CommFaults`, :func:`~.device._comm`). Every equation is the Warp
translation of ``core/equations.py``; the stack's steps (observe, reset, learner, consensus,
tracking error, command derivative, torque law, estimator advance) are the device functions of
:mod:`.stack`, shared with the batched environment: only the loop's own bookkeeping is written here.
"""

from __future__ import annotations

import warp as wp

from bioform_mj.batch import stack
from bioform_mj.batch.device import (
    A_,
    B_,
    BIO,
    CAPACITY,
    D_,
    DERIV,
    DERIV_A,
    DT,
    FCOMM,
    FNOISE,
    FNP0,
    FNV0,
    FRECV,
    FSEED,
    FW0,
    FW1,
    K1,
    K2,
    K3,
    LEARN,
    LFRAME,
    NPOSE0,
    NVEL0,
    ODO,
    SLIPFLOOR,
    SLIPMAX,
    SLIPNEED,
    SPIN,
    ST_CAP,
    STEER,
    STRIDE,
    TILT,
    TSPIN,
    USED,
    BatchGains,
    BatchState,
    CommFaults,
    F,
    PlantFaults,
    _act_scale,
    _comm,
    _push_row,
    check_world,
    clip,
    command_rate,
    encoder_angle,
    error_rate,
    neuron_rate,
    noisy_reading,
    slip_ratio,
    velocity_command,
    wrap,
)


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
    tk = F(k) * dt  # s: the time of control step k
    zero = F(0.0)
    odo = g.sc[w, ODO] != zero  # the controller measures by odometry (design §8.3)
    # ---- MuJoCo Warp dropped contacts or constraint rows in the last period: stop this world
    # (the CPU loop stops on MuJoCo's warnings: engine.PLANT_FAILED), never silently
    if k >= 1 and s.status[w] == 0 and (overflow[w] & CAPACITY) != 0:
        s.status[w] = ST_CAP
        s.diag[w, 0] = F(overflow[w] & CAPACITY)
        s.diag[w, 1] = F(-1.0)
        s.diag[w, 2] = tk  # the end of the period that overflowed
        s.k_done[w] = k - 1
    # ---- observe (mujoco_kernels.observe)
    for i in range(n):
        up = stack.observe(s, w, i, qpos, qvel, qadr, dadr, axle)
        # mujoco_kernels.watch_tilt and watch_slip after each plant step (k ≥ 1) until the loop stops
        if k >= 1 and s.status[w] == 0:
            if s.tip_step[w, i] < 0 and up < g.sc[w, TILT]:
                s.tip_step[w, i] = k
            worst = F(0.0)
            for c in range(2):
                sl = slip_ratio(
                    F(qvel[w, wdof[i, c]]) * wsign[i, c],
                    wrad[i],
                    s.vel[w, i, 0],
                    s.vel[w, i, 1],
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
        stack.formation_error(g, s, w, i, L_pose[kl, 0], L_pose[kl, 1], L_pose[kl, 2], lframe)
    # ---- reset (kernel.reset_state), and the loop's own metrics and watches
    if k == 0:
        stack.reset(g, s, w, n)
        for i in range(n):
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
        s.k_done[w] = 0
        if odo:  # mujoco_kernels.odometry_reset: the true pose, the sensordata of mjw.forward
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
            if odo:
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
            stack.learn(g, s, w, n, dt)
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
        stack.consensus(g, s, f, w, n, comm, recv, lp0, lp1, lp2, lv0, lv1)
        # ---- kernel.velocity_commands and torques
        first = s.first[w] == 1
        steer = g.sc[w, STEER] != zero
        bio = g.sc[w, BIO] != zero
        deriv = g.sc[w, DERIV]
        for i in range(n):
            e0, e1, e2, v_ref, w_ref = stack.follower_error(g, s, w, i, lframe)
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
                    stack.follower_derivative(g, s, w, i, c, first, dt)
            r0, r1 = stack.torque_law(g, s, w, i, vc, wc)
            L = g.lim[w, i]
            if pf.act_known[w] != 0:  # faults.actuator_known: the stack's own limit (ControlStack.set_tau_max)
                L = L * _act_scale(pf, w, i, k)
            stack.apply_torque(s, w, i, r0, r1, L, steer)
        s.first[w] = 0
        # ---- estimator_advance: one Euler step with this step's rates; the neuron (eq. 32)
        stack.advance(g, s, w, n, dt, bio)
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
        if check_world(g, s, w, n) != 0:
            s.status[w] = 1  # GUARD_FAILED
            running = False
        elif k % int(g.sc[w, STRIDE]) == 0:  # engine.record's row (formation error, vel) for the summary
            for i in range(n):
                s.fsq[w, i] = s.fsq[w, i] + s.ferr[w, i] * s.ferr[w, i]
                if k == 0:
                    s.fe0[w, i] = s.ferr[w, i]
                if tk >= g.sc[w, TSPIN] and wp.abs(s.vel[w, i, 1]) <= SPIN:
                    s.spin_ok[w, i] = s.spin_ok[w, i] + F(1.0)
            s.nrow[w] = s.nrow[w] + 1
    # ---- apply_inputs: this step's torques and d(k dt), held over the period (zero once stopped)
    d0 = zero
    d1 = zero
    if running and g.sc[w, USED] != zero:
        d0, d1 = stack.disturbance(g, w, tk)
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
