"""Ground-truth dynamics parameters of a MuJoCo robot, and their check by identification.

(:class:`RobotParams` and :func:`robot_parameters` live in :mod:`bioform_mj.robots.params`, below the plant;
they are re-exported here.)

design §5/§8: ``υ̇ = a τ_a + d1``, ``ω̇ = b τ_b + d2`` with ``τ_a = τ_L + τ_R`` and
``τ_b = τ_R − τ_L`` (design §5 sign fix of the paper's eq. 34: CCW-positive ω). With rolling
without slip and the centre of mass on the axle midpoint, Lagrange's equations give

    a_eff = 1 / (m r + 2 I_w / r),      b_eff = l / (I r + 2 I_w l² / r)

(``m`` total mass, ``I`` total yaw inertia about the vertical through the axle midpoint,
``I_w`` one wheel's spin inertia with welded bodies and joint armature, ``r`` wheel radius, ``l`` half
track). :func:`ground_truth` reads these from a compiled model; :func:`identify` checks
them by applying constant torques from rest and fitting the accelerations.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import mujoco
import numpy as np

from bioform_mj.assess.causes import (
    CASTER_CF_DEV,
    CAUSE_ORDER,
    DEADBAND_FINDING,
    DRAG_FINDING,
    MAPPING_TOL,
    RADIUS_FACTOR,
    ROCK_DEG,
    ROCK_GAP,
    SELF_CONTACT_LOAD,
    SLIP_FINDING,
    WHEEL_LOAD_MIN,
    _finding,
    _prefix,
    caster_counterfactual,
    caster_finding,
    caster_parts,
    check_radius,
    fit_findings,
    fit_holds,
    identify_notes,
    moving_brakes,
    on_floor,
    rest_findings,
)
from bioform_mj.assess.fit import fit_levels
from bioform_mj.robots.contacts import CASTER_LOAD, align_swivels, strip_prefix, swivel_casters
from bioform_mj.robots.level_support import level_support
from bioform_mj.robots.params import COM_TOLERANCE_M, RobotParams, ground_truth, robot_parameters, robot_truth

log = logging.getLogger(__name__)

__all__ = [
    "COM_TOLERANCE_M",
    "RobotParams",
    "robot_parameters",
    "robot_truth",
    "ground_truth",
    "identify",
    "identify_main",
    "identify_notes",
    "check_radius",
    "CAUSE_ORDER",
    "DEADBAND_FINDING",
    "DRAG_FINDING",
    "MAPPING_TOL",
    "RADIUS_FACTOR",
    "ROCK_DEG",
    "ROCK_GAP",
    "SELF_CONTACT_LOAD",
    "SLIP_FINDING",
    "WHEEL_LOAD_MIN",
]

#: a drive fit that does not hold is rerun at this share of its torque (design §14.2)
FIT_RERUN_SCALE = 1 / 3
#: the tests look for non-wheel geoms dragging on the floor every this many steps (design §14.2)
DRAG_SAMPLE = 10
#: the turn test of :func:`identify` ends below this yaw rate, rad/s
OMEGA_ID = 2.0
#: :func:`identify` steps at most ``DRAG_STEP / k`` s for a wheel drag rate ``k`` (1/s), so that
#: MuJoCo integrates the damping finely; robot check warns when the model's own step is coarser
DRAG_STEP = 0.02


#: a level stance (:mod:`bioform_mj.robots.level_support`) whose drive test is further than this from the formula is
#: one whose wheels do not carry it (``structural``; robot check's fail threshold, design §14)
LEVEL_OFF = 0.10
#: the identification's drive and turn tests last this long from rest, s (design §14)
ID_DURATION = 1.0
#: ... and are fitted only after this start-up transient, s (a tall chassis rocks on its casters there)
ID_SKIP = 0.3
#: a model drag rate k (1/s) with ``k · duration`` above this is fitted on the rates, not the summed speed
STRONG_DRAG = 5.0
#: a drive test whose chassis pitch has not settled (within SETTLED_DEG of its final lean) by ID_SKIP is
#: fitted over the ID_WINDOW s after it settles, the test lasting up to ID_MAX_S s
SETTLED_DEG = 0.05
ID_WINDOW = 0.7
ID_MAX_S = 2.0
#: ... unless the chassis pitched by more than this in that longer test (deg): then the 1 s test stands
PROBE_UPSET_DEG = 20.0
#: a drive test whose top level turns the heading by more than this (rad) is rerun at a lower torque, at most
#: DRIVE_SCALE_MIN times the first (design §14.1: a centre of mass beside the axle couples υ into ω)
DRIVE_HEADING_MAX = 0.1
DRIVE_SCALE_MIN = 0.1
#: the turn tests last this long from rest, s, fitted from the start
TURN_DURATION = 0.2
#: ... from this time on where the wheels have a frictionloss (design §14.1: MuJoCo's soft frictionloss
#: lets a wheel creep for its first ~0.1 s from rest; PAL PMB2: ω̇ 3.4 rad/s² where the dead band allows 1.5)
TURN_SKIP = 0.1
#: torque levels of each test, as fractions between the lowest usable torque and the top one
ID_LEVELS = (1.0, 0.5, 0.0)


@dataclass
class _Rest:
    """The robot at rest on the floor, what every test of :func:`identify` reads (design §14)."""

    plant: Any  # the MujocoPlant holding the one robot
    params: RobotParams
    lay: Any  # its RobotLayout
    dt: float  # the step, s
    weight: float  # N
    loads: np.ndarray  # (2,) the wheel loads, N (the stance's statics where the wheels stand level with others)
    contacts: list[dict]  # on_floor at rest
    level: dict | None  # level_support's reading, or None
    findings: list[dict]  # every cause found so far (appended to by the later steps)
    traction: float  # μ N r / f of the least-loaded wheel, N·m
    f: float  # the wheel frictionloss, N·m
    motor: float  # the lower wheel torque limit, N·m
    base: dict  # the result's entries that do not depend on the tests


@dataclass
class _Schedule:
    """How long the tests run and from which step they are fitted (design §14)."""

    duration: float  # s, after the motor's and the drag's limits
    n_settle: int  # steps at rest before each test
    n_run: int  # steps of a drive test
    k0: int  # first fitted step of a drive test
    rate_form: bool  # fitted on the rates (a drag that settles υ within the test)
    implicit_damping: bool  # the integrator's scheme (fit_levels)
    explicit: bool


@dataclass
class _Drive:
    """One set of drive tests and its fit of ``a`` (design §14.2)."""

    torque: float  # the top level, N·m per wheel
    levels: list[float]  # N·m per wheel
    runs: list[dict]  # the tests, one per level (_Rig.run)
    k0: int  # first fitted step
    n_run: int  # steps
    settle_s: float | None  # when the pitch settled, s, or None (not probed)


def _bench(model_file, timestep: float | None, duration: float, settle: float, payload) -> tuple[Any, float, float]:
    """The plant the tests run on: (plant, duration s, the formula's largest wheel drag rate 1/s). At the
    model's own step unless ``timestep`` s is given or the wheel drag needs a finer one (:data:`DRAG_STEP`)."""
    from bioform_mj.core.errors import InputError
    from bioform_mj.plants.mujoco.plant import MujocoPlant  # a floor up; imported when used
    from bioform_mj.robots.prepare import prepare_robot

    if not (math.isfinite(duration) and duration > 0) or not (math.isfinite(settle) and settle >= 0):
        raise InputError(f"identify: duration must be > 0 and settle >= 0 s, got {duration}, {settle}")
    auto_step = timestep is None
    if timestep is None:
        timestep = float(prepare_robot(model_file)[0].option.timestep)
    plant = MujocoPlant([model_file], np.zeros((1, 3)), timestep, timestep, None, slots=False)
    check_radius(plant)
    k_drag = max(plant.params[0].unmodelled(0.0, 0.0)["drag_rate_per_s"])
    if auto_step and k_drag * timestep > DRAG_STEP:
        # a wheel damping whose drag rate k is not small against 1/dt is integrated coarsely at the
        # model's own step (menagerie Stretch 3: k = 232 1/s, dt = 2 ms: a, b come out ~90 % high);
        # identify the continuous model at a step with k dt = DRAG_STEP (result "test.timestep_s")
        timestep = DRAG_STEP / k_drag
        plant = MujocoPlant([model_file], np.zeros((1, 3)), timestep, timestep, None, slots=False)
    if k_drag > 0:
        duration = min(duration, max(20.0 / k_drag, 50 * timestep))
    if payload is not None:
        plant.add_payload(0, *payload)
    return plant, duration, k_drag


def _at_rest(plant: Any, model_file, settle: float, duration: float) -> _Rest:
    """Settle the robot ``settle`` s on the floor and read what touches it, with what load (design §14:
    structural and braking-geom causes); refuses a step that would take days (``duration`` s per test)."""
    from bioform_mj.robots.sanity import StepPace, check_step_budget  # <option timestep="1e-9"/>: days

    params, lay = plant.params[0], plant.layouts[0]
    model, data = plant.model, plant.data
    dt = float(model.opt.timestep)
    what = f"{getattr(model_file, 'model', model_file)}: identification"
    seconds = settle + 2 * len(ID_LEVELS) * (settle + duration)
    check_step_budget(
        seconds, dt, what, "give the robot file an <option timestep> of 1e-4 s or more (MuJoCo's default is 0.002 s)"
    )
    pace = StepPace(seconds / dt, what, "a robot whose geoms touch each other in many pairs steps slowly", data)
    for k in range(max(1, round(settle / dt))):
        plant.step(np.zeros((1, 2)), k * dt)
        pace(k + 1)
    weight = params.mass * 9.81
    loads = plant.wheel_loads()[0]
    contacts = on_floor(plant)
    # design §14: wheels level with other supports carry what the stance's statics gives, not MuJoCo's arbitrary
    # resolution of it; the drive test below decides whether the robot drives as the formula says
    level = level_support(model, data, lay, weight, WHEEL_LOAD_MIN)
    if level is not None:
        loads = np.array(level["statics_n"])
    findings = rest_findings(plant, params, lay, weight, loads, contacts)
    # μ N r / f: the least-loaded wheel's own load, and only the share f of the torque that passes the
    # wheel's rotor pushes on the floor (design §13; a rotor of 10 m r² passes 5 %)
    traction = params.traction_torque(plant._wheel_friction(0), float(loads.min()))
    base = {
        "model": str(lay.file),
        "formula": {"a": params.a_eff, "b": params.b_eff},
        "params": asdict(params),
        "layout": asdict(lay),
        "floor_contacts": contacts,
        "wheel_load_n": loads.tolist(),
        "level_support": level,
        # design §14: a 4-wheel / skid-steer base is not the paper's differential drive; its a, b are a reading of
        # the tests (robot check fails it); the notes that name the other wheels, or None
        "skid_steer": [n for n in lay.notes if "other wheel '" in n] or None,
    }
    return _Rest(
        plant, params, lay, dt, weight, loads, contacts, level, findings, traction,
        params.wheel_frictionloss, min(params.tau_max), base,
    )  # fmt: skip


def _not_identified(rest: _Rest, why: str) -> dict:
    """The result of a robot the tests cannot measure: ``why``, as a ``structural`` finding where no finding
    already explains it (design §14)."""
    findings, params, f = rest.findings, rest.params, rest.f
    if not any(x["kind"] in ("structural", "braking_caster", "dead_band") for x in findings):
        findings.append(_finding("structural", why))
    return {
        **rest.base,
        "identified": {"a": None, "b": None},
        "relative_error": {"a": None, "b": None},
        "identified_com": {"a": None},
        "drag_rate_per_s": {"formula": params.unmodelled(0.0, 0.0)["drag_rate_per_s"], "identified": None},
        "deadband_torque_Nm": {"formula": [2 * f, 2 * f], "identified": None},
        "rocking": None,
        "slip_ratio": None,
        "findings": findings,
        "identifiable": False,
        "not_identified": why,
        "test": {"timestep_s": rest.dt, "mujoco_warnings": 0},
    }


def _test_torque(rest: _Rest, torque: float | None) -> tuple[float, str | None]:
    """The top test torque, N·m per wheel (``torque``, or half the motor limit, at most a quarter of the static
    traction limit μ N r, raised to clear the dead band), and None; or (nan, why) where no torque can test the
    robot. Raises InputError for a given torque outside (0, motor limit]."""
    from bioform_mj.core.errors import InputError

    findings, f, motor, traction = rest.findings, rest.f, rest.motor, rest.traction
    if any(x["kind"] == "structural" and "self_contacts" not in x for x in findings):
        return math.nan, findings[-1]["detail"]
    if torque is None:  # half the motor limit, at most a quarter of the static traction limit μ N r
        if not (math.isfinite(motor) and motor > 0):
            return math.nan, f"the motor limit is {motor:g} N·m: no torque to test with"
        if not traction > 0:
            return math.nan, (
                f"the wheels have no traction: friction μ = {rest.plant._wheel_friction(0):g} on a wheel load of "
                f"{float(rest.loads.min()):.3g} N"
            )
        torque = min(0.5 * motor, 0.25 * traction)
        if f > 0 and ID_LEVELS[-1] * torque <= 1.2 * f and torque <= 1.3 * f:
            # every level must clear the dead band (frictionloss f per wheel), else nothing moves and
            # ``a`` comes out ~0 (menagerie Stretch 3: f = 1 N·m, a quarter of traction 0.55 N·m)
            hi = min(motor, 0.5 * traction)
            if hi <= 1.3 * f:  # closer to the traction limit: the start risks a short skid
                hi = min(motor, 0.9 * traction)
            if hi <= 1.3 * f:
                findings.append(
                    _finding(
                        "dead_band",
                        f"the wheel frictionloss {f:g} N·m (dead band) leaves no torque below the traction limit "
                        f"{traction:.3g} N·m and the motor limit {motor:g} N·m that turns the wheels without skidding",
                        deadband_torque_Nm=2 * f,
                    )
                )
                return math.nan, findings[-1]["detail"]
            torque = hi
    if not (math.isfinite(torque) and 0 < torque <= motor):
        raise InputError(f"identify: torque must be in (0, {motor:g}] N·m, got {torque}")
    return torque, None


def _levels_of(top: float, f: float) -> list[float]:
    """The torque levels (N·m per wheel) below ``top``: the lowest a third of it, or halfway between the dead band
    ``f`` and it."""
    lo = top / 3 if top / 3 > 1.2 * f else f + 0.5 * (top - f)
    return [lo + x * (top - lo) for x in ID_LEVELS]


def _schedule(rest: _Rest, torque: float, duration: float, settle: float, k_drag: float) -> _Schedule:
    """The tests' length and fitted window at the top torque ``torque`` N·m (design §14, §8.2: a DC motor stays
    below its torque–speed line), ``duration`` and ``settle`` s, the wheel drag rate ``k_drag`` 1/s."""
    params, model, dt = rest.params, rest.plant.model, rest.dt
    if params.motor == "dc":  # design §8.2: stay below the torque–speed line; see the drag's transient
        k_v = params.unmodelled(0.0, 0.0)["drag_rate_per_s"][0]
        w0 = 0.3 * params.motor_no_load_speed * params.wheel_radius  # 30 % of the no-load wheel speed, m/s
        duration = min(duration, w0 / (2 * params.a_eff * torque))
        if k_v > 0:
            duration = min(duration, 3.0 / k_v)
    integ = int(model.opt.integrator)
    euler = integ == int(mujoco.mjtIntegrator.mjINT_EULER)
    eulerdamp = not (model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP))
    implicit_damping = integ in (
        int(mujoco.mjtIntegrator.mjINT_IMPLICIT),
        int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
    ) or (euler and eulerdamp)
    explicit = euler and not eulerdamp
    n_settle, n_run = round(settle / dt), max(round(duration / dt), 6)
    skip = min(ID_SKIP, 0.3 * n_run * dt)
    if k_drag > 0:  # a fast drag settles υ before ID_SKIP: keep the transient that identifies it
        skip = min(skip, 0.5 / k_drag)
    k0 = min(round(skip / dt), n_run - 4)
    rate_form = k_drag * n_run * dt > STRONG_DRAG
    if rate_form:  # no pitch transient to skip in the first steps of a drag this fast: fit them all
        k0 = 0
    return _Schedule(duration, n_settle, n_run, k0, rate_form, implicit_damping, explicit)


def _turn_plan(rest: _Rest, torque: float, levels: list[float], duration: float) -> tuple[int, list[float]]:
    """The turn tests: (steps, torque levels N·m per wheel). ω at the end at most OMEGA_ID rad/s, so the υ·ω
    coupling of a centre of mass off the axle (∝ ω²) stays small; short and fitted from rest: a chassis hardly
    pitches in a turn, and the soft contact's creep grows with ω (tb3: b 8 % low over 1 s, 0.01 % over 0.2 s)."""
    params, dt, f = rest.params, rest.dt, rest.f
    turn_s = min(TURN_DURATION, duration)
    n_turn = max(round(turn_s / dt), 6)
    t_turn = min(torque, OMEGA_ID / (2 * params.b_eff * turn_s))
    if params.motor == "dc":  # wheel rates l ω / r below 30 % of no-load in the turn tests too
        t_turn = min(
            t_turn,
            0.3 * params.motor_no_load_speed * params.wheel_radius / (params.half_track * 2 * params.b_eff * turn_s),
        )
    turn_levels = [x * t_turn / torque for x in levels]
    if f > 0 and min(turn_levels) < 1.1 * f:
        turn_levels = levels  # the dead band needs the turn tests at the drive torques
    return n_turn, turn_levels


class _Rig:
    """Runs one test from rest at constant wheel torques and records what the fits read (design §14)."""

    def __init__(self, rest: _Rest, sched: _Schedule) -> None:
        self.rest, self.sched = rest, sched
        plant, lay = rest.plant, rest.lay
        self.base_id = plant.model.body(lay.base).id
        self.wdof, self.wsign, self.r = plant._wheel_dof[0], plant._wheel_sign[0], rest.params.wheel_radius
        self.swivels = swivel_casters(plant.model, lay)
        self.fit = partial(
            fit_levels,
            dt=rest.dt,
            implicit_damping=sched.implicit_damping,
            explicit=sched.explicit,
            rate_form=sched.rate_form,
        )

    def run(self, tau_l: float, tau_r: float, n_run: int) -> dict:
        """One test of ``n_run`` steps at ``tau_l``, ``tau_r`` N·m after ``n_settle`` steps at rest: the series of
        υ, ω (``z``), the centre of mass's speed, the pitch, the rim speed and the heading, and what dragged."""
        plant, lay, dt = self.rest.plant, self.rest.lay, self.rest.dt
        model, data = plant.model, plant.data
        base_id, wdof, wsign, r = self.base_id, self.wdof, self.wsign, self.r
        mujoco.mj_resetData(model, data)  # not plant.reset(): that would remove the payload
        # design §14.1: each caster swivel starts trailing the coming motion (driving: behind its axis;
        # turning: tangent to its circle about the axle midpoint), as it runs once it has turned round
        align_swivels(data, self.swivels, lay.axle, tau_l + tau_r, tau_r - tau_l)
        mujoco.mj_forward(model, data)
        zero = np.zeros((1, 2))
        for k in range(self.sched.n_settle):
            plant.step(zero, k * dt)
        pose0, _ = plant.observe()
        tau = np.array([[tau_l, tau_r]])
        z = np.empty((n_run + 1, 2))
        vcom = np.empty(n_run + 1)
        pitch = np.empty(n_run + 1)
        rim = np.empty(n_run + 1)  # m/s: the wheels' mean rim speed
        heading = np.empty(n_run + 1)  # rad

        def sample(k: int) -> None:
            pose, vel = plant.observe()
            z[k] = vel[0]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            mujoco.mj_comVel(model, data)
            mujoco.mj_subtreeVel(model, data)
            th = heading[k] = pose[0, 2]
            lv = data.subtree_linvel[base_id]
            vcom[k] = np.cos(th) * lv[0] + np.sin(th) * lv[1]
            xm = data.xmat[base_id].reshape(3, 3)
            pitch[k] = np.arctan2(xm[2, 0], np.hypot(xm[0, 0], xm[1, 0]))
            rim[k] = float(np.mean(data.qvel[wdof] * wsign) * r)

        sample(0)
        dragging: dict[str, dict] = {}  # design §14.2: non-wheel geoms on the floor while it runs: mean, peak load
        n_samples = n_run // DRAG_SAMPLE
        for k in range(n_run):
            plant.step(tau, k * dt)
            sample(k + 1)
            if k % DRAG_SAMPLE == DRAG_SAMPLE - 1:
                for c in on_floor(plant):
                    if c["role"] != "wheel" and not c["rolls"]:
                        e = dragging.setdefault(c["geom"], {**c, "load_n": 0.0, "peak_n": 0.0})
                        e["load_n"] += c["load_n"] / n_samples
                        e["peak_n"] = max(e["peak_n"], c["load_n"])
        pose, vel = plant.observe()
        d = pose[0, :2] - pose0[0, :2]
        th0 = pose0[0, 2]
        return dict(
            z=z,
            vcom=vcom,
            pitch=pitch,
            rim=rim,
            heading=np.unwrap(heading),
            dragging=list(dragging.values()),
            lateral_m=float(-np.sin(th0) * d[0] + np.cos(th0) * d[1]),
            warnings=sum(int(w.number) for w in data.warning),
            heading_change_rad=float(np.angle(np.exp(1j * (pose[0, 2] - th0)))),
        )

    def drive_tests(self, torque: float, levels: list[float]) -> _Drive:
        """The drive tests at ``levels`` (top ``torque``), N·m per wheel."""
        s, dt = self.sched, self.rest.dt
        k0_, n_run_ = s.k0, s.n_run
        if s.rate_form or n_run_ * dt < ID_DURATION - 1e-9 or s.duration < ID_DURATION - 1e-9:
            return _Drive(torque, levels, [self.run(T, T, n_run_) for T in levels], k0_, n_run_, None)
        # a chassis that keeps pitching past ID_SKIP (a tall one bouncing between its casters): the drive
        # tests run ID_MAX_S; where every level's pitch settles (within SETTLED_DEG of its final lean)
        # later than ID_SKIP, the ID_WINDOW after the last of them is fitted, else the first
        # duration s as for any robot (the same numbers: the runs are deterministic) (design §14)
        n_long = round(ID_MAX_S / dt)
        drive_ = [self.run(T, T, n_long) for T in levels]
        settles, upset = [], False
        for r_ in drive_:
            p_ = r_["pitch"]
            away = np.nonzero(np.abs(p_ - p_[-1]) > SETTLED_DEG * np.pi / 180)[0]
            settles.append(float(away[-1] + 1) * dt if len(away) else 0.0)
            upset |= bool(np.degrees(np.abs(p_ - p_[0]).max()) > PROBE_UPSET_DEG)  # it tips, or the physics fails
            # ... or it does not drive straight (the pitch follows the turn): design §14.1
            upset |= bool(np.abs(r_["heading"][: n_run_ + 1] - r_["heading"][0]).max() > DRIVE_HEADING_MAX)
        settle_ = max(settles)
        if settle_ > ID_SKIP and not upset:
            k0_long = round(min(settle_ + 0.05, ID_MAX_S - ID_WINDOW) / dt)
            return _Drive(torque, levels, drive_, k0_long, n_long, settle_)
        for r_ in drive_:
            for key in ("z", "vcom", "pitch", "rim", "heading"):
                r_[key] = r_[key][: n_run_ + 1]
        return _Drive(torque, levels, drive_, k0_, n_run_, settle_)


def _straight_drive(rig: _Rig, torque: float) -> tuple[_Drive, float]:
    """The drive tests at ``torque`` N·m, rerun lower where they do not drive straight: (tests, how far the first
    top level turned, rad). design §14.1: a drive test is one while the robot drives straight; a centre of mass
    beside the axle couples υ into ω (§8.1: PAL TIAGo, 48 mm: 1.4 rad in 1 s at a quarter of the traction limit,
    a 10 % low); where the top level turns by more than DRIVE_HEADING_MAX, the tests rerun at a torque scaled
    down to turn by about that much (the turn grows with the torque), at most DRIVE_SCALE_MIN down and every
    level clear of the dead band."""
    f = rig.rest.f
    drive = rig.drive_tests(torque, _levels_of(torque, f))
    turned = float(np.abs(drive.runs[0]["heading"][: rig.sched.n_run + 1] - drive.runs[0]["heading"][0]).max())
    if turned > DRIVE_HEADING_MAX:
        lower = max(torque * max(DRIVE_HEADING_MAX / turned, DRIVE_SCALE_MIN), 3 * f)
        if lower < 0.9 * torque:
            drive = rig.drive_tests(lower, _levels_of(lower, f))
    return drive, turned


def _fit_drive(rig: _Rig, drive: _Drive, drag: bool) -> tuple[_Drive, tuple[float, ...], dict | None]:
    """The fit of ``a`` on ``drive`` (``drag``: with the drag term): (the tests kept, (a, c₀, β, residual), the
    rerun's record or None). design §14.2: a drive fit that does not hold (a chassis edge the torque pitches onto,
    a chassis bouncing on it) reruns once at FIT_RERUN_SCALE of the torque, every level clear of the dead band;
    kept where it holds."""
    f, torque = rig.rest.f, drive.torque
    a_id, ca, be, res_a = rig.fit(drive.runs, [2 * T for T in drive.levels], "z", 0, drag, drive.k0, residual=True)
    fit_rerun = None
    if not fit_holds(a_id, ca, res_a, torque) and (lower := max(torque * FIT_RERUN_SCALE, 3 * f)) < 0.9 * torque:
        drive2 = rig.drive_tests(lower, _levels_of(lower, f))
        fit2 = rig.fit(drive2.runs, [2 * T for T in drive2.levels], "z", 0, drag, drive2.k0, residual=True)
        fit_rerun = {
            "torque_Nm": lower,
            "first_torque_Nm": torque,
            "first_a": a_id,
            "first_fit_residual": res_a,
            "first_intercept_Nm": -ca / a_id if a_id else None,
            "kept": fit_holds(fit2[0], fit2[1], fit2[3], lower),
        }
        if fit_rerun["kept"]:
            return drive2, fit2, fit_rerun
    return drive, (a_id, ca, be, res_a), fit_rerun


def _caster_share(
    rig: _Rig,
    drive: _Drive,
    turn_levels: list[float],
    n_turn: int,
    k0_turn: int,
    k_form: list[float],
    ab: tuple[float, float],
) -> dict | None:
    """The ``caster_resistance`` finding or None (design §14.2): a robot with casters whose identified ``ab`` =
    (a, b) is off reruns its tests without what the casters resist with (their joints' damping and frictionloss,
    their own inertia, their scrub): the share they remove is theirs."""
    params, lay, model = rig.rest.params, rig.rest.lay, rig.rest.plant.model
    tau_a, tau_b = [2 * T for T in drive.levels], [2 * T for T in turn_levels]
    casters = caster_parts(model, lay)
    gaps = (ab[0] / params.a_eff - 1, ab[1] / params.b_eff - 1)
    if not (casters["joints"] and max(abs(g) for g in gaps) > CASTER_CF_DEV):
        return None

    def measure() -> tuple[float | None, float | None]:
        a_ = b_ = None
        if abs(gaps[0]) > CASTER_CF_DEV:
            drive_ = rig.drive_tests(drive.torque, drive.levels)
            a_ = rig.fit(drive_.runs, tau_a, "z", 0, k_form[0] > 0, drive_.k0)[0]
        if abs(gaps[1]) > CASTER_CF_DEV:
            turns = [rig.run(-T, T, n_turn) for T in turn_levels]
            b_ = rig.fit(turns, tau_b, "z", 1, k_form[1] > 0, k0_turn)[0]
        return a_, b_

    steps = caster_counterfactual(model, casters, measure)
    caster_cf = caster_finding(
        model,
        casters,
        (params.a_eff, params.b_eff),
        ab,
        steps,
        lay.base[: lay.base.index("/") + 1] if "/" in lay.base else "",
        (k_form[0] > 0, k_form[1] > 0),
    )
    if caster_cf is not None:
        caster_cf["steps"] = {k: list(v) for k, v in steps.items()}
    return caster_cf


def _final_findings(
    rest: _Rest, drive: _Drive, caster_cf: dict | None, k_form: list[float], ok: bool, ab: tuple[float, float]
) -> None:
    """Completes ``rest.findings`` after the fits (design §14.2): what a rocking chassis strikes the floor with;
    the casters' share, whose drag is then not said as damping; a level stance whose drive test does not follow
    the formula (``ab`` = the identified (a, b), ``ok`` whether they are)."""
    findings, params, level = rest.findings, rest.params, rest.level
    a_id, b_id = ab
    struck = [c for c in drive.runs[0]["dragging"] if c["peak_n"] > CASTER_LOAD * rest.weight]
    for fd in [x for x in findings if x["kind"] == "rocking"][:1] if struck else []:  # design §14.2: on what
        fd["detail"] += "; it strikes the floor with " + ", ".join(
            f"'{c['geom']}' (body '{c['body']}', up to {c['peak_n']:.3g} N, {c['load_n']:.3g} N on average)"
            for c in struck
        )
        fd["strikes"] = [{k: c[k] for k in ("geom", "body", "load_n", "peak_n")} for c in struck]
    if caster_cf is not None:
        findings.append(caster_cf)
        # a drag the wheel joints do not have, in a test the casters account for, is theirs: not said as damping
        theirs = [k_form[j] == 0 and w in caster_cf for j, w in enumerate(("a", "b"))]
        for fd in [x for x in findings if x["kind"] == "damping"]:
            if all(theirs[j] or t is None for j, t in enumerate(fd["time_constant_s"])):
                findings.remove(fd)
    if level is not None and (not ok or max(abs(a_id / params.a_eff - 1), abs(b_id / params.b_eff - 1)) > LEVEL_OFF):
        # design §14: a level stance whose drive test does not follow the formula: the wheels do not carry it
        findings.insert(
            0,
            _finding(
                "structural",
                f"the wheels do not stand on the floor as driven: at rest {level['detail'].split(': ', 1)[0]}, and "
                f"under torque it gives a = {a_id:.3g}, b = {b_id:.3g} against the formula's {params.a_eff:.3g}, "
                f"{params.b_eff:.3g}",
                wheel_load_n=level["measured_n"],
            ),
        )


def identify(
    model_file,
    *,
    torque: float | None = None,
    duration: float = ID_DURATION,
    settle: float = 0.2,
    timestep: float | None = None,
    payload: tuple[float, float] | None = None,
) -> dict:
    """Identify ``(a, b)`` of one robot by constant wheel torques from rest (design §14).

    ``model_file``: a shipped name, an MJCF path or a :class:`~bioform_mj.robots.refs.RobotRef` with a
    mapping. Drive tests ``τ_L = τ_R = T_k`` at the torque levels :data:`ID_LEVELS` (``τ_a = 2 T_k``),
    then turn tests ``τ_R = −τ_L``, each for ``duration`` s after ``settle`` s at rest on the floor,
    read through :class:`~bioform_mj.plants.mujoco.plant.MujocoPlant` (υ and ω of the axle
    midpoint, beside the centre of mass's forward speed and the chassis pitch). The fit skips the
    start-up transient (:data:`ID_SKIP` s, less when a wheel drag decays faster) and fits all levels
    at once in integral form, ``υ(t) − υ(t₀) = (a τ_a,k + c₀)(t − t₀) + β ∫υ``: the slope across
    the levels is ``a``, the intercept a dead band ``−c₀/a`` (frictionloss, a braking caster), ``β =
    −k`` a viscous drag (joint damping, back-EMF); the integral form averages a rocking chassis out
    instead of reading it as drag. ``T`` defaults to half the motor limit or a quarter of the
    traction limit ``μ N r``, whichever is lower. ``payload`` = (mass kg, yaw inertia kg·m²) adds a
    payload at the axle midpoint first.

    Returns a dict with the formula values, the identified values (``None`` when the robot cannot
    be identified: then ``findings`` says why), their relative differences, the identified drag
    and dead band beside their formulas, the centre of mass's ``a``, the rocking, the slip, the
    floor contacts at rest, and ``findings``: every cause found (``kind`` one of ``damping``,
    ``dead_band``, ``rocking``, ``slip``, ``braking_caster``, ``structural``, with ``detail`` and
    numbers). Raises :class:`~bioform_mj.core.errors.InputError` (exit 2) for a mapping no test can use.

    The steps: :func:`_bench` (the plant), :func:`_at_rest`, :func:`_test_torque`, :func:`_schedule`,
    :func:`_straight_drive`, the turn tests (:func:`_turn_plan`), :func:`_fit_drive`, the turn fit,
    :func:`_caster_share`, :func:`_final_findings`, the result.
    """
    plant, duration, k_drag = _bench(model_file, timestep, duration, settle, payload)
    rest = _at_rest(plant, model_file, settle, duration)
    torque, why = _test_torque(rest, torque)
    if why is not None:
        return _not_identified(rest, why)
    params, lay, dt, f, findings = rest.params, rest.lay, rest.dt, rest.f, rest.findings
    sched = _schedule(rest, torque, duration, settle, k_drag)
    n_turn, turn_levels = _turn_plan(rest, torque, _levels_of(torque, f), sched.duration)
    rig = _Rig(rest, sched)
    drive, turned = _straight_drive(rig, torque)
    first_torque, heading_torque = torque, drive.torque
    turn = [rig.run(-T, T, n_turn) for T in turn_levels]
    # design §14.2: a geom that is no wheel and no caster and drags on the floor while the robot drives (a chassis
    # edge the drive torque pitches onto) brakes it, whether or not it carried load at rest
    named = frozenset(strip_prefix(g, _prefix(lay)) for g in lay.casters)  # the mapping's casters (design §13)
    findings += moving_brakes(
        findings, drive.runs[0]["dragging"], rest.weight, params.wheel_radius, lay.base, 2 * drive.levels[0], named
    )
    # the drag term only where the model has a drag (wheel damping, back-EMF): free, it reads the
    # slow pitch settling of a tall chassis as a drag (design §14); without, a drag the formula does
    # not know shows in the free fit of the centre of mass (drag_rate_per_s.free_fit)
    k_form = params.unmodelled(0.0, 0.0)["drag_rate_per_s"]
    drive, (a_id, ca, be, res_a), fit_rerun = _fit_drive(rig, drive, k_form[0] > 0)
    torque, levels, tau_a = drive.torque, drive.levels, [2 * T for T in drive.levels]  # τ_a = τ_L + τ_R
    tau_b = [2 * T for T in turn_levels]  # τ_b = τ_R − τ_L (design §5 sign fix)
    k0_turn = 0 if sched.rate_form or f == 0 else min(round(TURN_SKIP / dt), n_turn - 4)
    b_id, cb, ge, res_b = rig.fit(turn, tau_b, "z", 1, k_form[1] > 0, k0_turn, residual=True)
    a_com, _, be_com = rig.fit(drive.runs, tau_a, "vcom", None, k_form[0] > 0, drive.k0)
    _, _, be_free = rig.fit(drive.runs, tau_a, "vcom", None, True, drive.k0)
    _, _, ge_free = rig.fit(turn, tau_b, "z", 1, True, k0_turn)
    windows = [(drive.n_run - drive.k0) * dt, (n_turn - k0_turn) * dt]
    truth = params.unmodelled(0.0, 0.0)
    ok = all(math.isfinite(x) for x in (a_id, b_id)) and a_id > 0 and b_id > 0
    caster_cf = _caster_share(rig, drive, turn_levels, n_turn, k0_turn, k_form, (a_id, b_id)) if ok else None
    fitted = fit_findings(
        findings,
        params=params,
        drive=drive.runs,
        k0=drive.k0,
        dt=dt,
        ok=ok,
        k_form=k_form,
        fits=dict(
            a_id=a_id,
            b_id=b_id,
            a_com=a_com,
            ca=ca,
            cb=cb,
            be=be,
            ge=ge,
            be_free=be_free,
            ge_free=ge_free,
            res_a=res_a,
            res_b=res_b,
        ),
        windows=windows,
        truth=truth,
        torque=torque,
        f=f,
        settle_s=drive.settle_s,
        id_skip=ID_SKIP,
    )
    _final_findings(rest, drive, caster_cf, k_form, ok, (a_id, b_id))
    if not ok:
        return _not_identified(
            rest, f"the tests give a = {a_id:.3g}, b = {b_id:.3g}: the robot does not move forward under forward torque"
        )
    return {
        **rest.base,
        "identified": {"a": a_id, "b": b_id},
        "relative_error": {"a": a_id / params.a_eff - 1, "b": b_id / params.b_eff - 1},
        "identified_com": {"a": a_com, "relative_error": a_com / params.a_eff - 1},
        "identified_axle_vs_com": fitted["com_gap"],
        "drag_rate_per_s": {"formula": truth["drag_rate_per_s"], "identified": fitted["drag"]},
        "deadband_torque_Nm": {"formula": truth["deadband_torque_Nm"], "identified": fitted["db"]},
        # design §14.2: the fits' intercepts as torques (a negative one: the linear model does not hold)
        "fit_intercept_Nm": fitted["intercept"],
        "fit_residual": {"a": res_a, "b": res_b},
        # design §14.2: whether the fit of each test holds (residual, intercept); where not, why (its a or b
        # is then a reading of the test, not the robot's)
        "fit_holds": {"a": fitted["holds"][0], "b": fitted["holds"][1]},
        "fit_problem": fitted["why_not"] or None,
        "rocking": {**fitted["rock"], "transient_deg": fitted["transient_deg"], "settled_s": drive.settle_s},
        "slip_ratio": fitted["slip"],
        "findings": findings,
        "identifiable": True,
        "test": {
            "torque_Nm": torque,
            "torque_levels_Nm": levels,
            # design §14.1: the first drive tests' top torque and how far its heading turned (rad), where
            # they turned by more than DRIVE_HEADING_MAX and reran at ``torque_Nm``
            "drive_rerun": (
                {"first_torque_Nm": first_torque, "first_heading_change_rad": turned}
                if heading_torque != first_torque
                else None
            ),
            # design §14.2: the drive tests rerun at a lower torque where their first fit did not hold
            "fit_rerun": fit_rerun,
            "caster_swivels": [s_.joint.split("/", 1)[-1] for s_ in rig.swivels],
            # what resists turning them round (a start from other angles, a change of direction)
            "caster_swivel_resistance": [x.resistance() for x in rig.swivels if x.damping or x.frictionloss],
            "turn_torque_Nm": turn_levels[0],
            "turn_torque_levels_Nm": turn_levels,
            "duration_s": drive.n_run * dt,
            "turn_duration_s": n_turn * dt,
            "turn_fit_from_s": k0_turn * dt,
            "fit_from_s": drive.k0 * dt,
            "pitch_settled_s": drive.settle_s,
            "fit": "rates" if sched.rate_form else "summed speed",
            "settle_s": settle,
            "timestep_s": dt,
            "integrator": mujoco.mjtIntegrator(plant.model.opt.integrator).name,
            "drive_lateral_drift_m": drive.runs[0]["lateral_m"],
            "drive_heading_change_rad": drive.runs[0]["heading_change_rad"],
            "mujoco_warnings": sum(x["warnings"] for x in drive.runs + turn),
        },
    }


def identify_main(model) -> dict:
    """JSON-able identification report of one robot (name, path or RobotRef; for ``bioform identify``).

    Never an internal error for a robot the tests cannot measure (design §14): an arithmetic
    failure of the fit becomes ``identifiable: false`` with a ``structural`` finding saying so."""
    try:
        return identify(model)
    except (ArithmeticError, np.linalg.LinAlgError) as exc:
        why = f"the identification could not be computed ({type(exc).__name__}: {exc}): degenerate robot or mapping"
        return {
            "model": str(getattr(model, "model", model)),
            "identified": {"a": None, "b": None},
            "relative_error": {"a": None, "b": None},
            "findings": [_finding("structural", why)],
            "identifiable": False,
            "not_identified": why,
        }
