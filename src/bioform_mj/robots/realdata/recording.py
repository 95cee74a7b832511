"""A real robot's recording read into arrays (issue 29, design §8: the wheel torques and what they did).

Three sources, one result (:class:`Recording`):

- a rosbag2 folder (``metadata.yaml`` + MCAP or SQLite storage) or a bare ``.mcap`` file, read with
  ``rosbags`` (the optional ``ros`` extra). Messages are streamed one at a time (a bag far larger than
  memory is never loaded whole) and only the fields the fit uses are kept:
  ``sensor_msgs/JointState`` (the two wheel joints' position, rad; velocity, rad/s; effort = the applied
  torque, N·m), ``nav_msgs/Odometry`` (pose in the odometry frame; twist in the body frame, m/s and rad/s)
  and ``sensor_msgs/Imu`` (angular velocity, rad/s), on the topics given (default ``/joint_states``,
  ``/odom``, ``/imu``; odometry and IMU optional);
- a CSV file with named columns, as a fallback: ``time`` (s), ``<joint>.position`` (rad),
  ``<joint>.velocity`` (rad/s), ``<joint>.effort`` (N·m) for both wheel joints, optional ``odom.vx``
  (m/s), ``odom.wz`` and ``imu.wz`` (rad/s).

Times are the messages' header stamps (the bag's receive time where a stamp is zero), shifted so that the
first joint state is at t = 0. Bad input raises :class:`~bioform_mj.core.errors.InputError` (exit 2) naming
what is there: a missing topic or joint, time that goes backwards, a NaN or infinite effort or speed, a
file that cannot be read.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bioform_mj.core.errors import InputError

__all__ = [
    "PAUSE_NOTE",
    "STILL_RIM_SPEED",
    "Recording",
    "Topics",
    "chunk_starts",
    "pauses",
    "read_recording",
    "still_note",
]

#: a recording whose largest wheel rim speed is below this (m/s) hardly moved the robot: measured 12.5 mm/s
#: on a tb3 held by a dragging caster (0.025 N·m, program 5), 355 mm/s without the drag
STILL_RIM_SPEED = 0.02


@dataclass(frozen=True)
class Topics:
    """Topic names of a recording (rosbag2/MCAP); ``None``: the default, under ``namespace`` if one is given
    (``/NS/joint_states``, ``/NS/odom`` — else ``/NS/ground_truth/odom``, the truth of this project's own
    bags —, ``/NS/imu``). Without a namespace and without ``/joint_states`` in the recording, the one robot
    namespace whose ``…/joint_states`` the recording has is taken (:func:`resolve_topics`)."""

    joint_states: str | None = None
    odom: str | None = None
    imu: str | None = None
    namespace: str | None = None


def resolve_topics(have: dict[str, str], topics: Topics, name: str) -> tuple[Topics, list[str]]:
    """The topic names to read from a recording whose topics are ``have`` (topic → message type), and notes
    saying what was chosen. A namespace is the one given, or found: when neither ``--joint-states-topic``
    nor a namespace is given and the recording has no ``/joint_states``, the single ``/NS/joint_states``
    (``sensor_msgs/msg/JointState``) is taken; several raise :class:`InputError` listing them."""
    notes: list[str] = []
    ns = (topics.namespace or "").strip("/") or None
    if ns is None and topics.joint_states is None and "/joint_states" not in have:
        found = sorted(
            t
            for t, typ in have.items()
            if t.endswith("/joint_states") and t.count("/") >= 2 and typ == "sensor_msgs/msg/JointState"
        )
        if len(found) > 1:
            nss = ", ".join(t[1 : -len("/joint_states")] for t in found)
            raise InputError(
                f"{name}: no '/joint_states' but the joint states of {len(found)} robots "
                f"({', '.join(found)}): choose one with --robot-ns (one of: {nss})"
            )
        if found:
            ns = found[0][1 : -len("/joint_states")]
            notes.append(f"robot namespace '/{ns}' taken: the recording's only joint states are {found[0]}")
    pre = f"/{ns}" if ns else ""
    odom = topics.odom
    if odom is None:
        odom = f"{pre}/odom"
        if ns and odom not in have and f"{pre}/ground_truth/odom" in have:
            odom = f"{pre}/ground_truth/odom"
            notes.append(f"odometry from {odom} (no {pre}/odom: a simulation's truth, this project's own bag)")
    out = Topics(
        topics.joint_states or f"{pre}/joint_states",
        odom,
        topics.imu or f"{pre}/imu",
        ns,
    )
    return out, notes


@dataclass
class Recording:
    """The arrays of one recording (SI units; times in s from the first joint state).

        ``t``: joint-state times (n,); ``position``, ``velocity``, ``effort``: (n, 2), the left and right
        wheel joints in that order (rad, rad/s, N·m). ``odom_t``/``odom_twist``: odometry times (m,) and the
        body-frame twist (m, 6: vx, vy, vz, wx, wy, wz in m/s and rad/s); ``odom_pose``: (m, 7) x, y, z (m),
        qw, qx, qy, qz. ``imu_t``/``imu_gyro``: IMU times and angular velocity (k, 3), rad/s. Absent streams
        are empty arrays. ``source``: the file read; ``notes``: what was assumed; ``stated``: what a bag of this
    project's export says of the recorded robot (``metadata.yaml``'s ``custom_data.bioform_mj``, its
    ``robots`` entry of the namespace read: ``effort`` ``"applied"`` or ``"command"``, ``motor``, ``driver``,
    ``robot``; empty for another bag).
    """

    source: str
    joints: tuple[str, str]
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    odom_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    odom_twist: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    odom_pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    imu_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    imu_gyro: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    notes: list[str] = field(default_factory=list)
    stated: dict = field(default_factory=dict)  # what the bag says of its robot (this project's export)
    others: dict = field(default_factory=dict)  # other joints asked for: name -> (n, 2) position, velocity (NaN: none)

    def effort_at(self, t: np.ndarray) -> np.ndarray:
        """The wheel torques (N·m, (len(t), 2)) at times ``t`` (s), interpolated linearly between the
        recorded efforts: a real robot's effort is a sample of a continuous torque (on the tb3 test recording
        a zero-order hold, the torque held until the next sample, biased the yaw inertia by 6 %). Where the bag
        states the interval each effort is the mean torque of (this project's export:
        ``stated["effort_interval_s"] = [a, b]``, from ``a`` to ``b`` s about its stamp: the log row's mean of the
        commands held over their control periods), each effort is held over its interval."""
        span = self.stated.get("effort_interval_s")
        if span is not None and len(self.t) > 1:
            k = np.clip(np.searchsorted(self.t + float(span[0]), t, side="right") - 1, 0, len(self.t) - 1)
            return self.effort[k]
        return np.stack([np.interp(t, self.t, self.effort[:, i]) for i in range(2)], axis=1)

    @property
    def duration(self) -> float:
        """Length of the joint-state stream, s."""
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0

    def window(self, t0: float, t1: float) -> Recording:
        """The part of the recording with ``t0 <= t <= t1`` (s), every stream cut alike."""

        def cut(t: np.ndarray) -> np.ndarray:
            return (t >= t0) & (t <= t1)

        j, o, i = cut(self.t), cut(self.odom_t), cut(self.imu_t)
        return Recording(
            self.source,
            self.joints,
            self.t[j],
            self.position[j],
            self.velocity[j],
            self.effort[j],
            self.odom_t[o],
            self.odom_twist[o],
            self.odom_pose[o],
            self.imu_t[i],
            self.imu_gyro[i],
            list(self.notes),
            dict(self.stated),
            {k: v[j] for k, v in self.others.items()},
        )


#: most names an error line lists (a JointState of 100,000 names, a CSV header of 10^7 columns: a line of 1 MB and of
#: 119 MB before, issue 28)
LIST_MAX = 20


def _listed(names: list[str]) -> str:
    """``names`` quoted and comma-separated, at most :data:`LIST_MAX` of them and how many more."""
    shown = ", ".join(repr(n) for n in names[:LIST_MAX])
    return shown + (f" and {len(names) - LIST_MAX} more" if len(names) > LIST_MAX else "")


def _listed_some(sample: list[str], total: int) -> str:
    """:func:`_listed` of ``sample``, the first names of ``total`` (only the first :data:`LIST_MAX` are kept)."""
    shown = ", ".join(repr(n) for n in sample[:LIST_MAX])
    more = max(total, len(sample)) - min(len(sample), LIST_MAX)
    return shown + (f" and {more} more" if more > 0 else "")


def _twice(names: list[str]) -> str | None:
    """The first name that ``names`` holds more than once (None: none does)."""
    seen: set[str] = set()
    for n in names:
        if n in seen:
            return n
        seen.add(n)
    return None


def _check_stream(name: str, t: np.ndarray, what: str) -> None:
    """Time must not go backwards; raise naming the first place it does."""
    if len(t) > 1:
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0])
            raise InputError(
                f"{name}: time goes backwards on {what} at message {k + 1}: {t[k]:.9f} s then {t[k + 1]:.9f} s "
                "(a recording must be in time order; re-record or sort it)"
            )


def _check_finite(name: str, t: np.ndarray, arr: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        k, col = np.argwhere(bad)[0]
        raise InputError(f"{name}: {what} is {arr[k, col]} at t = {t[k]:.6g} s (column {col}): NaN or infinite")


def _validate(rec: Recording, lines: np.ndarray | None = None) -> Recording:
    """Refuse what cannot be used; ``lines``: each joint state's line in a CSV file (for the messages)."""
    name = rec.source
    if len(rec.t) < 10:
        raise InputError(f"{name}: only {len(rec.t)} joint states of {rec.joints[0]}/{rec.joints[1]}: too short to fit")
    for t, what in ((rec.t, "the joint states"), (rec.odom_t, "the odometry"), (rec.imu_t, "the IMU")):
        if len(t) and not np.all(np.isfinite(t)):  # a NaN time passed the order check: an internal error later
            k = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputError(f"{name}: the time of {what} at message {k + 1} is {t[k]}: NaN or infinite")
    _check_stream(name, rec.t, "the joint states")
    _check_stream(name, rec.odom_t, "the odometry")
    _check_stream(name, rec.imu_t, "the IMU")
    _check_finite(name, rec.t, rec.effort, "a wheel effort (applied torque)")
    _check_finite(name, rec.t, rec.velocity, "a wheel velocity")
    _check_finite(name, rec.t, rec.position, "a wheel position")
    if len(rec.odom_t):
        _check_finite(name, rec.odom_t, rec.odom_twist, "an odometry twist")
    if len(rec.imu_t):
        _check_finite(name, rec.imu_t, rec.imu_gyro, "an IMU angular velocity")
    if float(rec.t[-1] - rec.t[0]) <= 0:
        raise InputError(f"{name}: the joint states span no time")
    _check_pauses(rec, lines)
    return rec


#: longest pause between two joint states a recording may hold, s: beyond it the file is two recordings joined (or a
#: time column in other units); a CSV with 1e11 s between rows was fitted over its interpolated gap (issue 28)
PAUSE_MAX_S = 600.0
#: a pause: a gap between joint states longer than this many median sample periods and than :data:`PAUSE_MIN_S`
PAUSE_FACTOR = 10.0
PAUSE_MIN_S = 0.1
#: how the note on pauses begins (the CLI says it in a ``warning:`` line)
PAUSE_NOTE = "the joint states pause"


def pauses(t: np.ndarray) -> np.ndarray:
    """Indices ``k`` where the joint states pause between ``t[k]`` and ``t[k + 1]`` (s): the gap is longer than
    :data:`PAUSE_FACTOR` median sample periods and :data:`PAUSE_MIN_S` (dropped messages; nothing was measured
    there, a fit's chunk must not span it)."""
    if len(t) < 3:
        return np.zeros(0, int)
    d = np.diff(t)
    period = float(np.median(d))
    return np.flatnonzero(d > max(PAUSE_FACTOR * period, PAUSE_MIN_S))


def _check_pauses(rec: Recording, lines: np.ndarray | None) -> None:
    """Refuse a pause above :data:`PAUSE_MAX_S` naming where it is; note the shorter ones (dropped messages)."""
    ks = pauses(rec.t)
    if not ks.size:
        return
    d = np.diff(rec.t)
    k = int(ks[np.argmax(d[ks])])
    where = f"lines {int(lines[k])} and {int(lines[k + 1])}" if lines is not None else f"messages {k + 1} and {k + 2}"
    gap = f"{d[k]:.3g} s between {where} (t = {rec.t[k]:.6g} s and {rec.t[k + 1]:.6g} s)"
    period = float(np.median(d))
    if d[k] > PAUSE_MAX_S:
        raise InputError(
            f"{rec.source}: the joint states pause for {gap}, the samples otherwise every {period:.3g} s (median): "
            f"above the {PAUSE_MAX_S:g} s a recording may pause (two recordings joined, or times not in seconds?); "
            "fit each part as a recording of its own"
        )
    rec.notes.append(
        f"{PAUSE_NOTE} {ks.size} time(s) (nothing recorded for over {PAUSE_FACTOR:g} sample periods; the "
        f"longest {gap}): the fit's chunks skip the pauses, a replay interpolates the efforts across them"
    )


def chunk_starts(rec: Recording, length: float, max_chunks: int) -> np.ndarray:
    """Indices ``c`` of the chunks ``[t[0] + c·length, t[0] + (c + 1)·length]`` (s) a fit simulates: at most
    ``max_chunks``, spread evenly over those that span no pause (:func:`pauses`); without pauses every chunk of
    the recording is a candidate. Candidates are counted as ranges, never listed (a long recording has many)."""
    t0 = float(rec.t[0])
    n_all = int((rec.t[-1] - t0 + 1e-9) // length)
    lo, hi = [0], []
    for k in pauses(rec.t):  # the chunks overlapping the open gap (t[k], t[k + 1]) are left out
        hi.append(min(n_all, math.floor((rec.t[k] - t0) / length)))
        lo.append(max(0, math.ceil((rec.t[k + 1] - t0) / length)))
    hi.append(n_all)
    ranges = [(a, b) for a, b in zip(lo, hi, strict=True) if b > a]
    sizes = np.array([b - a for a, b in ranges], dtype=np.int64)
    n_good = int(sizes.sum())
    if n_good == 0:
        return np.zeros(0, int)
    picks = np.unique(np.round(np.linspace(0, n_good - 1, min(n_good, max_chunks))).astype(np.int64))
    ends = np.cumsum(sizes)
    j = np.searchsorted(ends, picks, side="right")
    return np.array([ranges[i][0] + int(p - (ends[i - 1] if i else 0)) for i, p in zip(j, picks, strict=True)])


def read_recording(
    path: str | Path, joints: tuple[str, str], topics: Topics | None = None, others: tuple[str, ...] = ()
) -> Recording:
    """Read ``path`` (rosbag2 folder, ``.mcap``/``.db3`` file, or ``.csv``) for the wheel joints ``joints``
    (left, right), and of a bag's joint states also the joints ``others`` where they are there (``Recording.
    others``: the robot's caster swivels, whose angles set a chunk's start). Raises :class:`InputError` (exit 2)
    for anything that cannot be used (module docstring)."""
    from bioform_mj.robots.sanity import not_regular

    p = Path(path)
    if not p.exists():
        raise InputError(f"--bag {p}: no such file or folder")
    # a FIFO as the recording, or as a rosbag2 folder's metadata.yaml or storage file, blocked the reader forever
    for f in sorted(p.iterdir()) if p.is_dir() else [p]:  # (issue 28); a device is never read either
        if not f.is_dir() and (why := not_regular(f)):
            raise InputError(f"--bag {p}: {why}")
    if p.is_file() and p.suffix.lower() == ".csv":
        rec, lines = _read_csv(p, joints)
        return _validate(rec, lines)
    if p.is_dir():
        _check_metadata(p / "metadata.yaml")
    return _validate(_read_bag(p, joints, topics or Topics(), tuple(others)))


#: largest rosbag2 ``metadata.yaml`` read, MB (rosbag2 writes a few kB; the YAML is parsed whole)
METADATA_MAX_MB = 16


def _check_metadata(meta: Path) -> None:
    """Refuse a rosbag2 folder's ``metadata.yaml`` above :data:`METADATA_MAX_MB` MB or holding YAML aliases
    (``*name``): rosbag2 writes none, and nine lines of them in ``custom_data`` expand to 9^10 strings (the read
    hung past 120 s, trust5). Scanned as tokens, nothing built."""
    if not meta.is_file():
        return  # the reader says what is missing
    if (size := meta.stat().st_size) > METADATA_MAX_MB * 10**6:
        raise InputError(f"{meta}: {size / 1e6:.0f} MB, above the {METADATA_MAX_MB} MB a rosbag2 metadata file may be")
    try:  # ruamel.yaml: rosbags' own YAML library (the ros extra)
        from ruamel.yaml import YAML
        from ruamel.yaml.error import YAMLError
        from ruamel.yaml.tokens import AliasToken, AnchorToken
    except ImportError:  # pragma: no cover - without the extra the reader says what to install
        return
    try:
        with open(meta, encoding="utf-8") as fh:
            for tok in YAML(typ="safe", pure=True).scan(fh):
                if isinstance(tok, (AliasToken, AnchorToken)):
                    raise InputError(
                        f"{meta}: YAML anchors/aliases (&name, *name), which rosbag2 never writes: a few lines of them "
                        "can expand to gigabytes; not read"
                    )
    except YAMLError as exc:
        raise InputError(f"{meta}: not YAML ({' '.join(str(exc).split())[:200]})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{meta}: cannot read ({exc})") from None


# ------------------------------------------------------------------ rosbag2 / MCAP
def _stamp_s(msg: object) -> float:
    """The header stamp, s (0 where the message has none)."""
    st = getattr(getattr(msg, "header", None), "stamp", None)
    return st.sec + 1e-9 * st.nanosec if st is not None else 0.0


def _read_bag(p: Path, joints: tuple[str, str], topics: Topics, extra_joints: tuple[str, ...] = ()) -> Recording:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:  # pragma: no cover - the optional extra
        raise InputError(
            "reading a rosbag2/MCAP recording needs the 'ros' extra: pip install 'bioform-mj[ros]' "
            "(or give the recording as a CSV with named columns)"
        ) from None
    name = str(p)
    js: dict[str, list] = {"t": [], "pos": [], "vel": [], "eff": []}
    od: dict[str, list] = {"t": [], "twist": [], "pose": []}
    im: dict[str, list] = {"t": [], "gyro": []}
    extra: dict[str, list] = {n: [] for n in extra_joints}
    try:
        with AnyReader([p], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            have = {c.topic: c.msgtype for c in reader.connections}
            topics, ns_notes = resolve_topics(have, topics, name)
            custom = _custom_data(reader)
            want = {topics.joint_states: "sensor_msgs/msg/JointState"}
            if topics.joint_states not in have:
                there = ", ".join(f"{k} ({v})" for k, v in sorted(have.items())) or "no topics"
                raise InputError(
                    f"{name}: no topic '{topics.joint_states}' with the wheel joint states (it has: {there}); "
                    "name it with --joint-states-topic (or a robot's namespace with --robot-ns)"
                )
            for topic, typ in ((topics.odom, "nav_msgs/msg/Odometry"), (topics.imu, "sensor_msgs/msg/Imu")):
                if topic in have:
                    want[topic] = typ
            for topic, typ in want.items():
                if have[topic] != typ:
                    raise InputError(f"{name}: topic '{topic}' carries {have[topic]}, expected {typ}")
            conns = [c for c in reader.connections if c.topic in want]
            bag_t: dict[str, list[float]] = {t: [] for t in want}
            no_effort = 0
            others: dict[str, None] = {}  # joints of joint states without the wheels (skipped; named if no others)
            others_n = 0  # the most names one such message held
            idx: tuple[int, int] | None = None
            for conn, bag_ns, raw in _stream(reader, conns, name):
                msg = reader.deserialize(raw, conn.msgtype)
                t = _stamp_s(msg)
                if conn.topic != topics.joint_states:
                    bag_t[conn.topic].append(1e-9 * bag_ns)
                if conn.topic == topics.joint_states:
                    names = list(msg.name)
                    if (
                        idx is None
                        or len(names) <= max(idx)
                        or names[idx[0]] != joints[0]
                        or names[idx[1]] != joints[1]
                    ):
                        missing = [j for j in joints if j not in names]
                        if missing:
                            if not names:
                                continue
                            if len(missing) == len(joints):  # another publisher's joints (an arm, casters)
                                others.update(dict.fromkeys(names[:LIST_MAX]))
                                others_n = max(others_n, len(names))
                                continue
                            raise InputError(
                                f"{name}: '{topics.joint_states}' has no joint {_listed(missing)} "
                                f"(it has: {_listed(names)}); map the robot's wheels with "
                                "--left-wheel/--right-wheel or name the recorded joints with --left-joint/--right-joint"
                            )
                        for j in joints:  # two entries of one wheel: which is the wheel's? (taken silently before)
                            if names.count(j) > 1:
                                raise InputError(
                                    f"{name}: '{topics.joint_states}' at t = {t:.6g} s names joint {j!r} "
                                    f"{names.count(j)} times: which values are the wheel's is not known"
                                )
                        idx = (names.index(joints[0]), names.index(joints[1]))
                    if len(msg.effort) == 0:  # a state-only message (an exporter's last sample at t = T)
                        no_effort += 1
                        continue
                    js["t"].append(t)
                    bag_t[conn.topic].append(1e-9 * bag_ns)  # only for the joint states kept: one clock
                    if extra_joints:
                        at = {n: i for i, n in enumerate(names) if n in extra}
                        pv = (msg.position, msg.velocity)
                        for n in extra_joints:
                            i = at.get(n)
                            extra[n].append([float(a[i]) if i is not None and len(a) > i else math.nan for a in pv])
                    for key, arr in (("pos", msg.position), ("vel", msg.velocity), ("eff", msg.effort)):
                        if len(arr) == 0 and key != "eff":  # a driver that publishes no speeds (or angles)
                            js[key].append((math.nan, math.nan))
                            continue
                        if len(arr) <= max(idx):
                            what = {"pos": "position", "vel": "velocity", "eff": "effort"}[key]
                            raise InputError(
                                f"{name}: '{topics.joint_states}' at t = {t:.6g} s has no {what} for the wheels "
                                f"({len(arr)} values for {len(names)} joints): the fit needs the effort (the "
                                "applied torque) and a position or a velocity"
                            )
                        js[key].append((arr[idx[0]], arr[idx[1]]))
                elif conn.topic == topics.odom:
                    tw, ps = msg.twist.twist, msg.pose.pose
                    od["t"].append(t)
                    od["twist"].append(
                        (tw.linear.x, tw.linear.y, tw.linear.z, tw.angular.x, tw.angular.y, tw.angular.z)
                    )
                    q = ps.orientation
                    od["pose"].append((ps.position.x, ps.position.y, ps.position.z, q.w, q.x, q.y, q.z))
                else:
                    g = msg.angular_velocity
                    im["t"].append(t)
                    im["gyro"].append((g.x, g.y, g.z))
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types for a bad file: one line
        raise InputError(f"{name}: cannot read the recording: {type(exc).__name__}: {exc}") from None
    if not js["t"] and others:
        raise InputError(
            f"{name}: '{topics.joint_states}' has no joint {_listed(list(joints))} "
            f"(it has: {_listed_some(list(others), others_n)}); map the robot's wheels with --left-wheel/--right-wheel "
            "or name the recorded joints with --left-joint/--right-joint"
        )
    if not js["t"]:
        what = f" ({no_effort} without an effort: the fit needs the applied torques)" if no_effort else ""
        raise InputError(f"{name}: '{topics.joint_states}' holds no joint states{what}")
    notes = ns_notes + ([f"{no_effort} joint state(s) without an effort skipped"] if no_effort else [])
    if others:  # several publishers on one topic (ROS 2 merges none): those without the wheels are not theirs
        notes.append(
            f"joint states without the wheels skipped (another publisher's: {_listed_some(list(others), others_n)})"
        )
    # one clock for all topics: the header stamps where every topic has them (a stamp of 0 at sim time 0 is
    # one), else the bag's receive times
    streams = ((topics.joint_states, js), (topics.odom, od), (topics.imu, im))
    if not all(any(d["t"]) for _, d in streams if d["t"]):
        for topic, d in streams:
            if d["t"]:
                d["t"] = bag_t[topic]
        notes.append("times are the bag's receive times (a topic's header stamps are all zero)")
    t0 = js["t"][0]
    pos, vel = np.asarray(js["pos"], float), np.asarray(js["vel"], float)
    tj = np.asarray(js["t"], float)
    if np.isnan(vel).all() and np.isfinite(pos).all() and len(tj) > 2:
        vel = np.stack([np.gradient(pos[:, i], tj) for i in range(2)], axis=1)
        notes.append("the joint states carry no velocity: wheel speeds differentiated from the positions")
    elif np.isnan(pos).all() and np.isfinite(vel).all() and len(tj) > 1:
        dt = np.diff(tj, prepend=tj[0])[:, None]
        pos = np.cumsum(0.5 * (vel + np.vstack([vel[:1], vel[:-1]])) * dt, axis=0)
        notes.append("the joint states carry no position: wheel angles integrated from the velocities")
    js["pos"], js["vel"] = pos, vel
    if not od["t"]:
        notes.append(f"no odometry on '{topics.odom}': body velocities not fitted")
    if not im["t"]:
        notes.append(f"no IMU on '{topics.imu}': the IMU's yaw rate not fitted")
    return Recording(
        name,
        joints,
        np.asarray(js["t"]) - t0,
        np.asarray(js["pos"], float),
        np.asarray(js["vel"], float),
        np.asarray(js["eff"], float),
        np.asarray(od["t"]) - t0 if od["t"] else np.zeros(0),
        np.asarray(od["twist"], float).reshape(-1, 6),
        np.asarray(od["pose"], float).reshape(-1, 7),
        np.asarray(im["t"]) - t0 if im["t"] else np.zeros(0),
        np.asarray(im["gyro"], float).reshape(-1, 3),
        notes,
        _stated(custom, topics),
        {n: np.asarray(v, float).reshape(-1, 2) for n, v in extra.items() if np.isfinite(np.asarray(v, float)).any()},
    )


def _custom_data(reader: object) -> dict[str, str]:
    """``metadata.yaml``'s ``custom_data`` of a rosbag2 folder (empty for a bare MCAP file)."""
    out: dict[str, str] = {}
    for r in getattr(reader, "readers", []):
        inner = getattr(r, "storage", r)  # rosbags 0.11: the rosbag2 reader behind AnyReader's
        custom = getattr(getattr(inner, "metadata", None), "custom", None)
        if isinstance(custom, dict):  # rosbag2's custom_data is string to string: anything else is ignored
            out.update({k: v for k, v in custom.items() if isinstance(k, str) and isinstance(v, str)})
    return out


def _stated(custom: dict[str, str], topics: Topics) -> dict:
    """The ``robots`` entry of this project's ``custom_data.bioform_mj`` (JSON) for the namespace read
    (``topics.namespace``; without one, the only entry); empty where the bag has none."""
    import json

    try:
        robots = json.loads(custom.get("bioform_mj", "{}")).get("robots") or []
    except (ValueError, AttributeError):
        return {}
    ns = topics.namespace
    if ns is None:
        return dict(robots[0]) if len(robots) == 1 and isinstance(robots[0], dict) else {}
    for r in robots:
        if isinstance(r, dict) and r.get("namespace") == ns:
            return dict(r)
    return {}


def _stream(reader, conns, name: str) -> Iterator:
    """The reader's messages one at a time; a truncated file's error is raised when met."""
    yield from reader.messages(connections=conns)


# ------------------------------------------------------------------ CSV
#: largest CSV recording read, MB (2.5 million rows of 7 columns: 42 min at 1 kHz; read as Python rows first, it
#: takes about 8× its size in memory); a longer one: an MCAP, or a window of it
#: a body tilted more than this (deg) in the recorded odometry has lifted off its wheels or casters or tipped
#: over: the fit's and the replay's robot stands on a flat floor, so that part of a recording is not used.
#: Measured on test-recorder bags (60 s): 0.03° (Stretch at its drive program's 0.4 N·m), 0.8° (the lab robot);
#: the Stretch at 3 N·m passed 10° at 2.45 s (a wheelie) and lay on its back (180°) from 8.2 s
TIP_DEG = 10.0


def tipped_at(rec: Recording) -> tuple[float, float] | None:
    """``(t, tilt)``: the time (s) of the first odometry pose whose body z axis is tilted more than
    :data:`TIP_DEG` from the vertical, and the largest tilt in the recording (deg); None where the recording
    has no odometry orientation or never tilts that far. A pose's tilt is ``acos(1 - 2 (qx² + qy²))`` of
    its unit quaternion (the body z axis's vertical component)."""
    if not len(rec.odom_t):
        return None
    q = rec.odom_pose[:, 3:7]
    norm = np.linalg.norm(q, axis=1)
    ok = norm > 0.5  # a zero quaternion: a driver that does not publish orientation
    if not ok.any():
        return None
    qx, qy = q[ok, 1] / norm[ok], q[ok, 2] / norm[ok]
    tilt = np.degrees(np.arccos(np.clip(1.0 - 2.0 * (qx**2 + qy**2), -1.0, 1.0)))
    over = np.flatnonzero(tilt > TIP_DEG)
    if not len(over):
        return None
    return float(rec.odom_t[ok][over[0]]), float(tilt.max())


def upright_part(rec: Recording, need_s: float, name: str) -> tuple[Recording, str | None]:
    """``(rec, None)`` where the robot stays upright (:func:`tipped_at`); else the part of ``rec`` up to 0.1 s
    before its odometry tilted more than :data:`TIP_DEG` and the note saying so (also in the part's
    ``notes``). Raises :class:`InputError` (naming ``name``) where less than ``need_s`` s comes before it."""
    tip = tipped_at(rec)
    if tip is None:
        return rec, None
    t_tip, worst = tip
    what = (
        f"the robot's body tilted more than {TIP_DEG:g}° in the recording at t = {t_tip:.3g} s ({worst:.0f}° at "
        "most: it lifted off its wheels or casters, or tipped over; the model stands on a flat floor)"
    )
    t_end = t_tip - 0.1  # the lift starts before the tilt passes the threshold
    if t_end - float(rec.t[0]) < need_s:
        raise InputError(
            f"{name}: {what}, and less than one {need_s:g} s chunk comes before it: record again with "
            "smaller torques (bioform robot drive-program prints a program within the robot's limits)"
        )
    note = f"{what}: only the {t_end - float(rec.t[0]):.3g} s before it are used"
    out = rec.window(float(rec.t[0]), t_end)
    out.notes.append(note)
    return out, note


CSV_MAX_MB = 256


def _read_csv(p: Path, joints: tuple[str, str]) -> tuple[Recording, np.ndarray]:
    """The recording in CSV file ``p`` and each row's line in the file."""
    name = str(p)
    if (size := p.stat().st_size) > CSV_MAX_MB * 10**6:  # a 10 GB sparse CSV was read line by line, whole
        raise InputError(
            f"{name}: a CSV recording of {size / 1e6:.0f} MB, above the {CSV_MAX_MB} MB read (record an MCAP, or "
            "export a shorter window)"
        )
    try:
        with open(p, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise InputError(f"{name}: empty CSV file") from None
            need = ["time"] + [f"{j}.{f}" for j in joints for f in ("position", "velocity", "effort")]
            missing = [c for c in need if c not in header]
            if missing:
                raise InputError(
                    f"{name}: no column {_listed(missing)} (it has: {_listed(header)}); expected time, "
                    "<joint>.position, <joint>.velocity, <joint>.effort for both wheel joints"
                )
            used = [h for h in [*need, "odom.vx", "odom.wz", "imu.wz"] if h in header]
            if (twice := _twice([h for h in header if h in used])) is not None:  # the last one was taken silently
                raise InputError(f"{name}: column {twice!r} appears {header.count(twice)} times in the header")
            keep = [header.index(h) for h in used]  # only these are converted and kept (10^7 columns: gigabytes)
            col = {h: i for i, h in enumerate(used)}
            rows, lines = [], []
            for k, row in enumerate(reader):
                if not row:
                    continue
                lines.append(reader.line_num)
                if len(row) != len(header):
                    raise InputError(f"{name}: line {k + 2} has {len(row)} fields, the header {len(header)}")
                try:
                    rows.append([float(row[i]) if row[i].strip() else math.nan for i in keep])
                except ValueError as exc:
                    raise InputError(f"{name}: line {k + 2}: {exc}") from None
    except OSError as exc:
        raise InputError(f"{name}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{name}: not a text CSV file") from None
    except csv.Error as exc:  # a field above csv's limit (128 kB), a NUL byte: was an internal error (issue 28)
        raise InputError(f"{name}: not a CSV recording ({exc})") from None
    a = np.asarray(rows, float).reshape(-1, len(col))
    t = a[:, col["time"]]

    def pair(f: str) -> np.ndarray:
        return np.stack([a[:, col[f"{joints[0]}.{f}"]], a[:, col[f"{joints[1]}.{f}"]]], axis=1)

    rec = Recording(name, joints, t - (t[0] if len(t) else 0.0), pair("position"), pair("velocity"), pair("effort"))
    rec.t = rec.t if len(t) else t
    if "odom.vx" in col and "odom.wz" in col:
        tw = np.zeros((len(t), 6))
        tw[:, 0], tw[:, 5] = a[:, col["odom.vx"]], a[:, col["odom.wz"]]
        rec.odom_t, rec.odom_twist = rec.t.copy(), tw
        rec.odom_pose = np.tile([0, 0, 0, 1.0, 0, 0, 0], (len(t), 1))
    else:
        rec.notes.append("no odom.vx/odom.wz columns: body velocities not fitted")
    if "imu.wz" in col:
        g = np.zeros((len(t), 3))
        g[:, 2] = a[:, col["imu.wz"]]
        rec.imu_t, rec.imu_gyro = rec.t.copy(), g
    return rec, np.asarray(lines, np.int64)


def still_note(rec: Recording, wheel_radius: float) -> list[str]:
    """A note where the wheels (radius ``wheel_radius``, m) hardly turned in the whole recording (nothing to
    identify)."""
    rim = float(np.abs(rec.velocity).max()) * wheel_radius
    if rim >= STILL_RIM_SPEED:
        return []
    return [
        f"the wheels hardly turned (largest rim speed {1000 * rim:.2g} mm/s): the recorded torques hardly moved "
        "the robot (a dragging caster or stiff gearboxes hold it), so the recording identifies nothing; record "
        "with larger torques (bioform robot drive-program --accel)"
    ]
