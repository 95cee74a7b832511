#!/usr/bin/env python3
"""A user-written formation controller, compared with the paper's four methods.

Kanayama et al. (1990) tracking kinematics on the reference that the paper's distributed
estimator provides, and a plain proportional velocity loop with feed-forward for the wheel
torques, using the nominal parameters ``ĉ(0)`` (no learning, no sliding mode):

    υ_cmd = υ_ir cos θ̃ + kx x̃          ω_cmd = ω_ir + υ_ir (ky ỹ + kθ sin θ̃)
    τ_a = (kv (υ_cmd − υ)) / â0         τ_b = (kw (ω_cmd − ω)) / b̂0

It implements the ``Controller`` protocol (control/base.py) and reuses the package's own
estimator kernel and equations; nothing of the loop is copied. It honours the scenario options a
controller of this kind meets: offsets in the leader's frame (``formation.frame = "leader"``: it
tracks the slot's own pose and velocity, ``slot_reference``, design §4), the saturation mode
(``torque.saturation``), actuator faults the controller is told of (``set_tau_max``) and the
network's faults (the estimator's ``comm``). The paper's controller gains (``kinematic``,
``torque``, ``learner``) are not this controller's: they apply to the four methods it is compared
with. Run:

    .venv/bin/python examples/kanayama.py [SCENARIO] [--plant ideal|mujoco] [--duration S] [--out DIR]

(``SCENARIO``: a preset or TOML file, default ``paper``). It prints, and writes to
``DIR/table.md``, the Table I metric and the final formation error of this controller beside the
paper's four methods, in ``bioform table1``'s format. Bad input: one ``error:`` line, exit 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from bioform_mj.control.base import Comm
from bioform_mj.control.kernel import estimator_update, reset_state
from bioform_mj.control.stack import METHODS, ControlStack
from bioform_mj.core.equations import saturate, slot_reference, tracking_error
from bioform_mj.core.errors import InputError
from bioform_mj.run.simulate import make_plant, simulate, stack_params
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.loader import load


class Kanayama:
    """Kanayama tracking + proportional velocity loop, fed by the paper's distributed estimator."""

    def __init__(
        self,
        sc: Scenario,
        c_true: np.ndarray,
        tau_max: np.ndarray,
        kx: float = 2.0,
        ky: float = 8.0,
        kth: float = 4.0,
        kv: float = 10.0,
        kw: float = 10.0,
    ) -> None:
        self.n = sc.n
        # the paper's estimator: its gains and state come from the package's own stack
        self._est = ControlStack(sc.build_graph(), stack_params(sc, c_true, tau_max))
        self.gains, self.state = self._est.kernel
        self.c0 = np.asarray(sc.learner.c_hat0_scale) * c_true  # nominal [â, b̂], as the paper's stack starts
        self.steer = sc.torque.saturation == "steer-priority"  # the scenario's saturation mode (design §5)
        self.k = (kx, ky, kth, kv, kw)
        self.cmd = np.zeros((self.n, 2))
        self.tau = np.zeros((self.n, 2))
        self.tau_raw = np.zeros((self.n, 2))
        self.saturated = np.zeros(self.n, dtype=bool)

    def reset(self, est_pose0: np.ndarray, vel0: np.ndarray) -> None:
        reset_state(
            self.gains,
            self.state,
            np.ascontiguousarray(est_pose0, dtype=float),
            np.ascontiguousarray(vel0, dtype=float),
            np.ascontiguousarray(self.c0, dtype=float),
        )

    def step(self, leader_pose, leader_vel, pose, vel, comm: Comm | None = None) -> np.ndarray:
        kx, ky, kth, kv, kw = self.k
        s, g = self.state, self.gains
        for i in range(self.n):
            if g.leader_frame:  # offsets in the leader's frame: the slot's own pose and velocity (design §4)
                xs, ys, ths, v_ref, w_ref = slot_reference(*s.est_pose[i], *s.est_vel[i], *g.offsets[i])
                ex, ey, eth = tracking_error(xs, ys, ths, *pose[i], 0.0, 0.0)
            else:  # world-frame offsets (the paper): the slot moves with the leader's velocity
                ex, ey, eth = tracking_error(*s.est_pose[i], *pose[i], *g.offsets[i])
                v_ref, w_ref = s.est_vel[i]
            self.cmd[i] = (v_ref * np.cos(eth) + kx * ex, w_ref + v_ref * (ky * ey + kth * np.sin(eth)))
            ta = kv * (self.cmd[i, 0] - vel[i, 0]) / self.c0[i, 0]
            tb = kw * (self.cmd[i, 1] - vel[i, 1]) / self.c0[i, 1]
            self.tau_raw[i] = (0.5 * (ta - tb), 0.5 * (ta + tb))  # τ_b = τ_R − τ_L (design §5)
            lim = g.lim[i]
            self.saturated[i] = np.abs(self.tau_raw[i]).max() > lim
            self.tau[i] = saturate(self.tau_raw[i, 0], self.tau_raw[i, 1], lim, self.steer)
        estimator_update(g, s, np.asarray(leader_pose, float), np.asarray(leader_vel, float), self._est.comm_in(comm))
        return self.tau

    def signals(self) -> dict[str, np.ndarray]:
        s = self.state
        return {
            "est_pose": s.est_pose,
            "est_vel": s.est_vel,
            "cmd": self.cmd,
            "tau_raw": self.tau_raw,
            "saturated": self.saturated,
        }

    def set_tau_max(self, tau_max: np.ndarray) -> None:
        self.gains.lim[:] = tau_max


def compare(
    plant: str | None = "ideal", duration: float | None = None, scenario: str = "paper", overrides=()
) -> dict[str, dict]:
    """Summaries of the four methods and of :class:`Kanayama` on ``scenario`` (a preset or TOML file)."""
    ov = list(overrides) + ([] if duration is None else [f"sim.duration={duration}"])
    sc = load(scenario, ov, plant=plant)  # validated first: bad input before any run
    out = {m: simulate(load(scenario, ov, method=m, plant=plant)).summary for m in METHODS}
    pl = make_plant(sc)
    ctrl = Kanayama(sc, pl.c_true(), getattr(pl, "tau_max", np.full(sc.n, sc.torque.tau_max)))
    out["kanayama (examples/)"] = simulate(sc, plant=pl, controller=ctrl).summary
    return out


def table(summaries: dict[str, dict]) -> str:
    """Markdown: Table I metric and final formation error per follower, per controller."""
    n = len(next(iter(summaries.values()))["followers"])
    head = "| controller | " + " | ".join(f"J{i + 1}" for i in range(n)) + " | final formation error (m) | outcome |\n"
    head += "|---|" + "---|" * n + "---|---|\n"
    rows = []
    for name, s in summaries.items():
        f = s["followers"]
        mark = " (diverged)" if s["diverged"] else ""
        rows.append(
            f"| {name}{mark} | "
            + " | ".join(f"{x['total_velocity_error']:.2f}" for x in f)
            + " | "
            + ", ".join(f"{x['final_formation_error_m']:.3f}" for x in f)
            + " | "
            + ", ".join(x["outcome"] for x in f)
            + " |"
        )
    return head + "\n".join(rows) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default="paper", help="preset name or TOML file (default: paper)")
    ap.add_argument("--plant", choices=("ideal", "mujoco"), help="plant (default: the scenario's)")
    ap.add_argument("--duration", type=float)
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", type=Path, default=Path("runs/kanayama"))
    args = ap.parse_args()
    try:
        md = table(compare(args.plant, args.duration, args.scenario, args.overrides))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(md)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(md)


if __name__ == "__main__":
    main()
