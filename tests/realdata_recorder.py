"""Test-only: a "real robot's" recording, written without the project's exporter or model code (issue 29 item 4).

A published robot file is changed the way a real robot differs from its maker's numbers (a payload on the
chassis, wheel damping and dry friction in the gearboxes), simulated by a plain MuJoCo loop that applies an
excitation torque program to the two wheel joints, and written as a rosbag2 folder (MCAP storage) with
``rosbags``' writer: ``/joint_states`` (wheel angle, speed, applied torque), ``/odom`` (pose and body-frame
twist) and ``/imu`` (orientation, angular velocity, specific force), each with Gaussian sensor noise.

Nothing here imports ``bioform_mj``: the fit (``bioform robot fit``) must find these numbers from the bag
alone, so a shared bug cannot make the two agree by construction. Also a CSV writer for the fallback format.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

MODELS = Path(__file__).resolve().parents[1] / "src" / "bioform_mj" / "robots" / "models"


@dataclass
class Truth:
    """How the "real" robot differs from its published file (SI units)."""

    payload_kg: float = 0.0  # added to the chassis body's mass, at its centre of mass
    payload_yaw_kgm2: float = 0.0  # added to the chassis body's z inertia
    damping: tuple[float, float] = (0.0, 0.0)  # wheel joint damping, N·m·s/rad (left, right)
    frictionloss: tuple[float, float] = (0.0, 0.0)  # wheel joint dry friction, N·m
    armature: tuple[float, float] | None = None  # wheel joint armature, kg·m² (None: as published)
    caster_friction: float | None = None  # sliding friction of the caster geoms (None: as published)
    casters: tuple[str, ...] = ("back_caster",)
    joints: tuple[str, str] = ("left_wheel", "right_wheel")
    base: str = "base"  # the chassis body: the payload goes on it
    odom_body: str | None = None  # the body whose pose and twist /odom reports (None: ``base``)
    recorded: tuple[str, ...] = ()  # other 1-dof joints whose true angle and speed /joint_states also carries
    coupled: tuple[str, str] | None = None  # a skid steer's other pair (left, right): driven with its side's
    # torque and given its side's damping and dry friction (the Husky's rear wheels)
    point_wheels: bool | None = None  # the driven wheels' cylinders as spheres of their radius, one rolling
    # contact (None: a URDF's, not an MJCF's; the TIAGo's cylinders touch the floor along their edge)
    held: tuple[str, ...] = ()  # joints taken out of the file, their bodies welded at its pose (servos holding an
    # arm and a head still: the TIAGo's); unpowered, they sag and swing, which the fit's model does not (design §13)

    def values(self, published_mass: float, published_yaw_inertia: float) -> dict[str, float]:
        """The true values of the fit's parameters (its ``fit.json`` names; SI units) given the published chassis
        body's mass (kg) and z inertia (kg·m²): the fit test's and ``scripts/fit_coverage.py``'s ground truth."""
        return {
            "mass": published_mass + self.payload_kg,
            "yaw_inertia": published_yaw_inertia + self.payload_yaw_kgm2,
            "damping_L": self.damping[0],
            "damping_R": self.damping[1],
            "frictionloss_L": self.frictionloss[0],
            "frictionloss_R": self.frictionloss[1],
        }


#: the Kobuki URDF of the test zoo and a "real" Kobuki that differs from it (its base_link: 2.4 kg, izz 0.03675
#: kg·m²; the payload makes 3.0 kg and 0.04675 kg·m²), recorded at KOBUKI_TAU N·m: the fit's out-of-sample tests
#: and scripts/fit_coverage.py use this one recipe
KOBUKI_URDF = Path(__file__).resolve().parent / "zoo" / "kobuki_urdf" / "kobuki_standalone.urdf"
KOBUKI_TRUTH = Truth(
    payload_kg=0.6,
    payload_yaw_kgm2=0.01,
    damping=(0.0008, 0.001),
    frictionloss=(0.008, 0.006),
    caster_friction=0.0,
    casters=("caster_front_link", "caster_back_link"),
    joints=("wheel_left_joint", "wheel_right_joint"),
    base="base_link",
    odom_body="base_footprint",
)
KOBUKI_TAU = 0.0713


def _urdf_spec(robot_file: Path) -> mujoco.MjSpec:
    """A URDF through MuJoCo's own URDF parser (not the project's import): ``<gazebo>``, ``<transmission>`` and
    ``<visual>`` dropped, static links kept as bodies, links without ``<inertial>`` massless (the URDF rule), the
    root on a free joint, no self-collision (the URDF/Gazebo convention) and the wheels' collision cylinders as
    spheres of their radius (one rolling contact). Collision meshes are not supported (none in the Kobuki)."""
    import re

    text = Path(robot_file).read_text()
    for tag in ("gazebo", "transmission", "visual"):
        text = re.sub(rf"<{tag}\b.*?</{tag}>", "", text, flags=re.S)
    compiler = (  # balanceinertia: the PMB-2's antenna links publish an inertia that is not positive definite
        '<mujoco><compiler discardvisual="true" fusestatic="false" inertiafromgeom="false" balanceinertia="true"/>'
        "</mujoco>"
    )
    text = re.sub(r"(<robot[^>]*>)", r"\1" + compiler, text, count=1)
    spec = mujoco.MjSpec.from_string(text)
    spec.worldbody.first_body().add_freejoint()
    for b in spec.bodies:  # an inertia matrix that is not positive definite (the PMB-2's antennas): its diagonal
        fi = np.asarray(b.fullinertia, float)
        if np.all(np.isfinite(fi)) and np.any(fi[3:]):
            m = np.array([[fi[0], fi[3], fi[4]], [fi[3], fi[1], fi[5]], [fi[4], fi[5], fi[2]]])
            if np.linalg.eigvalsh(m).min() <= 0:
                b.fullinertia = [fi[0], fi[1], fi[2], 0.0, 0.0, 0.0]
    for g in spec.geoms:  # robot geoms 2/1, the floor 1/2: the robot touches the floor, never itself
        g.contype, g.conaffinity = 2, 1
    return spec


def _mesh_wheel_sphere(model: mujoco.MjModel, joint: int, mesh: str) -> tuple[list[float], list[float]]:
    """Centre (in the wheel body's frame, on the joint axis at the tread's middle) and radius (the largest distance
    of the mesh's vertices from the axis) of the sphere a mesh wheel rolls on, from the compiled ``model`` at qpos0."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    g = next(k for k in range(model.ngeom) if model.geom_dataid[k] == model.mesh(mesh).id)
    a, n = model.mesh_vertadr[model.geom_dataid[g]], model.mesh_vertnum[model.geom_dataid[g]]
    verts = data.geom_xpos[g] + model.mesh_vert[a : a + n] @ data.geom_xmat[g].reshape(3, 3).T  # world, m
    b = model.jnt_bodyid[joint]
    rot = data.xmat[b].reshape(3, 3)
    axis = rot @ model.jnt_axis[joint]
    anchor = data.xpos[b] + rot @ model.jnt_pos[joint]
    along = (verts - anchor) @ axis
    radius = float(np.linalg.norm((verts - anchor) - np.outer(along, axis), axis=1).max())
    centre = anchor + axis * 0.5 * (along.min() + along.max())
    return (rot.T @ (centre - data.xpos[b])).tolist(), [radius, 0.0, 0.0]


def true_model(robot_file: Path, truth: Truth) -> mujoco.MjModel:
    """The published file with the truth's changes and a floor, compiled."""
    urdf = Path(robot_file).suffix == ".urdf"
    spec = _urdf_spec(robot_file) if urdf else mujoco.MjSpec.from_file(str(robot_file))
    for k in list(spec.keys):
        spec.delete(k)
    for name in truth.held:
        spec.delete(spec.joint(name))
    for a in list(spec.actuators):  # torques go in as qfrc_applied; a DC motor at 0 V would brake (back-EMF)
        spec.delete(a)
    for s in list(spec.sensors):  # some name the actuators; the recording is written from the state
        spec.delete(s)
    model0 = spec.compile()
    if urdf:  # its inertials are full matrices: the payload as a body welded at the chassis' centre of mass
        load = spec.body(truth.base).add_body(name="test_payload", pos=model0.body(truth.base).ipos)
        load.explicitinertial = True
        load.mass = truth.payload_kg
        y = truth.payload_yaw_kgm2
        load.inertia = [y / 2 + 1e-9, y / 2 + 1e-9, y + 1e-9]
    else:
        base = spec.body(truth.base)
        base.mass = base.mass + truth.payload_kg
        inertia = np.array(base.inertia, float)
        inertia[2] += truth.payload_yaw_kgm2
        base.inertia = inertia
    if urdf if truth.point_wheels is None else truth.point_wheels:
        for j in truth.joints + (truth.coupled or ()):  # wheels roll on one contact point
            for g in spec.body(model0.body(model0.joint(j).bodyid[0]).name).geoms:
                if g.type == mujoco.mjtGeom.mjGEOM_CYLINDER:
                    g.type, g.size = mujoco.mjtGeom.mjGEOM_SPHERE, [g.size[0], 0, 0]
                elif g.type == mujoco.mjtGeom.mjGEOM_MESH:  # a mesh tyre (Fetch/Freight): a sphere of its radius
                    g.pos, g.size = _mesh_wheel_sphere(model0, model0.joint(j).id, g.meshname)
                    g.type, g.meshname = mujoco.mjtGeom.mjGEOM_SPHERE, ""
    pairs = list(zip(truth.joints, truth.damping, truth.frictionloss))
    pairs += list(zip(truth.coupled or (), truth.damping, truth.frictionloss))
    for name, d, f in pairs:
        j = spec.joint(name)
        damping = np.array(j.damping, float)  # MuJoCo 4: [linear, ...]; the linear coefficient
        damping[0] = d
        j.damping = damping
        j.frictionloss = f
    if truth.armature is not None:
        for name, a in zip(truth.joints, truth.armature):
            spec.joint(name).armature = a
    if truth.caster_friction is not None:
        for g in truth.casters:
            geom = spec.geom(g) or next(iter(spec.body(g).geoms))  # a URDF's unnamed geom: by its link
            geom.friction = [truth.caster_friction, 0.005, 0.0001]
            geom.condim = 3 if truth.caster_friction > 0 else 1
            geom.priority = 2  # its own friction wins against the floor's
    # MuJoCo's own contact defaults, not the file's default class (the menagerie TIAGo's, contype 0 and type mesh,
    # left its casters without a floor: it fell through in 0.3 s). A copy, on purpose, of the fit's floor
    # (bioform_mj/robots/realdata/simmodel.py, sim_spec): this recorder imports nothing of the project (issue 29
    # item 4), so that a wrong floor there cannot make the fit agree with its test recordings by construction
    floor = spec.worldbody.add_geom(
        name="test_floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 1],
        contype=1,
        conaffinity=1,
        condim=3,
        friction=[1.0, 0.005, 0.0001],
        mass=0.0,
    )
    if urdf:
        floor.contype, floor.conaffinity = 1, 2
    return spec.compile()


def torque_program(duration: float, tau: float, seed: int = 0) -> callable:
    """Wheel torques (N·m) against time: zero-mean pulse pairs (forward, back, turn left, turn right, and
    single wheels) of random amplitude 0.3–1 × ``tau`` and length 0.3–0.8 s, each followed by its negative, and
    pauses; so the robot speeds up and slows down in every mode and comes back near rest."""
    rng = np.random.default_rng(seed)
    modes = np.array([[1, 1], [1, -1], [-1, 1], [1, 0], [0, 1], [1, 0.5], [0.5, 1]], float)
    seg_t, seg_u = [0.0], [np.zeros(2)]
    t = 0.3
    while t < duration:
        u = modes[rng.integers(len(modes))] * tau * rng.uniform(0.3, 1.0) * rng.choice([-1, 1])
        d = rng.uniform(0.3, 0.8)
        seg_t += [t, t + d, t + 2 * d]
        seg_u += [u, -u, np.zeros(2)]
        t += 2 * d + rng.uniform(0.1, 0.4)
    seg_t, seg_u = np.array(seg_t), np.array(seg_u)

    def program(time: float) -> np.ndarray:
        return seg_u[np.searchsorted(seg_t, time, side="right") - 1]

    return program


def simulate(model: mujoco.MjModel, truth: Truth, duration: float, tau: float, seed: int = 0) -> dict:
    """Step the true model with the torque program; samples at every step (s, rad, rad/s, N·m, m, m/s)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for _ in range(300):  # settle on the floor
        mujoco.mj_step(model, data)
    data.time = 0.0
    program = torque_program(duration, tau, seed)
    dofs = [int(model.joint(j).dofadr[0]) for j in truth.joints]
    dofs2 = [int(model.joint(j).dofadr[0]) for j in truth.coupled or ()]
    qadr = [int(model.joint(j).qposadr[0]) for j in truth.joints]
    base = model.body(truth.odom_body or truth.base).id
    n = int(round(duration / model.opt.timestep))
    out = {k: [] for k in ("t", "q", "qd", "tau", "pos", "quat", "vbody", "wbody", "acc", "oq", "oqd")}
    oq = [int(model.joint(j).qposadr[0]) for j in truth.recorded]
    od = [int(model.joint(j).dofadr[0]) for j in truth.recorded]
    vel6 = np.zeros(6)
    acc6 = np.zeros(6)
    for _ in range(n + 1):
        u = program(data.time)
        data.qfrc_applied[:] = 0
        data.qfrc_applied[dofs] = u
        if dofs2:
            data.qfrc_applied[dofs2] = u
        mujoco.mj_forward(model, data)
        # at the body's origin (ROS base_link) in its frame: ang, lin. (mjOBJ_BODY gives them at the centre of mass
        # in the principal-axes frame: the menagerie TIAGo's, turned 90° about z, recorded its forward speed as vy)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_XBODY, base, vel6, 1)
        mujoco.mj_rnePostConstraint(model, data)
        mujoco.mj_objectAcceleration(model, data, mujoco.mjtObj.mjOBJ_XBODY, base, acc6, 1)
        out["t"].append(data.time)
        out["q"].append(data.qpos[qadr].copy())
        out["qd"].append(data.qvel[dofs].copy())
        out["tau"].append(u.copy())
        out["pos"].append(data.xpos[base].copy())
        out["quat"].append(data.xquat[base].copy())
        out["vbody"].append(vel6[3:].copy())
        out["wbody"].append(vel6[:3].copy())
        out["acc"].append(acc6[3:].copy())
        out["oq"].append(data.qpos[oq].copy())
        out["oqd"].append(data.qvel[od].copy())
        mujoco.mj_step(model, data)
    return {k: np.array(v) for k, v in out.items()}


def _stamp(ts, t_ns: int):
    Time = ts.types["builtin_interfaces/msg/Time"]
    return Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000))


def write_bag(
    path: Path,
    sim: dict,
    truth: Truth,
    *,
    noise: float = 0.01,
    rate_hz: float = 100.0,
    start_ns: int = 1_700_000_000_000_000_000,
    topics: tuple[str, str, str] = ("/joint_states", "/odom", "/imu"),
    joint_names: tuple[str, str] | None = None,
    seed: int = 1,
    velocities: bool = True,
    other_joint_states: tuple[str, ...] = (),
    extra_joints: tuple[str, ...] = (),
) -> None:
    """Write the simulation as a rosbag2 folder (MCAP) at ``rate_hz``; ``noise``: standard deviation of the
    speed noise (rad/s on wheels, m/s and rad/s on the body); angles get 1e-3 rad, torques 2 % of their scale;
    ``velocities=False``: the joint states carry no velocity (as some drivers publish); ``other_joint_states``:
    a second publisher on the joint-state topic, one message naming only these joints (zeros) before each;
    ``extra_joints``: more joints in each wheel message, after the wheels (joint ``i`` at angle ``0.01 (i + 1) t``
    rad, speed ``0.01 (i + 1)`` rad/s, effort 0)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    rng = np.random.default_rng(seed)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Header = T["std_msgs/msg/Header"]
    JointState = T["sensor_msgs/msg/JointState"]
    Odometry = T["nav_msgs/msg/Odometry"]
    Imu = T["sensor_msgs/msg/Imu"]
    Pose, PoseCov = T["geometry_msgs/msg/Pose"], T["geometry_msgs/msg/PoseWithCovariance"]
    Twist, TwistCov = T["geometry_msgs/msg/Twist"], T["geometry_msgs/msg/TwistWithCovariance"]
    Point, Quat, Vec3 = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]
    names = list(joint_names or truth.joints)
    step = max(1, int(round(1.0 / (rate_hz * (sim["t"][1] - sim["t"][0])))))
    tau_scale = float(np.abs(sim["tau"]).max()) or 1.0
    cov9, cov36 = np.zeros(9), np.zeros(36)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cj = w.add_connection(topics[0], JointState.__msgtype__, typestore=ts)
        co = w.add_connection(topics[1], Odometry.__msgtype__, typestore=ts)
        ci = w.add_connection(topics[2], Imu.__msgtype__, typestore=ts)
        for k in range(0, len(sim["t"]), step):
            t_ns = start_ns + int(round(sim["t"][k] * 1e9))
            st = _stamp(ts, t_ns)
            if other_joint_states:
                n = len(other_joint_states)
                z = np.zeros(n)
                arm = JointState(
                    header=Header(stamp=st, frame_id=""),
                    name=list(other_joint_states),
                    position=z,
                    velocity=z,
                    effort=z,
                )
                w.write(cj, t_ns, ts.serialize_cdr(arm, JointState.__msgtype__))
            rate = 0.01 * np.arange(1, len(extra_joints) + 1)
            n_rec = len(truth.recorded)  # true angles and speeds of the recorded other joints, with the wheels' noise
            rec_q = sim["oq"][k] + rng.normal(0, 1e-3, n_rec) if n_rec else np.zeros(0)
            rec_qd = sim["oqd"][k] + rng.normal(0, noise, n_rec) if n_rec else np.zeros(0)
            js = JointState(
                header=Header(stamp=st, frame_id=""),
                name=names + list(truth.recorded) + list(extra_joints),
                position=np.r_[sim["q"][k] + rng.normal(0, 1e-3, 2), rec_q, rate * sim["t"][k]],
                velocity=np.r_[sim["qd"][k] + rng.normal(0, noise, 2), rec_qd, rate] if velocities else np.zeros(0),
                effort=np.r_[sim["tau"][k] + rng.normal(0, 0.02 * tau_scale, 2), 0 * rec_q, 0 * rate],
            )
            w.write(cj, t_ns, ts.serialize_cdr(js, JointState.__msgtype__))
            p, q = sim["pos"][k], sim["quat"][k]
            v, om = sim["vbody"][k] + rng.normal(0, noise, 3), sim["wbody"][k] + rng.normal(0, noise, 3)
            od = Odometry(
                header=Header(stamp=st, frame_id="odom"),
                child_frame_id="base_link",
                pose=PoseCov(
                    pose=Pose(position=Point(x=p[0], y=p[1], z=p[2]), orientation=Quat(x=q[1], y=q[2], z=q[3], w=q[0])),
                    covariance=cov36,
                ),
                twist=TwistCov(
                    twist=Twist(linear=Vec3(x=v[0], y=v[1], z=v[2]), angular=Vec3(x=om[0], y=om[1], z=om[2])),
                    covariance=cov36,
                ),
            )
            w.write(co, t_ns, ts.serialize_cdr(od, Odometry.__msgtype__))
            g = sim["wbody"][k] + rng.normal(0, noise, 3)
            a = sim["acc"][k] + rng.normal(0, 0.05, 3)
            im = Imu(
                header=Header(stamp=st, frame_id="imu_link"),
                orientation=Quat(x=q[1], y=q[2], z=q[3], w=q[0]),
                orientation_covariance=cov9,
                angular_velocity=Vec3(x=g[0], y=g[1], z=g[2]),
                angular_velocity_covariance=cov9,
                linear_acceleration=Vec3(x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=cov9,
            )
            w.write(ci, t_ns, ts.serialize_cdr(im, Imu.__msgtype__))


def write_csv(path: Path, sim: dict, truth: Truth, rate_hz: float = 100.0, noise: float = 0.01, seed: int = 1) -> None:
    """The same recording as a CSV with named columns: ``time`` (s), ``<joint>.position`` (rad),
    ``<joint>.velocity`` (rad/s), ``<joint>.effort`` (N·m), ``odom.vx`` (m/s), ``odom.wz`` and ``imu.wz`` (rad/s)."""
    rng = np.random.default_rng(seed)
    step = max(1, int(round(1.0 / (rate_hz * (sim["t"][1] - sim["t"][0])))))
    cols = ["time"] + [f"{j}.{f}" for j in truth.joints for f in ("position", "velocity", "effort")]
    cols += ["odom.vx", "odom.wz", "imu.wz"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for k in range(0, len(sim["t"]), step):
            row = [sim["t"][k]]
            for i in range(2):
                row += [sim["q"][k, i], sim["qd"][k, i] + rng.normal(0, noise), sim["tau"][k, i]]
            row += [sim["vbody"][k, 0] + rng.normal(0, noise), sim["wbody"][k, 2] + rng.normal(0, noise)]
            row += [sim["wbody"][k, 2] + rng.normal(0, noise)]
            w.writerow([f"{x:.9g}" for x in row])


def record(
    out: Path,
    robot: str = "tb3",
    truth: Truth | None = None,
    duration: float = 20.0,
    tau: float = 0.06,
    fmt: str = "bag",
    seed: int = 0,
    **kw,
) -> Truth:
    """Simulate the shipped robot ``robot`` (or a robot file's path: MJCF, or a URDF through MuJoCo's parser)
    changed by ``truth`` and write ``out`` (a bag folder or a CSV)."""
    truth = truth or Truth()
    model = true_model(Path(robot) if robot.endswith((".urdf", ".xml")) else MODELS / f"{robot}_robot.xml", truth)
    sim = simulate(model, truth, duration, tau, seed)
    if fmt == "csv":
        write_csv(out, sim, truth)
    else:
        write_bag(out, sim, truth, **kw)
    return truth


if __name__ == "__main__":  # python tests/realdata_recorder.py OUT_DIR: a 60 s tb3 recording, for timing
    import sys

    t = Truth(payload_kg=0.3, payload_yaw_kgm2=0.001, damping=(0.002, 0.0025), frictionloss=(0.004, 0.003))
    record(Path(sys.argv[1]), duration=float(sys.argv[2]) if len(sys.argv) > 2 else 60.0, truth=t)
