"""The paper's control stack for ``n`` followers, as a :class:`~.base.Controller`.

:class:`ControlStack` holds the resolved gains (:class:`~.kernel.Gains`) and the state
(:class:`~.kernel.StackState`) and advances them with the compiled
:func:`~.kernel.control_step`, whose equations are in ``equations.py`` (written once).
The same object runs in the step-by-step loop (faults, debugging) and, because it
exposes :attr:`ControlStack.kernel`, in the compiled loops of the plants.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bioform_mj.control.base import Comm
from bioform_mj.control.kernel import (
    DERIVATIVES,
    CommIn,
    Gains,
    StackState,
    control_step,
    new_state,
    perfect_comm,
    reset_state,
)
from bioform_mj.core.equations import filter_coefficients
from bioform_mj.formation.graph import Graph

METHODS = ("backstepping", "bioinspired", "backstepping-learning", "bioinspired-learning")


def parse_method(method: str) -> tuple[str, bool]:
    """``'bioinspired-learning'`` → ``('bioinspired', True)``; ValueError if unknown."""
    if method not in METHODS:
        raise ValueError(f"unknown method '{method}' (expected one of: {', '.join(METHODS)})")
    law, _, learn = method.partition("-")
    return law, bool(learn)


@dataclass(frozen=True)
class StackParams:
    """Numbers of the control stack, already resolved per follower. Units in brackets.

    offsets (n,2) [m]: formation offsets ``(Δx, Δy)``, world frame (the paper) or, with
    leader_frame, the leader's frame (the formation turns with its leader).
    kp (3,) [1/s], ka (2,) [m/s², rad/s²], kb (2,) [1/s], est_phi (2,) [m/s, rad/s]: estimator.
    k1 [1/s], k2 [1/m²·…], k3 [1/m]: kinematic gains of eq. 31; A, B, D: neuron (eq. 32).
    law: 'bioinspired' or 'backstepping'; learning: run eq. 37 or keep ``ĉ = ĉ(0)``.
    c_gain (2,) [m/s², rad/s²]: ``c_a, c_b``; torque_phi: boundary layer of eqs. 38–39 (0 = sgn).
    tau_max (n,) [N·m]: wheel torque limit; steer_priority: keep τ_b when saturating;
    deriv_wn [rad/s]: command-derivative filter;
    derivative: how ``υ̇_cmd, ω̇_cmd`` are obtained, ``filter``, ``difference`` or ``analytic`` (design §6).
    k4 (2,) or (n,2), k5 (2,) [1/s]: learner gains; kd (2,): disturbance-estimate gain (0 = the paper);
    kk (2,): learned-drag gain (0 = the paper, design §14), k_max [1/s]: its projection bound;
    c_hat0, c_min, c_max (n,2): initial estimate and bounds.
    dt [s]: control period.
    """

    offsets: np.ndarray
    kp: np.ndarray
    ka: np.ndarray
    kb: np.ndarray
    est_phi: np.ndarray
    k1: float
    k2: float
    k3: float
    A: float
    B: float
    D: float
    law: str
    learning: bool
    c_gain: np.ndarray
    torque_phi: float
    tau_max: np.ndarray
    steer_priority: bool
    deriv_wn: float
    k4: np.ndarray
    k5: np.ndarray
    kd: np.ndarray
    c_hat0: np.ndarray
    c_min: np.ndarray
    c_max: np.ndarray
    dt: float
    leader_frame: bool = False
    derivative: str = "filter"
    kk: np.ndarray = field(default_factory=lambda: np.zeros(2))
    k_max: float = 0.0
    # the safety filter (design §19, control/cbf.py): off by default (the paper has none)
    cbf: bool = False
    cbf_par: tuple[float, ...] = (0.1, 5.0, 0.0, 2.0, 1.0)  # look-ahead l m, γ 1/s, d m, range m, pass_right
    cbf_radius: np.ndarray | None = None  # (n,) m, each robot's footprint radius (None: 0, points)
    cbf_obstacles: np.ndarray | None = None  # (m, 7) rows of obstacles.to_rows (None: none)
    # opt-in sizing of c_gain and kd to the identified resistance (learner_sizing.sizing; None: off)
    sizing: dict | None = None


class ControlStack:
    """The distributed formation controller of all ``n`` followers (a :class:`~.base.Controller`).

    Knows nothing of the plant: it maps measured ``pose`` (n,3) and ``vel`` (n,2) to wheel
    torques ``[τ_L, τ_R]`` (n,2). Every state and signal of the last step is an array of
    :attr:`state`, updated in place (views stay valid).
    """

    def __init__(self, graph: Graph, p: StackParams) -> None:
        n = graph.n
        self.n = n
        self.p = p
        self.graph = graph
        if p.derivative not in DERIVATIVES:
            raise ValueError(f"unknown derivative '{p.derivative}' (expected one of: {', '.join(DERIVATIVES)})")
        f00, f01, f10, f11, g0, g1 = filter_coefficients(p.deriv_wn, p.dt)
        c = np.ascontiguousarray
        self.gains = Gains(
            k1=float(p.k1),
            k2=float(p.k2),
            k3=float(p.k3),
            A=float(p.A),
            B=float(p.B),
            D=float(p.D),
            kx=float(p.kp[0]),
            ky=float(p.kp[1]),
            kth=float(p.kp[2]),
            ka0=float(p.ka[0]),
            ka1=float(p.ka[1]),
            kb0=float(p.kb[0]),
            kb1=float(p.kb[1]),
            ephi0=float(p.est_phi[0]),
            ephi1=float(p.est_phi[1]),
            ca=float(p.c_gain[0]),
            cb=float(p.c_gain[1]),
            tphi=float(p.torque_phi),
            f00=f00,
            f01=f01,
            f10=f10,
            f11=f11,
            g0=g0,
            g1=g1,
            deriv=DERIVATIVES[p.derivative],
            k5a=float(p.k5[0]),
            k5b=float(p.k5[1]),
            kda=float(np.broadcast_to(p.kd, (2,))[0]),
            kdb=float(np.broadcast_to(p.kd, (2,))[1]),
            dt=float(p.dt),
            bio=p.law == "bioinspired",
            learning=bool(p.learning),
            steer=bool(p.steer_priority),
            leader_frame=bool(p.leader_frame),
            kka=float(np.broadcast_to(p.kk, (2,))[0]),
            kkb=float(np.broadcast_to(p.kk, (2,))[1]),
            k_max=float(p.k_max),
            k4=c(np.broadcast_to(np.asarray(p.k4, dtype=float), (n, 2)), dtype=float),
            c_min=c(np.broadcast_to(p.c_min, (n, 2)), dtype=float),
            c_max=c(np.broadcast_to(p.c_max, (n, 2)), dtype=float),
            lim=np.array(np.broadcast_to(np.asarray(p.tau_max, dtype=float), (n,)), dtype=float),
            offsets=c(p.offsets, dtype=float).reshape(n, 2),
            src=c(graph.src, dtype=np.int64),
            dst=c(graph.dst, dtype=np.int64),
            lacc=c(graph.leader_access, dtype=float),
            cbf=bool(p.cbf),
            cbf_par=np.array(p.cbf_par, dtype=float),
            cbf_rad=np.zeros(n) if p.cbf_radius is None else c(p.cbf_radius, dtype=float).reshape(n),
            cbf_obst=np.zeros((0, 7)) if p.cbf_obstacles is None else c(p.cbf_obstacles, dtype=float).reshape(-1, 7),
            cbf_A=np.zeros((n + (0 if p.cbf_obstacles is None else len(p.cbf_obstacles)), 2)),
            cbf_b=np.zeros(n + (0 if p.cbf_obstacles is None else len(p.cbf_obstacles))),
            cbf_lam=np.zeros(n + (0 if p.cbf_obstacles is None else len(p.cbf_obstacles))),
            cbf_bad=np.zeros(n),
        )
        self.state: StackState = new_state(n)
        self._no_comm = perfect_comm(n, int(graph.src.shape[0]))
        self._pose_in = np.zeros((n, 3))
        self._vel_in = np.zeros((n, 2))

    # ------------------------------------------------------------------ Controller
    @property
    def kernel(self) -> tuple[Gains, StackState]:
        """``(gains, state)`` for :func:`~.kernel.control_step`: lets compiled loops run this stack."""
        return self.gains, self.state

    def reset(self, est_pose0: np.ndarray, vel0: np.ndarray) -> None:
        """Initial estimates ``P_ir(0)`` (n,3), measured velocities (n,2); ``V_s(0) = 0``."""
        self.gains.cbf_bad[:] = 0.0  # the safety filter's count of steps without a solution (design §19)
        reset_state(
            self.gains,
            self.state,
            np.ascontiguousarray(est_pose0, dtype=float),
            np.ascontiguousarray(vel0, dtype=float),
            np.ascontiguousarray(np.broadcast_to(self.p.c_hat0, (self.n, 2)), dtype=float),
        )

    def step(
        self,
        leader_pose: np.ndarray,
        leader_vel: np.ndarray,
        pose: np.ndarray,
        vel: np.ndarray,
        comm: Comm | None = None,
    ) -> np.ndarray:
        """Torques ``[τ_L, τ_R]`` (n, 2, N·m) to hold over the next control period.

        ``comm`` (optional): link weights and received neighbour estimates of a faulty
        network for this step's estimator update; None = the paper's perfect network.
        """
        self._pose_in[:] = pose
        self._vel_in[:] = vel
        lp = np.ascontiguousarray(leader_pose, dtype=float)
        lv = np.ascontiguousarray(leader_vel, dtype=float)
        control_step(self.gains, self.state, lp, lv, self._pose_in, self._vel_in, self.comm_in(comm))
        return self.state.tau

    def comm_in(self, comm: Comm | None) -> CommIn:
        """The kernel's :class:`~.kernel.CommIn` for ``comm`` (None: the perfect network)."""
        if comm is None:
            return self._no_comm
        g = self.graph
        m = int(g.src.shape[0])
        s = self.state
        rp = s.est_pose[g.dst] if comm.recv_pose is None else comm.recv_pose
        rv = s.est_vel[g.dst] if comm.recv_vel is None else comm.recv_vel
        c = np.ascontiguousarray
        return CommIn(
            True,
            c(comm.edge_w, dtype=float),
            c(comm.leader_w, dtype=float),
            c(rp, dtype=float).reshape(m, 3),
            c(rv, dtype=float).reshape(m, 2),
        )

    def set_tau_max(self, tau_max: np.ndarray) -> None:
        """Change the wheel torque limits (n,) N·m in place (e.g. an actuator fault mid-run)."""
        self.gains.lim[:] = tau_max

    def signals(self) -> dict[str, np.ndarray]:
        """The stack's signals of the last step, by log channel name (views)."""
        s = self.state
        return {
            "est_pose": s.est_pose,
            "est_vel": s.est_vel,
            "cmd": s.cmd,
            "dcmd": s.dcmd,
            "tau": s.tau,
            "tau_raw": s.tau_raw,
            "c_hat": s.c_hat,
            "z_hat": s.z_hat,
            "vs": s.vs,
            "tracking_error": s.err,
            "saturated": s.saturated,
        }

    # ------------------------------------------------------------------ conveniences
    @property
    def c_hat(self) -> np.ndarray:
        """Current ``[â, b̂]`` (n, 2)."""
        return self.state.c_hat

    @property
    def est_pose(self) -> np.ndarray:
        return self.state.est_pose

    @property
    def est_vel(self) -> np.ndarray:
        return self.state.est_vel

    @property
    def cmd(self) -> np.ndarray:
        return self.state.cmd

    @property
    def tau(self) -> np.ndarray:
        return self.state.tau

    @property
    def tau_raw(self) -> np.ndarray:
        return self.state.tau_raw

    @property
    def saturated(self) -> np.ndarray:
        return self.state.saturated
