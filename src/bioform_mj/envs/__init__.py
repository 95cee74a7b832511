"""Learning interfaces: the formation as a PettingZoo ``ParallelEnv`` (optional extra ``rl``).

``parallel_env(scenario, **options)`` builds :class:`~.parallel.FormationParallelEnv`, ``env``
(the same options) its AEC form (PettingZoo's ``parallel_to_aec``), ``follower_env`` one follower
as a Gymnasium ``Env`` (:class:`~.single.FollowerEnv`), ``vector_env`` many worlds on the CPU
(:class:`~.vector.VectorEnv`; :class:`~.tdict.TorchRLStyle`: TorchRL's batched keys for it and
``batch_env``); :class:`~.policy.ControllerPolicy` runs
any :class:`~bioform_mj.control.base.Controller` (the paper's four methods or a user's) as a
policy in it. Design §20; docs/envs.md.
"""

from __future__ import annotations

from bioform_mj.envs.parallel import ACTIONS, OBS_FIELDS, REWARD_WEIGHTS, FormationParallelEnv, parallel_env
from bioform_mj.envs.policy import ControllerPolicy, run_episode
from bioform_mj.envs.randomize import KEYS as RANDOMIZE_KEYS
from bioform_mj.envs.single import FollowerEnv, follower_env


def env(scenario="paper", **options):
    """The formation as a PettingZoo ``AECEnv`` (``parallel_to_aec`` of :func:`parallel_env`, the same
    options; PettingZoo's ``env()`` convention): the followers act in turn, one control period per cycle."""
    from pettingzoo.utils import parallel_to_aec

    return parallel_to_aec(parallel_env(scenario, **options))


aec_env = env


def vector_env(*args, **kwargs):
    """Many formations on the CPU in compiled code, threads over worlds (:func:`.vector.vector_env`)."""
    from bioform_mj.envs.vector import vector_env as _vector_env

    return _vector_env(*args, **kwargs)


def batch_env(*args, **kwargs):
    """The batched environment on MuJoCo Warp (:func:`.batch.batch_env`; optional extra ``gpu``)."""
    from bioform_mj.envs.batch import batch_env as _batch_env

    return _batch_env(*args, **kwargs)


__all__ = [
    "ACTIONS",
    "OBS_FIELDS",
    "RANDOMIZE_KEYS",
    "FollowerEnv",
    "aec_env",
    "env",
    "follower_env",
    "REWARD_WEIGHTS",
    "ControllerPolicy",
    "batch_env",
    "FormationParallelEnv",
    "parallel_env",
    "run_episode",
    "vector_env",
]
