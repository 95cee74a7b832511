"""Learning interfaces: the formation as a PettingZoo ``ParallelEnv`` (optional extra ``rl``).

``parallel_env(scenario, **options)`` builds :class:`~.parallel.FormationParallelEnv`;
:class:`~.policy.ControllerPolicy` runs any :class:`~bioform_mj.control.base.Controller`
(the paper's four methods or a user's) as a policy in it. Design §20; docs/envs.md.
"""

from __future__ import annotations

from bioform_mj.envs.parallel import ACTIONS, OBS_FIELDS, REWARD_WEIGHTS, FormationParallelEnv, parallel_env
from bioform_mj.envs.policy import ControllerPolicy, run_episode


def batch_env(*args, **kwargs):
    """The batched environment on MuJoCo Warp (:func:`.batch.batch_env`; optional extra ``gpu``)."""
    from bioform_mj.envs.batch import batch_env as _batch_env

    return _batch_env(*args, **kwargs)


__all__ = [
    "ACTIONS",
    "OBS_FIELDS",
    "REWARD_WEIGHTS",
    "ControllerPolicy",
    "batch_env",
    "FormationParallelEnv",
    "parallel_env",
    "run_episode",
]
