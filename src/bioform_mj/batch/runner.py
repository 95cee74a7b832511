"""One batch of worlds on a device: :class:`BatchRun` builds the MuJoCo Warp model and data, the
per-world gains, state and tables, steps them (``n_substeps`` × ``mjw.step``, each followed by
:func:`~.plant_kernels._sense` for odometry and :func:`~.plant_kernels._delivered` for DC motors, then one
:func:`~.step._control` launch per control step; the step counter lives on the device, so on CUDA a chunk
of control steps is captured once as a CUDA graph) and reads the summaries back; :func:`run_batch`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import mujoco_warp as mjw
import numpy as np
import warp as wp

from bioform_mj.assess.outcomes import lost_threshold_m
from bioform_mj.assess.prerun import for_summary as _prerun_summary
from bioform_mj.batch.demand_check import demand_of_worlds
from bioform_mj.batch.device import (
    CAPACITY_EXCEEDED,
    FAULT_SCALARS,
    GAIN_SCALARS,
    LEARN,
    ODO,
    SCALARS,
    BatchGains,
    BatchState,
    CommFaults,
    F,
    PlantFaults,
)
from bioform_mj.batch.plant_kernels import EVENT_FIELDS, _delivered, _events, _record, _replay, _sense
from bioform_mj.batch.probe import check_physics
from bioform_mj.batch.step import _control
from bioform_mj.batch.support import default_capacity
from bioform_mj.batch.tables import _check_compatible, _yaw_quat, event_tables, plant_fault_tables
from bioform_mj.control.stack import ControlStack
from bioform_mj.core.engine import GUARDS
from bioform_mj.core.thresholds import SLIP_RATIO, SLIP_TIME, TIP_ANGLE_DEG
from bioform_mj.formation.disturbance import Harmonic
from bioform_mj.plants.base import DeliveredTorques
from bioform_mj.run.demand import for_summary as _demand_summary
from bioform_mj.run.faults import Faults
from bioform_mj.scenario.config import Scenario


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
        from bioform_mj.control.params import stack_params
        from bioform_mj.run.simulate import initial_estimates, make_plant

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
        _refuse_what_robot_check_fails(plant)
        self.robot_check = _warn_what_robot_check_fails(sc0, plant)
        self.demand = demand_of_worlds(scs, plant, self.robot_check)  # design §21: as a single run, once a scenario
        if probe:
            check_physics(sc0, device, plant)  # the scene's physics is C MuJoCo's on this engine
        # DC motors (design §8.2): the learner is fed the torque delivered over each period (_delivered)
        self.feed_on = isinstance(plant, DeliveredTorques) and bool(plant.feed_delivered)
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
            row["slip_max"] = SLIP_RATIO  # the thresholds of the MuJoCo plant's watch_slip (core/thresholds.py)
            row["slip_floor"] = float(plant.slip_floor)  # core.thresholds.slip_v_floor: the plant's robots
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
                self._steps(1)
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
    def _outcome(self, w, i, diverged, final, fe0, t_end, nrow, spin_ok, tip, slip, learning, c_hat, lo, hi, c_true):
        """``sim.follower_outcomes`` from the device's counters (tilt and slip watched per world as
        ``mujoco_kernels.watch_tilt``/``watch_slip`` do), through the same ``sim.outcome_list``:
        ``(outcome, detail, outcomes)``; ``spinning`` is not checked in a world that diverged (its
        log would end earlier). ``c_hat_off``'s causes: the CPU plant's robot parameters and what ``robot check``
        identified (as a single run; no braking-caster check at the end: the device's contacts are not read back)."""
        from bioform_mj.assess.outcomes import injected_causes, outcome_list, robot_check_resistances, unmodelled_causes

        p = self.plant
        params = getattr(p, "params", None)
        lst = outcome_list(
            tip_t=tip * self.dt if tip >= 0 else None,
            slip_t=slip * self.dt if slip >= 0 else None,
            spinning=bool(not diverged and nrow and spin_ok == 0),
            final=final,
            fe0=fe0,
            t_end=t_end,
            learning=learning,
            c_hat=c_hat,
            lo=lo,
            hi=hi,
            c_true=c_true,
            causes=lambda: (
                injected_causes(self.scenarios[w], i)
                + unmodelled_causes(
                    params[i] if params is not None else None,
                    slip >= 0,
                    drag_max=self.scenarios[w].learner.drag_max,
                    identified=robot_check_resistances(self.robot_check, self.n)[i],
                )
            ),
            slip_ratio=SLIP_RATIO,
            slip_time=SLIP_TIME,
            lost_m=lost_threshold_m(self.scenarios[w]),
        )
        if lst:
            return lst[0]["kind"], lst[0]["detail"], lst
        return "ok", ("batch engine: spinning not checked (diverged)" if diverged else ""), lst

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
        scal = self.g.sc.numpy()  # (W, SCALARS): one copy off the device
        odo = scal[:, ODO] != 0
        drift = self._odometry_drift()
        c_min, c_max = self.g.c_min.numpy(), self.g.c_max.numpy()
        learning = scal[:, LEARN] != 0
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
                outcome, detail, outcomes = self._outcome(
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
                    c_true[i],
                )
                fol.append(
                    {
                        "id": i + 1,
                        "outcome": outcome,
                        "outcome_detail": detail,
                        "outcomes": outcomes,
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
                    "robot_check": _prerun_summary(self.robot_check),  # design §14.2: one scene, one check
                    "slip_floor": dict(self.plant.slip_floor_entry),  # design §21: as a single run's summary
                    # design §21: the scenario's demand against the robots' limits, as a single run's summary
                    **({"demand": _demand_summary(self.demand[w])} if self.demand[w] is not None else {}),
                }
            )
        return out


def _refuse_what_robot_check_fails(plant: Any) -> None:
    """``bioform run``'s refusals (``assess.feasibility.run_refusals``, design §14) for the batch's one scene:
    a skid-steer base, a statically unstable chassis, wheels off the floor, a dead band at the motor
    limit are exit 2 before any world runs."""
    import mujoco

    from bioform_mj.assess.feasibility import run_refusals
    from bioform_mj.core.errors import InputError

    scratch = mujoco.MjData(plant.model)
    mujoco.mj_kinematics(plant.model, scratch)
    why = run_refusals(plant, scratch, plant.settled_wheel_loads())
    from bioform_mj.assess.skip import skipped

    if why and skipped():  # design §14.2: a run told to skip the robot check is not refused by it
        import warnings

        from bioform_mj.core.errors import RobotWarning

        for w in why:
            warnings.warn(f"robot check skipped (the run goes ahead); it would refuse {w}", RobotWarning, stacklevel=3)
    elif why:
        raise InputError("the robots cannot run this scenario (robot check fails them): " + "; ".join(why))


def _warn_what_robot_check_fails(sc: Scenario, plant: Any) -> dict[str, Any] | None:
    """What ``robot check`` fails the batch's robots for (``prerun.before_run``, design §14.2), warned
    (a ``RobotWarning`` each) before any world runs; None for a plant that is not MuJoCo's."""
    import warnings

    from bioform_mj.assess.prerun import before_run
    from bioform_mj.core.errors import RobotWarning

    if sc.plant.kind != "mujoco":
        return None
    checked = before_run(sc, plant)
    for line in checked["warnings"]:
        warnings.warn(line, RobotWarning, stacklevel=3)
    return checked


def run_batch(scenarios: Sequence[Scenario], device: str = "cpu", **kw) -> list[dict[str, Any]]:
    """Run every scenario as one world of a MuJoCo Warp batch on ``device``; one summary
    dict per scenario (the per-follower fields of ``sim.simulate``'s summary that the batch
    engine computes, plus ``diverged``/``diverged_reason``)."""
    b = BatchRun(scenarios, device, **kw)
    wall = b.run()
    return b.summaries(wall)
