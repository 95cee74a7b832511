"""A sweep's ROS 2 bags (``bioform sweep … --rosbag``, issue 29): the checks before any work and the
clean-up of what an interrupted run left (:mod:`bioform_mj.jobs.sweep` writes one bag per row,
``DIR/bags/<key>/``)."""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bioform_mj.core.errors import InputError

__all__ = ["BAG_BYTES_PER_MESSAGE", "bag_bytes", "check_bags", "clean_bags"]

#: bytes of one bag message, measured (paper scenario, MuJoCo: 13.5 MB for 30 010 messages), with margin
BAG_BYTES_PER_MESSAGE = 600


def bag_bytes(sc: Any) -> float:
    """Estimated bytes of one run's bag: per state sample (``duration/log_dt + 1``) ``/clock``, ``/tf``, the
    leader and six topics per follower, :data:`BAG_BYTES_PER_MESSAGE` each."""
    samples = sc.sim.duration / sc.sim.log_dt + 1
    return samples * (3 + 6 * sc.n) * BAG_BYTES_PER_MESSAGE


def check_bags(specs: Sequence[Any], out: Path, backend: str, distro: str) -> None:
    """``--rosbag`` before any work: not on the warp backend (it keeps no 3-D state), the ``ros`` extra
    installed, ``distro`` known, and the bags' estimated size (:func:`bag_bytes`) within the free disk."""
    from bioform_mj.core.budget import fmt_bytes
    from bioform_mj.outputs.rosbag import DISTROS, check_available

    if backend == "warp":
        raise InputError("--rosbag: the warp backend keeps no 3-D state to write; use --backend local or ray")
    if distro not in DISTROS:
        raise InputError(f"unknown ROS 2 distribution '{distro}' (expected one of: {', '.join(DISTROS)})")
    check_available()
    need = sum(bag_bytes(sp.scenario) for sp in specs if sp.scenario is not None)
    probe = out if out.exists() else out.parent if out.parent.exists() else Path(".")
    free = shutil.disk_usage(probe).free
    if need > free:
        raise InputError(
            f"--rosbag: {len(specs)} bags need about {fmt_bytes(need)} and {probe} has {fmt_bytes(free)} free; "
            "free space or sweep fewer runs"
        )


def clean_bags(bags: Path) -> int:
    """Remove what an interrupted or killed run left in ``bags``: temporary folders (``.<key>.XXXX.tmp``,
    :func:`bioform_mj.outputs.rosbag.write_bag`); the sweep holds the folder's lock. Returns how many."""
    if not bags.is_dir():
        return 0
    left = [p for p in bags.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")]
    for p in left:
        shutil.rmtree(p, ignore_errors=True)
    return len(left)
