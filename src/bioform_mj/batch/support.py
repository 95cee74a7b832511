"""What the batch engine supports and the capacities it allocates: shared by :mod:`.backend` (sweep and
bench glue, refusals before any work) and :mod:`.runner` (the batch itself), below both, so neither
imports the other to get them. Pure Python: no Warp needed.
"""

from __future__ import annotations

from typing import Any


def default_capacity(n_robots: int) -> tuple[int, int]:
    """MuJoCo Warp's default ``(nconmax, njmax)`` per world for ``n_robots`` robots (contacts,
    constraint rows): what :class:`~.runner.BatchRun` uses when not told."""
    return 8 * n_robots + 16, 32 * n_robots + 16


def unsupported(sc: Any) -> str | None:
    """What of scenario ``sc`` the batch engine does not run yet (None: all of it)."""
    from bioform_mj.control.stack import METHODS  # loaded with the scenario already (this module stays light)

    if sc.method not in METHODS:  # design §22: a registered controller runs in Python, one robot team at a time
        return f"method = '{sc.method}' (a registered controller; the batch engine runs the paper's four methods only)"
    if sc.plant.kind != "mujoco":
        return (
            f"plant.kind = '{sc.plant.kind}' (the batch engine runs the MuJoCo plant only; "
            "use --plant mujoco or --backend local)"
        )
    f = sc.faults
    if f.friction_patch:
        return (
            "faults.friction_patch (MuJoCo Warp's wheel-on-box contacts differ from C MuJoCo's: one physics step "
            "from the same state on the patch, velocities differ by up to 35x, against ~1e-6 on the floor; "
            "use --backend local)"
        )
    if getattr(sc.learner, "drag", False):
        return "learner.drag (the learned-drag extension runs on the local engines only; use --backend local)"
    if getattr(sc.torque, "resistance_margin", 0.0) > 0 or getattr(sc.learner, "kd_deadband", ()):
        return (
            "torque.resistance_margin / learner.kd_deadband (sized to robot check's identification: the local engines "
            "only, design §14.4; use --backend local)"
        )
    if getattr(sc.plant, "sensing", "truth") not in ("truth", "odometry"):
        return f"plant.sensing = '{sc.plant.sensing}'"
    if getattr(sc, "obstacles", ()) or getattr(getattr(sc, "obstacle_field", None), "count", 0):
        return "obstacles (design §19: the batch engine has no obstacles nor a contact watch yet; use --backend local)"
    if getattr(getattr(sc, "safety", None), "filter", "none") != "none":
        return "safety.filter (the batch engine has no safety filter yet; use --backend local)"
    if getattr(getattr(sc, "safety", None), "distance", 0.0) > 0:
        return "safety.distance (the batch engine has no proximity watch yet; use --backend local)"
    return None
