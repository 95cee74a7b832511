"""Cause attribution of :func:`bioform_mj.assess.identify.identify` (design §14): what touches the floor and
with what load and the robot's own bodies pressing on each other (read with ``robots/contacts.py``'s one
classification, design §0), the findings at rest (structural,
braking geoms, mapping) and those the fit reads (damping, dead band, rocking, slip).

Split from :mod:`bioform_mj.assess.identify`, which re-exports the public names.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from bioform_mj.robots.contacts import brakes, floor_contacts, is_caster, self_contacts, strip_prefix
from bioform_mj.robots.layout import element_name, subtree

#: a finding of :func:`identify` (design §14): drag when it changes the speed by this fraction over a test
DRAG_FINDING = 0.02
#: ... a dead band above this fraction of the top test torque
DEADBAND_FINDING = 0.02
#: ... rocking: the chassis pitch oscillating by more than this (deg, half peak-to-peak) after the transient
ROCK_DEG = 0.5
#: ... or the centre of mass's ``a`` this far (relative) from the axle midpoint's while the chassis pitched
ROCK_GAP = 0.03
#: ... slip: the wheels' rim speed this far (relative) from the axle's speed at the end of a drive test
SLIP_FINDING = 0.05
# ... a braking geom: robot check's own test, robots/contacts.py: brakes (a caster by is_caster, CASTER_LOAD =
# 0.5 % of the weight, that cannot roll, with friction; design §0, §14.2)
#: a fit whose RMS residual exceeds this share of its torque term's RMS does not hold (design §14.3: measured
#: ≤ 0.6 % on a and ≤ 4.8 % on b over the zoo but for a skid-steer's b, 16 %; 8–31 % where a chassis edge drags)
FIT_RESIDUAL_MAX = 0.06
#: ... structural: two of the robot's own bodies pressing on each other at rest with more than this share
#: of its weight
SELF_CONTACT_LOAD = 0.01
#: ... structural: a wheel carrying less than this share of the weight at rest
WHEEL_LOAD_MIN = 0.02
#: a mapped wheel radius this many times off the wheel geoms' (or outside [1e-4, 1e2] m) is refused (exit 2)
RADIUS_FACTOR = 10.0


#: the kinds of :func:`identify`'s findings, the likeliest cause of a wrong identification first (design §14)
CAUSE_ORDER = (
    "structural",
    "mapping",
    "braking_caster",
    "caster_resistance",
    "dead_band",
    "slip",
    "rocking",
    "damping",
)
#: a mapped wheel radius or half track this far (relative) from the model's geometry is a ``mapping`` finding
MAPPING_TOL = 0.05


def _finding(kind: str, detail: str, **numbers: Any) -> dict[str, Any]:
    """One cause :func:`identify` names: ``{"kind", "detail", ...numbers}`` (design §14)."""
    return {"kind": kind, "detail": detail, **numbers}


def _prefix(lay: Any) -> str:
    """The robot's name prefix in the scene (``f1/``), from its layout's base body."""
    return lay.base[: lay.base.index("/") + 1] if "/" in lay.base else ""


def on_floor(plant: Any, i: int = 0, data: mujoco.MjData | None = None) -> list[dict[str, Any]]:
    """Robot ``i``'s floor contacts now, :func:`bioform_mj.robots.contacts.floor_contacts` (the one
    classification: ``role`` wheel, caster or other, ``rolls``, ``load_n``, the simulated ``friction`` and
    ``condim``, ...). ``data``: another state of the plant's model (a settled copy) instead of the plant's own."""
    lay = plant.layouts[i]
    return floor_contacts(plant.model, plant.data if data is None else data, lay, _prefix(lay))


def _given(lay: Any, what: str, says: str) -> float | None:
    """The model's own value of a mapped size that differs from it (``scene.layout_of``'s note), or None."""
    for n in lay.notes:
        if n.startswith(f"{what} ") and f"{says} say" in n:
            return float(n.rsplit("say ", 1)[1].split()[0])
    return None


def check_radius(plant: Any) -> None:
    """Refuse (exit 2) a mapped wheel radius or half track that no identification can use: more
    than :data:`RADIUS_FACTOR` off the model's geometry, or outside [1e-4, 100] m (design §14)."""
    from bioform_mj.core.errors import InputError

    lay = plant.layouts[0]
    for what, val, says, hint in (
        ("wheel_radius", lay.wheel_radius, "collision geoms", "the wheel geoms'"),
        ("half_track", lay.half_track, "joint anchors", "the wheel joint anchors'"),
    ):
        geo = _given(lay, what, says)
        if not (math.isfinite(val) and 1e-4 <= val <= 1e2) or (
            geo and not 1 / RADIUS_FACTOR <= val / geo <= RADIUS_FACTOR
        ):
            raise InputError(
                f"{lay.file}: {what.replace('_', ' ')} {val:g} m"
                + (f" is more than {RADIUS_FACTOR:g}x off {hint} {geo:.4g} m" if geo else " is outside [1e-4, 100] m")
                + f": no torque level identifies a robot with it (give the {what.replace('_', ' ')} of the "
                "wheels that touch the floor)"
            )


def _rocking(pitch: np.ndarray, dt: float) -> dict[str, float]:
    """Half peak-to-peak (deg) and frequency (Hz, from zero crossings) of a pitch series (rad)
    after removing its linear trend."""
    if len(pitch) < 4:
        return {"amplitude_deg": 0.0, "frequency_hz": 0.0}
    t = np.arange(len(pitch)) * dt
    res = pitch - np.polyval(np.polyfit(t, pitch, 1), t)
    amp = float(np.degrees(0.5 * (res.max() - res.min())))
    s = np.sign(res[np.abs(res) > 0.1 * np.abs(res).max()]) if amp > 0 else np.zeros(0)
    crossings = int(np.count_nonzero(np.diff(s))) if len(s) > 1 else 0
    return {"amplitude_deg": amp, "frequency_hz": crossings / (2 * t[-1]) if t[-1] > 0 else 0.0}


def _contact_kind(c: dict[str, Any], base: str) -> str:
    """``chassis`` for a floor contact of the base body itself or of a link welded to it that carries most of the
    robot's mass (a URDF's ``base_link`` below a massless ``base_footprint``), else ``caster`` (a link of its own)."""
    if c["body"] == base.split("/", 1)[-1]:
        return "chassis"
    return "chassis" if c.get("welded_to_base") and float(c.get("mass_share") or 0.0) >= 0.5 else "caster"


def _brake_what(c: dict[str, Any], base: str) -> str:
    """How a braking floor contact is named: the chassis itself dragging, or a non-wheel link (design §14.3)."""
    if _contact_kind(c, base) == "chassis":
        return f"the chassis '{c['body']}' drags on the floor (geom '{c['geom']}', no wheel, no caster):"
    return f"'{c['geom']}' (body '{c['body']}') is not a wheel,"


def dragging_brakes(c: dict[str, Any], weight: float, named: bool = False) -> bool:
    """Whether a driving mean of a floor contact (``c``: a :func:`on_floor` entry whose ``load_n`` is its mean
    over a drive test) brakes: ``robot check``'s test (:func:`~bioform_mj.robots.contacts.brakes`) with the
    caster rule (:func:`~bioform_mj.robots.contacts.is_caster`) applied to the mean load (``weight`` N;
    ``named``: the mapping names it a caster)."""
    if c["role"] == "wheel":
        return False
    return brakes({**c, "role": "caster" if is_caster(c["load_n"], weight, named) else "other"})


def _braking_finding(c: dict[str, Any], base: str, detail: str, while_driving: bool = False) -> dict[str, Any]:
    """The ``braking_caster`` finding of floor contact ``c`` (at rest, or ``while_driving`` with its
    ``peak_n``): named by :func:`_brake_what`, ``detail`` the rest of its sentence; braking force N."""
    numbers: dict[str, Any] = {
        "geom": c["geom"],
        "body": c["body"],
        "load_n": c["load_n"],
        "friction": c["friction"],
        "braking_force_n": c["friction"] * c["load_n"],
        "lever_m": c.get("lever_m"),  # m from the axle midpoint: its drag's moment on ω (run.demand, design §21)
    }
    if while_driving:
        numbers["peak_load_n"] = c["peak_n"]
    numbers["contact"] = _contact_kind(c, base)
    if while_driving:
        numbers["while_driving"] = True
    return _finding("braking_caster", _brake_what(c, base) + detail, **numbers)


def moving_brakes(
    findings: list[dict[str, Any]],
    dragging: list[dict[str, Any]],
    weight: float,
    r: float,
    base: str,
    tau_a: float,
    named: frozenset[str] = frozenset(),
) -> list[dict[str, Any]]:
    """``braking_caster`` findings for geoms that are no wheel and do not roll and drag on the floor while the
    robot drives (``dragging``: :func:`on_floor` entries with their mean ``load_n`` and their ``peak_n``
    over the top drive test, ``tau_a`` N·m) and brake by :func:`dragging_brakes` (``weight`` N; ``named``: the
    geoms the mapping names casters), not already named at rest."""
    done = {x.get("geom") for x in findings if x["kind"] == "braking_caster"}
    out = []
    for c in dragging:
        if c["geom"] in done or not dragging_brakes(c, weight, c["geom"] in named):
            continue
        brake = c["friction"] * c["load_n"]
        out.append(
            _braking_finding(
                c,
                base,
                f" carries {c['load_n']:.3g} N on average ({c['load_n'] / weight:.0%} of the "
                f"weight; {c['peak_n']:.3g} N at most) while it drives at τ_a = {tau_a:.3g} N·m (less at rest: the "
                f"drive torque pitches the chassis onto it) and slides with friction {c['friction']:g}: "
                f"{brake:.3g} N of braking on average, {brake * r:.3g} N·m of wheel torque lost",
                while_driving=True,
            )
        )
    return out


def rest_findings(
    plant: Any, params: Any, lay: Any, weight: float, loads: np.ndarray, contacts: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """The findings at rest (design §14): self contacts, braking geoms, wheels off the floor, a mapped
    size off the model's. ``weight`` N, ``loads`` (2,) the wheel loads N, ``contacts`` :func:`on_floor`;
    self contacts: :func:`bioform_mj.robots.contacts.self_contacts`, per pair of bodies."""
    findings: list[dict[str, Any]] = []
    pressing = self_contacts(plant.model, plant.data, plant.layouts[0], _prefix(plant.layouts[0]))
    selfc = [c for c in pressing if c["force_n"] > SELF_CONTACT_LOAD * weight]
    if selfc:
        findings.append(
            _finding(
                "structural",
                "the robot's own bodies press on each other at rest: "
                + ", ".join(f"'{c['body1']}'/'{c['body2']}' {c['force_n']:.3g} N" for c in selfc)
                + " (internal forces that brake or lock parts; exclude the pairs, as URDF/Gazebo do by default)",
                self_contacts=selfc,
            )
        )
    for c in contacts:
        if brakes(c):
            brake = c["friction"] * c["load_n"]
            findings.append(
                _braking_finding(
                    c,
                    lay.base,
                    f" carries {c['load_n']:.3g} N "
                    f"({c['load_n'] / weight:.0%} of the weight) and slides with friction {c['friction']:g}: "
                    f"up to {brake:.3g} N of braking, {brake * params.wheel_radius:.3g} N·m of wheel torque lost",
                )
            )
    if float(loads.min()) < WHEEL_LOAD_MIN * weight:
        findings.append(
            _finding(
                "structural",
                f"the wheels do not stand on the floor: they carry {loads[0]:.3g} N (left) and {loads[1]:.3g} N "
                f"(right) of the robot's {weight:.3g} N at rest"
                + (
                    "; it stands on " + ", ".join(f"'{c['geom']}'" for c in contacts if c["role"] != "wheel")
                    if any(c["role"] != "wheel" for c in contacts)
                    else ""
                ),
                wheel_load_n=loads.tolist(),
            )
        )
        geo_r = _given(lay, "wheel_radius", "collision geoms")
        if geo_r:  # a mapped radius the geoms disagree with: the simulated tyre (a contact proxy too) is the geoms'
            findings[-1]["detail"] += (
                f" (the mapped wheel radius {lay.wheel_radius:g} m is not the wheel geoms' {geo_r:.4g} m, the radius "
                "simulated)"
            )
    for what, says, val in (
        ("wheel_radius", "collision geoms", lay.wheel_radius),
        ("half_track", "joint anchors", lay.half_track),
    ):
        geo = _given(lay, what, says)
        if geo and abs(val / geo - 1) > MAPPING_TOL:
            findings.append(
                _finding(
                    "mapping",
                    f"the mapped {what.replace('_', ' ')} {val:g} m is {val / geo - 1:+.0%} off the model's {says}' "
                    f"{geo:.4g} m: the formula uses the mapped value, the physics the model's",
                    what=what,
                    mapped_m=val,
                    model_m=geo,
                )
            )
    return findings


def fit_holds(a: float, c0: float, residual: float, torque: float) -> bool:
    """Whether a fit of ``υ̇ = a τ + c₀ + β υ`` holds (design §14.3): ``a`` finite and > 0, the intercept as a
    torque ``−c₀/a`` no push at zero torque (≥ −:data:`DEADBAND_FINDING` of ``2 torque``, the top τ_a, N·m),
    the relative ``residual`` (:func:`~bioform_mj.assess.fit.fit_levels`) at most :data:`FIT_RESIDUAL_MAX`."""
    if not (math.isfinite(a) and a > 0):
        return False
    return -c0 / a >= -DEADBAND_FINDING * 2 * torque and residual <= FIT_RESIDUAL_MAX


def fit_findings(
    findings: list[dict[str, Any]],
    *,
    params: Any,
    drive: list[dict],
    k0: int,
    dt: float,
    ok: bool,
    k_form: list[float],
    fits: dict[str, float],
    windows: list[float],
    truth: dict[str, Any],
    torque: float,
    f: float,
    settle_s: float | None,
    id_skip: float,
) -> dict[str, Any]:
    """Append the findings the fit reads (damping, dead band, rocking, slip; design §14) to ``findings``;
    return the numbers they rest on (``rock``, ``transient_deg``, ``slip``, ``drag``, ``db``, ``com_gap``).
    ``id_skip``: identify's ID_SKIP (s). ``fits``: ``a_id, b_id, a_com`` and the fits' intercepts ``ca, cb``
    and drags ``be, ge, be_free, ge_free``."""
    a_id, b_id, a_com = fits["a_id"], fits["b_id"], fits["a_com"]
    ca, cb, be, ge, be_free, ge_free = (fits[k] for k in ("ca", "cb", "be", "ge", "be_free", "ge_free"))
    rock = _rocking(drive[0]["pitch"][k0:], dt)
    transient_deg = float(np.degrees(np.abs(drive[0]["pitch"] - drive[0]["pitch"][0]).max()))
    v_end = float(drive[0]["z"][-1, 0])
    rim_end = float(drive[0]["rim"][-1])
    slip = (rim_end - v_end) / max(abs(rim_end), abs(v_end), 1e-6)
    # the drag: fitted where the model has one, else the free fit's (a drag the formula does not know)
    drag = [-be if k_form[0] > 0 else -be_free, -ge if k_form[1] > 0 else -ge_free]
    rocks = rock["amplitude_deg"] > ROCK_DEG
    # design §14.3: a dead band is never negative; a fit whose intercept is an acceleration at zero torque
    # (a chassis edge whose drag grows with the torque, a rocking chassis) does not hold: said, not reported
    intercept = [-ca / a_id if ok else None, -cb / b_id if ok else None]
    db = [max(x, 0.0) if x is not None else None for x in intercept]
    residual = [fits.get("res_a", 0.0), fits.get("res_b", 0.0)]
    tol = DEADBAND_FINDING * 2 * torque
    holds = [ok and fit_holds(a, c, residual[j], torque) for j, (a, c) in enumerate(((a_id, ca), (b_id, cb)))]
    why_not = "".join(
        f"; the fit of υ̇ = {w} τ_{w} + … does not hold ("
        + ", ".join(
            ([f"its residual is {residual[j]:.0%} of the torque term"] if residual[j] > FIT_RESIDUAL_MAX else [])
            + (
                [f"its intercept, {intercept[j]:.3g} N·m, is a push at zero torque (no dead band is negative)"]
                if intercept[j] < -tol
                else []
            )
        )
        + f"): the identified {w} is not the robot's"
        for j, w in enumerate(("a", "b"))
        if ok and not holds[j]
    )
    tcs = [1 / k if k > 0 else None for k in drag]
    drag_seen = [k * windows[j] > DRAG_FINDING and (k_form[j] > 0 or not rocks) for j, k in enumerate(drag)]
    if ok and any(drag_seen):
        findings.append(
            _finding(
                "damping",
                "a viscous drag: time constant "
                + ", ".join(f"{t:.3g} s ({w})" for t, w in zip(tcs, ("drive", "turn")) if t is not None)
                + " (formula from the wheel joints' damping and back-EMF: "
                + ", ".join(f"{t:.3g} s" if t else "none" for t in truth["drag_time_constant_s"])
                + ")",
                drag_rate_per_s=drag,
                time_constant_s=tcs,
            )
        )
    braking = any(x["kind"] == "braking_caster" for x in findings)
    db_seen = ok and max(db[0], db[1]) > DEADBAND_FINDING * 2 * torque
    # a rocking chassis moves the fit's intercept too: an intercept neither the frictionloss nor a
    # braking geom explains is then said as part of the rocking, not as a dead band
    db_rocking = db_seen and rocks and f == 0 and not braking
    if db_seen and not db_rocking:
        findings.append(
            _finding(
                "dead_band",
                "a dead band of "
                + ", ".join(
                    f"{db[j]:.3g} N·m on τ_{w}" if holds[j] else f"(none read on τ_{w}: its fit does not hold)"
                    for j, w in enumerate(("a", "b"))
                )
                + " (torque that moves nothing; "
                f"formula from the wheel frictionloss: {2 * f:.3g} N·m"
                + (", the rest from the braking geoms" if braking else "")
                + ")",
                deadband_torque_Nm=db,
            )
        )
    com_gap = a_com / a_id - 1 if ok else 0.0
    if rocks or (abs(com_gap) > ROCK_GAP and transient_deg > ROCK_DEG):
        findings.append(
            _finding(
                "rocking",
                f"the chassis rocks by ±{rock['amplitude_deg']:.2g}° at {rock['frequency_hz']:.3g} Hz after the "
                f"start-up ({transient_deg:.2g}° at most from rest)"
                + (
                    f"; the centre of mass identifies a {a_com / params.a_eff - 1:+.1%} from the formula, the axle "
                    f"midpoint {a_id / params.a_eff - 1:+.1%}"
                    if holds[0]
                    else ""
                )
                + (f"; the fit reads it as a dead band of {max(db):.3g} N·m" if db_rocking else ""),
                transient_deg=transient_deg,
                a_com=a_com,
                **rock,
            )
        )
    elif ok and k0 * dt > id_skip and transient_deg > ROCK_DEG:  # rocked at start-up, settled, fitted after
        start = _rocking(drive[0]["pitch"][: max(k0, 4)], dt)
        findings.append(
            _finding(
                "rocking",
                f"the chassis rocks at start-up (±{start['amplitude_deg']:.2g}° at {start['frequency_hz']:.3g} Hz, "
                f"{transient_deg:.2g}° at most from rest) and settles after {settle_s:.2g} s: a, b fitted after it "
                f"(the axle midpoint {a_id / params.a_eff - 1:+.1%}, the centre of mass "
                f"{a_com / params.a_eff - 1:+.1%} from the formula); the start of each manoeuvre shakes it",
                transient_deg=transient_deg,
                settled_s=settle_s,
                a_com=a_com,
                **start,
            )
        )
    if abs(slip) > SLIP_FINDING:
        findings.append(
            _finding(
                "slip",
                f"the wheels' rim speed {rim_end:.3g} m/s against the axle's {v_end:.3g} m/s at the end of "
                f"the drive test ({slip:+.0%}): they do not roll on the floor",
                slip_ratio=slip,
            )
        )
    return dict(
        rock=rock,
        transient_deg=transient_deg,
        slip=slip,
        drag=drag,
        db=db,
        com_gap=com_gap,
        intercept=intercept,
        holds=holds,
        why_not=why_not[2:],
    )


def identify_notes(ident: dict | None) -> list[str]:
    """For ``robot check``'s notes: the caster swivels :func:`identify` turned before each test and what
    resists turning them, a drive test rerun at a lower torque (design §14.1)."""
    test, notes = (ident or {}).get("test", {}), []
    if test.get("caster_swivels"):
        res = test.get("caster_swivel_resistance") or [{"damping_Nms_per_rad": 0.0, "frictionloss_Nm": 0.0}]
        notes.append(
            f"caster swivel(s) {', '.join(repr(j) for j in test['caster_swivels'])} turned before each "
            "identification test to trail its motion (the casters' steady state); a start from other caster "
            f"angles turns them round first, against a swivel damping of up to "
            f"{max(r['damping_Nms_per_rad'] for r in res):g} N·m·s/rad and frictionloss of up to "
            f"{max(r['frictionloss_Nm'] for r in res):g} N·m"
        )
    if fr := test.get("fit_rerun"):
        notes.append(
            f"drive tests rerun at {fr['torque_Nm']:.3g} N·m per wheel: at {fr['first_torque_Nm']:.3g} N·m their fit "
            f"did not hold (residual {fr['first_fit_residual']:.0%} of the torque term"
            + (f", intercept {fr['first_intercept_Nm']:.3g} N·m" if fr["first_intercept_Nm"] is not None else "")
            + "; design §14.3)"
            + ("" if fr["kept"] else "; nor at the lower torque: the first tests stand")
        )
    if dr := test.get("drive_rerun"):
        notes.append(
            f"drive tests at {test['torque_Nm']:.3g} N·m: at {dr['first_torque_Nm']:.3g} N·m the robot turned "
            f"{dr['first_heading_change_rad']:.2g} rad within the test (design §14.1: a centre of mass beside "
            "the axle couples υ into ω)"
        )
    return notes


#: :func:`identify` reruns its tests without what its casters resist with (design §14.3) where a or b is this far
#: (relative) from the formula and the robot has caster joints ...
CASTER_CF_DEV = 0.05
#: ... and names the casters (``caster_resistance``) where they account for more than this share of the gap
CASTER_CF_SHARE = 0.5
#: the steps of that counterfactual, each on top of the ones before
CASTER_STEPS = ("joints", "inertia", "scrub")


def caster_parts(model: mujoco.MjModel, lay: Any) -> dict[str, Any]:
    """The robot's caster joints (the layout's ``rolling_joints``: passive joints above a floor contact),
    their dofs, the bodies below them and those bodies' collision geoms (design §14.3)."""
    joints = [j for j in (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in lay.rolling_joints) if j >= 0]
    ndof = {int(mujoco.mjtJoint.mjJNT_BALL): 3, int(mujoco.mjtJoint.mjJNT_FREE): 6}
    dofs = [int(model.jnt_dofadr[j]) + k for j in joints for k in range(ndof.get(int(model.jnt_type[j]), 1))]
    bodies: set[int] = set()
    for j in joints:
        bodies |= set(subtree(model, int(model.jnt_bodyid[j])).tolist())
    geoms = [
        g
        for g in range(model.ngeom)
        if int(model.geom_bodyid[g]) in bodies and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]
    return {"joints": joints, "dofs": dofs, "bodies": sorted(bodies), "geoms": geoms}


def caster_counterfactual(model: mujoco.MjModel, parts: dict[str, Any], measure: Any) -> dict[str, Any]:
    """``measure()`` (→ ``(a, b)``, either None where not measured) rerun on ``model`` changed in
    :data:`CASTER_STEPS`, each on top of the last (design §14.3): ``joints``, the caster joints' damping and
    frictionloss zeroed; ``inertia``, their armature and the caster bodies' rotational inertia cut to 1e-3
    (their mass stays: the formula counts it); ``scrub``, the caster geoms frictionless (condim 1, a
    priority over the floor's). The model is restored after. Returns ``{step: (a, b)}``."""
    dofs, bodies, geoms = parts["dofs"], parts["bodies"], parts["geoms"]
    saved = [
        (model.dof_damping, dofs),
        (model.dof_frictionloss, dofs),
        (model.dof_armature, dofs),
        (model.body_inertia, bodies),
        (model.geom_condim, geoms),
        (model.geom_priority, geoms),
    ]
    keep = [arr[idx].copy() for arr, idx in saved]
    out: dict[str, Any] = {}
    try:
        model.dof_damping[dofs] = 0.0
        model.dof_frictionloss[dofs] = 0.0
        out["joints"] = measure()
        model.dof_armature[dofs] *= 1e-3
        model.body_inertia[bodies] *= 1e-3
        out["inertia"] = measure()
        model.geom_condim[geoms] = 1
        model.geom_priority[geoms] = int(model.geom_priority.max()) + 1
        out["scrub"] = measure()
    finally:
        for (arr, idx), v in zip(saved, keep):
            arr[idx] = v
    return out


def caster_finding(
    model: mujoco.MjModel,
    parts: dict[str, Any],
    formula: tuple[float, float],
    identified: tuple[float, float],
    steps: dict[str, Any],
    prefix: str,
    wheel_drag: tuple[bool, bool] = (False, False),
) -> dict[str, Any] | None:
    """The ``caster_resistance`` finding (design §14.3), or None: for each of a (drive) and b (turn) measured
    in ``steps`` (:func:`caster_counterfactual`), the gap to the formula and the share of it that each step
    removed — the caster joints' damping and frictionloss, the casters' own inertia (the wheels' spin, the
    forks' swivel), the caster wheels' scrub on the floor — where the casters account for more than
    :data:`CASTER_CF_SHARE` of a gap over :data:`CASTER_CF_DEV`. ``wheel_drag``: whether the wheel joints have a
    drag in the drive and the turn test (then it is not said that they have none)."""

    def name(kind: Any, k: int) -> str:
        return strip_prefix(element_name(model, kind, k), prefix)

    parts_by: dict[str, Any] = {}
    texts = []
    for j, what in enumerate(("a", "b")):
        gaps = [identified[j] / formula[j] - 1] + [
            steps[s][j] / formula[j] - 1 if steps[s][j] is not None else None for s in CASTER_STEPS
        ]
        if any(g is None or not math.isfinite(g) for g in gaps) or abs(gaps[0]) <= CASTER_CF_DEV:
            continue
        share = (gaps[0] - gaps[-1]) / gaps[0]
        if share <= CASTER_CF_SHARE:
            continue
        each = {s: gaps[k] - gaps[k + 1] for k, s in enumerate(CASTER_STEPS)}
        parts_by[what] = {"gap": gaps[0], "casters_share": share, "by_step": each, "without_casters": gaps[-1]}
        texts.append(
            f"{what} {gaps[0]:+.1%} from the formula ({'drive' if j == 0 else 'turn'}), {gaps[-1]:+.1%} with ideal "
            f"casters: {each['joints']:+.1%} from the caster joints' damping and frictionloss, "
            f"{each['inertia']:+.1%} from the casters' own inertia (wheel spin, swivel), {each['scrub']:+.1%} from "
            "the caster wheels' scrub on the floor"
        )
    if not texts:
        return None
    joints = [name(mujoco.mjtObj.mjOBJ_JOINT, j) for j in parts["joints"]]
    damp = [float(model.dof_damping[d]) for d in parts["dofs"]]
    fl = [float(model.dof_frictionloss[d]) for d in parts["dofs"]]
    return _finding(
        "caster_resistance",
        f"the casters resist the motion (their passive joints {', '.join(repr(j) for j in joints)}; damping up to "
        f"{max(damp):g} N·m·s/rad, frictionloss up to {max(fl):g} N·m"
        + (
            "; the wheel joints have no drag"
            if not any(wheel_drag[j] for j, w in enumerate(("a", "b")) if w in parts_by)
            else ""
        )
        + "): "
        + "; ".join(texts),
        caster_joints=joints,
        **parts_by,
    )
