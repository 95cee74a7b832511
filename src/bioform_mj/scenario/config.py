"""The scenario's configuration: frozen dataclasses, their allowed values and the bounds on a run.

The dataclass defaults *are* the paper scenario (one source of defaults); the
shipped ``scenarios/paper.toml`` restates them with the choices the paper leaves
open, and a test keeps the two equal. Follower ids are 1-based in files and messages.
Reading files and ``--set`` overrides is :mod:`bioform_mj.scenario.loader`'s, the checks
:mod:`bioform_mj.scenario.check`'s; :mod:`bioform_mj.scenario` gathers all three.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from bioform_mj.control.tuning import PAPER_C
from bioform_mj.core.units import unit
from bioform_mj.formation.graph import Graph
from bioform_mj.formation.graph import chain as _chain
from bioform_mj.formation.graph import complete as _complete
from bioform_mj.formation.graph import from_edges as _from_edges
from bioform_mj.formation.graph import ring as _ring
from bioform_mj.formation.graph import star as _star
from bioform_mj.formation.leader import Harmonic as _HarmonicLeader
from bioform_mj.formation.leader import Trajectory
from bioform_mj.formation.leader import circle as _circle
from bioform_mj.formation.leader import figure_eight as _figure_eight
from bioform_mj.formation.leader import line as _line
from bioform_mj.formation.leader import paper as _paper_leader
from bioform_mj.formation.obstacles import Obstacle, ObstacleCfg, ObstacleFieldCfg
from bioform_mj.formation.obstacles import resolve as _resolve_obstacles
from bioform_mj.formation.safety import SafetyCfg
from bioform_mj.robots.refs import PackagePath, RobotRef

# Why a key is not scaled with the experiment, and the paper's mixed-unit places (design §21)
_STEP = "a numerical step (the robot's and the computer's): a slower scenario is stepped finer"
_GUARD = "a divergence guard, not a quantity of the experiment"
_SENSOR = "a property of the robot's sensor"
_EQ32 = "eq. 32 adds |x̃| (m) to A (1/s): A, B, D scaled as rates, similar where |x̃| ≪ A (design §21)"
_EQ37 = "eq. 37: k4 is S's integral gain (1/s) and the adaptation gain; × σ² keeps k4 τ²/k5 × 1/σ (design §21)"

#: the kinds of the string keys, as ``Literal`` types (the annotation of each key) and their allowed values
#: (``typing.get_args`` of the same type: one source)
PlantKind = Literal["ideal", "mujoco"]  # the shipped kinds; plant.kind takes any registered kind (check.plant_kinds)
LeaderKind = Literal["paper", "line", "circle", "figure8", "harmonic"]
GraphKind = Literal["explicit", "chain", "ring", "star", "complete"]
EstimatorInit = Literal["zero", "self", "leader"]
EventKind = Literal["payload"]
Saturation = Literal["steer-priority", "wheel"]
Sensing = Literal["truth", "odometry"]
#: how the torque law gets ``υ̇_cmd, ω̇_cmd`` (design §6)
Derivative = Literal["filter", "difference", "analytic"]
GainScaling = Literal["none", "c_hat0"]
OffsetFrame = Literal["world", "leader"]
PLANTS: tuple[str, ...] = typing.get_args(PlantKind)
LEADER_KINDS: tuple[str, ...] = typing.get_args(LeaderKind)
GRAPH_KINDS: tuple[str, ...] = typing.get_args(GraphKind)
ESTIMATOR_INITS: tuple[str, ...] = typing.get_args(EstimatorInit)
EVENT_KINDS: tuple[str, ...] = typing.get_args(EventKind)
SATURATIONS: tuple[str, ...] = typing.get_args(Saturation)
SENSINGS: tuple[str, ...] = typing.get_args(Sensing)
DERIVATIVES: tuple[str, ...] = typing.get_args(Derivative)
GAIN_SCALINGS: tuple[str, ...] = typing.get_args(GainScaling)

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
#: largest magnitude of a number anywhere in a scenario (SI units): beyond it ratios of times overflow
#: (``--set sim.log_dt=1e30`` was a numba typing error, ``sim.control_dt=1e308`` an OverflowError)
MAX_FLOAT = 1e12
#: most values of one array of a scenario (followers, edges, events, ...; the largest preset has 1024 robots):
#: ``bioform_mj.load(overrides={"formation.offsets": [[1, 0]] * 10**6})`` took minutes to be refused
MAX_ARRAY = 2**16
#: longest scenario name (it becomes a folder name, with plant and method appended)
MAX_NAME = 120


@dataclass(frozen=True)
class SimCfg:
    """Time axis. duration, control_dt, physics_dt, log_dt in s."""

    duration: float = unit(20.0, "s")
    control_dt: float = unit(0.001, "s", kept=_STEP)
    physics_dt: float = unit(0.001, "s", kept=_STEP)
    log_dt: float = unit(0.01, "s", kept=_STEP)
    seed: int = unit(0, "1")


@dataclass(frozen=True)
class LeaderCfg:
    """Virtual leader (design §2). Lengths in m, speeds in m/s, angles in rad, rates in rad/s.

    paper: ``x = x0 + speed t``, ``y = y0 + amplitude cos(frequency t − π/2)``;
    line: from (x0, y0) at ``speed`` along ``heading``; circle: centre (x0, y0),
    ``radius``, ``speed``; figure8: centre (x0, y0), ``radius``, ``frequency``;
    harmonic: ``x = x0 + vx t + Σ A cos(w t + φ)`` with ``x_terms = [[A, w, φ], …]``, same for y.
    """

    kind: LeaderKind = unit("paper", "-")
    x0: float = unit(0.0, "m")
    y0: float = unit(3.0, "m")
    speed: float = unit(1.0, "m/s")
    heading: float = unit(0.0, "rad")
    amplitude: float = unit(0.4, "m")
    frequency: float = unit(1.0, "rad/s")
    radius: float = unit(5.0, "m")
    vx: float = unit(0.0, "m/s")
    vy: float = unit(0.0, "m/s")
    x_terms: tuple[tuple[float, ...], ...] = unit((), ("m", "rad/s", "rad"))
    y_terms: tuple[tuple[float, ...], ...] = unit((), ("m", "rad/s", "rad"))


@dataclass(frozen=True)
class GraphCfg:
    """Communication graph (design §1). The paper's Fig. 1 is missing; default: leader → 1, edges 1–2, 1–3."""

    kind: GraphKind = unit("explicit", "-")
    edges: tuple[tuple[int, ...], ...] = unit(((1, 2), (1, 3)), "1")
    leader_access: tuple[int, ...] = unit((1,), "1")
    center: int = unit(1, "1")


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

    offsets: tuple[tuple[float, ...], ...] = unit(((3.0, 0.0), (4.0, 5.0), (4.0, -5.0)), ("m", "m"))
    initial_poses: tuple[tuple[float, ...], ...] = unit(
        ((0.0, 0.0, 0.0), (-1.0, -4.0, 0.0), (-1.0, 4.0, 0.0)), ("m", "m", "rad")
    )
    init_jitter: float = unit(0.0, "m")
    init_jitter_heading: float = unit(-1.0, "rad")  # rad; -1: the number of init_jitter (as written, unscaled)
    #: the whole experiment at a robot's scale (apply_scale); 1 = as written, "auto": s from the half track
    scale: float | str = unit(1.0, "1", kept="the length factor itself")
    #: offsets in "world" axes (the paper) or in the "leader"'s frame (turns with it)
    frame: OffsetFrame = unit("world", "-")
    #: time factor σ (design §21): every time × σ and every key by its unit; 1 = as written, "auto": from
    #: the robot's limits and the scenario's demand (:mod:`bioform_mj.run.auto_scale`)
    time_scale: float | str = unit(1.0, "1", kept="the time factor itself")
    #: not a scenario key: the ``scale`` the lengths already carry, set by :func:`apply_scale` (1: as
    #: written), so :func:`~bioform_mj.run.simulate.simulate` can tell a ``scale`` changed by ``dataclasses.replace``
    #: from one applied (design §18.1); not in ``to_dict``, files, ``--set`` nor equality
    scale_applied: float = field(default=1.0, compare=False, repr=False, metadata={"internal": True})
    #: not a scenario key: the ``time_scale`` the times already carry (as ``scale_applied``)
    time_scale_applied: float = field(default=1.0, compare=False, repr=False, metadata={"internal": True})
    #: not a scenario key: why ``scale`` / ``time_scale`` have their values ("auto": which limit set σ)
    scale_note: str = field(default="", compare=False, repr=False, metadata={"internal": True})


@dataclass(frozen=True)
class EstimatorCfg:
    """Eqs. 12–13. ``kp = (k_x, k_y, k_θ)``; ``ka = (k_a1, k_a2)`` sign-term gains; ``kb = (k_b1, k_b2)``.

    ``phi``: boundary layers (m/s, rad/s), 0 = the paper's sgn. ``init``: ``P_ir(0)`` is
    ``zero`` (origin, heading 0), ``self`` (own pose + offset) or ``leader`` (true leader pose).
    The proof (eq. 15) swaps the gains (ka = 1, kb = 25): 25× less chatter.
    """

    kp: tuple[float, ...] = unit((15.0, 15.0, 15.0), "1/s")
    ka: tuple[float, ...] = unit((25.0, 25.0), ("m/s^2", "rad/s^2"))
    kb: tuple[float, ...] = unit((1.0, 1.0), "1/s")
    phi: tuple[float, ...] = unit((0.0, 0.0), ("m/s", "rad/s"))
    init: EstimatorInit = unit("zero", "-")


@dataclass(frozen=True)
class KinematicCfg:
    """Eq. 31 gains ``k1, k2, k3`` and neuron parameters ``A, B, D`` (eq. 32)."""

    k1: float = unit(2.0, "1/s")
    k2: float = unit(3.0, "1/m^2")
    k3: float = unit(4.0, "1/m")
    A: float = unit(2.0, "1/s", mixed=_EQ32)
    B: float = unit(2.0, "1/s", mixed=_EQ32)
    D: float = unit(2.0, "1/s", mixed=_EQ32)


@dataclass(frozen=True)
class TorqueCfg:
    """Eqs. 38–39: ``c = (c_a, c_b)``, boundary layer ``phi`` (0 = sgn), wheel limit ``tau_max`` (N·m),
    command-derivative filter natural frequency ``deriv_wn`` (rad/s). ``saturation``: ``wheel``
    clips each wheel alone; ``steer-priority`` keeps the differential torque and clips the common mode.
    ``derivative`` (design §6): ``filter`` (critically damped 2nd order, ``ω_n = deriv_wn``, the
    output's change over the step), ``difference`` (backward difference of the command) or
    ``analytic`` (chain rule through the estimator, neuron and error dynamics)."""

    c: tuple[float, ...] = unit((3.0, 3.0), ("m/s^2", "rad/s^2"))
    phi: float = unit(0.0, "rad/s", mixed="one boundary layer for υ̃ (m/s) and ω̃ (rad/s): scaled as rad/s")
    tau_max: float = unit(20.0, "N·m")
    deriv_wn: float = unit(50.0, "rad/s")
    saturation: Saturation = unit("steer-priority", "-")
    derivative: Derivative = unit("filter", "-")
    #: opt-in (issue 27 item 5; design §14): c at least this many times the identified resistance; 0 = off
    resistance_margin: float = unit(0.0, "1", kept="a ratio of two torques")


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

    k4: tuple[float, ...] = unit((6.0, 50.0), "s^2", mixed=_EQ37)
    k5: tuple[float, ...] = unit((25.0, 50.0), "1/s")
    kd: tuple[float, ...] = unit((0.0, 0.0), "1/s^2")
    c_hat0_scale: tuple[float, ...] = unit((0.5, 0.5), "1")
    c_bounds: tuple[float, ...] = unit((0.1, 10.0), "1")
    gain_scaling: GainScaling = unit("none", "-")
    drag: bool = unit(False, "-")
    drag_gain: tuple[float, ...] = unit((30.0, 50.0), ("1/m^2", "1/rad^2"))
    drag_max: float = unit(50.0, "1/s")
    #: opt-in (issue 27 item 5; design §14): project ĉ onto [lo, hi] × the prior c_true (the robot's formula
    #: values, what robot check gives) instead of c_bounds × ĉ(0); empty: the paper's c_bounds
    projection_band: tuple[float, ...] = unit((), "1")
    #: opt-in (issue 27 item 5): the kd used where robot check identifies a dead band; empty: off
    kd_deadband: tuple[float, ...] = unit((), "1/s^2")


@dataclass(frozen=True)
class PlantCfg:
    """Plant. Ideal: ``c_true = (a, b)`` and the mass (kg) / yaw inertia (kg·m²) consistent with
    them for r = 0.1 m, l = 0.2 m (used by payload events). ``robots``: shipped names, MJCF paths
    or tables ``{model, base, left_wheel, right_wheel, wheel_radius, half_track, tau_max}``
    (:mod:`bioform_mj.robots.refs`), one per follower or one for all; relative paths in a TOML file
    are relative to that file. On the ideal plant a robot other than ``paper`` gives ``c_true``
    (and ``mass``, ``inertia`` = ``M_eff``, ``I_eff``) from its compiled model
    (:func:`apply_robots_to_ideal`). ``package_path``: ``{NAME = "DIR"}``, where the URDF robots'
    ``package://NAME/…`` URIs point (design §12; relative to the TOML file), merged into every
    robot's own ``package_path`` (the robot's entries first)."""

    kind: PlantKind = unit("ideal", "-")
    c_true: tuple[float, ...] = unit(PAPER_C, ("1/kg·m", "1/kg·m^2"))
    mass: float = unit(25.0, "kg")
    inertia: float = unit(0.2, "kg·m^2")
    robots: tuple[RobotRef, ...] = unit((RobotRef("paper"),), "-", kept="the robot itself")
    # design §8.3, MuJoCo only: what the controllers are given ("truth" or "odometry")
    sensing: Sensing = unit("truth", "-")
    encoder_cpr: int = unit(-1, "1")  # counts per wheel revolution; -1: each robot file's <numeric name="encoder_cpr">
    sensor_dt: float = unit(0.0, "s", kept=_STEP)  # s, encoder and gyro period; 0: every physics step
    gyro_noise: float = unit(0.0, "rad/s", kept=_SENSOR)  # rad/s, standard deviation per sample
    gyro_bias: float = unit(0.0, "rad/s", kept=_SENSOR)  # rad/s, constant
    package_path: PackagePath = unit(PackagePath(), "-")  # design §12: package:// search path of URDF robots

    def __post_init__(self) -> None:
        if self.package_path:  # every robot searches the scenario's packages after its own
            robots = tuple(
                dataclasses.replace(r, package_path=r.package_path.merged(self.package_path))
                if isinstance(r, RobotRef)
                else r
                for r in self.robots
            )
            object.__setattr__(self, "robots", robots)


@dataclass(frozen=True)
class DisturbanceCfg:
    """``d_k = bias_k + amp_k cos(freq_k t + phase_k)``, k = (υ m/s², ω rad/s²). Paper: d1 = 0.1, d2 = 0.1 cos t."""

    bias: tuple[float, ...] = unit((0.1, 0.0), ("m/s^2", "rad/s^2"))
    amp: tuple[float, ...] = unit((0.0, 0.1), ("m/s^2", "rad/s^2"))
    freq: tuple[float, ...] = unit((0.0, 1.0), "rad/s")
    phase: tuple[float, ...] = unit((0.0, 0.0), "rad")


@dataclass(frozen=True)
class EventCfg:
    """A timed event. ``payload``: follower (1-based) gains ``mass`` kg and yaw ``inertia`` kg·m²."""

    time: float = unit(0.0, "s")
    kind: EventKind = unit("payload", "-")
    follower: int = unit(1, "1")
    mass: float = unit(0.0, "kg")
    inertia: float = unit(0.0, "kg·m^2")


@dataclass(frozen=True)
class LimitsCfg:
    """Divergence guard: the run stops (exit 3) beyond these magnitudes."""

    speed: float = unit(100.0, "m/s", kept=_GUARD)  # m/s, measured or commanded
    position: float = unit(1.0e4, "m", kept=_GUARD)  # m, robot or estimate
    torque: float = unit(1.0e6, "N·m", kept=_GUARD)  # N·m, commanded before saturation


@dataclass(frozen=True)
class FaultsCfg:
    """Injected faults (issue 6, ``run/faults.py``); the defaults inject none. Follower ids 1-based, times in s.

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

    link_fail: tuple[tuple[float, ...], ...] = unit((), ("1", "1", "s", "s"))
    packet_loss: float = unit(0.0, "1")
    delay: float = unit(0.0, "s")
    noise_pose: tuple[float, ...] = unit((0.0, 0.0, 0.0), ("m", "m", "rad"))
    noise_vel: tuple[float, ...] = unit((0.0, 0.0), ("m/s", "rad/s"))
    window: tuple[float, ...] = unit((), "s")
    actuator: tuple[tuple[float, ...], ...] = unit((), ("1", "s", "s", "1"))
    actuator_known: bool = unit(True, "-")
    push: tuple[tuple[float, ...], ...] = unit((), ("1", "s", "s", "N", "N", "N·m"))
    friction_patch: tuple[float, ...] = unit((), ("m", "m", "m", "m", "1"))

    @property
    def configured(self) -> bool:
        """True when any fault is injected."""
        return self.per_step or bool(self.friction_patch)

    @property
    def per_step(self) -> bool:
        """True when a fault acts in the loop (it then builds :class:`~bioform_mj.run.faults.Faults`);
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

    name: str = unit("paper", "-")
    description: str = unit("Xu et al. 2024, Sec. IV: three followers track a sinusoidal leader.", "-")
    method: str = unit("bioinspired-learning", "-")
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
        for f in dataclasses.fields(FormationCfg):  # internal (design §18.1): not a key of a file or a record
            if f.metadata.get("internal"):
                del d["formation"][f.name]
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
        """The fixed obstacles and the seeded random field's (:func:`bioform_mj.formation.obstacles.resolve`;
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


@functools.cache
def keys_of(cls: Any) -> dict[str, Any]:
    """The scenario keys of a config dataclass ``cls``: ``{name: type}`` of its fields, without the
    internal ones (``metadata["internal"]``: :attr:`FormationCfg.scale_applied`). Cached: resolving
    the annotations was 40 % of checking a scenario (do not modify the dict returned)."""
    import typing

    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if not f.metadata.get("internal")}


def _to_plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_plain(v) for v in obj]
    return obj
