"""Scenarios: frozen dataclasses, TOML files, presets, ``--set`` overrides, validation.

The dataclass defaults *are* the paper scenario (one source of defaults); the
shipped ``scenarios/paper.toml`` restates them with the choices the paper leaves
open, and a test keeps the two equal. Unknown keys are an error, never ignored.
Follower ids are 1-based in files and messages.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .control.stack import METHODS
from .errors import GraphError, InputError, ScenarioError
from .graph import Graph
from .graph import chain as _chain
from .graph import complete as _complete
from .graph import from_edges as _from_edges
from .graph import ring as _ring
from .graph import star as _star
from .leader import Harmonic as _HarmonicLeader
from .leader import Trajectory
from .leader import circle as _circle
from .leader import figure_eight as _figure_eight
from .leader import line as _line
from .leader import paper as _paper_leader
from .obstacles import Obstacle, ObstacleCfg, ObstacleFieldCfg
from .obstacles import resolve as _resolve_obstacles
from .obstacles import scaled as _scaled_obstacles
from .obstacles import validate as _validate_obstacles
from .robots import PackagePath, RobotRef, as_package_path, as_ref, rebase_entries, rebase_package_path
from .safety import SafetyCfg
from .safety import validate as _validate_safety

PLANTS = ("ideal", "mujoco")
LEADER_KINDS = ("paper", "line", "circle", "figure8", "harmonic")
GRAPH_KINDS = ("explicit", "chain", "ring", "star", "complete")
ESTIMATOR_INITS = ("zero", "self", "leader")
EVENT_KINDS = ("payload",)
SATURATIONS = ("steer-priority", "wheel")
#: how the torque law gets ``υ̇_cmd, ω̇_cmd`` (design §6)
DERIVATIVES = ("filter", "difference", "analytic")
GAIN_SCALINGS = ("none", "c_hat0")
#: the robot the paper's learner gains were tuned for: ``c = (a, b)`` of Sec. IV
PAPER_C = (0.4, 10.0)

# Bounds on the time axis: beyond them a run would not finish or would not fit in memory
# (issue 11). Refused up front with the estimate, before any work.
#: smallest physics step, s (below it the step count is beyond reason and the substep count
#: overflows the compiled loop's integers: 1e-300 used to be a numba typing error)
MIN_PHYSICS_DT = 1e-6
#: most control steps in one run (1e8 = 28 h simulated at the default 1 ms)
MAX_CONTROL_STEPS = 1e8
#: most physics steps in one run
MAX_PHYSICS_STEPS = 1e9
#: most memory for the in-memory log and the precomputed leader trajectory, bytes
MAX_RUN_BYTES = 4e9
#: integers anywhere in a scenario
MAX_INT = 2**62
#: longest scenario name (it becomes a folder name, with plant and method appended)
MAX_NAME = 120


@dataclass(frozen=True)
class SimCfg:
    """Time axis. duration, control_dt, physics_dt, log_dt in s."""

    duration: float = 20.0
    control_dt: float = 0.001
    physics_dt: float = 0.001
    log_dt: float = 0.01
    seed: int = 0


@dataclass(frozen=True)
class LeaderCfg:
    """Virtual leader (design §2). Lengths in m, speeds in m/s, angles in rad, rates in rad/s.

    paper: ``x = x0 + speed t``, ``y = y0 + amplitude cos(frequency t − π/2)``;
    line: from (x0, y0) at ``speed`` along ``heading``; circle: centre (x0, y0),
    ``radius``, ``speed``; figure8: centre (x0, y0), ``radius``, ``frequency``;
    harmonic: ``x = x0 + vx t + Σ A cos(w t + φ)`` with ``x_terms = [[A, w, φ], …]``, same for y.
    """

    kind: str = "paper"
    x0: float = 0.0
    y0: float = 3.0
    speed: float = 1.0
    heading: float = 0.0
    amplitude: float = 0.4
    frequency: float = 1.0
    radius: float = 5.0
    vx: float = 0.0
    vy: float = 0.0
    x_terms: tuple[tuple[float, ...], ...] = ()
    y_terms: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class GraphCfg:
    """Communication graph (design §1). The paper's Fig. 1 is missing; default: leader → 1, edges 1–2, 1–3."""

    kind: str = "explicit"
    edges: tuple[tuple[int, ...], ...] = ((1, 2), (1, 3))
    leader_access: tuple[int, ...] = (1,)
    center: int = 1


@dataclass(frozen=True)
class FormationCfg:
    """Offsets ``(Δx, Δy)`` (m, world frame) and initial poses ``(x, y, θ)`` (m, m, rad), one row per follower.

    ``init_jitter`` adds a seeded uniform perturbation ``±init_jitter`` to the initial positions (m; × ``scale``)
    and ``±init_jitter_heading`` to the headings (rad; not scaled: an angle; -1, the default, takes the number
    of ``init_jitter`` as written).
    ``frame``: ``"world"`` (the paper: offsets in world axes, the formation keeps its orientation
    while the leader turns) or ``"leader"`` (offsets in the leader's frame, x forward, y left: the
    formation turns with its leader).
    ``scale`` (not in the paper) maps the experiment to a robot ``scale`` times the size of the
    paper's, when the scenario is loaded (:func:`apply_scale`).
    """

    offsets: tuple[tuple[float, ...], ...] = ((3.0, 0.0), (4.0, 5.0), (4.0, -5.0))
    initial_poses: tuple[tuple[float, ...], ...] = ((0.0, 0.0, 0.0), (-1.0, -4.0, 0.0), (-1.0, 4.0, 0.0))
    init_jitter: float = 0.0
    init_jitter_heading: float = -1.0  # rad; -1: the number of init_jitter (as written, unscaled)
    scale: float = 1.0  # the whole experiment at a robot's scale (apply_scale); 1 = as written
    frame: str = "world"  # offsets in "world" axes (the paper) or in the "leader"'s frame (turns with it)


@dataclass(frozen=True)
class EstimatorCfg:
    """Eqs. 12–13. ``kp = (k_x, k_y, k_θ)``; ``ka = (k_a1, k_a2)`` sign-term gains; ``kb = (k_b1, k_b2)``.

    ``phi``: boundary layers (m/s, rad/s), 0 = the paper's sgn. ``init``: ``P_ir(0)`` is
    ``zero`` (origin, heading 0), ``self`` (own pose + offset) or ``leader`` (true leader pose).
    The proof (eq. 15) swaps the gains (ka = 1, kb = 25): 25× less chatter.
    """

    kp: tuple[float, ...] = (15.0, 15.0, 15.0)
    ka: tuple[float, ...] = (25.0, 25.0)
    kb: tuple[float, ...] = (1.0, 1.0)
    phi: tuple[float, ...] = (0.0, 0.0)
    init: str = "zero"


@dataclass(frozen=True)
class KinematicCfg:
    """Eq. 31 gains ``k1, k2, k3`` and neuron parameters ``A, B, D`` (eq. 32)."""

    k1: float = 2.0
    k2: float = 3.0
    k3: float = 4.0
    A: float = 2.0
    B: float = 2.0
    D: float = 2.0


@dataclass(frozen=True)
class TorqueCfg:
    """Eqs. 38–39: ``c = (c_a, c_b)``, boundary layer ``phi`` (0 = sgn), wheel limit ``tau_max`` (N·m),
    command-derivative filter natural frequency ``deriv_wn`` (rad/s). ``saturation``: ``wheel``
    clips each wheel alone; ``steer-priority`` keeps the differential torque and clips the common mode.
    ``derivative`` (design §6): ``filter`` (critically damped 2nd order, ``ω_n = deriv_wn``, the
    output's change over the step), ``difference`` (backward difference of the command) or
    ``analytic`` (chain rule through the estimator, neuron and error dynamics)."""

    c: tuple[float, ...] = (3.0, 3.0)
    phi: float = 0.0
    tau_max: float = 20.0
    deriv_wn: float = 50.0
    saturation: str = "steer-priority"
    derivative: str = "filter"


@dataclass(frozen=True)
class LearnerCfg:
    """Eq. 37 gains; ``ĉ(0) = c_hat0_scale ⊙ c_true`` per follower; projection onto
    ``[c_bounds[0], c_bounds[1]] × ĉ(0)``. ``kd > 0`` (not in the paper) also estimates the
    disturbance ``d̂' = −kd S`` so that ``d`` does not bias ``ĉ``. ``gain_scaling = "c_hat0"``
    (not in the paper) gives follower ``i`` the gain ``k4 ⊙ (ĉ_i(0) / ĉ_paper(0))²`` with
    ``ĉ_paper(0) = c_hat0_scale ⊙ (0.4, 10)``: a channel learns at a rate ∝ ``k4 τ²`` and the
    torques scale as ``1/c``, so every robot then learns as fast as the paper's robot does
    with the paper's gains (which it keeps). ``drag = true`` (not in the paper; design §14) also
    learns a viscous drag rate ``k̂`` per channel, ``ẑ' = τ ĉ + d̂ − k̂ z − …``, ``k̂' = drag_gain z S``
    projected onto ``[0, drag_max]`` (1/s), so that wheel damping or back-EMF does not bias ``ĉ``."""

    k4: tuple[float, ...] = (6.0, 50.0)
    k5: tuple[float, ...] = (25.0, 50.0)
    kd: tuple[float, ...] = (0.0, 0.0)
    c_hat0_scale: tuple[float, ...] = (0.5, 0.5)
    c_bounds: tuple[float, ...] = (0.1, 10.0)
    gain_scaling: str = "none"
    drag: bool = False
    drag_gain: tuple[float, ...] = (30.0, 50.0)
    drag_max: float = 50.0


@dataclass(frozen=True)
class PlantCfg:
    """Plant. Ideal: ``c_true = (a, b)`` and the mass (kg) / yaw inertia (kg·m²) consistent with
    them for r = 0.1 m, l = 0.2 m (used by payload events). ``robots``: shipped names, MJCF paths
    or tables ``{model, base, left_wheel, right_wheel, wheel_radius, half_track, tau_max}``
    (:mod:`bioform_mj.robots`), one per follower or one for all; relative paths in a TOML file
    are relative to that file. On the ideal plant a robot other than ``paper`` gives ``c_true``
    (and ``mass``, ``inertia`` = ``M_eff``, ``I_eff``) from its compiled model
    (:func:`apply_robots_to_ideal`). ``package_path``: ``{NAME = "DIR"}``, where the URDF robots'
    ``package://NAME/…`` URIs point (design §12; relative to the TOML file), merged into every
    robot's own ``package_path`` (the robot's entries first)."""

    kind: str = "ideal"
    c_true: tuple[float, ...] = (0.4, 10.0)
    mass: float = 25.0
    inertia: float = 0.2
    robots: tuple[RobotRef, ...] = (RobotRef("paper"),)
    # design §8.3, MuJoCo only: what the controllers are given ("truth" or "odometry")
    sensing: str = "truth"
    encoder_cpr: int = -1  # counts per wheel revolution; -1: each robot file's <numeric name="encoder_cpr">
    sensor_dt: float = 0.0  # s, encoder and gyro period; 0: every physics step
    gyro_noise: float = 0.0  # rad/s, standard deviation per sample
    gyro_bias: float = 0.0  # rad/s, constant
    package_path: PackagePath = PackagePath()  # design §12: package:// search path of URDF robots

    def __post_init__(self) -> None:
        if self.package_path:  # every robot searches the scenario's packages after its own
            robots = tuple(
                dataclasses.replace(r, package_path=r.package_path.merged(self.package_path))
                if isinstance(r, RobotRef)
                else r
                for r in self.robots
            )
            object.__setattr__(self, "robots", robots)


SENSINGS = ("truth", "odometry")


def robot_encoder_cpr(model: str) -> float | None:
    """Encoder counts per revolution an MJCF robot file declares (``<custom><numeric
    name="encoder_cpr" data="4096"/>``), None if it has no encoders (design §8.3). Read with
    ElementTree: no MuJoCo needed to validate a scenario."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(model).getroot()
    except (OSError, ET.ParseError):
        return None  # the scene reports an unreadable file
    for num in root.iter("numeric"):
        if num.get("name") == "encoder_cpr":
            try:
                return float((num.get("data") or "").split()[0])
            except (ValueError, IndexError):
                return 0.0
    return None


@dataclass(frozen=True)
class DisturbanceCfg:
    """``d_k = bias_k + amp_k cos(freq_k t + phase_k)``, k = (υ m/s², ω rad/s²). Paper: d1 = 0.1, d2 = 0.1 cos t."""

    bias: tuple[float, ...] = (0.1, 0.0)
    amp: tuple[float, ...] = (0.0, 0.1)
    freq: tuple[float, ...] = (0.0, 1.0)
    phase: tuple[float, ...] = (0.0, 0.0)


@dataclass(frozen=True)
class EventCfg:
    """A timed event. ``payload``: follower (1-based) gains ``mass`` kg and yaw ``inertia`` kg·m²."""

    time: float = 0.0
    kind: str = "payload"
    follower: int = 1
    mass: float = 0.0
    inertia: float = 0.0


@dataclass(frozen=True)
class LimitsCfg:
    """Divergence guard: the run stops (exit 3) beyond these magnitudes."""

    speed: float = 100.0  # m/s, measured or commanded
    position: float = 1.0e4  # m, robot or estimate
    torque: float = 1.0e6  # N·m, commanded before saturation


@dataclass(frozen=True)
class FaultsCfg:
    """Injected faults (issue 6, ``faults.py``); the defaults inject none. Follower ids 1-based, times in s.

    ``link_fail = [[i, j, t_fail, t_recover], …]``: the undirected link i–j is down in
    ``[t_fail, t_recover)`` (``j = 0``: follower i's leader link); the follower knows (weight 0).
    ``packet_loss``: probability that a packet on any link is lost in a control step (the
    receiver keeps the last value it got). ``delay``: every link delivers values this old
    (s, rounded to control steps). ``noise_pose = [σx m, σy m, σθ rad]``, ``noise_vel = [συ m/s, σω rad/s]``:
    Gaussian noise on what the controller measures. ``window = [t0, t1]``: when packet loss, delay
    and noise act (empty: the whole run). ``actuator = [[i, t_start, t_end, scale], …]``: follower i's
    wheel torque limit times ``scale`` ∈ [0, 1]; ``actuator_known``: the controller is told (its own
    limit changes too) or not (only the motors weaken). ``push = [[i, t, duration, fx, fy, tz], …]``:
    external force (N, world frame) and yaw torque (N·m) on follower i's chassis. ``friction_patch =
    [x0, y0, x1, y1, mu]``: a floor rectangle with sliding friction ``mu`` (MuJoCo only).
    """

    link_fail: tuple[tuple[float, ...], ...] = ()
    packet_loss: float = 0.0
    delay: float = 0.0
    noise_pose: tuple[float, ...] = (0.0, 0.0, 0.0)
    noise_vel: tuple[float, ...] = (0.0, 0.0)
    window: tuple[float, ...] = ()
    actuator: tuple[tuple[float, ...], ...] = ()
    actuator_known: bool = True
    push: tuple[tuple[float, ...], ...] = ()
    friction_patch: tuple[float, ...] = ()

    @property
    def configured(self) -> bool:
        """True when any fault is injected."""
        return self.per_step or bool(self.friction_patch)

    @property
    def per_step(self) -> bool:
        """True when a fault acts in the loop (it then builds :class:`~bioform_mj.faults.Faults`);
        a friction patch is part of the MuJoCo scene and needs nothing per step."""
        return bool(
            self.link_fail
            or self.packet_loss > 0
            or self.delay > 0
            or any(self.noise_pose)
            or any(self.noise_vel)
            or self.actuator
            or self.push
        )


@dataclass(frozen=True)
class Scenario:
    """A complete, validated run description."""

    name: str = "paper"
    description: str = "Xu et al. 2024, Sec. IV: three followers track a sinusoidal leader."
    method: str = "bioinspired-learning"
    sim: SimCfg = field(default_factory=SimCfg)
    leader: LeaderCfg = field(default_factory=LeaderCfg)
    graph: GraphCfg = field(default_factory=GraphCfg)
    formation: FormationCfg = field(default_factory=FormationCfg)
    estimator: EstimatorCfg = field(default_factory=EstimatorCfg)
    kinematic: KinematicCfg = field(default_factory=KinematicCfg)
    torque: TorqueCfg = field(default_factory=TorqueCfg)
    learner: LearnerCfg = field(default_factory=LearnerCfg)
    plant: PlantCfg = field(default_factory=PlantCfg)
    disturbance: DisturbanceCfg = field(default_factory=DisturbanceCfg)
    limits: LimitsCfg = field(default_factory=LimitsCfg)
    events: tuple[EventCfg, ...] = ()
    faults: FaultsCfg = field(default_factory=FaultsCfg)
    obstacles: tuple[ObstacleCfg, ...] = ()  # design §19
    obstacle_field: ObstacleFieldCfg = field(default_factory=ObstacleFieldCfg)
    safety: SafetyCfg = field(default_factory=SafetyCfg)

    @property
    def n(self) -> int:
        """Number of followers."""
        return len(self.formation.offsets)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON/TOML-able) of every resolved value (a robot without a mapping
        as its name or path, one with a mapping as a table)."""
        d = _to_plain(dataclasses.asdict(self))
        d["plant"]["robots"] = [_to_plain(r.to_entry()) for r in self.plant.robots]
        d["plant"]["package_path"] = dict(self.plant.package_path)
        if not d["plant"]["package_path"]:  # absent when unused: a sweep's content keys stay as they were
            del d["plant"]["package_path"]
        return d

    # ---- derived objects -------------------------------------------------------------
    def build_graph(self) -> Graph:
        g, n = self.graph, self.n
        if g.kind == "explicit":
            return _from_edges(n, g.edges, g.leader_access)
        if g.kind == "star":
            return _star(n, g.center, g.leader_access)
        builder = {"chain": _chain, "ring": _ring, "complete": _complete}[g.kind]
        return builder(n, g.leader_access)

    def build_leader(self) -> Trajectory:
        c = self.leader
        if c.kind == "paper":
            return _paper_leader(c.x0, c.y0, c.speed, c.amplitude, c.frequency)
        if c.kind == "line":
            return _line(c.x0, c.y0, c.speed, c.heading)
        if c.kind == "circle":
            return _circle(c.x0, c.y0, c.radius, c.speed)
        if c.kind == "figure8":
            return _figure_eight(c.x0, c.y0, c.radius, c.frequency)
        return _HarmonicLeader(c.x0, c.y0, c.vx, c.vy, tuple(map(tuple, c.x_terms)), tuple(map(tuple, c.y_terms)))

    def obstacle_list(self) -> list[Obstacle]:
        """The fixed obstacles and the seeded random field's (:func:`bioform_mj.obstacles.resolve`;
        the field keeps ``keep_out`` m from the leader's positions every 0.05 s of the run and from
        the followers' initial positions, jitter included)."""
        path = None
        if self.obstacle_field.count and self.obstacle_field.keep_out > 0:
            t = np.arange(0.0, self.sim.duration + 1e-9, 0.05)
            path = np.asarray(self.build_leader().states(t)[0])[:, :2]
            path = np.vstack([path, self.initial_poses()[:, :2]])
        return _resolve_obstacles(self.obstacles, self.obstacle_field, self.sim.seed, path)

    def initial_poses(self) -> np.ndarray:
        """(n, 3) initial poses, with the seeded jitter applied: ``U(−j, j)`` on x and y (m, ``j =
        init_jitter``), ``U(−j_θ, j_θ)`` on θ (rad, ``j_θ = init_jitter_heading``, -1: ``j``), one
        (n, 3) draw seeded by ``sim.seed``."""
        f = self.formation
        p = np.array(f.initial_poses, dtype=float)
        j = f.init_jitter
        jh = j if f.init_jitter_heading < 0 else f.init_jitter_heading
        if j > 0 or jh > 0:
            rng = np.random.default_rng(self.sim.seed)
            if jh == j:  # one bound for all three: the draw as it always was
                p += rng.uniform(-j, j, size=p.shape)
            else:
                bound = np.array([j, j, jh])
                p += rng.uniform(-bound, bound, size=p.shape)
        return p


# ---------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------


def preset_names() -> list[str]:
    """Names of the shipped presets (``scenarios/*.toml`` inside the package)."""
    d = resources.files("bioform_mj") / "scenarios"
    return sorted(p.name[:-5] for p in d.iterdir() if p.name.endswith(".toml"))


def preset_descriptions() -> dict[str, str]:
    """``{preset name: its one-line description}`` (the file's ``description``, else the default's)."""
    out = {}
    for name in preset_names():
        raw = (resources.files("bioform_mj") / "scenarios" / f"{name}.toml").read_bytes()
        text = _read_toml(raw, f"preset {name}").get("description", Scenario.description)
        out[name] = " ".join(str(text).split())
    return out


def load(
    source: str | Path | None = None,
    overrides: Mapping[str, Any] | list[str] | None = None,
    method: str | None = None,
    plant: str | None = None,
) -> Scenario:
    """Load a preset name, a TOML path or a run's ``summary.json`` (its ``config``: the run again, bit for
    bit), apply ``--set`` overrides, method and plant; validate.

    Raises :class:`InputError` (or a subclass) with one line naming the problem.
    """
    data: dict[str, Any]
    if source is None:
        source = "paper"
    src = str(source)
    if "\x00" in src:
        raise InputError(f"scenario {src!r} contains a NUL character")
    if src.endswith(".toml") or "/" in src or Path(src).is_file():
        path = Path(src)
        if path.is_dir():
            raise InputError(f"scenario file '{path}' is a directory")
        if not path.exists():
            raise InputError(f"scenario file '{path}' does not exist")
        try:
            raw = path.read_bytes()
        except OSError as exc:  # PermissionError, a FIFO that errors, an I/O error
            raise InputError(f"scenario file '{path}' cannot be read: {exc.strerror or exc}") from None
        data = _read_record(raw, str(path)) if path.suffix.lower() == ".json" else _read_toml(raw, str(path))
        if isinstance(data.get("plant"), dict) and "robots" in data["plant"]:  # design §10: relative to the file
            data["plant"]["robots"] = rebase_entries(data["plant"]["robots"], path.parent.resolve())
        if isinstance(data.get("plant"), dict) and "package_path" in data["plant"]:  # design §12: likewise
            data["plant"]["package_path"] = rebase_package_path(data["plant"]["package_path"], path.parent.resolve())
    else:
        names = preset_names()
        if src not in names:
            raise InputError(f"unknown preset '{src}' (expected one of: {', '.join(names)}, or a .toml path)")
        data = _read_toml((resources.files("bioform_mj") / "scenarios" / f"{src}.toml").read_bytes(), f"preset {src}")
    if overrides:
        items = overrides.items() if isinstance(overrides, Mapping) else [parse_override(s) for s in overrides]
        for key, value in items:
            _set_path(data, key, value)
    if method is not None:
        data["method"] = method
    if plant is not None:
        data.setdefault("plant", {})["kind"] = plant
    sc = apply_scale(from_dict(data))
    validate(sc)
    return apply_robots_to_ideal(sc)


def _read_record(raw: bytes, where: str) -> dict[str, Any]:
    """A run's ``summary.json``: its ``config`` (:func:`bioform_mj.record.resolved_config`)."""
    import json

    try:
        data = json.loads(raw.decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{where} is not valid JSON: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("config"), dict):
        raise InputError(f"{where} is not a run's summary.json (no 'config' table); give a scenario TOML file")
    return data["config"]


def _read_toml(raw: bytes, where: str) -> dict[str, Any]:
    try:
        return tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{where} is not valid TOML: {exc}") from None


def parse_override(text: str) -> tuple[str, Any]:
    """``'kinematic.k1=3'`` → ``('kinematic.k1', 3)``; values are TOML literals, bare words are strings."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise InputError(f"--set '{text}': expected KEY=VALUE, e.g. kinematic.k1=3")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key, value


def _set_path(data: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    cls: Any = Scenario
    node = data
    for i, part in enumerate(parts):
        hints = typing.get_type_hints(cls)
        if part not in hints:
            raise ScenarioError(key, f"unknown key (expected one of: {', '.join(hints)})")
        if i == len(parts) - 1:
            node[part] = value
            return
        cls = hints[part]
        if cls is PackagePath and i == len(parts) - 2:  # plant.package_path.NAME=DIR adds one package
            table = node.get(part)
            node[part] = {**(table if isinstance(table, Mapping) else {}), parts[-1]: value}
            return
        if not dataclasses.is_dataclass(cls):
            raise ScenarioError(key, f"'{'.'.join(parts[: i + 1])}' is a value, not a table")
        node = node.setdefault(part, {})
        if not isinstance(node, dict):  # e.g. `sim = 3` in the file, then --duration
            raise ScenarioError(".".join(parts[: i + 1]), f"expected a table, got {type(node).__name__} {node!r}")


def from_dict(data: Mapping[str, Any]) -> Scenario:
    """Build a :class:`Scenario` from nested dicts; unknown keys and wrong types raise ScenarioError."""
    return _build(Scenario, data, "")


def _build(cls: Any, data: Any, prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise ScenarioError(prefix.rstrip("."), f"expected a table, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    unknown = [k for k in data if k not in hints]
    if unknown:
        raise ScenarioError(prefix + unknown[0], f"unknown key (expected one of: {', '.join(hints)})")
    kwargs = {k: _convert(v, hints[k], prefix + k) for k, v in data.items()}
    return cls(**kwargs)


def _convert(value: Any, tp: Any, key: str) -> Any:
    if tp is RobotRef:  # a name, a path or a mapping table (robots.py)
        return as_ref(value, key)
    if tp is PackagePath:  # {NAME = "DIR"} (robots.py, design §12)
        return as_package_path(value, key)
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, key + ".")
    origin = typing.get_origin(tp)
    if origin is tuple:
        (inner, *_rest) = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ScenarioError(key, f"expected an array, got {type(value).__name__} {value!r}")
        if dataclasses.is_dataclass(inner) and inner is not RobotRef:
            return tuple(_build(inner, v, f"{key}[{i}].") for i, v in enumerate(value))
        return tuple(_convert(v, inner, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(key, f"expected a number, got {type(value).__name__} {value!r}")
        if not math.isfinite(value):
            raise ScenarioError(key, f"expected a finite number, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ScenarioError(key, f"expected an integer, got {type(value).__name__} {value!r}")
        if not -MAX_INT <= value <= MAX_INT:  # numpy and the compiled loop take 64-bit integers
            raise ScenarioError(key, f"integer out of range (|value| <= 2^62), got {value}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ScenarioError(key, f"expected a string, got {type(value).__name__} {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ScenarioError(key, f"expected true or false, got {value!r}")
        return value
    raise TypeError(f"unsupported field type {tp} for {key}")  # programming error, not user input


def _to_plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_plain(v) for v in obj]
    return obj


# ---------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------


def _positive(key: str, values: Any, strict: bool = True) -> None:
    for v in np.atleast_1d(values):
        if (v <= 0) if strict else (v < 0):
            raise ScenarioError(key, f"must be {'> 0' if strict else '>= 0'}, got {v:g}")


def _length(key: str, values: tuple, n: int) -> None:
    if len(values) != n:
        raise ScenarioError(key, f"expected {n} values, got {len(values)}")


def validate(sc: Scenario) -> None:
    """Check every value the algorithm's assumptions need; raise on the first problem found."""
    if sc.method not in METHODS:
        raise ScenarioError("method", f"unknown method '{sc.method}' (expected one of: {', '.join(METHODS)})")
    if sc.plant.kind not in PLANTS:
        raise ScenarioError("plant.kind", f"unknown plant '{sc.plant.kind}' (expected one of: {', '.join(PLANTS)})")
    _validate_text(sc)
    s = sc.sim
    _positive("sim.duration", s.duration)
    _positive("sim.control_dt", s.control_dt)
    _positive("sim.physics_dt", s.physics_dt)
    _positive("sim.log_dt", s.log_dt)
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
    vmin = traj.min_speed(s.duration)
    if not vmin > 1e-6:
        raise ScenarioError(
            "leader", f"the leader's speed reaches {vmin:g} m/s; its heading is undefined where it stops"
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
    if pc.kind == "mujoco":
        from .robots import resolve_robot
        from .urdf import check_file, is_urdf

        for name, folder in pc.package_path:
            if not Path(folder).is_dir():
                raise ScenarioError(f"plant.package_path.{name}", f"directory '{folder}' does not exist")
        for r in pc.robots:
            ref = resolve_robot(r)  # raises InputError naming an unknown robot or a missing file
            if is_urdf(ref.model):
                check_file(ref)  # design §12: root, package://, meshes, wheels: before any work
    _validate_sensing(sc)

    d = sc.disturbance
    for key in ("bias", "amp", "freq", "phase"):
        _length(f"disturbance.{key}", getattr(d, key), 2)

    lim = sc.limits
    for key in ("speed", "position", "torque"):
        _positive(f"limits.{key}", getattr(lim, key))

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
    from .robots import resolve_robot

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
    elif any(ord(c) < 32 or ord(c) == 127 for c in name):
        bad = "contains a control character"
    elif len(name) > MAX_NAME:
        bad = f"is longer than {MAX_NAME} characters"
    if bad:
        raise ScenarioError("name", f"{bad}, got {name!r}")
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
    from .engine import CHANNELS  # here, not at import: the engine imports this module's users

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
        from .budget import require, scene_bytes

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
        if len(p) != 5 or not (p[0] < p[2] and p[1] < p[3]) or p[4] < 0:
            raise ScenarioError(
                "faults.friction_patch",
                f"expected [x0, y0, x1, y1, mu] with x0 < x1, y0 < y1, mu >= 0, or [], got {list(p)}",
            )
        if sc.plant.kind != "mujoco":
            raise ScenarioError(
                "faults.friction_patch", "needs plant.kind = 'mujoco': the ideal plant's wheels cannot slip"
            )


# ---------------------------------------------------------------------------------------
# Robots on the ideal plant (issue 10: plant.robots is never ignored)
# ---------------------------------------------------------------------------------------


def apply_robots_to_ideal(sc: Scenario) -> Scenario:
    """On the ideal plant, ``plant.robots`` other than the shipped ``paper`` robot decide ``c_true``.

    The ideal plant is then the paper's model of that robot: ``c_true = (a_eff, b_eff)`` from its
    compiled model, ``mass = M_eff = 1/(a_eff r)`` and ``inertia = I_eff = l/(b_eff r)`` (for
    payload events). The ``paper`` robot (the default) leaves ``plant.c_true`` as given, so the
    paper's abstract plant keeps ``--set plant.c_true=…``. Refused (ScenarioError): robots whose
    ``c_true`` differ (the ideal plant takes one ``c_true``), and a ``plant.c_true`` other than the
    paper's that disagrees with the robots. The MuJoCo plant is returned unchanged.
    """
    pc = sc.plant
    if pc.kind != "ideal":
        return sc
    from .robots import resolve_robot

    refs = [resolve_robot(r) for r in pc.robots]
    paper = resolve_robot("paper")
    if all(Path(r.model).resolve() == Path(paper.model).resolve() and not r.mapped for r in refs):
        return sc
    from .identify import robot_truth  # MuJoCo only when a robot asks for it

    truths = [robot_truth(r) for r in refs]
    c = np.array([t.c for t in truths])
    if np.any(np.abs(c / c[0] - 1) > 1e-6):
        raise ScenarioError(
            "plant.robots",
            "the ideal plant takes one c_true, but the robots differ "
            f"({'; '.join(f'{r.model}: a={x[0]:.4g}, b={x[1]:.4g}' for r, x in zip(refs, c))}); "
            "use plant.kind = 'mujoco' for a heterogeneous team",
        )
    if tuple(pc.c_true) != PAPER_C and np.any(np.abs(np.asarray(pc.c_true) / c[0] - 1) > 1e-3):
        raise ScenarioError(
            "plant.c_true",
            f"{list(pc.c_true)} disagrees with plant.robots ({refs[0].model}: "
            f"a={c[0, 0]:.4g}, b={c[0, 1]:.4g}); give one of them",
        )
    t = truths[0]
    plant = dataclasses.replace(pc, c_true=(float(c[0, 0]), float(c[0, 1])), mass=t.mass_eff, inertia=t.inertia_eff)
    return dataclasses.replace(sc, plant=plant)


# ---------------------------------------------------------------------------------------
# The paper's experiment at a robot's scale (issue 10)
# ---------------------------------------------------------------------------------------


def apply_scale(sc: Scenario) -> Scenario:
    """Scale the experiment by ``s = formation.scale``: every length × s, every time unchanged.

    So every speed and acceleration is × s and every angle, rate and time constant stays: the
    leader (``x0, y0, speed, amplitude, radius, vx, vy`` and the amplitudes of ``x_terms`` /
    ``y_terms``), the offsets and initial positions (and ``init_jitter``, the positions' jitter; the
    headings' jitter ``init_jitter_heading`` is an angle and stays, resolved from -1 to the
    ``init_jitter`` as written), and the gains that
    carry a length so that the closed loop is the paper's, shrunk: the estimator's ``υ``-channel
    sign gain ``ka[0]`` and boundary layer ``phi[0]`` (m/s², m/s), the torque law's ``c[0]``
    (m/s²), the disturbance's ``υ`` channel (m/s²) × s; the obstacles (positions, sizes, the
    field's numbers) and ``safety.distance``, ``lookahead``, ``range`` × s (design §19);
    ``k2 / s²`` and ``k3 / s`` (eq. 31:
    ``ω_cmd = ω_ir + k2 υ_ir ỹ + k3 υ_ir sin θ̃`` is then unchanged). ``k1`` stays: the neuron
    (eq. 32) works in metres, and in its linear range (``|x̃| ≪ A``, which a small robot's
    errors are) ``k1 V_s ≈ k1 B x̃ / A`` already scales with the error; its bound ``k1 B`` does
    not shrink. The torque law's ``phi`` (one layer on both channels) and the learner's gains
    are not scaled: use ``learner.gain_scaling = "c_hat0"`` (the scaled presets do); the
    learned-drag gain's ``υ`` channel (``k̂' = drag_gain z S``: 1/m²) is ``/ s²`` (design §14). The values
    are those written (file and ``--set``); the returned scenario holds the scaled values and
    ``scale``; a run's record (:func:`bioform_mj.record.resolved_config`) holds the scaled values
    with ``scale = 1``, so loading it again does not scale twice (the ``lost`` threshold and the
    video's sizes are taken from the scaled lengths, not from ``scale``).
    """
    s = sc.formation.scale
    if s == 1.0:
        return sc
    if not (math.isfinite(s) and s > 0):
        raise ScenarioError("formation.scale", f"must be a number > 0, got {s:g}")
    if not 1e-3 <= s <= 1e3:  # beyond, k2 / s² and the lengths leave floating point's comfortable range
        raise ScenarioError("formation.scale", f"must lie in [0.001, 1000], got {s:g}")

    def rows(values: tuple, cols: int) -> tuple:
        return tuple(tuple(v * s if j < cols else v for j, v in enumerate(r)) for r in values)

    ld = sc.leader
    leader = dataclasses.replace(
        ld,
        x0=ld.x0 * s,
        y0=ld.y0 * s,
        speed=ld.speed * s,
        amplitude=ld.amplitude * s,
        radius=ld.radius * s,
        vx=ld.vx * s,
        vy=ld.vy * s,
        x_terms=rows(ld.x_terms, 1),
        y_terms=rows(ld.y_terms, 1),
    )
    f = sc.formation
    formation = dataclasses.replace(
        f,
        offsets=rows(f.offsets, 2),
        initial_poses=rows(f.initial_poses, 2),
        init_jitter=f.init_jitter * s,  # positions: a length
        init_jitter_heading=f.init_jitter if f.init_jitter_heading < 0 else f.init_jitter_heading,  # an angle
    )
    e = sc.estimator
    first = lambda v: (v[0] * s, *v[1:]) if v else v  # noqa: E731 - the υ channel of a (υ, ω) pair
    estimator = dataclasses.replace(e, ka=first(e.ka), phi=first(e.phi))
    k = sc.kinematic
    kinematic = dataclasses.replace(k, k2=k.k2 / s**2, k3=k.k3 / s)
    torque = dataclasses.replace(sc.torque, c=first(sc.torque.c))
    d = sc.disturbance
    disturbance = dataclasses.replace(d, bias=first(d.bias), amp=first(d.amp))
    lg = sc.learner.drag_gain
    learner = dataclasses.replace(sc.learner, drag_gain=(lg[0] / s**2, *lg[1:]) if lg else lg)
    obstacles, obstacle_field = _scaled_obstacles(sc.obstacles, sc.obstacle_field, s)
    sf = sc.safety
    safety = dataclasses.replace(sf, distance=sf.distance * s, lookahead=sf.lookahead * s, range=sf.range * s)
    return dataclasses.replace(
        sc,
        learner=learner,
        obstacles=obstacles,
        obstacle_field=obstacle_field,
        safety=safety,
        leader=leader,
        formation=formation,
        estimator=estimator,
        kinematic=kinematic,
        torque=torque,
        disturbance=disturbance,
    )
