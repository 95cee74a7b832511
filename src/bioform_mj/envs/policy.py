"""A :class:`~bioform_mj.control.base.Controller` as a policy of the formation environment (design §20).

The paper's four methods (and any user controller) are centralised objects that compute every
follower's torques at once from what each follower may read (the leader only through
``a_ir``); :class:`ControllerPolicy` gives them the environment's measurements and the
leader's state, and returns their torques as the agents' actions (``action = "torque"``). An
episode of it is the run ``bioform run`` makes of the same scenario: same plant, same order
(control at ``t_k`` from the state at ``t_k``, held over the period), so the summaries agree
(``tests/test_envs.py`` states the tolerance).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bioform_mj.control.stack import ControlStack
from bioform_mj.envs.fast import FAST, Compiled, make_policy_args, policy_call
from bioform_mj.envs.parallel import FormationParallelEnv


class ControllerPolicy:
    """Runs ``controller`` (default: the paper's stack for the scenario's method) in ``env``.

    ``action = "torque"``: its wheel torques (``bioform run``'s episode). ``action = "velocity"``:
    its kinematic law's command ``(υ_cmd, ω_cmd)`` (the ``cmd`` of ``controller.signals()``),
    clipped to the action space, which the environment's own torque law then tracks (a baseline
    for a velocity-action agent, and the other followers of :class:`~.single.FollowerEnv`)."""

    def __init__(self, env: FormationParallelEnv, controller: Any = None) -> None:
        self.env = env
        self.controller = controller
        self.verr = np.zeros(env.n)
        self._fast: Any = None

    def __getstate__(self) -> dict[str, Any]:
        """Everything but the compiled call's arguments (a numba structref: not picklable; built again)."""
        return {**self.__dict__, "_fast": None}

    def reset(self) -> None:
        """After ``env.reset``: the controller's initial estimates, as ``bioform run`` sets them."""
        from bioform_mj.control.base import TorqueLimited
        from bioform_mj.control.params import stack_params
        from bioform_mj.control.stack import ControlStack
        from bioform_mj.run.simulate import initial_estimates  # the run package registers the opt-in sizing

        env = self.env
        if self.controller is None or isinstance(self.controller, ControlStack):
            p = env._plant
            c = getattr(env, "nominal_c_true", None)  # the prior of the scenario's robot, not a randomised truth
            c = p.c_true() if c is None else c
            self.controller = ControlStack(
                env.graph, stack_params(env._sc, c, p.tau_max if isinstance(p, TorqueLimited) else None)
            )
        self.controller.reset(initial_estimates(env._sc, env._pose, env.L_pose[0]), env._vel)  # as sim.simulate
        self.verr[:] = 0.0
        self._fast = None

    def __call__(self, obs: Any = None) -> dict[str, np.ndarray]:
        """The actions of every live agent for this control step."""
        env = self.env
        if FAST and env._faults is None and type(self.controller) is ControlStack:  # one compiled call (envs/fast.py)
            return self._stack_step(env)
        lp, lv = env.leader_state()
        mp, mv = env.measured_state()
        f = env._faults
        if f is not None and f.has_act and f.act_known and hasattr(self.controller, "set_tau_max"):
            self.controller.set_tau_max(np.array(env._g.lim))  # the limits the faults told the stack
        comm = env.network()
        if comm is None:
            tau = self.controller.step(lp, lv, mp, mv)
        else:
            tau = self.controller.step(lp, lv, mp, mv, comm)
        tau = np.asarray(tau, dtype=float)
        cmd = self.controller.signals().get("cmd") if hasattr(self.controller, "signals") else None
        if cmd is not None:  # Table I's metric, as engine.accumulate sums it (true velocities)
            v = env._vel
            self.verr += np.abs(cmd[:, 0] - v[:, 0]) + np.abs(cmd[:, 1] - v[:, 1])
        else:
            self.verr[:] = np.nan
        if env.action_mode == "velocity":
            if cmd is None:
                raise ValueError(
                    "ControllerPolicy with action='velocity' needs a controller whose signals() give 'cmd'"
                )
            u = np.clip(np.asarray(cmd, dtype=float), env._low, env._high)
            return {a: u[env._index[a]].copy() for a in env.agents}
        return {a: tau[env._index[a]].copy() for a in env.agents}

    def _stack_step(self, env: FormationParallelEnv) -> dict[str, np.ndarray]:
        """:meth:`__call__` for the paper's stack on the perfect network: ``ControlStack.step``'s
        ``control_step`` and the metric's sum in one compiled call, the same numbers."""
        st = self.controller
        if self._fast is None:
            g, s = st.kernel
            a = make_policy_args(g, s, st.comm_in(None), self.verr)
            self._fast = (a, Compiled(policy_call, (a, env._lp_rx, env._lv_rx, env._mp, env._mv, env._vel,
                                                              np.empty((env.n, 2)))).call)  # fmt: skip
        tau = np.empty((env.n, 2))
        a, call = self._fast
        call(a, env._lp_rx, env._lv_rx, env._mp, env._mv, env._vel, tau)
        if env.action_mode == "velocity":
            tau = np.clip(st.state.cmd, env._low, env._high)
        return dict(zip(env.agents, tau)) if len(env.agents) == env.n else {a: tau[env._index[a]] for a in env.agents}


def run_episode(env: FormationParallelEnv, policy: Any, seed: int | None = None) -> dict[str, Any]:
    """One episode of ``policy`` (a :class:`ControllerPolicy`, or any ``obs dict -> action dict``
    callable) in ``env``; returns :meth:`FormationParallelEnv.episode_summary` with the episode's
    return per agent (``return``)."""
    obs, _ = env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset()
    ret = dict.fromkeys(env.possible_agents, 0.0)
    while env.agents:
        obs, rew, _term, _trunc, _info = env.step(policy(obs))
        for a, r in rew.items():
            ret[a] += r
    ctrl = getattr(policy, "controller", None)
    summary = env.episode_summary(ctrl)
    if isinstance(policy, ControllerPolicy):
        for f, v in zip(summary["followers"], policy.verr):
            f["total_velocity_error"] = float(v * env.dt)
    for f, a in zip(summary["followers"], env.possible_agents):
        f["return"] = ret[a]
    return summary
