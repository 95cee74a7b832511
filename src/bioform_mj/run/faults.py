"""Fault injection (issue 6): what a run's network, sensors, motors and floor do wrong.

Configured by the scenario's ``[faults]`` table (:class:`~bioform_mj.scenario.config.FaultsCfg`); the
loop (``sim.simulate``) builds a :class:`Faults` only when some fault is configured, so a run
without faults executes none of this. Every step here is vectorised over followers and links.

- **Link failure** ``[i, j, t_fail, t_recover]``: the undirected link i–j (``j = 0``: i's leader
  link) carries nothing in ``[t_fail, t_recover)``. The follower knows the link is down: its
  weight in the consensus sums of eqs. 12–13 is 0, so a follower cut off from everybody
  dead-reckons its leader estimate. After recovery the link counts again from its first packet.
- **Packet loss** ``p``: each link between followers (each direction on its own) loses its packet
  of a control step with probability ``p``, and so does the leader's broadcast (lost for every
  leader-connected follower at once: the stack takes one leader state); the receiver keeps the
  last value it got (zero-order hold).
- **Delay** ``τ``: every link delivers the sender's estimate (the leader's state) of ``round(τ/dt)``
  control steps ago, from a ring buffer of past estimates.
- **Sensor noise**: Gaussian, on the pose and velocity the controller measures (the log keeps the
  true state, so formation errors are true errors).
- **Actuator**: follower i's wheel torque limit times ``scale`` in ``[t_start, t_end)``; the
  torque reaching the plant is clipped per wheel. ``actuator_known``: the controller's own
  saturation (steer-priority) and its learner see the new limit; otherwise it goes on computing
  (and learning from) torques its motors no longer deliver.
- **Push** ``[i, t, duration, fx, fy, tz]``: ``plant.push``; in MuJoCo a force/torque on the
  chassis, on the ideal plant the acceleration its heading component and ``tz`` give.
- **Friction patch**: built into the MuJoCo scene (``scene.build_scene``), nothing per step.

Randomness comes from the counter hash of ``core/equations.py`` (as the gyro's noise), so the
batch engine's device draws the very same numbers: packet loss ``packet_received(p, seed, i, k)``,
sensor noise ``noisy_reading(x, σ, seed, i, k)`` (:func:`~bioform_mj.core.equations.hash_normal`),
keyed by ``seed = sim.seed mod 2^31 − 1``, the control step ``k`` and a counter index
``i = STREAM[source] · STREAM_STRIDE + j`` (:func:`counter`): ``j`` the graph edge (``m`` for the
leader's broadcast), ``3 f + c`` for pose component ``c`` of follower ``f``, ``2 f + c`` for its
velocity. The gyro draws with ``i`` = robot < ``STREAM_STRIDE`` (stream 0), so no two sources share
a draw. Runs are bit-identical for a seed and differ between seeds where noise or loss is on.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bioform_mj.control.base import Comm
from bioform_mj.control.stack import ControlStack
from bioform_mj.core.equations import njit, noisy_reading, packet_received, wrap
from bioform_mj.core.thresholds import SPIN_RAD_S, TIP_ANGLE_DEG
from bioform_mj.formation.graph import Graph
from bioform_mj.scenario.config import Scenario

#: Streams of the counter hash (the module doc): source -> stream number (0 is the gyro's).
STREAM = {"packet_loss": 1, "noise_pose": 2, "noise_vel": 3}
#: counter indices per stream (``hash_uniform`` takes ``i < 2^20``: 16 streams of 2^16)
STREAM_STRIDE = 65536
#: the seed's modulus (``sim.seed mod HASH_SEED_MOD``, as the gyro's)
HASH_SEED_MOD = 2147483647


def counter(stream: str, j: int) -> int:
    """The counter-hash index ``i`` of item ``j`` (< :data:`STREAM_STRIDE`) of random ``stream``."""
    return STREAM[stream] * STREAM_STRIDE + j


@njit
def add_noise(x, sigma, seed, base, k, angle):
    """In place on ``x`` (n, nc): ``x[f, c] = noisy_reading(x[f, c], sigma[c], seed, base + nc f + c, k)``
    (control step ``k``; ``base`` the stream's first counter index); column ``angle`` (−1: none) is
    then wrapped to (−π, π]."""
    n, nc = x.shape
    for f in range(n):
        for c in range(nc):
            x[f, c] = noisy_reading(x[f, c], sigma[c], seed, float(base + nc * f + c), float(k))
        if angle >= 0:
            x[f, angle] = wrap(x[f, angle])


@njit
def arrivals(out, p, seed, base, k):
    """``out[j]`` (bool, (m + 1,)) = the packet of counter index ``base + j`` arrives at control step ``k``
    (:func:`~bioform_mj.core.equations.packet_received` with loss probability ``p``)."""
    for j in range(out.shape[0]):
        out[j] = packet_received(p, seed, float(base + j), float(k)) != 0.0


#: Formation error (m) under which a follower counts as back in formation.
TOLERANCE = 0.1


class Faults:
    """The configured faults of one run, stepped by the loop.

    Parameters
    ----------
    sc : the scenario (``sc.faults`` configured).
    graph : its communication graph.
    nominal_tau_max : (n,) wheel torque limits (N·m) without faults.
    """

    def __init__(self, sc: Scenario, graph: Graph, nominal_tau_max: np.ndarray) -> None:
        fc = sc.faults
        n, dt = sc.n, sc.sim.control_dt
        self.n, self.dt, self.graph = n, dt, graph
        self.seed = float(sc.sim.seed % HASH_SEED_MOD)  # the counter hash's key (as the gyro's)
        self.w0, self.w1 = fc.window if fc.window else (-np.inf, np.inf)

        # ---- communication ------------------------------------------------------------
        m = len(graph.src)
        if max(3 * n, m + 1) > STREAM_STRIDE:
            raise ValueError(f"faults: {n} followers / {m} links exceed the counter hash's {STREAM_STRIDE} per stream")
        e_idx, e_t0, e_t1, l_idx, l_t0, l_t1 = [], [], [], [], [], []
        for i, j, t0, t1 in fc.link_fail:
            i, j = int(i) - 1, int(j) - 1
            if j < 0:
                l_idx.append(i)
                l_t0.append(t0)
                l_t1.append(t1)  # noqa: E702
                continue
            rows = np.flatnonzero(((graph.src == i) & (graph.dst == j)) | ((graph.src == j) & (graph.dst == i)))
            e_idx += rows.tolist()
            e_t0 += [t0] * len(rows)
            e_t1 += [t1] * len(rows)  # noqa: E702
        self._e_fail = (np.array(e_idx, dtype=int), np.array(e_t0), np.array(e_t1))
        self._l_fail = (np.array(l_idx, dtype=int), np.array(l_t0), np.array(l_t1))
        self.loss = fc.packet_loss
        self.delay_steps = int(round(fc.delay / dt)) if fc.delay > 0 else 0
        self.has_comm = bool(fc.link_fail) or self.loss > 0 or self.delay_steps > 0
        self.has_recv = self.loss > 0 or self.delay_steps > 0  # received values differ from the current ones
        self._draw = np.ones(m + 1, dtype=bool)  # this step's arrivals: edges, then the leader's broadcast
        self._up_e = np.ones(m, dtype=bool)
        self._up_l = np.ones(n, dtype=bool)
        if self.has_recv:
            R = self.delay_steps + 1
            self._ring = (np.zeros((R, n, 3)), np.zeros((R, n, 2)), np.zeros((R, 3)), np.zeros((R, 2)))
            self._held = (np.zeros((m, 3)), np.zeros((m, 2)), np.zeros(3), np.zeros(2))
            self._valid_e = np.ones(m, dtype=bool)
            self._valid_l = np.ones(n, dtype=bool)
            self._started = False

        # ---- sensing --------------------------------------------------------------------
        self.noise_pose = np.asarray(fc.noise_pose, dtype=float)
        self.noise_vel = np.asarray(fc.noise_vel, dtype=float)
        self.has_noise = bool(np.any(self.noise_pose > 0) or np.any(self.noise_vel > 0))

        # ---- actuators ------------------------------------------------------------------
        self.nominal = np.asarray(nominal_tau_max, dtype=float).copy()
        act = np.array(fc.actuator, dtype=float).reshape(-1, 4)
        self._act = (act[:, 0].astype(int) - 1, act[:, 1], act[:, 2], act[:, 3])
        self.has_act = len(act) > 0
        self.act_known = fc.actuator_known
        self._scale = np.ones(n)
        self._lim = None  # (n, 1) clip of the torque reaching the plant while a limit is reduced

        # ---- pushes ---------------------------------------------------------------------
        self._pushes = sorted(fc.push, key=lambda r: r[1])
        self._push_i = 0

    # ------------------------------------------------------------------ the loop's hook
    def step(
        self,
        k: int,
        t: float,
        stack: ControlStack,
        plant: Any,
        leader_pose: np.ndarray,
        leader_vel: np.ndarray,
        pose: np.ndarray,
        vel: np.ndarray,
    ) -> np.ndarray:
        """One control step at ``t = k dt`` under the faults; returns the torques (n, 2) reaching the plant.

        ``pose``/``vel`` are the true states (not modified); the stack sees them with noise, and
        reads the network through :meth:`comm`.
        """
        if self.has_act:
            self.actuate(t, stack)
        while self._push_i < len(self._pushes) and self._pushes[self._push_i][1] <= t + 1e-12:
            i, t0, dur, fx, fy, tz = self._pushes[self._push_i]
            plant.push(int(i) - 1, (fx, fy), tz, t0 + dur)
            self._push_i += 1
        if self.has_noise:
            pose, vel = self.sense(k, t, pose, vel)
        comm = None
        if self.has_comm:
            comm, leader_pose, leader_vel = self.comm(
                k, t, stack.signals()["est_pose"], stack.signals()["est_vel"], leader_pose, leader_vel
            )
        tau = stack.step(leader_pose, leader_vel, pose, vel, comm)
        if self._lim is not None:
            tau = np.clip(tau, -self._lim, self._lim)  # the weakened motors deliver no more, per wheel
        return tau

    # ------------------------------------------------------------------ pieces
    def comm(
        self,
        k: int,
        t: float,
        est_pose: np.ndarray,
        est_vel: np.ndarray,
        leader_pose: np.ndarray,
        leader_vel: np.ndarray,
    ) -> tuple[Comm, np.ndarray, np.ndarray]:
        """The network of step ``k``: a :class:`Comm` and the leader state ``(3,)``, ``(2,)`` as received."""
        ei, et0, et1 = self._e_fail
        li, lt0, lt1 = self._l_fail
        up_e, up_l = self._up_e, self._up_l
        up_e[:] = True
        up_l[:] = True
        up_e[ei[(t >= et0) & (t < et1)]] = False
        up_l[li[(t >= lt0) & (t < lt1)]] = False
        if not self.has_recv:  # link failures only: the links that are up carry current values
            return Comm(up_e.astype(float), up_l.astype(float)), leader_pose, leader_vel
        g = self.graph
        rp, rv, rlp, rlv = self._ring
        hp, hv, hlp, hlv = self._held
        R = self.delay_steps + 1
        now = k % R
        rp[now], rv[now], rlp[now], rlv[now] = est_pose, est_vel, leader_pose, leader_vel
        if not self._started:  # before the first step there is no history: the initial values
            rp[:], rv[:], rlp[:], rlv[:] = est_pose, est_vel, leader_pose, leader_vel
            hp[:], hv[:], hlp[:], hlv[:] = est_pose[g.dst], est_vel[g.dst], leader_pose, leader_vel
            self._started = True
        on = self.w0 <= t < self.w1
        old = (k - self.delay_steps) % R if on else now  # what the links deliver this step
        if on and self.loss > 0:
            draw = self._draw
            arrivals(draw, self.loss, self.seed, counter("packet_loss", 0), k)
            got_e = draw[:-1] & up_e
            got_l = up_l & draw[-1]  # the leader's broadcast arrives for all or for none
        else:
            got_e, got_l = up_e, up_l
        np.copyto(hp, rp[old][g.dst], where=got_e[:, None])
        np.copyto(hv, rv[old][g.dst], where=got_e[:, None])
        if got_l.any():
            hlp[:], hlv[:] = rlp[old], rlv[old]
        self._valid_e = (self._valid_e | got_e) & up_e  # a link that was down counts from its first packet
        self._valid_l = (self._valid_l | got_l) & up_l
        return Comm(self._valid_e.astype(float), self._valid_l.astype(float), hp, hv), hlp, hlv

    def sense(self, k: int, t: float, pose: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pose (n, 3) and velocity (n, 2) as measured at control step ``k`` (``t = k dt``): inside the
        window, Gaussian noise of ``noise_pose``/``noise_vel`` from the counter hash (module doc) and
        the heading wrapped (new arrays); outside it the arguments themselves."""
        if not self.w0 <= t < self.w1:
            return pose, vel
        pose = np.array(pose, dtype=float)
        vel = np.array(vel, dtype=float)
        add_noise(pose, self.noise_pose, self.seed, counter("noise_pose", 0), k, 2)
        add_noise(vel, self.noise_vel, self.seed, counter("noise_vel", 0), k, -1)
        return pose, vel

    def actuate(self, t: float, stack: ControlStack) -> None:
        """Torque limits at ``t``; told to the stack when ``actuator_known`` and they change."""
        idx, t0, t1, s = self._act
        on = (t >= t0) & (t < t1)
        scale = np.ones(self.n)
        np.minimum.at(scale, idx[on], s[on])
        if np.array_equal(scale, self._scale):
            return
        self._scale = scale
        lim = self.nominal * scale
        self._lim = None if np.all(scale == 1.0) else lim[:, None]
        if self.act_known:
            stack.set_tau_max(lim)


# ---------------------------------------------------------------------------------------
# Outcome of a run under faults
# ---------------------------------------------------------------------------------------


def fault_interval(sc: Scenario, log: dict[str, np.ndarray]) -> tuple[float, float]:
    """``(t_start, t_end)`` s of the configured faults; for a friction patch, while any follower is on it."""
    fc = sc.faults
    starts: list[float] = []
    ends: list[float] = []
    for _i, _j, t0, t1 in fc.link_fail:
        starts.append(t0)
        ends.append(t1)  # noqa: E702
    if fc.packet_loss > 0 or fc.delay > 0 or any(fc.noise_pose) or any(fc.noise_vel):
        w0, w1 = fc.window if fc.window else (0.0, sc.sim.duration)
        starts.append(w0)
        ends.append(w1)  # noqa: E702
    for _i, t0, t1, _s in fc.actuator:
        starts.append(t0)
        ends.append(t1)  # noqa: E702
    for _i, t0, dur, *_f in fc.push:
        starts.append(t0)
        ends.append(t0 + dur)  # noqa: E702
    if fc.friction_patch and len(log["t"]):
        x0, y0, x1, y1, _mu = fc.friction_patch
        p = log["pose"]
        on = ((p[..., 0] >= x0) & (p[..., 0] <= x1) & (p[..., 1] >= y0) & (p[..., 1] <= y1)).any(axis=1)
        if on.any():
            t = log["t"][on]
            starts.append(float(t[0]))
            ends.append(float(t[-1]))  # noqa: E702
    if not starts:
        return (0.0, 0.0)
    return float(min(starts)), float(min(max(ends), sc.sim.duration))


def outcome(
    result: Any, tol: float = TOLERANCE, final_window: float = 2.0, interval: tuple[float, float] | None = None
) -> dict[str, Any]:
    """Measured outcome of a run under faults (all errors are formation errors, m, max over followers).

    ``before``: peak in the second before the fault; ``peak_during``: peak in the fault interval;
    ``peak_after``: peak from its end to the end of the run; ``final``: at the end; ``recovered``:
    no divergence and below ``tol`` over the last ``final_window`` s; ``recovery_s``: time after
    the fault's end until the error stays below ``tol`` (None if it never does); ``tipped_over``:
    followers (1-based) tilted more than ``TIP_ANGLE_DEG`` at the end (MuJoCo); ``spinning``: followers
    turning faster than ``SPIN_RAD_S`` at the end (the run's outcomes' thresholds, ``core/thresholds.py``:
    30°, 6 rad/s; they were 60° and 10 rad/s here, design §0). ``interval``
    overrides :func:`fault_interval` (e.g. to measure a fault-free reference run).
    """
    sc, log = result.scenario, result.log
    t0, t1 = fault_interval(sc, log) if interval is None else interval
    t = log["t"]
    fe = log["formation_error"].max(axis=1) if len(t) else np.zeros(0)

    def peak(mask: np.ndarray) -> float | None:
        return float(fe[mask].max()) if mask.any() else None

    diverged = result.diverged is not None
    upright = getattr(result.plant, "upright", None)
    tilt_cos = math.cos(math.radians(TIP_ANGLE_DEG))
    tipped = (np.flatnonzero(upright() < tilt_cos) + 1).tolist() if upright is not None else []
    T = float(t[-1]) if len(t) else 0.0
    above = np.flatnonzero((fe >= tol) & (t >= t1)) if len(t) else np.zeros(0, int)
    if diverged or (above.size and above[-1] == len(t) - 1):
        recovery = None
    else:
        recovery = float(t[above[-1] + 1] - t1) if above.size else 0.0
    last = t >= T - final_window
    recovered = (not diverged) and T >= sc.sim.duration - sc.sim.log_dt - 1e-9 and bool(fe[last].max() < tol)
    return {
        "scenario": sc.name,
        "plant": sc.plant.kind,
        "method": sc.method,
        "fault_start_s": t0,
        "fault_end_s": t1,
        "before": peak((t >= t0 - 1.0) & (t < t0)),
        "peak_during": peak((t >= t0) & (t <= t1)),
        "peak_after": peak(t > t1),
        "final": float(fe[-1]) if len(fe) else None,
        "recovered": recovered,
        "recovery_s": recovery,
        "diverged": None if not diverged else str(result.diverged),
        "tipped_over": tipped,
        "spinning": (np.flatnonzero(np.abs(log["vel"][-1, :, 1]) > SPIN_RAD_S) + 1).tolist() if len(t) else [],
        "sim_time_s": T,
    }
