"""``bioform robot drive-program``: the wheel torques to record for ``robot fit`` (issue 29, design §8).

Zero-mean pulse pairs: a torque pattern held for 0.2–0.5 s, then its negative as long (the robot slows back
towards rest), then a pause; amplitudes 30–100 % of the program's torque. The patterns (:data:`PATTERNS`)
come in rounds: each round drives every pattern once in each sign, in a shuffled order, so that even a short
recording holds all of them:

- both wheels forward or back: accelerations (mass), speeds of both signs (damping, dry friction);
- turns on the spot either way: yaw inertia;
- one wheel alone (a pivot about the other) and uneven pairs (arcs), each of both signs: what tells a
  dragging caster from the wheels' own dry friction. Driving straight or turning on the spot, a caster
  that trails the axle by about the half track brakes each wheel as a dry friction of its own would
  (tb3: 81 mm against 80 mm); on a pivot the caster slides at 45° and brakes the moving wheel about 1.4×
  as much and the still one not at all, and on an arc the split depends on the two speeds' ratio, while a
  wheel's dry friction depends on its own sense of turning only.

The torque is the smallest of: half the motor limit, a third of the traction limit, and the torque that
accelerates the robot at ``accel`` m/s² (default 1) — gentle enough that it neither slips nor tips (a robot
that lifts a wheel makes a recording no rigid model can follow). A robot whose wheels do not turn under it
(a dragging caster, stiff gearboxes) needs a larger ``accel``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PATTERNS", "drive_program", "program_torque"]

#: the torque patterns (left, right; × the amplitude and a sign): straight, a turn on the spot, one wheel
#: alone (left, right), uneven pairs (arcs either way)
PATTERNS = np.array([[1, 1], [1, -1], [1, 0], [0, 1], [1, 0.5], [0.5, 1]], float)


def program_torque(params, accel: float = 1.0) -> float:
    """The program's torque (N·m) for :class:`~bioform_mj.robots.params.RobotParams` ``params``."""
    traction = params.traction_torque(1.0, params.mass * 9.81 / 2)
    by_accel = accel / (2.0 * params.a_eff)  # υ̇ = 2 τ a_eff with both wheels
    return float(min(0.5 * min(params.tau_max), traction / 3.0, by_accel))


def drive_program(tau: float, seconds: float = 60.0, rate_hz: float = 100.0, seed: int = 0) -> np.ndarray:
    """``(n, 3)``: time (s), left and right wheel torque (N·m, forward positive), at ``rate_hz``."""
    rng = np.random.default_rng(seed)
    combos = [(k, s) for k in range(len(PATTERNS)) for s in (1.0, -1.0)]
    queue: list[tuple[int, float]] = []
    t_edges, u_edges = [0.0], [np.zeros(2)]
    t = 0.5
    while t < seconds - 0.5:
        if not queue:  # a new round: every pattern once in each sign, shuffled
            queue = [combos[i] for i in rng.permutation(len(combos))]
        k, s = queue.pop()
        u = PATTERNS[k] * tau * rng.uniform(0.3, 1.0) * s
        d = rng.uniform(0.2, 0.5)
        t_edges += [t, t + d, t + 2 * d]
        u_edges += [u, -u, np.zeros(2)]
        t += 2 * d + rng.uniform(0.2, 0.5)
    te, ue = np.array(t_edges), np.array(u_edges)
    tt = np.arange(0.0, seconds + 1e-9, 1.0 / rate_hz)
    uu = ue[np.searchsorted(te, tt, side="right") - 1]
    uu[tt >= seconds - 0.5] = 0.0
    return np.column_stack([tt, uu])
