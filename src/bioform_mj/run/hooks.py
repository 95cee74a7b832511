"""What :func:`bioform_mj.run.simulate.simulate` checks of a user's controller and observers (design §17): the
protocol methods before any step, the shape and finiteness of each step's torques, and the note that
names who raised mid-run."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from bioform_mj.core.errors import ControllerError


def _tag(exc: BaseException, source: str, step: int, t: float) -> None:
    """Remember where ``exc`` came from (the innermost caller wins) for the note and the summary."""
    if not hasattr(exc, "_bioform_source"):
        exc._bioform_source = source  # type: ignore[attr-defined]
        exc._bioform_step = step  # type: ignore[attr-defined]
        exc._bioform_time = t  # type: ignore[attr-defined]


#: what :func:`simulate` needs of a user's controller and observers (design §17)
CONTROLLER_METHODS = ("reset", "step", "signals")
OBSERVER_METHODS = ("start", "sample", "finish")


def _lacking(obj: Any, methods: tuple[str, ...], what: str) -> str:
    """``"<what> <class> has no a(), b() methods"`` for the ``methods`` ``obj`` lacks (not callable), "" if none."""
    lacks = [m for m in methods if not callable(getattr(obj, m, None))]
    if not lacks:
        return ""
    return (
        f"{what} {type(obj).__name__} has no {', '.join(m + '()' for m in lacks)} method{'s' if len(lacks) > 1 else ''}"
    )


def check_controller(controller: Any) -> None:
    """Raise :class:`~bioform_mj.core.errors.ControllerError` naming what ``controller`` lacks of the
    :class:`~bioform_mj.control.base.Controller` protocol (called before any step)."""
    lacks = _lacking(controller, CONTROLLER_METHODS, "controller")
    if lacks:
        raise ControllerError(
            f"{lacks}; a controller needs reset(est_pose0, vel0), "
            "step(leader_pose, leader_vel, pose, vel, comm=None) -> (n, 2) torques and signals() -> dict "
            "(see bioform_mj.control.base.Controller)"
        )


def check_observers(observers: Sequence[Any]) -> None:
    """Raise :class:`~bioform_mj.core.errors.ControllerError` naming what an observer lacks of :class:`Observer`."""
    for o in observers:
        name = type(o).__name__
        lacks = _lacking(o, OBSERVER_METHODS, "observer")
        if lacks:
            raise ControllerError(f"{lacks} (an observer needs period, start, sample, finish: sim.Observer)")
        period = getattr(o, "period", None)
        try:
            ok = period is not None and float(period) > 0 and math.isfinite(float(period))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ControllerError(f"observer {name}: period must be a finite number of seconds > 0, got {period!r}")


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``: what a user's controller is handed (design §17; a controller that wrote
    into its ``pose`` changed the logged trajectory and the metrics, issue 28). Writing raises ``ValueError``."""
    v = np.asarray(a).view()
    v.flags.writeable = False
    return v


def _checked_torques(tau: Any, n: int, name: str, k: int, dt: float) -> np.ndarray:
    """A user's controller's torques as a float (n, 2) array, or a :class:`ControllerError`."""
    try:
        arr = np.asarray(tau, dtype=float)
    except (TypeError, ValueError) as exc:
        err = ControllerError(
            f"controller {name}.step returned {type(tau).__name__}, not an (n, 2) = ({n}, 2) array of "
            f"torques, at t = {k * dt:.4f} s (step {k}): {exc}"
        )
        _tag(err, f"controller {name}.step", k, k * dt)
        raise err from exc
    if arr.shape != (n, 2):
        err = ControllerError(
            f"controller {name}.step returned torques of shape {arr.shape}, expected (n, 2) = ({n}, 2) "
            f"[tau_L, tau_R] N·m per follower, at t = {k * dt:.4f} s (step {k})"
        )
        _tag(err, f"controller {name}.step", k, k * dt)
        raise err
    return arr


def _add_outcome(f: dict[str, Any], kind: str, detail: str, t: float | None) -> None:
    """Give follower ``f`` (a summary entry) the outcome ``kind``, the most severe (it caused the
    run's end), keeping the others in ``outcomes`` (the outcomes contract)."""
    prev = f.get("outcomes")
    if prev is None:
        prev = (
            []
            if f.get("outcome", "ok") == "ok"
            else [{"kind": f["outcome"], "detail": f.get("outcome_detail", ""), "t": None}]
        )
    f["outcomes"] = [{"kind": kind, "detail": detail, "t": t}] + [o for o in prev if o.get("kind") != kind]
    f["outcome"] = kind
    f["outcome_detail"] = detail
