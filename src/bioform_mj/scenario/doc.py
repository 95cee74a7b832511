"""What every scenario key means: unit and one line, the source of the generated scenario reference.

:data:`KEYS` maps each dotted key of :class:`~bioform_mj.scenario.config.Scenario` (``events[].time`` for the
fields of an array of tables) to ``(unit, description)``; :data:`CHOICES` gives the allowed values of
the keys that take one of a few strings. :func:`reference_rows` walks the dataclasses and joins them
with their types and defaults; ``scripts/gen_docs.py`` renders it into ``reference/scenario.md`` at
build time, and ``tests/test_docs.py`` fails when a key has no entry (or an entry no key). A key marked
"× scale" is multiplied by ``formation.scale`` when the scenario is loaded
(:func:`~bioform_mj.scenario.loader.apply_scale`).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any

from bioform_mj.control.stack import METHODS
from bioform_mj.formation.obstacles import SHAPES
from bioform_mj.formation.safety import FILTERS
from bioform_mj.robots.refs import RobotRef
from bioform_mj.scenario.config import (
    DERIVATIVES,
    ESTIMATOR_INITS,
    EVENT_KINDS,
    GAIN_SCALINGS,
    GRAPH_KINDS,
    LEADER_KINDS,
    PLANTS,
    SATURATIONS,
    SENSINGS,
    Scenario,
)

#: allowed values of the string keys that take one of a few (validated in scenario_check.validate)
CHOICES: dict[str, tuple[str, ...]] = {
    "method": tuple(METHODS),
    "leader.kind": LEADER_KINDS,
    "graph.kind": GRAPH_KINDS,
    "formation.frame": ("world", "leader"),
    "estimator.init": ESTIMATOR_INITS,
    "torque.saturation": SATURATIONS,
    "obstacles[].shape": SHAPES,
    "obstacle_field.shape": SHAPES,
    "safety.filter": FILTERS,
    "torque.derivative": DERIVATIVES,
    "learner.gain_scaling": GAIN_SCALINGS,
    "plant.kind": PLANTS,
    "plant.sensing": SENSINGS,
    "plant.robots[].motor": ("", "ideal", "dc"),
    "plant.robots[].driver": ("", "current", "voltage"),
    "events[].kind": EVENT_KINDS,
}

#: ``dotted key -> (unit, one-line description)``; "" for a unit-less key
KEYS: dict[str, tuple[str, str]] = {
    "name": ("", "Scenario name; the default output folder is `runs/<name>-<plant>-<method>` (a plain file name)."),
    "description": ("", "One line shown by `bioform presets`."),
    "method": (
        "",
        "Control method: the paper's four (eq. 31 backstepping or bioinspired, with or without learning), or a "
        "controller registered by name (bioform_mj.register_controller, entry points bioform_mj.controllers).",
    ),
    # sim
    "sim.duration": ("s", "Simulated time."),
    "sim.control_dt": ("s", "Control period (zero-order hold between control steps)."),
    "sim.physics_dt": ("s", "Ideal-plant RK4 step or MuJoCo timestep; must divide `control_dt`."),
    "sim.log_dt": ("s", "Time between log rows (metrics are integrated every control step)."),
    "sim.seed": ("", "Seed of every random draw (jitter, packet loss, noise): same seed, same run bit for bit."),
    # leader
    "leader.kind": ("", "Virtual-leader trajectory (design §2); which keys below it reads is said on each."),
    "leader.x0": ("m", "`paper`, `line`: start x; `circle`, `figure8`: centre x; `harmonic`: offset x. × scale."),
    "leader.y0": ("m", "As `x0`, for y. × scale."),
    "leader.speed": ("m/s", "`paper`: forward speed `ẋ`; `line`, `circle`: path speed. × scale."),
    "leader.heading": ("rad", "`line`: direction of travel (0 = +x)."),
    "leader.amplitude": ("m", "`paper`: amplitude of the y sinusoid `y0 + A cos(ft − π/2)`. × scale."),
    "leader.frequency": ("rad/s", "`paper`: angular frequency of the y sinusoid; `figure8`: `Ω` of `x = R sin Ωt`."),
    "leader.radius": (
        "m",
        "`circle`: radius (counter-clockwise, starts at `(x0, y0 − R)` heading +x); `figure8`: `R`. × scale.",
    ),
    "leader.vx": ("m/s", "`harmonic`: drift velocity in x. × scale."),
    "leader.vy": ("m/s", "`harmonic`: drift velocity in y. × scale."),
    "leader.x_terms": ("m, rad/s, rad", "`harmonic`: `[[A, w, φ], …]`, x = x0 + vx t + Σ A cos(w t + φ). A × scale."),
    "leader.y_terms": ("m, rad/s, rad", "`harmonic`: as `x_terms`, for y. A × scale."),
    # graph
    "graph.kind": ("", "Topology of the follower graph; `explicit` reads `edges`, `star` reads `center`."),
    "graph.edges": ("", "`explicit`: undirected follower links `[[i, j], …]`, 1-based."),
    "graph.leader_access": ("", "Followers (1-based) that receive the leader's state."),
    "graph.center": ("", "`star`: the hub follower (1-based)."),
    # formation
    "formation.offsets": (
        "m",
        "`[[Δx, Δy], …]` per follower: the slot is the leader's position **minus** the offset. × scale.",
    ),
    "formation.initial_poses": ("m, m, rad", "`[[x, y, θ], …]` per follower. x, y × scale."),
    "formation.init_jitter": ("m", "Seeded uniform perturbation `±j` of the initial x and y. × scale."),
    "formation.init_jitter_heading": (
        "rad",
        "The same on the initial headings, not scaled (an angle); -1: the number of `init_jitter` as written.",
    ),
    "formation.scale": (
        "",
        "The whole experiment at a robot's size: every length × scale (our extension; design §21). "
        "`\"auto\"`: the robot's half track / the paper's 0.2 m.",
    ),
    "formation.time_scale": (
        "",
        "Time factor σ (our extension; design §21): every time × σ and every key by its unit (speeds × "
        'scale/σ, rates × 1/σ, accelerations × 1/σ²); 1 = as written; `"auto"`: from the robot\'s limits.',
    ),
    "formation.frame": (
        "",
        "`world`: offsets in world axes (the paper); `leader`: in the leader's frame, x forward, y left.",
    ),
    # estimator
    "estimator.kp": ("1/s", "Eq. 12 consensus gains `(k_x, k_y, k_θ)`."),
    "estimator.ka": ("m/s², rad/s²", "Eq. 13 sign-term gains `(k_a1, k_a2)`; the υ channel × scale."),
    "estimator.kb": ("1/s", "Eq. 13 linear-term gains `(k_b1, k_b2)`."),
    "estimator.phi": (
        "m/s, rad/s",
        "Boundary layers of eq. 13's sign terms; 0 = the paper's `sgn`. υ channel × scale.",
    ),
    "estimator.init": ("", "`P_ir(0)`: `zero` (origin), `self` (own pose + offset) or `leader` (true leader pose)."),
    # kinematic
    "kinematic.k1": ("1/s", "Eq. 31 gain on `x̃` (through the neuron for bioinspired methods)."),
    "kinematic.k2": ("1/m²", "Eq. 31 gain on `ỹ`; ÷ scale²."),
    "kinematic.k3": ("1/m", "Eq. 31 gain on `sin θ̃`; ÷ scale."),
    "kinematic.A": ("1/s", "Eq. 32 neuron decay rate; × 1/σ (eq. 32 adds |x̃| in m to it: design §21)."),
    "kinematic.B": ("", "Eq. 32 neuron upper bound; × 1/σ, as a rate (design §21)."),
    "kinematic.D": ("", "Eq. 32 neuron lower bound (the state stays in `(−D, B)`); × 1/σ (design §21)."),
    # torque
    "torque.c": ("m/s², rad/s²", "Eqs. 38–39 sliding-mode gains `(c_a, c_b)`; `c_a` × scale."),
    "torque.phi": (
        "m/s, rad/s",
        "Boundary layer of the torque law's sign terms (one for both channels: × 1/σ); 0 = the paper's `sgn`.",
    ),
    "torque.tau_max": ("N·m", "Wheel torque limit on the ideal plant (MuJoCo robots bring their actuator limits)."),
    "torque.deriv_wn": ("rad/s", "Natural frequency of the command-derivative filter (`derivative = filter`)."),
    "torque.saturation": ("", "`steer-priority`: keep `τ_R − τ_L`, clip the common mode; `wheel`: clip each wheel."),
    "torque.resistance_margin": (
        "",
        "Opt-in (design §14): `c_a, c_b` at least this many times the dead band `robot check` identifies, as "
        "`a τ_db`, `b τ_db` (m/s², rad/s²); 0 (default) = the paper's `c`.",
    ),
    "torque.derivative": ("", "How `υ̇_cmd, ω̇_cmd` are obtained (design §6): filter, backward difference or analytic."),
    # learner
    "learner.k4": ("", "Eq. 37 learning gains `(k4_a, k4_b)`; × σ², the adaptation rate's scaling (design §21)."),
    "learner.k5": ("", "Eq. 37 leakage gains `(k5_a, k5_b)`."),
    "learner.kd": ("", "Disturbance estimate `d̂' = −kd S` (our extension; 0 = the paper)."),
    "learner.c_hat0_scale": ("", "`ĉ(0) = c_hat0_scale ⊙ c_true` per follower."),
    "learner.c_bounds": ("", "Projection bounds of `ĉ` as factors of `ĉ(0)`: lower ≤ 1 ≤ upper."),
    "learner.kd_deadband": (
        "",
        "Opt-in (design §14): the `kd` used where `robot check` identifies a dead band (`[]`: off, `kd` stands).",
    ),
    "learner.projection_band": (
        "",
        "Opt-in (design §14): project `ĉ` onto `[lower, upper] × c_true` (the robot's formula values) instead of "
        "`c_bounds × ĉ(0)`; `[]` (default) = the paper's bounds.",
    ),
    "learner.gain_scaling": ("", "`c_hat0`: `k4 ⊙ (ĉ_i(0)/ĉ_paper(0))²` per robot, so any robot learns as fast."),
    "learner.drag": (
        "",
        "Also learn a viscous drag rate per channel (not in the paper; design §14): for wheel damping or back-EMF.",
    ),
    "learner.drag_gain": ("", "Adaptation gains of the learned drag `[υ, ω]` (the `υ` one ÷ scale²)."),
    "learner.drag_max": ("1/s", "Upper projection bound of the learned drag rate."),
    # plant
    "plant.kind": (
        "",
        "`ideal`: the paper's unicycle model (RK4); `mujoco`: MJCF robots simulated by MuJoCo; or a kind registered "
        "with `bioform_mj.plants.registry.register_plant` (also as `--plant`).",
    ),
    "plant.c_true": ("1/(kg·m), 1/(kg·m²)", "Ideal plant's `(a, b) = (1/(m r), l/(I r))`; MuJoCo: from the models."),
    "plant.mass": ("kg", "Ideal plant's mass consistent with `a` (used by payload events)."),
    "plant.inertia": ("kg·m²", "Ideal plant's yaw inertia consistent with `b` (used by payload events)."),
    "plant.robots[].model": ("", "A shipped robot (`paper`, `lab`, `tb3`, `stretch`) or an MJCF path."),
    "plant.robots[].base": ("", "Chassis body (default `base`)."),
    "plant.robots[].left_wheel": ("", "Left wheel hinge joint (default `left_wheel`)."),
    "plant.robots[].right_wheel": ("", "Right wheel hinge joint (default `right_wheel`)."),
    "plant.robots[].wheel_radius": ("m", "Overrides the radius found from the wheel's collision geoms (0: found)."),
    "plant.robots[].half_track": ("m", "Overrides the half track found from the joint anchors (0: found)."),
    "plant.robots[].tau_max": ("N·m", "Wheel torque limit of the attached motors (0: the model's own)."),
    "plant.robots[].motor": ("", '`ideal` torque sources (the paper; `""` = ideal) or the model\'s `dc` motors.'),
    "plant.robots[].driver": ("", 'With `motor = "dc"`: `current` (default) or `voltage` driver (design §8.2).'),
    "plant.robots[].casters": (
        "",
        "Geoms or bodies that are casters (design §13); their friction can be set by `caster_friction`.",
    ),
    "plant.robots[].caster_friction": (
        "",
        "Sliding friction of the casters against the floor (they win it by priority); < 0: as published.",
    ),
    "plant.robots[].free_joints": (
        "",
        "Leave the joints other than the wheels free (default: held at the file's configuration, design §13).",
    ),
    "plant.robots[].keyframe": (
        "",
        'MJCF: the keyframe the robot starts and is held in (`""`: `home` where the file has one, else '
        '`qpos0`; `"none"`: `qpos0`; design §13.2).',
    ),
    "plant.robots[].top_speed": (
        "m/s",
        "The robot's top speed at the tyre, the maker's figure (design §21); 0: from the URDF wheel "
        "`<limit velocity>` or the `<dcmotor>` no-load speed.",
    ),
    "plant.robots[].control_rate": (
        "Hz",
        "The rate the robot's own controller commands its wheels at, the maker's figure (a ROS 2 "
        "diff_drive_controller's `update_rate`, a firmware's loop; design §19): the hardware verdict's "
        "`control_rate` limit; 0: a shipped preset's rate, else not checked.",
    ),
    "plant.robots[].self_collide": (
        "",
        "URDF: keep contacts between the robot's own links (default off, as in Gazebo; design §12).",
    ),
    "plant.robots[].balance_inertia": (
        "",
        "Set MuJoCo's compiler option `balanceinertia` (an inertia that breaks the triangle inequality "
        "A + B >= C, which Gazebo takes and MuJoCo refuses, is balanced; default off).",
    ),
    "plant.robots[].package_path": (
        "",
        "URDF: `{NAME = \"DIR\"}` where this robot's `package://NAME/…` point (before the scenario's).",
    ),
    "plant.robots[].xacro": (
        "",
        "URDF: the file may be expanded by xacro, which runs it as a program (in a separate process with no "
        "environment, limited memory and time, reading only the robot's packages; default false: a file that "
        "needs xacro is refused; `--xacro` on the command line; design §12).",
    ),
    "plant.robots[].xacro_args": (
        "",
        'URDF with `xacro = true`: `{NAME = "VALUE"}`, the values of xacro\'s `$(arg NAME)` '
        "(`--xacro-arg NAME=VALUE`).",
    ),
    "plant.robots[].asset_roots": (
        "",
        'MJCF: `["DIR", …]`, folders its includes, meshes, textures, height fields and skins may be in besides '
        "the robot file's own (default: none, a file outside is refused; `--asset-root DIR`; design §12).",
    ),
    "plant.package_path": (
        "",
        'URDF: `{NAME = "DIR"}` where `package://NAME/…` point, before `$BIOFORM_PACKAGE_PATH`, '
        "`$ROS_PACKAGE_PATH` (design §12).",
    ),
    "plant.sensing": ("", "What the controllers are given (MuJoCo): the `truth`, or `odometry` (design §8.3)."),
    "plant.encoder_cpr": ("counts/rev", "Wheel encoder resolution; -1: each robot file's `encoder_cpr`."),
    "plant.sensor_dt": (
        "s",
        "Encoder and gyro period, a multiple of `physics_dt` dividing `control_dt`; 0: every step.",
    ),
    "plant.gyro_noise": ("rad/s", "Gyro z white noise, standard deviation per sample."),
    "plant.gyro_bias": ("rad/s", "Gyro z constant bias."),
    # disturbance
    "disturbance.bias": (
        "m/s², rad/s²",
        "Eq. 34 disturbance `d = bias + amp cos(freq t + phase)`: the bias; υ × scale.",
    ),
    "disturbance.amp": ("m/s², rad/s²", "Amplitude of the disturbance's cosine; υ × scale."),
    "disturbance.freq": ("rad/s", "Angular frequency of the disturbance's cosine."),
    "disturbance.phase": ("rad", "Phase of the disturbance's cosine."),
    # limits
    "limits.speed": ("m/s", "Divergence guard: a measured or commanded speed beyond it stops the run (exit 3)."),
    "limits.position": ("m", "Divergence guard on robot and estimate positions."),
    "limits.torque": ("N·m", "Divergence guard on commanded torques before saturation."),
    # events
    "events[].time": ("s", "When the event happens, in `[0, sim.duration]`."),
    "events[].kind": ("", "`payload`: a follower gains mass and yaw inertia."),
    "events[].follower": ("", "The follower (1-based)."),
    "events[].mass": ("kg", "Mass added."),
    "events[].inertia": ("kg·m²", "Yaw inertia added."),
    # faults
    "faults.link_fail": ("—, —, s, s", "`[[i, j, t_fail, t_recover], …]`: link i–j down (j = 0: i's leader link)."),
    "faults.packet_loss": ("", "Probability that a packet on any link is lost in a control step (last value kept)."),
    "faults.delay": ("s", "Every link delivers values this old (rounded to control steps)."),
    "faults.noise_pose": ("m, m, rad", "Gaussian noise `[σx, σy, σθ]` on the pose the controller measures."),
    "faults.noise_vel": ("m/s, rad/s", "Gaussian noise `[συ, σω]` on the velocity the controller measures."),
    "faults.window": ("s", "`[t0, t1]`: when packet loss, delay and noise act (empty: the whole run)."),
    "faults.actuator": ("—, s, s, —", "`[[i, t_start, t_end, scale], …]`: follower i's torque limit × scale ∈ [0, 1]."),
    "faults.actuator_known": ("", "The controller is told of an actuator fault (its own limit changes too)."),
    "faults.push": ("—, s, s, N, N, N·m", "`[[i, t, duration, fx, fy, tz], …]`: external wrench on i's chassis."),
    "faults.friction_patch": ("m, m, m, m, —", "`[x0, y0, x1, y1, mu]`: a floor rectangle with friction mu (MuJoCo)."),
    "obstacles[].shape": (
        "",
        "`box` or `cylinder` (design §19): fixed, standing on the floor; a wall is a long thin box.",
    ),
    "obstacles[].position": ("m", "`[x, y]` of its centre (× scale)."),
    "obstacles[].size": ("m", "box: half-extents `[sx, sy, sz]`; cylinder: `[radius, half_height]` (× scale)."),
    "obstacles[].yaw": ("rad", "Heading of a box."),
    "obstacle_field.count": ("", "How many random obstacles (seeded by `sim.seed`); 0: no field."),
    "obstacle_field.shape": ("", "`box` (square footprint) or `cylinder`."),
    "obstacle_field.size": ("m", "`[min, max]` of the half-side or radius, drawn uniformly (× scale)."),
    "obstacle_field.height": ("m", "Height of every field obstacle (× scale)."),
    "obstacle_field.region": ("m", "`[x0, y0, x1, y1]` where the centres are drawn (× scale)."),
    "obstacle_field.keep_out": (
        "m",
        "> 0: no obstacle this close to the leader's path or a follower's start (× scale).",
    ),
    "obstacle_field.gap": ("m", "Least distance between two field obstacles (× scale)."),
    "safety.distance": (
        "m",
        "A follower closer than this to a robot or obstacle is `too_close`; the filter's margin (× scale).",
    ),
    "safety.filter": (
        "",
        "`none` (the paper's) or `cbf`: a control barrier function between eq. 31 and the torque law.",
    ),
    "safety.lookahead": ("m", "The CBF's point ahead of the axle (Robotarium's construction; × scale)."),
    "safety.gain": ("1/s", "The CBF's class-K gain γ."),
    "safety.range": ("m", "Neighbours and obstacles within this distance enter the CBF's QP (× scale)."),
    "safety.pass_right": ("", "Weight of the right-hand rule that breaks the deadlock of two robots meeting; 0: off."),
}


def _type_name(tp: Any) -> str:
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        inner = _type_name(args[0])
        return f"array of {inner}" if args[-1] is Ellipsis else f"[{', '.join(_type_name(a) for a in args)}]"
    if tp is RobotRef:
        return "robot"
    if typing.get_origin(tp) is typing.Literal:  # a kind: its values are the choices column
        return "string"
    if isinstance(tp, types.UnionType):  # formation.scale, time_scale (design §21)
        return 'number or "auto"'
    return {float: "number", int: "integer", str: "string", bool: "boolean"}.get(tp, getattr(tp, "__name__", str(tp)))


def _fields(cls: Any, prefix: str) -> list[tuple[str, Any, Any]]:
    """``(dotted key, type, default)`` of every leaf of ``cls``; arrays of tables as ``key[].field``."""
    out: list[tuple[str, Any, Any]] = []
    hints = typing.get_type_hints(cls)
    inst = cls() if cls is not RobotRef else None
    for f in dataclasses.fields(cls):
        if f.metadata.get("internal"):  # not a scenario key (FormationCfg.scale_applied)
            continue
        tp = hints[f.name]
        default = getattr(inst, f.name) if inst is not None else f.default
        if dataclasses.is_dataclass(tp) and tp is not RobotRef:
            out += _fields(tp, f"{prefix}{f.name}.")
            continue
        if typing.get_origin(tp) is tuple and dataclasses.is_dataclass(typing.get_args(tp)[0]):
            out += _fields(typing.get_args(tp)[0], f"{prefix}{f.name}[].")
            continue
        if default is dataclasses.MISSING:
            default = None
        out.append((prefix + f.name, tp, default))
    return out


def scenario_keys() -> list[str]:
    """Every dotted key of a scenario, in the dataclasses' order."""
    return [k for k, _tp, _d in _fields(Scenario, "")]


def reference_rows() -> list[dict[str, str]]:
    """One row per key: ``key, type, unit, default, choices, description`` (strings; missing entries empty)."""
    rows = []
    for key, tp, default in _fields(Scenario, ""):
        unit, doc = KEYS.get(key, ("", ""))
        if isinstance(default, tuple):
            default = [list(v) if isinstance(v, tuple) else v for v in default]
            if key == "plant.robots":
                default = ["paper"]
        rows.append(
            {
                "key": key,
                "type": _type_name(tp),
                "unit": unit,
                "default": "(required)" if default is None else repr(default).replace("'", '"'),
                "choices": ", ".join(f'"{c}"' for c in CHOICES.get(key, ())),
                "description": doc,
            }
        )
    return rows
