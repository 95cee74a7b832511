"""Host-side tables of a batch: the worlds' compatibility (one composed scene, one leader),
payload-event rows (:func:`event_tables`) and the plant faults' per-world rows (:func:`plant_fault_tables`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bioform_mj.batch.plant_kernels import EVENT_FIELDS
from bioform_mj.batch.support import unsupported
from bioform_mj.scenario.config import Scenario


def _check_compatible(scs: Sequence[Scenario]) -> None:
    """All worlds share one composed scene and one leader: say what differs if not."""
    sc0 = scs[0]
    if sc0.plant.kind != "mujoco":
        raise ValueError("the batch engine runs the MuJoCo plant only (plant.kind = 'mujoco')")
    for sc in scs:
        what = unsupported(sc)  # the same list the sweep refuses up front (exit 2): never run it silently
        if what is not None:
            raise ValueError(f"scenario '{sc.name}': {what} is not supported by the batch engine yet")
        for what, a, b in (
            ("plant", sc.plant, sc0.plant),
            ("faults.friction_patch", sc.faults.friction_patch, sc0.faults.friction_patch),  # part of the scene
            ("sim.control_dt", sc.sim.control_dt, sc0.sim.control_dt),
            ("sim.physics_dt", sc.sim.physics_dt, sc0.sim.physics_dt),
            ("sim.duration", sc.sim.duration, sc0.sim.duration),
            ("leader", sc.leader, sc0.leader),
            ("graph", sc.graph, sc0.graph),
            ("n", sc.n, sc0.n),
        ):
            if a != b:
                raise ValueError(
                    f"scenario '{sc.name}': {what} differs from the first world's; the batch engine "
                    "needs one scene, one leader and one graph for all worlds (not supported yet)"
                )


def _yaw_quat(q0: np.ndarray, dth: float) -> np.ndarray:
    """``q_z(dth) ⊗ q0`` (w, x, y, z)."""
    c, s = math.cos(dth / 2), math.sin(dth / 2)
    w0, x0, y0, z0 = q0
    return np.array([c * w0 - s * z0, c * x0 - s * y0, c * y0 + s * x0, c * z0 + s * w0])


def event_tables(sc0: Scenario, scs: Sequence[Scenario], N: int, dt: float) -> dict[str, np.ndarray] | None:
    """Each world's model after each of its payload events, from C MuJoCo (None: no world has one).

    One CPU plant of the shared scene (``sim.make_plant(sc0)``) replays every world's events in
    ``sim.EventQueue``'s order (sorted by time, stable): ``add_payload`` (the base body's inertial,
    then ``mj_setConst``) and, after each, the :data:`EVENT_FIELDS` and ``_m_eff``, ``_i_eff``,
    ``c_true()``; ``reset()`` restores the nominal model between worlds (equal payload sequences
    are computed once). Returns, with ``W`` worlds and ``E`` the most events of a world:
    ``step`` (W, E) int, each event's control step (``sim.first_step_at``), ascending, padded with
    −1; per field of :data:`EVENT_FIELDS` an array (W, E + 1, *the field's C shape*): row 0 the
    initial model, row ``e + 1`` the model after events ``0..e`` (padding rows repeat the last);
    ``m_eff`` (W, E + 1, n) kg, ``i_eff`` (W, E + 1, n) kg·m², ``c_true`` (W, E + 1, n, 2)."""
    from bioform_mj.run.loop import first_step_at
    from bioform_mj.run.simulate import make_plant

    if not any(sc.events for sc in scs):
        return None
    plant = make_plant(sc0)
    m = plant.model
    W, E = len(scs), max(len(sc.events) for sc in scs)

    def snap() -> dict[str, np.ndarray]:
        out = {f: np.array(getattr(m, f), dtype=float) for f in EVENT_FIELDS}
        out.update(m_eff=plant._m_eff.copy(), i_eff=plant._i_eff.copy(), c_true=plant.c_true())
        return out

    first = snap()
    tab = {k: np.empty((W, E + 1, *v.shape)) for k, v in first.items()}
    tab["step"] = np.full((W, E), -1, dtype=np.int32)
    cache: dict[tuple, dict[str, np.ndarray]] = {(): first}
    cur: tuple = ()  # the events the plant's model holds now
    for w, sc in enumerate(scs):
        evs = sorted(sc.events, key=lambda e: e.time)  # sim.EventQueue's order
        rows = [first]
        for e in range(len(evs)):
            key = tuple((ev.follower, ev.mass, ev.inertia) for ev in evs[: e + 1])
            if key not in cache:
                if cur != key[:-1]:  # else the plant holds this prefix's model already
                    plant.reset()  # the nominal model
                    cur = ()
                for ev in evs[len(cur) : e + 1]:
                    if ev.kind != "payload":
                        raise ValueError(f"scenario '{sc.name}': event kind '{ev.kind}' is not supported")
                    plant.add_payload(ev.follower - 1, ev.mass, ev.inertia)
                cur = key
                cache[key] = snap()
            rows.append(cache[key])
            tab["step"][w, e] = first_step_at(evs[e].time, dt)
        rows += [rows[-1]] * (E + 1 - len(rows))
        for k in first:
            tab[k][w] = [r[k] for r in rows]
    return tab


def _first_step(ok: np.ndarray) -> int:
    """The first index where ``ok`` (monotone, False then True) holds; ``len(ok)`` if none."""
    return int(np.argmax(ok)) if ok.any() else len(ok)


def plant_fault_tables(scs: Sequence[Scenario], N: int, dt: float) -> dict[str, np.ndarray]:
    """Each world's ``faults.actuator`` and ``faults.push`` rows as :class:`PlantFaults`' padded tables.

    Row times become control steps by ``Faults.step``'s own float64 comparisons at ``t = k dt``
    (``k`` = 0..N): an actuator row acts at the steps with ``t_start ≤ t < t_end``; a push row
    starts at the first step with ``t ≤ t_k + 1e-12`` (``Faults.step``) and acts while
    ``t + duration > t_k + 1e-12`` (``MujocoPlant._apply_push``). Push rows are sorted by ``t``
    (stable, as ``Faults``) so that the last started row of a follower is the one acting. Steps
    ``N + 1`` mean never. Returns ``act_i`` (W, Ra) int32, ``act_k0``, ``act_k1`` (W, Ra) int32,
    ``act_s`` (W, Ra), ``act_known`` (W,) int32, ``push_i``, ``push_k0``, ``push_k1`` (W, Rp) int32,
    ``push_w`` (W, Rp, 3) [fx N, fy N, tz N·m]; ``Ra``, ``Rp`` ≥ 1, padding rows with follower −1."""
    W = len(scs)
    tk = np.arange(N + 1) * dt  # t = k * dt, as sim.simulate passes it
    Ra = max(1, *(len(sc.faults.actuator) for sc in scs))
    Rp = max(1, *(len(sc.faults.push) for sc in scs))
    never = N + 1
    out = {
        "act_i": np.full((W, Ra), -1, dtype=np.int32),
        "act_k0": np.full((W, Ra), never, dtype=np.int32),
        "act_k1": np.full((W, Ra), never, dtype=np.int32),
        "act_s": np.ones((W, Ra)),
        "act_known": np.zeros(W, dtype=np.int32),
        "push_i": np.full((W, Rp), -1, dtype=np.int32),
        "push_k0": np.full((W, Rp), never, dtype=np.int32),
        "push_k1": np.full((W, Rp), never, dtype=np.int32),
        "push_w": np.zeros((W, Rp, 3)),
    }
    for w, sc in enumerate(scs):
        fc = sc.faults
        out["act_known"][w] = int(bool(fc.actuator_known))
        for r, (i, t0, t1, scale) in enumerate(fc.actuator):
            out["act_i"][w, r] = int(i) - 1
            out["act_k0"][w, r] = _first_step(tk >= t0)
            out["act_k1"][w, r] = _first_step(~(tk < t1))
            out["act_s"][w, r] = float(scale)
        for r, (i, t0, dur, fx, fy, tz) in enumerate(sorted(fc.push, key=lambda row: row[1])):
            out["push_i"][w, r] = int(i) - 1
            out["push_k0"][w, r] = _first_step(t0 <= tk + 1e-12)
            out["push_k1"][w, r] = _first_step(~(t0 + dur > tk + 1e-12))
            out["push_w"][w, r] = (fx, fy, tz)
    return out
