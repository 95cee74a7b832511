"""``bioform sweep --backend warp``: the runs of a sweep as worlds of MuJoCo Warp batches.

Importing this module imports nothing optional: :func:`require_warp` says how to install
the extra, :func:`plan` checks every spec (supported features, one group per distinct
scene, device memory) before any work, :func:`run_warp` runs the groups one batch each and
hands back one sweep row per run (the columns of ``sweep.run_one``).

Worlds are grouped by what a batch must share (:func:`group_key`): the plant (robots,
``c_true``, …), the time axis (``control_dt``, ``physics_dt``, ``duration``), the leader, the
graph and the team size (the plant includes ``plant.sensing`` and the sensor keys: a scene has
the odometry's sensors or not). Everything else (seed, so the gyro noise, gains, formation offsets
and jitter, disturbance, limits, method, the offsets' frame, timed payload events, actuator faults,
pushes, network faults and sensor noise) varies per world.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from bioform_mj.batch.support import default_capacity, unsupported
from bioform_mj.core.errors import InputError

INSTALL = "pip install 'bioform-mj[gpu]'"

#: Peak device bytes per world during ``mjw.step`` (docs/warp_engine.md, measured with
#: ``wp.ScopedMemoryTracker``): 255 KB for 3 robots, 3.6 MB for 64 → a + b n.
WORLD_BYTES_BASE = 90e3
WORLD_BYTES_PER_ROBOT = 55e3
#: controller state, gains and metrics per robot (float64), and per world
CONTROL_BYTES_PER_ROBOT = 1e3
#: the delay's ring of past estimates (``control.CommFaults``): float64 pose and velocity per robot
#: and row, plus the leader's, per world (rows: the batch's largest delay in control steps + 1)
RING_BYTES_PER_ROBOT_ROW = 40
RING_BYTES_PER_ROW = 40
#: payload events: bytes per robot per model row (``control.EVENT_FIELDS`` in float32 and the
#: effective mass/inertia in float64; measured 336 B for the paper scene, 283 B for ``large64``)
EVENT_BYTES_PER_ROBOT_ROW = 400.0
#: share of the free memory a batch may plan to use
MEMORY_SHARE = 0.9
#: device bytes per contact and per constraint row of a world's capacity beyond the defaults
#: (``--nconmax``/``--njmax``): MuJoCo Warp's ``put_data`` arrays measured at 168 B per contact and
#: 163-188 B per row (nv 24-512), with margin for the solver's per-row work arrays (design §16)
CONTACT_BYTES = 250.0
ROW_BYTES = 300.0


def capacity_redo(row: dict[str, Any], backend: str, nconmax: int | None, njmax: int | None) -> str | None:
    """A finished sweep row that stopped on MuJoCo Warp's capacity (``capacity_exceeded``) is
    redone when the resumed sweep would run it with other capacities (or on another backend):
    returns why, or None to keep the row."""
    if not row.get("capacity_exceeded"):
        return None
    if backend != "warp":
        return f"it stopped on MuJoCo Warp's capacity and now runs on the {backend} backend"
    n = int(row.get("n_robots") or 0)
    dc, dj = default_capacity(n)
    now = (dc if nconmax is None else nconmax, dj if njmax is None else njmax)
    was = (row.get("batch_nconmax"), row.get("batch_njmax"))
    if now != was:
        return (
            f"it stopped on MuJoCo Warp's capacity with nconmax {was[0]}, njmax {was[1]}; "
            f"now nconmax {now[0]}, njmax {now[1]}"
        )
    return None


def quiet_warp() -> None:
    """Silence Warp's informational lines (its greeting, one ``Module … load on device`` line per
    kernel module: ~50 on stdout per sweep, with or without ``--quiet``); its warnings stay.
    Warp 1.19 reads ``config.log_level`` (``config.quiet`` is gone); older ones ``config.quiet``
    (design §17)."""
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = max(int(getattr(wp.config, "log_level", 0)), int(getattr(wp, "LOG_WARNING", 30)))


def require_warp() -> None:
    """InputError (exit 2) unless ``warp`` and ``mujoco_warp`` import (Warp silenced: :func:`quiet_warp`)."""
    try:
        import warp  # noqa: F401

        quiet_warp()  # before mujoco_warp, whose import may initialise Warp
        import mujoco_warp  # noqa: F401
    except ImportError as exc:
        raise InputError(
            f"--backend warp needs the optional GPU extra (mujoco-warp, warp-lang): {INSTALL} ({exc})"
        ) from None


def resolve_device(device: str | None) -> str:
    """The Warp device to use: ``device`` checked, or ``cuda:0`` when there is one, else ``cpu``."""
    import warp as wp

    quiet_warp()
    if device is None:
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    try:
        return str(wp.get_device(device))
    except (RuntimeError, ValueError) as exc:
        names = ", ".join(str(d) for d in wp.get_devices())
        raise InputError(f"--device '{device}': not a Warp device here ({exc}; available: {names})") from None


def group_key(sc: Any) -> str:
    """What the worlds of one batch share (one composed scene, one time axis, one leader, one graph).
    Not ``events``: payloads change each world's own batched model fields (``control._events``)."""
    d = sc.to_dict()
    return json.dumps(
        {
            "plant": d["plant"],
            "friction_patch": list(sc.faults.friction_patch),  # part of the composed scene
            "control_dt": sc.sim.control_dt,
            "physics_dt": sc.sim.physics_dt,
            "duration": sc.sim.duration,
            "leader": d["leader"],
            "graph": d["graph"],
            "n": sc.n,
        },
        sort_keys=True,
        default=repr,
    )


def world_bytes(n_robots: int, nconmax: int | None = None, njmax: int | None = None) -> float:
    """Estimated peak device bytes of one world of ``n_robots`` followers (see the constants), with
    ``nconmax`` contacts and ``njmax`` constraint rows per world (None: :func:`default_capacity`)."""
    dc, dj = default_capacity(n_robots)
    extra = CONTACT_BYTES * max(0, (nconmax or dc) - dc) + ROW_BYTES * max(0, (njmax or dj) - dj)
    return WORLD_BYTES_BASE + (WORLD_BYTES_PER_ROBOT + CONTROL_BYTES_PER_ROBOT) * n_robots + extra


def free_memory(device: str) -> int:
    """Free bytes on ``device``: CUDA from the driver (Warp), the CPU from /proc/meminfo or psutil."""
    import warp as wp

    dev = wp.get_device(device)
    if dev.is_cuda:
        return int(dev.free_memory)
    from bioform_mj.core.budget import available_memory

    return available_memory()  # MemAvailable, or the cgroup's limit when lower


@dataclass
class Group:
    """One batch: specs sharing a scene."""

    key: str
    specs: list
    n: int
    ring_rows: int = 1  # the batch's largest faults.delay in control steps + 1
    events: int = 0  # the most payload events of one of its worlds
    nconmax: int | None = None  # contacts / constraint rows per world (None: the defaults)
    njmax: int | None = None

    @property
    def world_bytes(self) -> float:
        """Estimated peak device bytes of one of its worlds (with the delay's ring and, with events,
        the per-world model rows: ``control.event_tables`` (E + 1 rows) and the batched fields)."""
        ev = (self.events + 2) * EVENT_BYTES_PER_ROBOT_ROW * self.n if self.events else 0.0
        ring = self.ring_rows * (RING_BYTES_PER_ROW + RING_BYTES_PER_ROBOT_ROW * self.n)
        return world_bytes(self.n, self.nconmax, self.njmax) + ring + ev

    @property
    def bytes(self) -> float:
        return len(self.specs) * self.world_bytes


def plan(specs: Sequence[Any], device: str, nconmax: int | None = None, njmax: int | None = None) -> list[Group]:
    """Check ``specs`` (with resolved scenarios) for the batch engine and group them; InputError
    naming the first unsupported feature, or the memory estimate of a batch that does not fit
    (with ``nconmax`` contacts and ``njmax`` constraint rows per world; None: the defaults)."""
    from bioform_mj.scenario.loader import load

    if specs:  # the capacity alone, before any scene is built: --nconmax 1e9 must not reach put_data
        free = free_memory(device)
        sc0 = specs[0].scenario
        n0 = sc0.n if sc0 is not None else 1
        one = world_bytes(n0, nconmax, njmax)
        if one > MEMORY_SHARE * free:
            raise InputError(
                f"--backend warp: one world of {n0} robots with nconmax {nconmax or default_capacity(n0)[0]}, "
                f"njmax {njmax or default_capacity(n0)[1]} needs about {one / 1e9:.3g} GB on {device} "
                f"({CONTACT_BYTES:g} B per contact, {ROW_BYTES:g} B per constraint row, estimated), "
                f"{free / 1e9:.2f} GB free; lower --nconmax/--njmax"
            )
    groups: dict[str, Group] = {}
    for sp in specs:
        sc = (
            sp.scenario
            if sp.scenario is not None
            else load(sp.source, list(sp.overrides), method=sp.method, plant=sp.plant)
        )
        why = unsupported(sc)
        if why is not None:
            raise InputError(
                f"--backend warp: the batch engine does not support {why} yet "
                f"(run {sp.method}, seed {sp.seed}); use --backend local"
            )
        k = group_key(sc)
        if k not in groups:  # a new scene: its physics on MuJoCo Warp must be C MuJoCo's
            from bioform_mj.batch.probe import check_physics

            try:
                check_physics(sc, device)
            except ValueError as exc:
                raise InputError(f"--backend warp: {exc}; use --backend local") from None
        g = groups.setdefault(k, Group(k, [], sc.n, nconmax=nconmax, njmax=njmax))
        g.specs.append(sp)
        if sc.faults.delay > 0:
            g.ring_rows = max(g.ring_rows, int(round(sc.faults.delay / sc.sim.control_dt)) + 1)
        g.events = max(g.events, len(sc.events))
    out = list(groups.values())
    if out:
        free = free_memory(device)
        big = max(out, key=lambda g: g.bytes)
        if big.bytes > MEMORY_SHARE * free:
            fit = int(MEMORY_SHARE * free // big.world_bytes)
            raise InputError(
                f"--backend warp: {len(big.specs)} worlds of {big.n} robots need about "
                f"{big.bytes / 1e9:.2f} GB on {device} ({big.world_bytes / 1e3:.0f} KB per world, "
                f"estimated), {free / 1e9:.2f} GB free: at most {fit} worlds fit; "
                "split the sweep (fewer --seeds or --vary values)"
            )
    return out


def rows_from_summaries(
    specs: Sequence[Any],
    summaries: Sequence[dict],
    base_row: Callable[[Any], dict],
    metrics: Sequence[str],
    batch_wall: float,
    device: str,
    capacity: tuple[int, int] | None = None,
) -> list[dict[str, Any]]:
    """One sweep row per world, with ``sweep.run_one``'s columns; ``capacity`` = the batch's
    ``(nconmax, njmax)`` per world, recorded so a resume can tell a capacity stop (:func:`capacity_redo`)."""
    import numpy as np

    rows = []
    W = len(specs)
    for sp, s in zip(specs, summaries):
        row = base_row(sp)
        row["plant"] = "mujoco"
        div = bool(s["diverged"])
        row["status"] = "diverged" if div else "ok"
        row["error"] = s["diverged_reason"] if div else ""
        row["diverged_at_s"] = s["sim_time"] if div else None
        from bioform_mj.assess.outcomes import outcome_kinds

        row["follower_outcomes"] = ";".join("+".join(outcome_kinds(f)) or "ok" for f in s["followers"])
        bad = sorted({k for f in s["followers"] for k in outcome_kinds(f)})
        row["outcome"] = "diverged" if div else (",".join(bad) if bad else "ok")
        row["sim_time_s"] = s["sim_time"]
        row["wall_time_s"] = batch_wall / W  # the batch's loop time shared out over its worlds
        for m in metrics:
            if m not in s["followers"][0]:
                continue
            vals = np.array([f[m] for f in s["followers"]], dtype=float)
            row[f"{m}_mean"] = float(np.mean(vals))
            row[f"{m}_max"] = float(np.max(vals))
        ch = np.array([f["c_hat_rel_error"] for f in s["followers"]], dtype=float)
        row["c_hat_abs_rel_error_max"] = float(np.max(np.abs(ch)))
        row["backend"] = "warp"
        row["device"] = device
        row["batch_worlds"] = W
        row["batch_wall_time_s"] = batch_wall
        row["n_robots"] = len(s["followers"])
        row["capacity_exceeded"] = bool(s.get("capacity_exceeded", False))
        if capacity is not None:
            row["batch_nconmax"], row["batch_njmax"] = capacity
        rows.append(row)
    return rows


def run_warp(
    groups: Sequence[Group],
    device: str,
    base_row: Callable[[Any], dict],
    metrics: Sequence[str],
    done: Callable[[dict], None],
    stop: Callable[[], bool] = lambda: False,
    failed_row: Callable[[Any, str], dict] | None = None,
    nconmax: int | None = None,
    njmax: int | None = None,
) -> None:
    """Run every group as one batch on ``device``; ``done(row)`` per world as each batch ends.
    ``nconmax``/``njmax``: MuJoCo Warp's capacities per world (None: :class:`~.control.BatchRun`'s).
    ``stop()`` is asked between batches. A batch that raises fails its rows (``failed_row``)."""

    from bioform_mj.batch.runner import BatchRun
    from bioform_mj.scenario.loader import load

    quiet_warp()
    for g in groups:
        if stop():
            return
        scs = [
            sp.scenario
            if sp.scenario is not None
            else load(sp.source, list(sp.overrides), method=sp.method, plant=sp.plant)
            for sp in g.specs
        ]
        try:
            t0 = time.perf_counter()
            b = BatchRun(scs, device, nconmax=nconmax, njmax=njmax)
            setup = time.perf_counter() - t0
            wall = b.run()
            summ = b.summaries(wall)
            rows = rows_from_summaries(g.specs, summ, base_row, metrics, wall, device, (b.nconmax, b.njmax))
            for r in rows:
                r["batch_setup_s"] = setup
            del b
        except Exception as exc:  # noqa: BLE001 - a failed batch fails its rows, not the sweep
            if failed_row is None:
                raise
            rows = [failed_row(sp, f"{type(exc).__name__}: {exc}") for sp in g.specs]
        for r in rows:
            done(r)
