"""A run's log as a tidy table: one row per log sample and follower, named columns with units.

:data:`COMPONENTS` names the components of every channel of :data:`bioform_mj.core.engine.CHANNELS` and
their units; :func:`columns` turns a log (``RunResult.log``, ``log.npz``) into ``{column: array}`` of
``K × n`` rows (sample-major: rows ``j n … j n + n − 1`` are sample ``j``'s followers 1 … n), with
``t_s`` and ``follower`` (1-based) first, the leader's channels repeated on each follower's row.
:func:`to_arrow` makes a ``pyarrow.Table`` of it (each field's unit in its metadata; pyarrow comes
with rerun-sdk); pandas and polars frames are built from that table when those packages are installed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bioform_mj.core.engine import CHANNELS

_POSE = (("x", "m"), ("y", "m"), ("theta", "rad"))
_VEL = (("v", "m/s"), ("w", "rad/s"))
_ACC = (("v", "m/s^2"), ("w", "rad/s^2"))
_WHEELS = (("left", "N*m"), ("right", "N*m"))
_C = (("a", "1/(kg*m)"), ("b", "1/(kg*m^2)"))

#: channel -> ((component, unit), ...) for its last axis; one ``(name, unit)`` for a scalar channel
COMPONENTS: dict[str, tuple[tuple[str, str], ...]] = {
    "t": (("", "s"),),
    "leader_pose": _POSE,
    "leader_vel": _VEL,
    "pose": _POSE,
    "vel": _VEL,
    "est_pose": _POSE,
    "est_vel": _VEL,
    "cmd": _VEL,
    "cmd_min": _VEL,
    "cmd_max": _VEL,
    "dcmd": _ACC,
    "tau": _WHEELS,
    "tau_min": _WHEELS,
    "tau_max": _WHEELS,
    "tau_raw": _WHEELS,
    "c_hat": _C,
    "c_true": _C,
    "z_hat": _VEL,
    "vs": (("", ""),),
    "tracking_error": _POSE,
    "slots": (("x", "m"), ("y", "m")),
    "formation_error": (("", "m"),),
    "estimation_error": (("", "m"),),
    "saturated": (("", "fraction"),),
    "odom_pose": _POSE,
    "odom_vel": _VEL,
}

_UNIT_TAG = {"m": "m", "rad": "rad", "s": "s", "m/s": "m_s", "rad/s": "rad_s", "m/s^2": "m_s2"}
_UNIT_TAG |= {"rad/s^2": "rad_s2", "N*m": "Nm"}


def column_name(channel: str, component: str, unit: str) -> str:
    """``pose, x, m`` → ``pose_x_m``; a unit without a short tag (``1/(kg*m)``, fractions) is left out."""
    parts = [channel] + ([component] if component else []) + ([_UNIT_TAG[unit]] if unit in _UNIT_TAG else [])
    return "_".join(parts)


def column_units() -> dict[str, str]:
    """``{column: unit}`` of every column :func:`columns` can make, in its order."""
    out = {"t_s": "s", "follower": ""}
    for ch in CHANNELS:
        if ch == "t":
            continue
        for comp, unit in COMPONENTS[ch]:
            out[column_name(ch, comp, unit)] = unit
    return out


def columns(log: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The log as ``{column: (K·n,) array}``, one row per sample and follower (sample-major)."""
    t = np.asarray(log["t"], dtype=float)
    K = t.shape[0]
    n = np.asarray(log["pose"]).shape[1]
    out: dict[str, np.ndarray] = {"t_s": np.repeat(t, n), "follower": np.tile(np.arange(1, n + 1), K)}
    for ch, (shape, _doc) in CHANNELS.items():
        if ch == "t" or ch not in log:
            continue
        a = np.asarray(log[ch])
        per_follower = bool(shape) and shape[0] == "n"
        if per_follower:
            a = a.reshape(K * n, -1)  # (K, n[, c]) -> (K n, c)
        else:
            a = np.repeat(a.reshape(K, -1), n, axis=0)  # the leader's: the same on each follower's row
        comps = COMPONENTS[ch]
        for j, (comp, unit) in enumerate(comps):
            col = a[:, j]
            out[column_name(ch, comp, unit)] = col.astype(bool) if a.dtype == bool else col
    return out


def to_arrow(log: Mapping[str, np.ndarray], metadata: Mapping[str, str] | None = None) -> Any:
    """The tidy table as a ``pyarrow.Table``; each field's unit in its metadata (``unit``), ``metadata``
    (e.g. scenario name, plant, method) in the schema's."""
    import pyarrow as pa

    cols = columns(log)
    units = column_units()
    fields = [pa.field(k, pa.array(v).type, metadata={"unit": units.get(k, "")}) for k, v in cols.items()]
    schema = pa.schema(fields, metadata=dict(metadata or {}))
    return pa.Table.from_arrays([pa.array(v) for v in cols.values()], schema=schema)
