"""The control step of many formations on MuJoCo Warp, one thread per world: :func:`_control`.

``control/kernel.py``'s ``control_step`` (learner, estimator consensus, command and torques with the
world's ``torque.derivative`` mode, estimator advance) plus the loop bookkeeping of ``engine.py`` (run
metrics, divergence guards) and the plant glue of ``plants/mujoco_kernels.py`` (observe, wheel torques
and the eq. 34 disturbance as chassis ``xfrc_applied``; ``ctrl = scale · τ``, the DC motors' driver input
per N·m, design §8.2; actuator limits and pushes from :class:`~.device.PlantFaults`), looping over the
followers and graph edges in the same order as the CPU kernels, with each world's network faults and
sensor noise (:class:`~.device.CommFaults`, :func:`~.device._comm`). Every equation is the Warp
translation of ``control/equations.py``: only loops, indexing and bookkeeping are written here.
"""

from __future__ import annotations

import warp as wp

from .device import (
    A_,
    B_,
    BIO,
    CA,
    CAPACITY,
    CB,
    D_,
    DD0,
    DE0,
    DERIV,
    DERIV_A,
    DERIV_D,
    DT,
    EPHI0,
    EPHI1,
    F00,
    F01,
    F10,
    F11,
    FCOMM,
    FNOISE,
    FNP0,
    FNV0,
    FRECV,
    FSEED,
    FW0,
    FW1,
    G0,
    G1,
    K1,
    K2,
    K3,
    K5A,
    KA0,
    KA1,
    KB0,
    KB1,
    KDA,
    KTH,
    KX,
    KY,
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
    TPHI,
    TSPIN,
    USED,
    BatchGains,
    BatchState,
    CommFaults,
    F,
    PlantFaults,
    _act_scale,
    _check,
    _comm,
    _push_row,
    backward_difference,
    clip,
    command_rate,
    encoder_angle,
    error_rate,
    estimator_euler,
    estimator_rates,
    filter_derivative,
    formation_offset,
    harmonic,
    learner_step,
    neuron_rate,
    neuron_step,
    noisy_reading,
    planar_state,
    saturate,
    sliding_mode,
    slip_ratio,
    slot_reference,
    tracking_error,
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
