"""Tutorial: a formation controller of your own, run on the paper's scenario (executed by tests/test_docs.py).

The controller: each follower tracks its formation slot, as its distributed estimate of the leader
gives it, with Kanayama's kinematic law, and a proportional velocity loop turns the command into wheel
torques. The estimate comes from the package's own distributed estimator (eqs. 12-13).
"""

import numpy as np

import bioform_mj as bf
from bioform_mj.control.kernel import estimator_update, reset_state
from bioform_mj.control.stack import ControlStack
from bioform_mj.core.equations import saturate, slot_reference, tracking_error
from bioform_mj.run.simulate import make_plant, stack_params


class SlotTracker:
    """Kanayama tracking of the estimated slot + a P velocity loop with nominal ĉ(0) (no learning)."""

    def __init__(self, sc: bf.Scenario, c_true, tau_max, kx=2.0, ky=8.0, kth=4.0, kv=10.0, kw=10.0):
        self.n = sc.n
        est = ControlStack(sc.build_graph(), stack_params(sc, c_true, tau_max))  # the paper's estimator
        self.comm_in = est.comm_in
        self.gains, self.state = est.kernel
        self.c0 = np.asarray(sc.learner.c_hat0_scale) * c_true  # nominal [a, b]
        self.steer = sc.torque.saturation == "steer-priority"
        self.k = (kx, ky, kth, kv, kw)
        self.cmd = np.zeros((self.n, 2))
        self.tau = np.zeros((self.n, 2))

    def reset(self, est_pose0, vel0):
        reset_state(self.gains, self.state, np.ascontiguousarray(est_pose0), np.ascontiguousarray(vel0), self.c0)

    def step(self, leader_pose, leader_vel, pose, vel, comm=None):
        kx, ky, kth, kv, kw = self.k
        g, s = self.gains, self.state
        for i in range(self.n):
            # the slot's pose and velocity from the estimate (offsets in the leader's frame or the world's)
            xs, ys, ths, v_ref, w_ref = (
                slot_reference(*s.est_pose[i], *s.est_vel[i], *g.offsets[i])
                if g.leader_frame
                else (
                    s.est_pose[i, 0] - g.offsets[i, 0],
                    s.est_pose[i, 1] - g.offsets[i, 1],
                    s.est_pose[i, 2],
                    *s.est_vel[i],
                )
            )
            ex, ey, eth = tracking_error(xs, ys, ths, *pose[i], 0.0, 0.0)
            self.cmd[i] = (v_ref * np.cos(eth) + kx * ex, w_ref + v_ref * (ky * ey + kth * np.sin(eth)))
            ta = kv * (self.cmd[i, 0] - vel[i, 0]) / self.c0[i, 0]  # body-frame torques
            tb = kw * (self.cmd[i, 1] - vel[i, 1]) / self.c0[i, 1]
            self.tau[i] = saturate(0.5 * (ta - tb), 0.5 * (ta + tb), g.lim[i], self.steer)  # [τ_L, τ_R]
        estimator_update(g, s, np.asarray(leader_pose, float), np.asarray(leader_vel, float), self.comm_in(comm))
        return self.tau

    def signals(self):
        return {"est_pose": self.state.est_pose, "est_vel": self.state.est_vel, "cmd": self.cmd}


sc = bf.load("paper", ["sim.duration=8"], plant="ideal")
plant = make_plant(sc)
mine = bf.simulate(sc, plant=plant, controller=SlotTracker(sc, plant.c_true(), np.full(sc.n, sc.torque.tau_max)))
paper = bf.simulate(sc)  # the paper's bioinspired-learning on the same scenario

for name, res in (("SlotTracker", mine), ("bioinspired-learning", paper)):
    tbl = res.table()  # the log as a tidy pyarrow table: one row per sample and follower
    t = tbl["t_s"].to_numpy()
    last = tbl.filter(t == t.max()).to_pylist()  # the last sample's rows, one per follower
    errs = ", ".join(f"{r['formation_error_m']:.3f}" for r in last)
    print(f"{name:22s} final formation error per follower (m): {errs}")
