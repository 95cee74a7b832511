"""A run as a ROS 2 bag: a rosbag2 folder (``metadata.yaml`` + MCAP storage) of standard messages.

``bioform run … --rosbag`` writes ``rosbag/`` beside ``log.npz``; from Python,
``write_bag(simulate(sc, full_state=True), "run/rosbag")``. The topics, frames and the meaning of
every field are in ``docs/guide/rosbag.md``; in short, per follower ``fI``
(``I`` = 1 … n) and for the virtual leader:

- ``/clock`` (``rosgraph_msgs/Clock``), ``/tf`` and ``/tf_static`` (``tf2_msgs/TFMessage``: a common
  ``world`` frame, ``world → fI/odom`` identity, ``fI/odom → fI/base_link`` the true 3-D pose);
- ``/fI/ground_truth/odom`` (``nav_msgs/Odometry``, the truth), ``/fI/odom`` (the dead reckoning,
  ``plant.sensing = "odometry"`` only), ``/fI/cmd_vel`` (``geometry_msgs/Twist``, the kinematic
  command), ``/fI/joint_states`` (``sensor_msgs/JointState``: wheel angle, rate, applied torque),
  ``/fI/imu`` (``sensor_msgs/Imu``, where the plant has one), ``/fI/leader_estimate``
  (``nav_msgs/Odometry``, the follower's estimate of the leader), ``/leader/ground_truth/odom``.

Messages are stamped with simulated time (``start_ns`` + t; ``/clock`` says it), one message per topic
at every log row and, for the state topics, at the run's end ``T``. The message definitions and type
hashes are those of the chosen ROS 2 distribution (:data:`DISTROS`, default :data:`DEFAULT_DISTRO`)
from ``rosbags`` (the ``ros`` extra), which writes the folder; no ROS install is needed.

Speed (design §9, a run as a ROS 2 bag: a fraction of the run's stepping time): each topic's message has
one fixed layout, so one message is serialised by ``rosbags`` with marker values, the markers'
byte offsets are found, and every row's numbers are written into a copy of it by one compiled pass per
MCAP chunk (:mod:`bioform_mj.outputs.rosbag_kernel`, the log's arrays read in place), which also writes the
chunk's message index times (:mod:`bioform_mj.outputs.rosbag_write`). ``rosbags``'
reader reads the result back (``tests/test_outputs_rosbag.py`` compares it with ``log.npz``).
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import struct
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.outputs.fullstate import quat_of_rpy, quat_of_yaw
from bioform_mj.outputs.rosbag_write import CHUNK_BYTES, MSG_HEAD, bulk_writer

__all__ = ["DISTROS", "DEFAULT_DISTRO", "BagInfo", "check_available", "warm_up", "write_bag", "topics_of"]

#: ROS 2 distributions whose message definitions and type hashes a bag can carry (``rosbags`` stores)
DISTROS = ("humble", "iron", "jazzy", "kilted")
#: the current long-term-support release
DEFAULT_DISTRO = "jazzy"
#: rosbag2 metadata version written (``rosbags`` writes 8 or 9; 9 = Jazzy's)
BAG_VERSION = 9

INSTALL_HINT = "pip install 'bioform-mj[ros]' (or: pip install rosbags==0.11.9)"


def check_available() -> None:
    """Raise :class:`~bioform_mj.errors.InputError` saying how to install ``rosbags`` when it is missing."""
    import importlib.util

    if importlib.util.find_spec("rosbags") is None:
        raise InputError(f"--rosbag needs the ros extra (the rosbags package), which is not installed: {INSTALL_HINT}")


def check_args(rosbag: bool, distro: str | None, like: Any = None) -> None:
    """``bioform run``'s ``--rosbag`` and ``--ros-distro``, before any work: the extra is installed
    (else :func:`check_available`'s error), ``--ros-distro`` only with ``--rosbag``; ``like``: the run's
    scenario (:func:`warm_up`)."""
    if not rosbag:
        raise InputError("--ros-distro only applies to --rosbag")
    check_available()
    try:
        warm_up(distro or DEFAULT_DISTRO, like)
    except OSError as exc:  # the temporary folder, not the package
        raise InputError(f"--rosbag: could not write a trial bag in the temporary folder: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - a broken install: one error: line, before the run
        raise InputError(
            f"--rosbag: the rosbags package does not work ({type(exc).__name__}: {exc}); reinstall it: {INSTALL_HINT}"
        ) from exc


def warm_up(distro: str = DEFAULT_DISTRO, like: Any = None) -> float:
    """Import ``rosbags``, build ``distro``'s type store and every serialiser a bag uses, once per
    process (about 0.3 s, the first time), by writing a one-row stand-in log's bag into a temporary
    folder; returns the seconds it took.
    ``bioform run --rosbag`` does it before the run, with its other start-up work: a broken install
    fails there, and the bag's own write time is then what the run's numbers cost.

    ``like``: the run's scenario. Where its plant is planar (the ideal plant, a user's: the layout of
    its bag is known before the run: its followers, no wheels, no IMU), a stand-in bag of that layout
    is written too (of zeros, about 3 chunks), so that the run's bag finds its templates, chunk buffer
    and connection records made, as a sweep's later bags do."""
    t0 = time.perf_counter()
    z = np.zeros
    log = {
        "t": z(1),
        "t_state": np.array([0.0, 0.001]),
        "pose_3d": z((2, 1, 6)),
        "twist_3d": z((2, 1, 6)),
        "wheel_angle": z((2, 1, 2)),
        "wheel_speed": z((2, 1, 2)),
        "imu_gyro": z((2, 1, 3)),
        "imu_accel": z((2, 1, 3)),
        "leader_state": z((2, 5)),
        "wheel_sign": np.ones((1, 2)),
        "wheel_joints": np.array([["l", "r"]]),
        "cmd": z((1, 1, 2)),
        "tau": z((1, 1, 2)),
        "est_pose": z((1, 1, 3)),
        "est_vel": z((1, 1, 2)),
        "odom_pose": z((1, 1, 3)),
        "odom_vel": z((1, 1, 2)),
    }
    with tempfile.TemporaryDirectory(prefix="bioform-rosbag-") as tmp:  # every path once: YAML, MCAP, files
        _write(Path(tmp) / "bag", log, {}, "odometry", distro, 0)
    if like is not None and getattr(getattr(like, "plant", None), "kind", "mujoco") != "mujoco":
        try:  # a speed-up only: where it fails, the run's bag makes its layout
            _warm_layout(distro, int(like.n), str(getattr(like.plant, "sensing", "truth")))
        except (ValueError, TypeError, AttributeError):
            pass
    return time.perf_counter() - t0


def _planar_log(n: int, K: int) -> dict[str, np.ndarray]:
    """A planar plant's ``K``-row log of ``n`` followers as ``simulate(sc, full_state=True)`` gives it
    (zeros; the wheels' angles and rates NaN, as a plant without wheels has them; no IMU)."""
    z, S = np.zeros, K + 1
    nan = np.full((S, n, 2), np.nan)
    log = {"t": z(K), "t_state": np.arange(S) * 0.01, "pose_3d": z((S, n, 6)), "twist_3d": z((S, n, 6))}
    log |= {"wheel_angle": nan, "wheel_speed": nan.copy(), "leader_state": z((S, 5)), "wheel_sign": np.ones((n, 2))}
    log |= {"wheel_joints": np.array([["left_wheel", "right_wheel"]] * n), "cmd": z((K, n, 2)), "tau": z((K, n, 2))}
    return log | {
        "est_pose": z((K, n, 3)),
        "est_vel": z((K, n, 2)),
        "odom_pose": z((K, n, 3)),
        "odom_vel": z((K, n, 2)),
    }


def _warm_layout(distro: str, n: int, sensing: str) -> None:
    """Write a stand-in bag of a planar run's layout (:func:`warm_up` ``like``): enough rows for a chunk
    between the first and the last (the chunk buffer), into a temporary folder."""
    topics = topics_of(_planar_log(n, 1), sensing, _messages(distro))
    K = 2 * max(1, CHUNK_BYTES // sum(tp.width for tp in topics)) + 2
    with tempfile.TemporaryDirectory(prefix="bioform-rosbag-") as tmp:
        _write(Path(tmp) / "bag", _planar_log(n, K), {}, sensing, distro, 0)


def write_run_bag(result: Any, out: Path, distro: str | None) -> str:
    """``bioform run --rosbag``: write ``out/rosbag`` (:func:`write_bag`); the line the run prints about it."""
    bag = write_bag(result, Path(out) / "rosbag", distro=distro or DEFAULT_DISTRO)
    return f"rosbag/: {bag.messages} messages on {len(bag.topics)} topics ({bag.distro}) written in {bag.write_s:.2f} s"


def write(result: Any, out: Path, watcher: Any = None, options: Any = None, progress: Any = None) -> str:
    """The registered output ``rosbag`` (:mod:`bioform_mj.outputs.registry`): :func:`write_run_bag` with the
    distribution ``options`` (``--ros-distro``; None: the default)."""
    return write_run_bag(result, out, options)


@dataclass
class BagInfo:
    """What :func:`write_bag` wrote: the folder, message and topic counts, the distribution, wall time (s)."""

    path: Path
    messages: int
    topics: dict[str, int]  # topic → message count
    distro: str
    write_s: float


@dataclass
class _Topic:
    """One topic: its rows (indices into ``t_state``), the message template and where each row's numbers go."""

    name: str
    msgtype: str
    rows: np.ndarray  # (m,) int: the state samples it is published at
    template: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))  # (L,) uint8, CDR
    #: (offset, dtype, (m,) values, their source ``(a, idx)``: values = ``a[idx]``)
    fields: list[tuple[int, str, np.ndarray, tuple[np.ndarray, tuple]]] = field(default_factory=list)
    extra: list[tuple[int, bytes]] = field(default_factory=list)  # (row, CDR bytes): messages of another layout
    qos: list[Any] = field(default_factory=list)
    #: the layout it belongs to (topics_of's cache key; None: not cached), by which the writer keeps its
    #: chunk buffers (:class:`~bioform_mj.outputs.rosbag_write.ChunkPlan`)
    layout: Any = None

    def record_at(self, cid: int, stamp: int, j: int) -> bytes:
        """This topic's MCAP message record (:data:`MSG_HEAD` bytes of record header, then the template
        with the numbers of sample ``j``), log and publish time ``stamp`` ns: the bytes the bulk writer
        places for a row (``np.asarray(values, dtype)``'s: float64 bits as they are, integers modulo 2⁶⁴
        or 2³²), written with :mod:`struct` (the end of the run's one message per topic)."""
        out = bytearray(MSG_HEAD) + self.template.tobytes()
        struct.pack_into("<BQHIQQ", out, 0, 0x05, 2 + 4 + 8 + 8 + self.template.size, cid, 0, stamp, stamp)
        for off, dt, vals, _ in self.fields:
            v, at = vals[j], MSG_HEAD + off
            kind = getattr(v, "dtype", np.dtype(object)).kind
            if dt == "<f8" and kind == "f" and v.dtype.itemsize == 8:
                struct.pack_into("<d", out, at, float(v))
            elif dt != "<f8" and kind in "iu":
                wide = dt == "<u8"
                struct.pack_into("<Q" if wide else "<I", out, at, int(v) & (2**64 - 1 if wide else 2**32 - 1))
            else:  # any other kind: numpy's conversion
                b = np.asarray(vals[j : j + 1], dtype=dt).tobytes()
                out[at : at + len(b)] = b
        return bytes(out)

    @property
    def width(self) -> int:
        """Bytes of one message record of this topic."""
        return MSG_HEAD + self.template.size


class _Markers:
    """Marker values for the fields of a template message, and the rows' values they stand for: each a
    1-D selection ``a[idx]`` of an array ``a`` (kept with it: the writer reads the numbers from ``a``
    itself, :func:`bioform_mj.outputs.rosbag_write.number_sources`)."""

    def __init__(self) -> None:
        self.items: list[tuple[bytes, str, np.ndarray, tuple[np.ndarray, tuple]]] = []

    def f64(self, a: np.ndarray, *idx: Any) -> float:
        """A marker float64 for the values ``a[idx]`` (m,) (``a`` itself without ``idx``)."""
        v = 1.2345678901234567e250 * (1.0 + len(self.items) * 2.0**-30)
        a = np.asarray(a, dtype=float)
        self.items.append((struct.pack("<d", v), "<f8", a[idx] if idx else a, (a, idx)))
        return v

    def int32(self, dt: str, a: np.ndarray, *idx: Any) -> int:
        """A marker 32-bit integer (``dt`` ``<i4`` or ``<u4``) for the values ``a[idx]`` (m,)."""
        v = 0x3A5B0000 + 2 * len(self.items) + 1
        a = np.asarray(a)
        self.items.append((struct.pack("<I", v), dt, a[idx] if idx else a, (a, idx)))
        return v

    def locate(self, raw: bytes) -> list[tuple[int, str, np.ndarray, tuple[np.ndarray, tuple]]]:
        """Each marker's byte offset in the serialised template (exactly one match each), with its dtype,
        values and their source ``(a, idx)``."""
        out = []
        for pat, dt, vals, src in self.items:
            off = raw.find(pat)
            if off < 0 or raw.find(pat, off + 1) >= 0:
                raise RuntimeError(f"rosbag template: marker {pat.hex()} found {raw.count(pat)} times")
            out.append((off, dt, vals, src))
        return out


class _Messages:
    """Builders of the ROS 2 message objects of one ``rosbags`` typestore."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self.T = store.types

    def _t(self, name: str) -> Any:
        return self.T[name]

    def time(self, sec: int, nsec: int) -> Any:
        return self._t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nsec)

    def header(self, stamp: Any, frame: str) -> Any:
        return self._t("std_msgs/msg/Header")(stamp=stamp, frame_id=frame)

    def vec(self, x: float, y: float, z: float) -> Any:
        return self._t("geometry_msgs/msg/Vector3")(x=x, y=y, z=z)

    def quat(self, wxyz: tuple[float, float, float, float]) -> Any:
        w, x, y, z = wxyz
        return self._t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)

    def twist(self, lin: tuple[float, ...], ang: tuple[float, ...]) -> Any:
        return self._t("geometry_msgs/msg/Twist")(linear=self.vec(*lin), angular=self.vec(*ang))

    def odometry(self, stamp: Any, frame: str, child: str, pos, wxyz, lin, ang) -> Any:
        T = self._t
        pose = T("geometry_msgs/msg/Pose")(position=T("geometry_msgs/msg/Point")(*pos), orientation=self.quat(wxyz))
        return T("nav_msgs/msg/Odometry")(
            header=self.header(stamp, frame),
            child_frame_id=child,
            pose=T("geometry_msgs/msg/PoseWithCovariance")(pose=pose, covariance=np.zeros(36)),
            twist=T("geometry_msgs/msg/TwistWithCovariance")(twist=self.twist(lin, ang), covariance=np.zeros(36)),
        )

    def transform(self, stamp: Any, frame: str, child: str, xyz, wxyz) -> Any:
        T = self._t
        tf = T("geometry_msgs/msg/Transform")(translation=self.vec(*xyz), rotation=self.quat(wxyz))
        return T("geometry_msgs/msg/TransformStamped")(
            header=self.header(stamp, frame), child_frame_id=child, transform=tf
        )

    def tf(self, transforms: list[Any]) -> Any:
        return self._t("tf2_msgs/msg/TFMessage")(transforms=transforms)

    def joint_state(self, stamp: Any, names: list[str], pos, vel, eff) -> Any:
        return self._t("sensor_msgs/msg/JointState")(
            header=self.header(stamp, ""),
            name=list(names),
            position=np.asarray(pos, dtype=float),
            velocity=np.asarray(vel, dtype=float),
            effort=np.asarray(eff, dtype=float),
        )

    def imu(self, stamp: Any, frame: str, gyro, accel) -> Any:
        cov = np.zeros(9)
        unknown = np.zeros(9)
        unknown[0] = -1.0  # REP 145: no orientation estimate
        return self._t("sensor_msgs/msg/Imu")(
            header=self.header(stamp, frame),
            orientation=self.quat((1.0, 0.0, 0.0, 0.0)),
            orientation_covariance=unknown,
            angular_velocity=self.vec(*gyro),
            angular_velocity_covariance=cov,
            linear_acceleration=self.vec(*accel),
            linear_acceleration_covariance=cov.copy(),
        )

    def clock(self, stamp: Any) -> Any:
        return self._t("rosgraph_msgs/msg/Clock")(clock=stamp)


@functools.cache
def _messages(distro: str) -> _Messages:
    """The message builders of ``distro``'s ``rosbags`` type store, made once per process (``rosbags``
    generates each type's serialiser on first use: about 0.1 s for a bag's types)."""
    from rosbags.typesys import Stores, get_typestore

    return _Messages(get_typestore(Stores[f"ROS2_{distro.upper()}"]))


def _static_qos() -> list[Any]:
    """``/tf_static``'s QoS as ROS publishes it: reliable, transient local (latched), keep last 1."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    inf = QosTime(2147483647, 4294967295)  # rosbag2's "infinite"
    return [
        Qos(
            QosHistory.KEEP_LAST,
            1,
            QosReliability.RELIABLE,
            QosDurability.TRANSIENT_LOCAL,
            inf,
            inf,
            QosLiveliness.AUTOMATIC,
            inf,
            False,
        )
    ]


def _need(log: Mapping[str, Any], key: str) -> np.ndarray:
    if key not in log:
        raise ValueError(
            f"the log has no '{key}': a bag needs the 3-D state of simulate(sc, full_state=True) (bioform run --rosbag)"
        )
    return np.asarray(log[key])


def topics_of(log: Mapping[str, Any], sensing: str, msgs: _Messages, start_ns: int = 0) -> list[_Topic]:
    """Every topic of the bag of ``log`` (a ``simulate(..., full_state=True)`` log or its ``log.npz``),
    templates built and fields located, in the order a sample's messages are written."""
    ts = _need(log, "t_state")
    K = int(np.asarray(log["t"]).shape[0])
    n = int(_need(log, "pose_3d").shape[1])
    S = K + 1  # state samples: the log rows and the end
    ns = start_ns + np.rint(ts * 1e9).astype(np.int64)
    sec, nsec = ns // 1_000_000_000, ns % 1_000_000_000
    pose3, twist3 = np.asarray(log["pose_3d"], float), np.asarray(log["twist_3d"], float)
    q = quat_of_rpy(pose3[..., 3:6])  # (S, n, 4) w x y z
    leader = np.asarray(log["leader_state"], float)  # (S, 5)
    sign = np.asarray(log["wheel_sign"], float)
    names = np.asarray(log["wheel_joints"]).astype(str)
    wa, ws = np.asarray(log["wheel_angle"], float), np.asarray(log["wheel_speed"], float)
    wheels = bool(np.isfinite(wa).any())
    imu = "imu_gyro" in log
    cmd, tau = np.asarray(log["cmd"], float), np.asarray(log["tau"], float)
    ep, ev = np.asarray(log["est_pose"], float), np.asarray(log["est_vel"], float)
    odo = sensing == "odometry"
    op, ov = (np.asarray(log["odom_pose"], float), np.asarray(log["odom_vel"], float)) if odo else (None, None)
    # the headings' quaternions (the leader's; each follower's estimate of it and, with odometry, its own
    # dead reckoning): one call of quat_of_yaw for all, each a row block of its result
    yaws = [leader[:, 2]] + [ep[:, i, 2] for i in range(n)] + ([op[:, i, 2] for i in range(n)] if odo else [])
    heads = quat_of_yaw(np.concatenate(yaws))
    lq = heads[:S]
    eqs = [heads[S + i * K : S + (i + 1) * K] for i in range(n)]
    oqs = [heads[S + (n + i) * K : S + (n + i + 1) * K] for i in range(n)] if odo else []
    g, a = (np.asarray(log["imu_gyro"], float), np.asarray(log["imu_accel"], float)) if imu else (None, None)
    # the wheels' numbers as the joints state them (each joint's sign applied; sign · x, numpy's product)
    jp, jv, jt = (wa * sign, ws * sign, tau * sign) if wheels else (None, None, None)
    # every array the numbers are read from, by name: a layout's templates and field offsets are kept with
    # those names (_LAYOUTS: the same topics, frames and joints) and bound to this log's arrays
    named = {"sec": sec, "nsec": nsec, "pose3": pose3, "q": q, "twist3": twist3, "leader": leader, "lq": lq}
    named |= {"cmd": cmd, "tau": tau, "ep": ep, "ev": ev, "op": op, "ov": ov, "g": g, "a": a}
    named |= {"jp": jp, "jv": jv, "jt": jt} | {f"eq{i}": x for i, x in enumerate(eqs)}
    named |= {f"oq{i}": x for i, x in enumerate(oqs)}
    # the layout (not K: the rows' slices are kept as "S" and "K", bound to this log's)
    key = (id(msgs.store), n, odo, wheels, imu, names.shape, tuple(names.ravel().tolist()))
    layout = _LAYOUTS.get(key)
    if layout is None:
        topics = _build_topics(msgs, named, K, n, odo, wheels, imu, names, sign)
        layout = _layout_of(topics, named, K)
        if layout is not None:
            _LAYOUTS[key] = layout
            while len(_LAYOUTS) > _LAYOUTS_KEPT:
                _LAYOUTS.pop(next(iter(_LAYOUTS)), None)
    else:
        topics = []
        rows = {"S": slice(0, S), "K": slice(0, K)}
        for name, msgtype, m, template, fields in layout:
            bound = []
            for off, dt, nm, kept in fields:
                idx = tuple(rows[x] if type(x) is str else x for x in kept)
                bound.append((off, dt, named[nm][idx] if idx else named[nm], (named[nm], idx)))
            topics.append(_Topic(name, msgtype, np.arange(S if m == "S" else K), template, bound))
    for tp in topics if layout is not None else ():
        tp.layout = key
    if wheels:  # at T no torque interval ends: the last joint state has positions and rates only
        for tp in topics:
            if tp.name.endswith("/joint_states"):  # /fI/joint_states
                i = int(tp.name.split("/")[1][1:]) - 1
                sg, jn = sign[i], [str(x) for x in names[i]]
                last = msgs.joint_state(msgs.time(int(sec[K]), int(nsec[K])), jn, sg * wa[K, i], sg * ws[K, i], [])
                tp.extra.append((K, bytes(msgs.store.serialize_cdr(last, tp.msgtype))))
    return topics


#: the templates and field offsets of the layouts built lately (:func:`topics_of`), most recent last
_LAYOUTS: dict[tuple, list[tuple[str, str, str, np.ndarray, list[tuple[int, str, str, tuple]]]]] = {}
_LAYOUTS_KEPT = 8


def _layout_of(topics: list[_Topic], named: Mapping[str, Any], K: int) -> list[tuple] | None:
    """``topics`` as :data:`_LAYOUTS` keeps them: per topic its name, type, message count (``"S"``: the
    ``K + 1`` samples, ``"K"``: the log rows), template and fields ``(offset, dtype, array name, idx)``, the
    slices of the rows in ``idx`` kept as ``"S"`` and ``"K"``; None where a field's array is not one of
    ``named`` or two names are one array (the next log's may be two)."""
    rows = {(0, K + 1, None): "S", (0, K, None): "K"}
    ids = {id(v): k for k, v in named.items() if v is not None}
    if len(ids) != sum(v is not None for v in named.values()):
        return None
    out = []
    for tp in topics:
        fields = []
        for off, dt, _, (arr, idx) in tp.fields:
            if id(arr) not in ids:
                return None
            kept = tuple(rows.get((x.start, x.stop, x.step), x) if type(x) is slice else x for x in idx)
            fields.append((off, dt, ids[id(arr)], kept))
        out.append((tp.name, tp.msgtype, "S" if tp.rows.size == K + 1 else "K", tp.template, fields))
    return out


def _build_topics(
    msgs: _Messages,
    named: Mapping[str, Any],
    K: int,
    n: int,
    odo: bool,
    wheels: bool,
    imu: bool,
    names: np.ndarray,
    sign: np.ndarray,
) -> list[_Topic]:
    """The topics of :func:`topics_of` built by ``rosbags`` (one message serialised per topic, with
    marker values located in it), their numbers bound to the arrays ``named``."""
    S = K + 1
    all_rows, log_rows = slice(0, S), slice(0, K)  # the rows a topic's numbers come from (views, not copies)
    sec, nsec, pose3, q, twist3, leader, lq = (
        named[k] for k in ("sec", "nsec", "pose3", "q", "twist3", "leader", "lq")
    )
    cmd, tau, ep, ev, op, ov, g, a = (named[k] for k in ("cmd", "tau", "ep", "ev", "op", "ov", "g", "a"))
    jp, jv, jt = named["jp"], named["jv"], named["jt"]
    eqs = [named[f"eq{i}"] for i in range(n)]
    oqs = [named[f"oq{i}"] for i in range(n)] if odo else []
    topics: list[_Topic] = []

    def build(name: str, msgtype: str, rows: slice, make) -> _Topic:
        mk = _Markers()
        stamp = msgs.time(mk.int32("<i4", sec, rows), mk.int32("<u4", nsec, rows))
        msg = make(mk, stamp, rows)
        raw = msgs.store.serialize_cdr(msg, msgtype)
        tp = _Topic(
            name, msgtype, np.arange(rows.stop), np.frombuffer(bytes(raw), np.uint8).copy(), mk.locate(bytes(raw))
        )
        topics.append(tp)
        return tp

    def stamp_of(mk: _Markers, rows: slice) -> Any:
        return msgs.time(mk.int32("<i4", sec, rows), mk.int32("<u4", nsec, rows))

    build("/clock", "rosgraph_msgs/msg/Clock", all_rows, lambda mk, st, r: msgs.clock(st))

    def tf(mk: _Markers, st: Any, r: slice) -> Any:
        out = []
        for i in range(n):
            f = f"f{i + 1}"
            xyz = tuple(mk.f64(pose3, r, i, c) for c in range(3))
            wxyz = tuple(mk.f64(q, r, i, c) for c in range(4))
            out.append(msgs.transform(st if i == 0 else stamp_of(mk, r), f"{f}/odom", f"{f}/base_link", xyz, wxyz))
        xyz = (mk.f64(leader, r, 0), mk.f64(leader, r, 1), 0.0)
        wxyz = tuple(mk.f64(lq, r, c) for c in range(4))
        out.append(msgs.transform(stamp_of(mk, r), "leader/odom", "leader/base_link", xyz, wxyz))
        return msgs.tf(out)

    build("/tf", "tf2_msgs/msg/TFMessage", all_rows, tf)
    build(
        "/leader/ground_truth/odom",
        "nav_msgs/msg/Odometry",
        all_rows,
        lambda mk, st, r: msgs.odometry(
            st,
            "leader/odom",
            "leader/base_link",
            (mk.f64(leader, r, 0), mk.f64(leader, r, 1), 0.0),
            tuple(mk.f64(lq, r, c) for c in range(4)),
            (mk.f64(leader, r, 3), 0.0, 0.0),
            (0.0, 0.0, mk.f64(leader, r, 4)),
        ),
    )
    for i in range(n):
        f = f"f{i + 1}"
        build(
            f"/{f}/ground_truth/odom",
            "nav_msgs/msg/Odometry",
            all_rows,
            lambda mk, st, r, i=i, f=f: msgs.odometry(
                st,
                f"{f}/odom",
                f"{f}/base_link",
                tuple(mk.f64(pose3, r, i, c) for c in range(3)),
                tuple(mk.f64(q, r, i, c) for c in range(4)),
                tuple(mk.f64(twist3, r, i, c) for c in range(3)),
                tuple(mk.f64(twist3, r, i, c) for c in range(3, 6)),
            ),
        )
        if odo:
            oq = oqs[i]
            build(
                f"/{f}/odom",
                "nav_msgs/msg/Odometry",
                log_rows,
                lambda mk, st, r, i=i, f=f, op=op, ov=ov, oq=oq: msgs.odometry(
                    st,
                    f"{f}/odom",
                    f"{f}/base_link",
                    (mk.f64(op, r, i, 0), mk.f64(op, r, i, 1), 0.0),
                    tuple(mk.f64(oq, r, c) for c in range(4)),
                    (mk.f64(ov, r, i, 0), 0.0, 0.0),
                    (0.0, 0.0, mk.f64(ov, r, i, 1)),
                ),
            )
        mk_cmd = _Markers()
        raw = msgs.store.serialize_cdr(
            msgs.twist((mk_cmd.f64(cmd, slice(None), i, 0), 0.0, 0.0), (0.0, 0.0, mk_cmd.f64(cmd, slice(None), i, 1))),
            "geometry_msgs/msg/Twist",
        )
        topics.append(
            _Topic(
                f"/{f}/cmd_vel",
                "geometry_msgs/msg/Twist",
                np.arange(K),
                np.frombuffer(bytes(raw), np.uint8).copy(),
                mk_cmd.locate(bytes(raw)),
            )
        )
        jn = [str(x) for x in names[i]]
        if wheels:  # its last message (at T): topics_of
            build(
                f"/{f}/joint_states",
                "sensor_msgs/msg/JointState",
                log_rows,
                lambda mk, st, r, i=i, jn=jn: msgs.joint_state(
                    st,
                    jn,
                    [mk.f64(jp, r, i, c) for c in range(2)],
                    [mk.f64(jv, r, i, c) for c in range(2)],
                    [mk.f64(jt, r, i, c) for c in range(2)],
                ),
            )
        else:  # no wheels (the ideal plant): the applied torques only
            build(
                f"/{f}/joint_states",
                "sensor_msgs/msg/JointState",
                log_rows,
                lambda mk, st, r, i=i, jn=jn: msgs.joint_state(
                    st, jn, [], [], [mk.f64(tau, r, i, c) for c in range(2)]
                ),
            )
        if imu:
            build(
                f"/{f}/imu",
                "sensor_msgs/msg/Imu",
                all_rows,
                lambda mk, st, r, i=i, f=f, g=g, a=a: msgs.imu(
                    st,
                    f"{f}/imu_link",
                    tuple(mk.f64(g, r, i, c) for c in range(3)),
                    tuple(mk.f64(a, r, i, c) for c in range(3)),
                ),
            )
        eq = eqs[i]
        build(
            f"/{f}/leader_estimate",
            "nav_msgs/msg/Odometry",
            log_rows,
            lambda mk, st, r, i=i, f=f, eq=eq: msgs.odometry(
                st,
                "world",
                f"{f}/leader_estimate",
                (mk.f64(ep, r, i, 0), mk.f64(ep, r, i, 1), 0.0),
                tuple(mk.f64(eq, r, c) for c in range(4)),
                (mk.f64(ev, r, i, 0), 0.0, 0.0),
                (0.0, 0.0, mk.f64(ev, r, i, 1)),
            ),
        )
    return topics


def _static_tf(log: Mapping[str, Any], msgs: _Messages, start_ns: int) -> bytes:
    """``/tf_static``: ``world → fI/odom`` and ``world → leader/odom`` (identity: the odometry frames
    are the world's), ``fI/base_link → fI/imu_link`` (the IMU site at the axle midpoint) with an IMU."""
    n = int(np.asarray(log["pose_3d"]).shape[1])
    t0 = start_ns + int(np.rint(float(np.asarray(log["t_state"])[0]) * 1e9))
    axle = None
    if "imu_gyro" in log:
        axle = tuple(tuple(float(v) for v in row) for row in np.asarray(log.get("axle", np.zeros((n, 3))), float))
    return _static_tf_of(msgs, n, t0, axle)


@functools.lru_cache(maxsize=64)
def _static_tf_of(msgs: _Messages, n: int, t0: int, axle: tuple | None) -> bytes:
    """:func:`_static_tf` of ``n`` followers at ``t0`` ns (``axle``: each IMU's place, None: no IMU), made
    once per process (a sweep's bags state the same)."""
    st = msgs.time(t0 // 1_000_000_000, t0 % 1_000_000_000)
    one = (1.0, 0.0, 0.0, 0.0)
    out = [msgs.transform(st, "world", f"f{i + 1}/odom", (0.0, 0.0, 0.0), one) for i in range(n)]
    out.append(msgs.transform(st, "world", "leader/odom", (0.0, 0.0, 0.0), one))
    if axle is not None:
        out += [msgs.transform(st, f"f{i + 1}/base_link", f"f{i + 1}/imu_link", axle[i], one) for i in range(n)]
    return bytes(msgs.store.serialize_cdr(msgs.tf(out), "tf2_msgs/msg/TFMessage"))


def write_bag(
    result: Any,
    path: str | Path,
    *,
    distro: str = DEFAULT_DISTRO,
    start_ns: int = 0,
    overwrite: bool = False,
) -> BagInfo:
    """Write the run ``result`` (a :class:`~bioform_mj.run.simulate.RunResult` of ``simulate(sc, full_state=True)``)
    as the rosbag2 folder ``path`` (``metadata.yaml`` and ``<name>.mcap``), complete or not at all.

    ``distro``: the ROS 2 distribution whose message definitions and type hashes the bag carries
    (:data:`DISTROS`); ``start_ns``: the stamp of t = 0, ns since the epoch (0: simulated time from 0,
    as ``/clock`` of a simulator); ``overwrite``: replace an existing ``path`` (else ``FileExistsError``).
    The folder is written under a temporary name beside ``path`` and renamed when complete.
    """
    if distro not in DISTROS:
        raise InputError(f"unknown ROS 2 distribution '{distro}' (expected one of: {', '.join(DISTROS)})")
    if start_ns < 0:
        raise InputError(f"start_ns must be >= 0 ns, got {start_ns}")
    check_available()
    t0 = time.perf_counter()
    log = result.log
    _need(log, "t_state")  # before anything is written
    summary = getattr(result, "summary", {}) or {}
    sensing = str(summary.get("sensing", "truth"))
    robots = robots_stated(result)
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (overwrite=True replaces it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _fresh_tmp(path)
    try:
        counts = _write(tmp, log, summary, sensing, distro, start_ns, robots, name=path.name)
        if path.exists():
            shutil.rmtree(path)
        os.replace(tmp, path)
    except OSError as exc:
        from bioform_mj.core.errors import WriteFailed

        raise WriteFailed(str(path), exc) from exc
    finally:
        if os.path.lexists(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
    return BagInfo(path, sum(counts.values()), counts, distro, time.perf_counter() - t0)


def _fresh_tmp(path: Path) -> Path:
    """A name beside ``path`` that does not exist, ``.NAME.XXXXXXXXXXXX.tmp`` (the pattern of
    :func:`bioform_mj.outputs.files.atomic_path`'s temporaries, which an interrupted run's clean-up
    removes): the bag's folder is written there, its MCAP file already under its final name, and renamed
    to ``path`` when complete (one folder created and renamed; no folder around it to remove: on ext4
    that ``rmdir`` waited for the journal, 0.3-8 ms a bag)."""
    import secrets

    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        if not os.path.lexists(tmp):
            return tmp
    raise FileExistsError(f"no free temporary name beside {path}")


def robots_stated(result: Any) -> list[dict[str, Any]]:
    """What the bag's ``custom_data`` says of each follower ``fI``'s robot, so that ``bioform robot fit``
    reads the bag without flags: its namespace, robot mapping (``robot``: the scenario's table of it) and
    what ``/fI/joint_states``' ``effort`` is: ``"applied"`` (the torque on the joint: torque motors, the
    ideal plant) or ``"command"`` (the torque commanded to the robot file's ``<dcmotor>`` drives through
    the mapping's ``driver``: the log's ``tau``; the motor delivers less along its torque–speed line and,
    with the voltage driver, less by its back-EMF; design §8.2); ``effort_interval_s = [a, b]``: each
    effort is the mean torque over ``[stamp + a, stamp + b)`` s (design §9, log rows: the row's control steps,
    each command held for its period; the fit holds it there); ``disturbance``: the scenario's disturbance
    forces, where the run had them (no robot model holds them)."""
    sc = getattr(result, "scenario", None)
    sim = getattr(sc, "sim", None)
    log = getattr(result, "log", {}) or {}
    n = int(np.asarray(log["pose_3d"]).shape[1]) if "pose_3d" in log else 0
    refs = tuple(getattr(getattr(sc, "plant", None), "robots", ()) or ())
    kind = str(getattr(getattr(sc, "plant", None), "kind", ""))
    out = []
    for i in range(n):
        ref = refs[i] if len(refs) == n else (refs[0] if refs else None)
        dc = ref is not None and kind == "mujoco" and ref.motor == "dc"
        entry: dict[str, Any] = {
            "namespace": f"f{i + 1}",
            "effort": "command" if dc else "applied",
        }
        dist = getattr(sc, "disturbance", None)
        if dist is not None and kind == "mujoco" and (np.any(dist.bias) or np.any(dist.amp)):
            # forces on the body that no robot model has: robot fit says its numbers are biased by them
            entry["disturbance"] = {"bias": [float(v) for v in dist.bias], "amp": [float(v) for v in dist.amp]}
        if sim is not None:  # a row's torque: the mean of the commands of its control steps, each held one period
            entry["effort_interval_s"] = [float(sim.control_dt - sim.log_dt), float(sim.control_dt)]
        if ref is not None and kind == "mujoco":
            entry["robot"] = ref.to_table()
            entry["motor"] = "dc" if dc else "ideal"
            if dc:
                entry["driver"] = ref.driver or "current"
        out.append(entry)
    return out


def _write(
    path: Path,
    log: Mapping[str, Any],
    summary: Mapping[str, Any],
    sensing: str,
    distro: str,
    start_ns: int,
    robots: list[dict[str, Any]] | None = None,
    name: str | None = None,
):
    """Write the bag folder ``path`` (must not exist); returns ``{topic: messages}``. ``robots``:
    :func:`robots_stated`, written into ``custom_data`` once; ``name``: the bag's name (its MCAP file
    ``NAME.mcap``; default: the folder's)."""
    from rosbags.rosbag2 import StoragePlugin

    msgs = _messages(distro)
    topics = topics_of(log, sensing, msgs, start_ns)
    static = _static_tf(log, msgs, start_ns)
    with bulk_writer(path, name=name, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as w:
        w.set_custom_data(
            "bioform_mj",
            json.dumps(
                {
                    "scenario": summary.get("scenario"),
                    "method": summary.get("method"),
                    "plant": summary.get("plant"),
                    "sensing": sensing,
                    "ros_distro": distro,
                    "followers": int(np.asarray(log["pose_3d"]).shape[1]),
                    "robots": robots or [],
                },
                sort_keys=True,
            ),
        )
        conns = {}
        c_static = w.add_connection(
            "/tf_static", "tf2_msgs/msg/TFMessage", typestore=msgs.store, offered_qos_profiles=_static_qos()
        )
        for tp in topics:
            if tp.name not in conns:
                conns[tp.name] = w.add_connection(tp.name, tp.msgtype, typestore=msgs.store)
        ts = np.asarray(log["t_state"], float)
        stamps = start_ns + np.rint(ts * 1e9).astype(np.int64)
        w.write_samples(c_static, static, topics, conns, stamps)
        counts = {"/tf_static": 1} | {tp.name: len(tp.rows) + len(tp.extra) for tp in topics}
    return counts
