"""``batch_env``: the formation environment batched on MuJoCo Warp (optional extra ``gpu``; design §20)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from bioform_mj.scenario.config import Scenario


def batch_env(
    scenario: str | Path | Scenario = "paper",
    worlds: int = 8,
    device: str = "cpu",
    *,
    seeds: Any = None,
    overrides: Any = None,
    **options: Any,
):
    """``worlds`` formations of ``scenario`` stepped together on a MuJoCo Warp ``device`` (``"cpu"``,
    ``"cuda:0"`` …): a :class:`~bioform_mj.envs.batched.BatchEnv` with the observation and action layout of
    :func:`~bioform_mj.envs.parallel_env`, per world and agent. World ``w`` runs ``sim.seed = seeds[w]``
    (default ``0 … worlds − 1``: the seeded jitter of the initial poses). ``options``: ``action``,
    ``reward``, ``v_max``, ``w_max``, ``nconmax``, ``njmax``."""
    from bioform_mj.scenario.loader import checked, load

    if isinstance(scenario, Scenario):
        if overrides:
            raise ValueError("overrides= needs a preset name or TOML path, not a Scenario object")
        sc = checked(scenario)  # as simulate (design §18.1)
    else:
        sc = load(scenario, overrides)
    W = int(worlds)
    if W < 1:
        raise ValueError(f"worlds must be >= 1, got {worlds}")
    from bioform_mj.batch.backend import world_bytes

    # the memory first, from every number that sizes it (worlds, robots, nconmax, njmax): before the seed
    # list or any array (worlds=10**9 built a list of 10**9 seeds and died in a bare MemoryError, issue 28)
    cap = {k: options.get(k) for k in ("nconmax", "njmax")}
    for k, v in cap.items():
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise ValueError(f"batch_env: {k} must be an integer >= 1, got {v!r}")
    _check_memory(W * world_bytes(sc.n, cap["nconmax"], cap["njmax"]), device)
    seeds = list(range(W)) if seeds is None else [int(s) for s in seeds]
    if len(seeds) != W:
        raise ValueError(f"{len(seeds)} seeds for {W} worlds")
    try:
        from bioform_mj.envs.batched import BatchEnv
    except ImportError as exc:  # pragma: no cover - without the extra
        raise ImportError("batch_env needs the optional extra 'gpu': pip install -e '.[gpu]'") from exc
    scs = [dataclasses.replace(sc, sim=dataclasses.replace(sc.sim, seed=s)) for s in seeds]
    return BatchEnv(scs, device, **options)


def _check_memory(need: float, device: str) -> None:
    """Refuse a batch whose estimated device memory exceeds what is free (host memory for ``cpu``)."""
    if device == "cpu":
        try:
            with open("/proc/meminfo") as fh:
                avail = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable"))
        except (OSError, StopIteration):
            return
    else:
        import warp as wp

        avail = wp.get_device(device).free_memory
    if need > 0.8 * avail:
        raise ValueError(
            f"batch_env: ~{need / 2**30:.1f} GiB estimated for the worlds (with their nconmax/njmax), "
            f"{avail / 2**30:.1f} GiB free; fewer worlds or a smaller nconmax/njmax"
        )
