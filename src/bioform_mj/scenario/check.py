"""Scenario validation: every value the algorithm's assumptions need, checked before any work.

:func:`validate` raises :class:`~bioform_mj.core.errors.ScenarioError` (one line naming the key) on the
first problem found; :func:`run_size` estimates a run's steps and memory, which bound the time axis.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.control.registry import is_registered, unknown_method
from bioform_mj.core.errors import UNSAFE_TEXT, GraphError, ScenarioError, escape_unsafe
from bioform_mj.formation.obstacles import validate as _validate_obstacles
from bioform_mj.formation.safety import validate as _validate_safety
from bioform_mj.scenario.config import (
    DERIVATIVES,
    ESTIMATOR_INITS,
    EVENT_KINDS,
    GAIN_SCALINGS,
    GRAPH_KINDS,
    LEADER_KINDS,
    MAX_CONTROL_STEPS,
    MAX_NAME,
    MAX_PHYSICS_STEPS,
    MAX_RUN_BYTES,
    MIN_PHYSICS_DT,
    PLANTS,
    SATURATIONS,
    SENSINGS,
    Scenario,
)


def robot_encoder_cpr(model: str) -> float | None:
    """Encoder counts per revolution an MJCF robot file declares (``<custom><numeric
    name="encoder_cpr" data="4096"/>``), None if it has no encoders (design §8.3). Read with
    ElementTree: no MuJoCo needed to validate a scenario."""
    import xml.etree.ElementTree as ET

    from bioform_mj.robots.sanity import parse_xml  # fed whole (a huge attribute: quadratic in chunks)

    try:
        root = parse_xml(model)
    except (OSError, ET.ParseError):
        return None  # the scene reports an unreadable file
    for num in root.iter("numeric"):
        if num.get("name") == "encoder_cpr":
            try:
                return float((num.get("data") or "").split()[0])
            except (ValueError, IndexError):
                return 0.0
    return None


def _positive(key: str, values: Any, strict: bool = True) -> None:
    for v in np.atleast_1d(values):
        if (v <= 0) if strict else (v < 0):
            raise ScenarioError(key, f"must be {'> 0' if strict else '>= 0'}, got {v:g}")


def _length(key: str, values: tuple, n: int) -> None:
    if len(values) != n:
        raise ScenarioError(key, f"expected {n} values, got {len(values)}")


#: what lists the plant kinds a scenario may name beyond the shipped ones (``PLANTS``): the plant registry
#: (``plants.registry.plant_kinds``, a package on this floor), registered here when the run package is imported
#: (``bioform_mj.load`` and the CLI import it; design §0)
_PLANT_KINDS: list[Callable[[], tuple[str, ...]]] = []


def register_plant_kinds(kinds: Callable[[], tuple[str, ...]]) -> None:
    """Register what lists the plant kinds ``plant.kind`` (and ``--plant``) may name: the shipped ones and those
    registered with :func:`bioform_mj.plants.registry.register_plant`.

    Parameters
    ----------
    kinds : callable
        ``kinds() -> tuple of str``, asked at each validation (a kind registered later is known then).
    """
    _PLANT_KINDS[:] = [kinds]


def plant_kinds() -> tuple[str, ...]:
    """The plant kinds a scenario may name now: the shipped ones (``PLANTS``), then the registry's
    (:func:`register_plant_kinds`) in registration order, each once."""
    return tuple(dict.fromkeys((*PLANTS, *(_PLANT_KINDS[-1]() if _PLANT_KINDS else ()))))


def validate(sc: Scenario) -> None:
    """Check every value the algorithm's assumptions need; raise on the first problem found."""
    if not is_registered(sc.method):  # the paper's four, or a registered controller (design §22)
        raise ScenarioError("method", unknown_method(sc.method))
    if sc.plant.kind not in PLANTS and sc.plant.kind not in (kinds := plant_kinds()):  # or a registered plant (§22)
        raise ScenarioError("plant.kind", f"unknown plant '{sc.plant.kind}' (expected one of: {', '.join(kinds)})")
    _validate_text(sc)
    s = sc.sim
    _positive("sim.duration", s.duration)
    _positive("sim.control_dt", s.control_dt)
    _positive("sim.physics_dt", s.physics_dt)
    _positive("sim.log_dt", s.log_dt)
    if s.physics_dt < MIN_PHYSICS_DT:  # before the ratios: control_dt / 5e-324 is inf
        raise ScenarioError("sim.physics_dt", f"must be >= {MIN_PHYSICS_DT:g} s, got {s.physics_dt:g}")
    if s.physics_dt > s.control_dt * (1 + 1e-9):
        raise ScenarioError(
            "sim.physics_dt", f"must not exceed sim.control_dt = {s.control_dt:g} s, got {s.physics_dt:g}"
        )
    ratio = s.control_dt / s.physics_dt
    if abs(ratio - round(ratio)) > 1e-6:
        raise ScenarioError(
            "sim.physics_dt",
            f"must divide sim.control_dt = {s.control_dt:g} s into whole substeps, got {s.physics_dt:g}",
        )
    if s.log_dt < s.control_dt * (1 - 1e-9):
        raise ScenarioError("sim.log_dt", f"must be >= sim.control_dt = {s.control_dt:g} s, got {s.log_dt:g}")
    if s.duration < s.control_dt:
        raise ScenarioError(
            "sim.duration", f"must be at least one control period ({s.control_dt:g} s), got {s.duration:g}"
        )
    if s.seed < 0:
        raise ScenarioError("sim.seed", f"must be >= 0, got {s.seed}")
    _validate_size(sc)

    ld = sc.leader
    if ld.kind not in LEADER_KINDS:
        raise ScenarioError(
            "leader.kind", f"unknown trajectory '{ld.kind}' (expected one of: {', '.join(LEADER_KINDS)})"
        )
    if ld.kind in ("circle", "figure8"):
        _positive("leader.radius", ld.radius)
    if ld.kind in ("paper", "line", "circle"):
        _positive("leader.speed", ld.speed)
    if ld.kind == "figure8":
        _positive("leader.frequency", ld.frequency)
    for key, terms in (("leader.x_terms", ld.x_terms), ("leader.y_terms", ld.y_terms)):
        for i, t in enumerate(terms):
            if len(t) != 3:
                raise ScenarioError(f"{key}[{i}]", f"expected [amplitude, frequency, phase], got {list(t)}")
    traj = sc.build_leader()
    vmin, vmax, wmax = traj.motion_range(s.duration)
    if not vmin > 1e-6:
        raise ScenarioError(
            "leader", f"the leader's speed reaches {vmin:g} m/s; its heading is undefined where it stops"
        )
    if not vmax < sc.limits.speed and not vmax <= (reach := _reach(sc))[0]:  # 1e12 ran into the guard (issue 28)
        raise ScenarioError(
            "leader.speed" if ld.kind in ("paper", "line", "circle") else "leader",
            f"the leader's speed reaches {vmax:g} m/s, more than any robot of the scene could reach in the run: "
            f"{reach[1]}; and beyond limits.speed = {sc.limits.speed:g} m/s (the run would stop as diverged)",
        )
    # a circle of radius 1e-300 m: a torque of 1e296 N·m at t = 0 (issue 28); a MuJoCo robot compiled only past 1 rad/s
    if wmax > 1.0 and wmax > (turn := _reach(sc, yaw=True))[0]:
        raise ScenarioError(
            "leader",
            f"the leader turns at up to {wmax:g} rad/s, more than any robot of the scene could in the run: {turn[1]}",
        )

    n = sc.n
    f = sc.formation
    if n < 1:
        raise ScenarioError("formation.offsets", "need at least one follower")
    for i, o in enumerate(f.offsets):
        if len(o) != 2:
            raise ScenarioError(f"formation.offsets[{i}]", f"expected [dx, dy], got {list(o)}")
    _length("formation.initial_poses", f.initial_poses, n)
    for i, p in enumerate(f.initial_poses):
        if len(p) != 3:
            raise ScenarioError(f"formation.initial_poses[{i}]", f"expected [x, y, theta], got {list(p)}")
    _positive("formation.init_jitter", f.init_jitter, strict=False)
    if not (f.init_jitter_heading == -1.0 or f.init_jitter_heading >= 0):
        raise ScenarioError(
            "formation.init_jitter_heading",
            f"must be >= 0 (or -1: the number of init_jitter), got {f.init_jitter_heading:g}",
        )
    if f.frame not in ("world", "leader"):
        raise ScenarioError("formation.frame", f"must be 'world' or 'leader', got {f.frame!r}")
    offs = np.array(f.offsets)
    uniq, inv, counts = np.unique(np.round(offs, 9), axis=0, return_inverse=True, return_counts=True)
    if np.any(counts > 1):
        dup = np.flatnonzero(counts[inv.reshape(-1)] > 1)[:2] + 1
        raise ScenarioError(
            "formation.offsets", f"followers {dup[0]} and {dup[1]} are assigned the same formation slot"
        )

    g = sc.graph
    if g.kind not in GRAPH_KINDS:
        raise ScenarioError("graph.kind", f"unknown topology '{g.kind}' (expected one of: {', '.join(GRAPH_KINDS)})")
    if g.kind == "complete" and n * (n - 1) // 2 > MAX_EDGES:  # 20,000 followers: a MemoryError after 25 s
        raise ScenarioError(
            "graph.kind",
            f"'complete' over {n} followers is {n * (n - 1) // 2} edges, above the {MAX_EDGES:.0e} a run holds (each "
            "control step reads every edge); use 'chain', 'ring', 'star' or explicit edges",
        )
    try:
        sc.build_graph()
    except GraphError as exc:
        raise ScenarioError("graph", str(exc)) from None

    e = sc.estimator
    _length("estimator.kp", e.kp, 3)
    _positive("estimator.kp", e.kp)
    for key, vals in (("estimator.ka", e.ka), ("estimator.kb", e.kb), ("estimator.phi", e.phi)):
        _length(key, vals, 2)
    _positive("estimator.ka", e.ka)
    _positive("estimator.kb", e.kb)
    _positive("estimator.phi", e.phi, strict=False)
    if e.init not in ESTIMATOR_INITS:
        raise ScenarioError("estimator.init", f"unknown '{e.init}' (expected one of: {', '.join(ESTIMATOR_INITS)})")

    k = sc.kinematic
    for name in ("k1", "k2", "k3", "A", "B", "D"):
        _positive(f"kinematic.{name}", getattr(k, name))

    t = sc.torque
    _length("torque.c", t.c, 2)
    _positive("torque.c", t.c)
    _positive("torque.phi", t.phi, strict=False)
    _positive("torque.tau_max", t.tau_max)
    _positive("torque.deriv_wn", t.deriv_wn)
    _positive("torque.resistance_margin", (t.resistance_margin,), strict=False)  # opt-in (learner_sizing)
    if t.derivative not in DERIVATIVES:
        raise ScenarioError(
            "torque.derivative", f"unknown '{t.derivative}' (expected one of: {', '.join(DERIVATIVES)})"
        )
    if t.saturation not in SATURATIONS:
        raise ScenarioError(
            "torque.saturation", f"unknown '{t.saturation}' (expected one of: {', '.join(SATURATIONS)})"
        )

    lc = sc.learner
    for key in ("k4", "k5", "c_hat0_scale", "c_bounds"):
        _length(f"learner.{key}", getattr(lc, key), 2)
        _positive(f"learner.{key}", getattr(lc, key))
    _length("learner.kd", lc.kd, 2)
    _positive("learner.kd", lc.kd, strict=False)
    _length("learner.drag_gain", lc.drag_gain, 2)
    for key, vals in (("learner.drag_gain", lc.drag_gain), ("learner.drag_max", (lc.drag_max,))):
        if not all(math.isfinite(v) and v > 0 for v in vals):
            raise ScenarioError(key, f"must be finite numbers > 0, got {list(vals)}")
    if lc.gain_scaling not in GAIN_SCALINGS:
        raise ScenarioError(
            "learner.gain_scaling", f"unknown '{lc.gain_scaling}' (expected one of: {', '.join(GAIN_SCALINGS)})"
        )
    if lc.kd_deadband:  # opt-in (learner_sizing): [] or two gains >= 0
        _length("learner.kd_deadband", lc.kd_deadband, 2)
        _positive("learner.kd_deadband", lc.kd_deadband, strict=False)
    band = lc.projection_band  # opt-in (design §14): factors of the prior c_true
    if band and not (len(band) == 2 and all(math.isfinite(v) for v in band) and 0 < band[0] <= 1.0 <= band[1]):
        raise ScenarioError(
            "learner.projection_band",
            f"must be [] or [lower, upper] with 0 < lower <= 1 <= upper (factors of c_true), got {list(band)}",
        )
    if not lc.c_bounds[0] <= 1.0 <= lc.c_bounds[1]:
        raise ScenarioError(
            "learner.c_bounds", f"must satisfy lower <= 1 <= upper (factors of c_hat0), got {list(lc.c_bounds)}"
        )

    pc = sc.plant
    _length("plant.c_true", pc.c_true, 2)
    _positive("plant.c_true", pc.c_true)
    _positive("plant.mass", pc.mass)
    _positive("plant.inertia", pc.inertia)
    if len(pc.robots) not in (1, n):
        raise ScenarioError("plant.robots", f"expected 1 or {n} robot models, got {len(pc.robots)}")
    from bioform_mj.robots.refs import as_ref, asset_root_problem

    for i, r in enumerate(pc.robots):  # a typo names the key, not an "outside" refusal later (issue 28)
        for folder in as_ref(r, f"plant.robots[{i}]").asset_roots:
            if why := asset_root_problem(folder):
                raise ScenarioError(f"plant.robots[{i}].asset_roots", why)
    if pc.kind == "mujoco":
        from bioform_mj.robots.entries import resolve_robot
        from bioform_mj.robots.formats import format_of

        for name, folder in pc.package_path:
            if not Path(folder).is_dir():
                raise ScenarioError(f"plant.package_path.{name}", f"directory '{folder}' does not exist")
        for r in pc.robots:
            ref = resolve_robot(r)  # raises InputError naming an unknown robot or a missing file
            if (precheck := format_of(ref.model).precheck) is not None:
                precheck(ref)  # design §12 (a URDF: root, package://, meshes, wheels): before any work
    _validate_sensing(sc)

    d = sc.disturbance
    for key in ("bias", "amp", "freq", "phase"):
        _length(f"disturbance.{key}", getattr(d, key), 2)

    lim = sc.limits
    for key in ("speed", "position", "torque"):
        _positive(f"limits.{key}", getattr(lim, key))
    _validate_start(sc)

    for i, ev in enumerate(sc.events):
        key = f"events[{i}]"
        if ev.kind not in EVENT_KINDS:
            raise ScenarioError(f"{key}.kind", f"unknown event '{ev.kind}' (expected one of: {', '.join(EVENT_KINDS)})")
        if not 1 <= ev.follower <= n:
            raise ScenarioError(f"{key}.follower", f"must be a follower id in 1..{n}, got {ev.follower}")
        if not 0 <= ev.time <= s.duration:
            raise ScenarioError(f"{key}.time", f"must lie in [0, sim.duration = {s.duration:g}], got {ev.time:g}")
        # design §17: an event is applied at the first control step at or after its time; one past the
        # last step (k = N - 1) would never be applied, silently
        n_steps = max(1, int(round(s.duration / s.control_dt)))
        t_last = (n_steps - 1) * s.control_dt
        if math.ceil((ev.time - 1e-12) / s.control_dt - 1e-9) > n_steps - 1:
            raise ScenarioError(
                f"{key}.time",
                f"{ev.time:g} s is after the last control step (t = {t_last:g} s of sim.duration = "
                f"{s.duration:g} s), so the event would never be applied; use a time <= {t_last:g} s",
            )
        _positive(f"{key}.mass", ev.mass, strict=False)
        _positive(f"{key}.inertia", ev.inertia, strict=False)
        _check_payload(sc, key, ev.mass, ev.inertia)

    _validate_faults(sc)
    _validate_safety(sc.safety)
    if sc.safety.filter == "cbf" and sc.torque.derivative == "analytic":
        raise ScenarioError(
            "safety.filter",
            "the analytic command derivative differentiates eq. 31, not the filtered command: "
            "use torque.derivative = 'filter' or 'difference' with the cbf filter",
        )
    _validate_obstacles(sc.obstacles, sc.obstacle_field)
    if sc.obstacles or sc.obstacle_field.count:
        if pc.kind != "mujoco":
            raise ScenarioError(
                "obstacles", "the ideal plant has no bodies to touch obstacles: use plant.kind = 'mujoco'"
            )
        sc.obstacle_list()  # a field too dense to place fails here, before any work


#: most edges a follower graph may have (a complete graph of 1414 followers; issue 28)
MAX_EDGES = 1_000_000


#: the most a payload may be, in multiples of the heaviest robot's own mass and yaw inertia: no wheeled robot carries a
#: hundred times its weight (a 1 kg TurtleBot3 Burger is rated for 15 kg); 1e12 kg ran and diverged (issue 28)
PAYLOAD_MAX_RATIO = 100.0


@functools.lru_cache(maxsize=64)
def _robot_numbers(ref: Any) -> tuple[float, float, float, float, float]:
    """A MuJoCo robot's mass (kg), yaw inertia (kg·m²), ``a_eff`` (m/(s²·N·m)), largest wheel torque (N·m) and
    ``b_eff`` (rad/(s²·N·m)), compiled once a process (30 ms; only for a payload or a leader beyond reach)."""
    from bioform_mj.robots.params import robot_truth

    t = robot_truth(ref)
    return float(t.mass), float(t.yaw_inertia), float(t.a_eff), float(max(t.tau_max)), float(t.b_eff)


#: the shortest time the reach of :func:`_reach` is taken over, s: a short run of the paper's 1.08 m/s leader (a test
#: of the start, a guard probed with a low ``limits.speed``) is not a leader beyond reach; 1e12 m/s is in any run
REACH_MIN_S = 10.0


def _reach(sc: Scenario, yaw: bool = False) -> tuple[float, str]:
    """The fastest a robot of the scene could go (``yaw``: turn) by the run's end, m/s (rad/s), and how: from rest at
    full torque on both wheels, ``2 a τ_max`` m/s² (``2 b τ_max`` rad/s²) for ``sim.duration`` (the ideal plant's
    ``plant.c_true`` and ``torque.tau_max``, a MuJoCo robot's compiled ``a_eff``/``b_eff`` and drive limit; the
    fastest robot of the team)."""
    pc, d, k = sc.plant, max(sc.sim.duration, REACH_MIN_S), 1 if yaw else 0
    if pc.kind == "mujoco" and pc.robots:
        nums = [_robot_numbers(r) for r in dict.fromkeys(pc.robots)]
        c, tau = max(((n[2 + 2 * k], n[3]) for n in nums), key=lambda x: x[0] * x[1])
    else:
        c, tau = float(pc.c_true[k]), float(sc.torque.tau_max)
    v = 2.0 * c * tau * d
    name, unit_ = ("b", "rad/(s²·N·m)") if yaw else ("a", "m/(s²·N·m)")
    return (
        v,
        f"from rest at full torque ({tau:g} N·m a wheel, {name} = {c:.4g} {unit_}) over {d:g} s (sim.duration, at "
        f"least {REACH_MIN_S:g} s), "
        f"{v:.4g} {'rad/s' if yaw else 'm/s'}",
    )


def _check_payload(sc: Scenario, key: str, mass: float, inertia: float) -> None:
    """Refuse a payload of more than :data:`PAYLOAD_MAX_RATIO` times the heaviest robot of the scene (kg, and its
    yaw inertia, kg·m²): the ideal plant's ``plant.mass``/``plant.inertia``, the MuJoCo robots' compiled ones."""
    if mass <= 0 and inertia <= 0:
        return
    pc = sc.plant
    if pc.kind == "mujoco" and pc.robots:
        sizes = [_robot_numbers(r) for r in dict.fromkeys(pc.robots)]
        own = {"mass": max(n[0] for n in sizes), "inertia": max(n[1] for n in sizes)}
        whose = {k: f"the heaviest robot's {'yaw inertia' if k == 'inertia' else k}" for k in own}
    else:
        own = {"mass": float(pc.mass), "inertia": float(pc.inertia)}
        whose = {k: f"the robot's (plant.{k})" for k in own}
    for what, v, unit_ in (("mass", mass, "kg"), ("inertia", inertia, "kg·m²")):
        if v > PAYLOAD_MAX_RATIO * own[what]:
            raise ScenarioError(
                f"{key}.{what}",
                f"a payload of {v:g} {unit_}, above {PAYLOAD_MAX_RATIO:g} × {whose[what]} {own[what]:.4g} {unit_} = "
                f"{PAYLOAD_MAX_RATIO * own[what]:.4g} {unit_}: no robot of the scene could carry it",
            )


def _validate_sensing(sc: Scenario) -> None:
    """``plant.sensing`` and the sensor keys (design §8.3)."""
    pc, s = sc.plant, sc.sim
    if pc.sensing not in SENSINGS:
        raise ScenarioError("plant.sensing", f"unknown '{pc.sensing}' (expected one of: {', '.join(SENSINGS)})")
    if pc.encoder_cpr == 0 or pc.encoder_cpr < -1:
        raise ScenarioError(
            "plant.encoder_cpr", f"must be >= 1 count per revolution (or -1: each robot file's), got {pc.encoder_cpr}"
        )
    _positive("plant.gyro_noise", pc.gyro_noise, strict=False)
    _positive("plant.sensor_dt", pc.sensor_dt, strict=False)
    if pc.sensor_dt > 0:
        ratio = pc.sensor_dt / s.physics_dt
        if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ScenarioError(
                "plant.sensor_dt", f"must be a multiple of sim.physics_dt = {s.physics_dt:g} s, got {pc.sensor_dt:g}"
            )
        per = s.control_dt / pc.sensor_dt
        if per < 1 - 1e-9 or abs(per - round(per)) > 1e-9 * per:
            raise ScenarioError(
                "plant.sensor_dt",
                f"must divide sim.control_dt = {s.control_dt:g} s into whole sensor periods, got {pc.sensor_dt:g}",
            )
    if pc.sensing != "odometry":
        return
    if pc.kind != "mujoco":
        raise ScenarioError(
            "plant.sensing", '"odometry" needs plant.kind = "mujoco" (encoders and gyro are MuJoCo sensors)'
        )
    if pc.encoder_cpr > 0:
        return
    from bioform_mj.robots.entries import resolve_robot

    for r in pc.robots:
        ref = resolve_robot(r)
        cpr = robot_encoder_cpr(ref.model)
        if cpr is None:
            raise ScenarioError(
                "plant.sensing",
                f"\"odometry\" needs wheel encoders, and robot '{r.model}' "
                f'({ref.model}) declares none (no <numeric name="encoder_cpr">): '
                "set plant.encoder_cpr",
            )
        if not cpr >= 1:
            raise ScenarioError(
                "plant.encoder_cpr",
                f"robot '{r.model}' ({ref.model}) declares {cpr:g} encoder counts per revolution; must be >= 1",
            )


def _validate_start(sc: Scenario) -> None:
    """The followers' starts, jitter included, within ``limits.position`` (the divergence guard's bound on ``|x|``
    and ``|y|``, m): ``formation.init_jitter = 1e12`` was a run diverged at t = 0 (exit 3, issue 28). The bound
    is the worst draw's: the farthest nominal start coordinate plus the jitter, whatever the seed."""
    f, lim = sc.formation, float(sc.limits.position)
    p = np.array(f.initial_poses, dtype=float).reshape(-1, 3)
    far = float(np.max(np.abs(p[:, :2]))) if p.size else 0.0
    if not far < lim:
        raise ScenarioError(
            "formation.initial_poses", f"a start at |x| or |y| = {far:g} m is beyond limits.position = {lim:g} m"
        )
    if far + f.init_jitter >= lim:
        raise ScenarioError(
            "formation.init_jitter",
            f"{f.init_jitter:g} m can put a start at |x| or |y| = {far + f.init_jitter:g} m, beyond limits.position = "
            f"{lim:g} m (the run would stop as diverged at t = 0); here it must be below {lim - far:g} m",
        )


def _validate_text(sc: Scenario) -> None:
    """``name`` becomes the default output folder ``runs/<name>-<plant>-<method>``: a plain file name."""
    name = sc.name
    bad = None
    if not name.strip():
        bad = "is empty"
    elif any(c in name for c in "/\\") or "\x00" in name:
        bad = "contains a path separator or NUL; it names the output folder under runs/ and must be a plain file name"
    elif name.startswith("."):
        bad = "starts with '.'; it names the output folder under runs/ and must be a plain, visible file name"
    elif UNSAFE_TEXT.search(name):  # a newline, or U+202E showing the name reversed (issue 28)
        bad = "contains a control character or a bidirectional-format one"
    elif len(name) > MAX_NAME:
        bad = f"is longer than {MAX_NAME} characters"
    if bad:
        raise ScenarioError("name", f"{bad}, got {escape_unsafe(repr(name))}")
    if "\x00" in sc.description:
        raise ScenarioError("description", "contains a NUL character")


def _fmt_bytes(b: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def run_size(sc: Scenario) -> dict[str, float]:
    """Estimated size of a run: control and physics steps, log rows, and memory in bytes.

    Memory: the log (every channel of ``engine.CHANNELS``, float64, every ``log_dt``) and the
    leader trajectory precomputed for every control step (t, pose, velocity).
    """
    from bioform_mj.core.engine import CHANNELS  # here, not at import: the engine imports this module's users

    s = sc.sim
    steps = s.duration / s.control_dt
    substeps = max(1.0, round(s.control_dt / s.physics_dt))
    stride = max(1.0, round(s.log_dt / s.control_dt))
    rows = steps / stride + 1
    dims = {"n": sc.n, "3": 3, "2": 2}
    per_row = 0
    for shape, _doc in CHANNELS.values():  # name -> (trailing shape, description)
        per_row += 8 * int(np.prod([dims[d] for d in shape]))
    log_bytes = rows * per_row
    traj_bytes = (steps + 1) * 8 * (1 + 3 + 2)
    return {
        "control_steps": steps,
        "physics_steps": steps * substeps,
        "log_rows": rows,
        "log_bytes": log_bytes,
        "trajectory_bytes": traj_bytes,
        "bytes": log_bytes + traj_bytes,
    }


def _validate_size(sc: Scenario) -> None:
    """Refuse a time axis whose step count or memory is beyond reason, saying so with the estimate."""
    s = sc.sim
    if s.physics_dt < MIN_PHYSICS_DT:
        raise ScenarioError("sim.physics_dt", f"must be >= {MIN_PHYSICS_DT:g} s, got {s.physics_dt:g}")
    est = run_size(sc)
    what = f"sim.duration {s.duration:g} s at control_dt {s.control_dt * 1e3:g} ms is {est['control_steps']:.3g} steps"
    mem = f"~{_fmt_bytes(est['bytes'])} of log and trajectory in memory"
    if est["control_steps"] > MAX_CONTROL_STEPS:
        raise ScenarioError("sim.duration", f"{what} ({mem}); at most {MAX_CONTROL_STEPS:.0e} control steps")
    if est["physics_steps"] > MAX_PHYSICS_STEPS:
        raise ScenarioError(
            "sim.physics_dt",
            f"sim.duration {s.duration:g} s at physics_dt {s.physics_dt:g} s is "
            f"{est['physics_steps']:.3g} physics steps; at most {MAX_PHYSICS_STEPS:.0e}",
        )
    if est["bytes"] > MAX_RUN_BYTES:
        hint = " (raise sim.log_dt for a smaller log)" if est["log_bytes"] > est["trajectory_bytes"] else ""
        raise ScenarioError(
            "sim.duration",
            f"{what}, log every {s.log_dt:g} s for {sc.n} followers: {mem}; at most {_fmt_bytes(MAX_RUN_BYTES)}{hint}",
        )
    if sc.plant.kind == "mujoco":  # the compiled scene grows with n² (its contact arena): known before it is built
        from bioform_mj.core.budget import require, scene_bytes

        require(
            scene_bytes(sc.n) + est["bytes"],
            f"a MuJoCo scene of {sc.n} followers ({_fmt_bytes(scene_bytes(sc.n))} for the compiled model and its "
            f"data, {_fmt_bytes(est['bytes'])} of log)",
            "use fewer followers, or the ideal plant",
        )


def _follower_id(key: str, value: float, n: int, lo: int = 1, what: str = "a follower id") -> int:
    if not float(value).is_integer() or not lo <= value <= n:
        raise ScenarioError(key, f"must be {what} in {lo}..{n}, got {value:g}")
    return int(value)


def _rows(key: str, rows: tuple, width: int, fields: str) -> None:
    for r, row in enumerate(rows):
        if len(row) != width:
            raise ScenarioError(f"{key}[{r}]", f"expected [{fields}], got {list(row)}")


def _validate_faults(sc: Scenario) -> None:
    """Faults: ids in range, links that exist, times >= 0 and ordered, probabilities in [0, 1)."""
    fc, n, dt = sc.faults, sc.n, sc.sim.control_dt
    graph = sc.build_graph()
    edges = {tuple(e) for e in (graph.edges + 1).tolist()}
    _rows("faults.link_fail", fc.link_fail, 4, "i, j, t_fail, t_recover")
    for r, (i, j, t0, t1) in enumerate(fc.link_fail):
        key = f"faults.link_fail[{r}]"
        i = _follower_id(key, i, n)
        j = _follower_id(key, j, n, lo=0, what="0 (the leader) or a follower id")
        if j == 0 and not graph.leader_access[i - 1] > 0:
            raise ScenarioError(
                key,
                f"follower {i} has no leader link to fail (leader access: "
                f"{(np.flatnonzero(graph.leader_access) + 1).tolist()})",
            )
        if j > 0 and (min(i, j), max(i, j)) not in edges:
            raise ScenarioError(
                key, f"there is no link {i}-{j} in the graph (links: {', '.join(f'{a}-{b}' for a, b in sorted(edges))})"
            )
        if not 0 <= t0 < t1:
            raise ScenarioError(key, f"needs 0 <= t_fail < t_recover, got t_fail = {t0:g}, t_recover = {t1:g}")
    if not 0 <= fc.packet_loss < 1:
        raise ScenarioError("faults.packet_loss", f"must be a probability in [0, 1), got {fc.packet_loss:g}")
    _positive("faults.delay", fc.delay, strict=False)
    if fc.delay > 0 and round(fc.delay / dt) < 1:
        raise ScenarioError("faults.delay", f"must be 0 or at least one control period ({dt:g} s), got {fc.delay:g}")
    if fc.delay > sc.sim.duration:
        raise ScenarioError("faults.delay", f"must not exceed sim.duration = {sc.sim.duration:g} s, got {fc.delay:g}")
    _length("faults.noise_pose", fc.noise_pose, 3)
    _positive("faults.noise_pose", fc.noise_pose, strict=False)
    _length("faults.noise_vel", fc.noise_vel, 2)
    _positive("faults.noise_vel", fc.noise_vel, strict=False)
    if fc.window:
        if len(fc.window) != 2 or not 0 <= fc.window[0] < fc.window[1]:
            raise ScenarioError(
                "faults.window", f"expected [t_start, t_end] with 0 <= t_start < t_end, or [], got {list(fc.window)}"
            )
    _rows("faults.actuator", fc.actuator, 4, "i, t_start, t_end, scale")
    for r, (i, t0, t1, scale) in enumerate(fc.actuator):
        key = f"faults.actuator[{r}]"
        _follower_id(key, i, n)
        if not 0 <= t0 < t1:
            raise ScenarioError(key, f"needs 0 <= t_start < t_end, got {t0:g}, {t1:g}")
        if not 0 <= scale <= 1:
            raise ScenarioError(key, f"scale of the torque limit must lie in [0, 1], got {scale:g}")
    _rows("faults.push", fc.push, 6, "i, t, duration, fx, fy, tz")
    for r, (i, t0, dur, *_w) in enumerate(fc.push):
        key = f"faults.push[{r}]"
        _follower_id(key, i, n)
        if not t0 >= 0:
            raise ScenarioError(key, f"time must be >= 0, got {t0:g}")
        if not dur > 0:
            raise ScenarioError(key, f"duration must be > 0, got {dur:g}")
    if fc.friction_patch:
        p = fc.friction_patch
        if len(p) != 5 or not (p[0] < p[2] and p[1] < p[3]) or not (0 < p[4] < float("inf")):
            raise ScenarioError(  # μ 0: no grip, the wheels would not stand on the floor (issue 28)
                "faults.friction_patch",
                f"expected [x0, y0, x1, y1, mu] with x0 < x1, y0 < y1, 0 < mu < inf, or [], got {list(p)}",
            )
        if sc.plant.kind != "mujoco":
            raise ScenarioError(
                "faults.friction_patch", "needs plant.kind = 'mujoco': the ideal plant's wheels cannot slip"
            )
