"""The batch engine's kernels between physics steps: the torque the DC motors delivered
(:func:`_delivered`, design §8.2), payload events (:func:`_events`), the encoders, gyro and dead
reckoning of ``plant.sensing = "odometry"`` (:func:`_sense`, design §8.3), and the recording and
replay of a closed loop's inputs for the benchmark (:func:`_record`, :func:`_replay`).
"""

from __future__ import annotations

import warp as wp

from bioform_mj.batch.device import GBIAS, GSIGMA, ODO, OSEED, F, encoder_angle, gyro_reading, odometry_step


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
