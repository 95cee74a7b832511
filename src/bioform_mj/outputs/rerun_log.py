"""Rerun recordings of a run (rerun-sdk ≥ 0.24; written against 0.41).

Two ways, sharing one entity layout:

- :func:`write_rrd` writes ``run.rrd`` after the run from the :class:`~bioform_mj.run.simulate.RunResult`
  log with ``send_columns`` (a whole series per call: fast, nothing in the loop), to a
  temporary name in the same directory that is renamed once the file sink is closed.
- :class:`RerunLive` is an :class:`~bioform_mj.run.simulate.Observer` that streams the run as it
  happens to a viewer it spawns (``--rerun-spawn``) or to one already running
  (``--rerun-connect rerun+http://HOST:PORT/proxy``), at ``period`` s of simulated time.

Layout (timeline ``sim_time``, a duration in s)::

    /world                         right-handed, z up, metres
    /world/leader                  Transform3D of the true leader + its box (static)
    /world/paths/leader            LineStrips3D of the leader's path so far
    /world/follower/<i>/robot      Transform3D of follower i + its box (static)
    /world/follower/<i>/estimate   Transform3D of follower i's estimate P_ir of the leader + a box
    /world/follower/<i>/slot       Points3D, its formation slot p_r − Δ_i
    /world/follower/<i>/path       LineStrips3D of its path so far
    /follower/<i>/formation_error  Scalars |p_i − (p_r − Δ_i)|  (m)
    /follower/<i>/estimation_error Scalars [position (m), heading (rad)] of P_ir − leader
    /follower/<i>/tracking_error   Scalars [x̃, ỹ (m), θ̃ (rad)]
    /follower/<i>/v                Scalars [υ_cmd, υ, υ_ir] (m/s)
    /follower/<i>/omega            Scalars [ω_cmd, ω, ω_ir] (rad/s)
    /follower/<i>/torque           Scalars [τ_L, τ_R] applied (N·m)
    /follower/<i>/a, /b            Scalars [ĉ, c_true] of a = 1/(m r), b = l/(I r)
    /follower/<i>/vs               Scalars V_s, the neuron output
    /summary                       TextDocument (static), the run's summary

``<i>`` is 1-based. A default blueprint shows the 3D view beside one tab of plots per follower.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.control.common import wrap_angles
from bioform_mj.core.errors import InputError
from bioform_mj.outputs.figures import LEADER_RGB, follower_rgb

#: Rerun application id of every recording this package writes.
APP_ID = "bioform_mj"
#: Name of the simulated-time timeline (durations in s).
TIMELINE = "sim_time"

_PATH_HZ = 10.0  # growing path strips logged this often (s⁻¹ of simulated time), post-hoc
_PATH_POINTS = 600  # at most this many points per path strip
_ROBOT_HALF = (0.17, 0.22, 0.08)  # m, box drawn for a follower (paper robot: 0.2 m half track)
_LEADER_HALF = (0.15, 0.12, 0.05)  # m, the ghost's box in the MuJoCo scene

_URL = re.compile(r"^rerun(\+https?)?://[^/\s]+(/proxy)?$")


def connect_url(addr: str) -> str:
    """Normalise ``--rerun-connect``: ``HOST:PORT``, ``PORT`` or a ``rerun+http://…/proxy`` URL (else InputError)."""
    a = addr.strip()
    if re.fullmatch(r"\d{1,5}", a):
        return f"rerun+http://127.0.0.1:{a}/proxy"
    if re.fullmatch(r"[A-Za-z0-9_.\-\[\]:]+:\d{1,5}", a):
        return f"rerun+http://{a}/proxy"
    if _URL.match(a):
        return a if a.endswith("/proxy") else a + "/proxy"
    raise InputError(
        f"--rerun-connect: '{addr}' is not a rerun address (expected rerun+http://HOST:PORT/proxy, HOST:PORT or PORT)"
    )


def check_can_spawn() -> None:
    """InputError, before the run, when a spawned viewer could not open a window (Linux without a display)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise InputError(
            "--rerun-spawn needs a display for the viewer window (DISPLAY or WAYLAND_DISPLAY is not set); "
            "use --rrd and open run.rrd elsewhere, or --rerun-connect to a viewer on another machine"
        )


def _viewer_on_path() -> None:
    """Put rerun-sdk's viewer (``rerun`` beside this Python, e.g. in ``.venv/bin``) on PATH for ``spawn``.

    ``RecordingStream.spawn`` looks the viewer up on PATH, which a venv's ``bin`` is not on
    when the ``bioform`` script is called by its path.
    """
    if shutil.which("rerun") is None:
        exe = Path(sys.executable).with_name("rerun")
        if exe.is_file():
            os.environ["PATH"] = str(exe.parent) + os.pathsep + os.environ.get("PATH", "")


def _quat_xyzw(theta: np.ndarray) -> np.ndarray:
    """Rerun quaternions ``[x, y, z, w]`` of yaw rotations ``theta`` (rad), shape (K, 4)."""
    th = np.asarray(theta, dtype=float)
    return np.column_stack([np.zeros_like(th), np.zeros_like(th), np.sin(th / 2), np.cos(th / 2)])


def _u8(rgb: tuple[float, float, float], alpha: float = 1.0) -> list[int]:
    return [int(round(255 * c)) for c in rgb] + [int(round(255 * alpha))]


#: Scalar series per follower: entity leaf, extractor (log, i) → (K, m), names, colours of the m lines.
_SERIES: list[tuple[str, Callable[[Mapping[str, np.ndarray], int], np.ndarray], tuple[str, ...]]] = [
    ("formation_error", lambda g, i: g["formation_error"][:, i, None], ("|p − slot| (m)",)),
    (
        "estimation_error",
        lambda g, i: np.column_stack(
            [g["estimation_error"][:, i], wrap_angles(g["est_pose"][:, i, 2] - g["leader_pose"][:, 2])]
        ),
        ("position (m)", "heading (rad)"),
    ),
    ("tracking_error", lambda g, i: g["tracking_error"][:, i, :], ("x̃ (m)", "ỹ (m)", "θ̃ (rad)")),
    (
        "v",
        lambda g, i: np.column_stack([g["cmd"][:, i, 0], g["vel"][:, i, 0], g["est_vel"][:, i, 0]]),
        ("υ_cmd", "υ", "υ_ir (estimate of υ_r)"),
    ),
    (
        "omega",
        lambda g, i: np.column_stack([g["cmd"][:, i, 1], g["vel"][:, i, 1], g["est_vel"][:, i, 1]]),
        ("ω_cmd", "ω", "ω_ir (estimate of ω_r)"),
    ),
    (
        "torque",
        lambda g, i: (
            np.column_stack([g["tau"][:, i, :], g["tau_min"][:, i, :], g["tau_max"][:, i, :]])
            if "tau_min" in g
            else g["tau"][:, i, :]
        ),
        ("τ_L mean (N·m)", "τ_R mean (N·m)", "τ_L min", "τ_R min", "τ_L max", "τ_R max"),
    ),
    ("a", lambda g, i: np.column_stack([g["c_hat"][:, i, 0], g["c_true"][:, i, 0]]), ("â", "a (true)")),
    ("b", lambda g, i: np.column_stack([g["c_hat"][:, i, 1], g["c_true"][:, i, 1]]), ("b̂", "b (true)")),
    ("vs", lambda g, i: g["vs"][:, i, None], ("V_s",)),
]
_LINE_COLORS = [
    (0.84, 0.15, 0.16),
    (0.12, 0.47, 0.71),
    (0.5, 0.5, 0.5),
    (0.12, 0.47, 0.71),
    (0.95, 0.6, 0.6),
    (0.6, 0.75, 0.9),
]


def blueprint(n: int) -> Any:
    """Default layout: the 3D formation beside one tab of time series per follower."""
    import rerun.blueprint as rrb

    tabs = []
    for i in range(1, n + 1):
        views = [rrb.TimeSeriesView(origin=f"/follower/{i}/{leaf}", name=leaf) for leaf, _, _ in _SERIES]
        tabs.append(rrb.Grid(*views, name=f"follower {i}"))
    overview = rrb.TimeSeriesView(
        origin="/follower",
        name="formation errors",
        contents=[f"/follower/{i}/formation_error" for i in range(1, n + 1)],
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.Spatial3DView(origin="/world", name="formation"), overview, row_shares=[3, 1]),
            rrb.Tabs(*tabs),
            column_shares=[1, 1],
        ),
        collapse_panels=True,
    )


def _log_obstacles(rec: Any, obstacles: Any) -> None:
    """The obstacles (design §19) as static boxes and cylinders under ``/world/obstacles``."""
    import rerun as rr

    from bioform_mj.formation.obstacles import from_rows
    from bioform_mj.outputs.figures import OBSTACLE_RGB

    obs = from_rows(obstacles) if obstacles is not None and len(obstacles) else []
    boxes = [o for o in obs if o.shape == "box"]
    cyls = [o for o in obs if o.shape == "cylinder"]
    col = _u8(OBSTACLE_RGB)
    if boxes:
        rec.log(
            "/world/obstacles/boxes",
            rr.Boxes3D(
                half_sizes=[list(o.size) for o in boxes],
                centers=[[o.x, o.y, o.size[2]] for o in boxes],
                quaternions=[rr.Quaternion(xyzw=[0.0, 0.0, np.sin(o.yaw / 2), np.cos(o.yaw / 2)]) for o in boxes],
                colors=[col] * len(boxes),
                labels=[o.name for o in boxes],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=True,
        )
    if cyls:
        rec.log(
            "/world/obstacles/cylinders",
            rr.Cylinders3D(
                lengths=[2 * o.size[1] for o in cyls],
                radii=[o.size[0] for o in cyls],
                centers=[[o.x, o.y, o.size[1]] for o in cyls],
                colors=[col] * len(cyls),
                labels=[o.name for o in cyls],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=True,
        )


def _log_static(rec: Any, n: int, summary: Mapping[str, Any] | None, label: str, obstacles: Any = None) -> None:
    """Everything that does not change: view coordinates, boxes, series names and colours, summary,
    obstacles (``(m, 7)`` rows of :func:`bioform_mj.formation.obstacles.to_rows`)."""
    import rerun as rr

    rec.send_recording_name(label)
    rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log(
        "/world/leader",
        rr.Boxes3D(
            half_sizes=[_LEADER_HALF],
            centers=[[0, 0, _LEADER_HALF[2]]],
            colors=[_u8(LEADER_RGB, 0.6)],
            labels=["leader"],
            fill_mode=rr.components.FillMode.Solid,
        ),
        static=True,
    )
    rec.log("/world/paths/leader", rr.LineStrips3D([], colors=[_u8(LEADER_RGB)], radii=[0.02]), static=True)
    _log_obstacles(rec, obstacles)
    for i in range(n):
        c = follower_rgb(i)
        base = f"/world/follower/{i + 1}"
        rec.log(
            f"{base}/robot",
            rr.Boxes3D(
                half_sizes=[_ROBOT_HALF],
                centers=[[0, 0, _ROBOT_HALF[2]]],
                colors=[_u8(c)],
                labels=[f"F{i + 1}"],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=True,
        )
        rec.log(
            f"{base}/robot/heading",
            rr.Arrows3D(vectors=[[0.4, 0, 0]], origins=[[0, 0, 0.17]], colors=[_u8(c)]),
            static=True,
        )
        rec.log(
            f"{base}/estimate",
            rr.Boxes3D(
                half_sizes=[_LEADER_HALF],
                centers=[[0, 0, _LEADER_HALF[2]]],
                colors=[_u8(c, 0.5)],
                labels=[f"F{i + 1}'s leader estimate"],
            ),
            static=True,
        )
        rec.log(f"{base}/slot", rr.Points3D.from_fields(colors=[_u8(c)], radii=[0.12]), static=True)
        rec.log(f"{base}/path", rr.LineStrips3D.from_fields(colors=[_u8(c)], radii=[0.015]), static=True)
        for leaf, _, names in _SERIES:
            rec.log(
                f"/follower/{i + 1}/{leaf}",
                rr.SeriesLines(
                    names=list(names),
                    colors=[_u8(col) for col in _LINE_COLORS[: len(names)]],
                    widths=[1.5] * len(names),
                ),
                static=True,
            )
    if summary is not None:
        brief = {k: v for k, v in summary.items() if k != "config"}
        text = "```json\n" + json.dumps(brief, indent=1, default=str) + "\n```"
        rec.log("/summary", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)


def _strip_rows(t: np.ndarray, xy: np.ndarray, hz: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Times and growing path strips (each the path up to that time, thinned to ``_PATH_POINTS``)."""
    K = len(t)
    if K == 0:
        return t, []
    dt = float(np.median(np.diff(t))) if K > 1 else 1.0
    step = max(1, int(round(1.0 / (hz * dt))))
    ks = list(range(0, K, step))
    if ks[-1] != K - 1:
        ks.append(K - 1)
    xyz = np.column_stack([xy, np.full(K, 0.01)])
    strips = []
    for k in ks:
        if k + 1 <= _PATH_POINTS:
            idx = np.arange(k + 1)
        else:
            idx = np.unique(np.linspace(0, k, _PATH_POINTS).round().astype(int))
        strips.append(xyz[idx])
    return t[ks], strips


def send_log(rec: Any, log: Mapping[str, np.ndarray]) -> None:
    """Send a whole log (the ``log.npz`` channels) to ``rec`` with ``send_columns``."""
    import rerun as rr

    t = np.asarray(log["t"], dtype=float)
    if len(t) == 0:
        return
    n = log["pose"].shape[1]
    idx = [rr.TimeColumn(TIMELINE, duration=t)]
    lp = log["leader_pose"]
    rec.send_columns(
        "/world/leader",
        idx,
        rr.Transform3D.columns(
            translation=np.column_stack([lp[:, :2], np.zeros(len(t))]), quaternion=_quat_xyzw(lp[:, 2])
        ),
    )
    ts, strips = _strip_rows(t, lp[:, :2], _PATH_HZ)
    rec.send_columns(
        "/world/paths/leader", [rr.TimeColumn(TIMELINE, duration=ts)], rr.LineStrips3D.columns(strips=strips)
    )
    offsets = np.asarray(log["offsets"], dtype=float) if "offsets" in log else np.zeros((n, 2))
    for i in range(n):
        base = f"/world/follower/{i + 1}"
        p = log["pose"][:, i]
        rec.send_columns(
            f"{base}/robot",
            idx,
            rr.Transform3D.columns(
                translation=np.column_stack([p[:, :2], np.zeros(len(t))]), quaternion=_quat_xyzw(p[:, 2])
            ),
        )
        e = log["est_pose"][:, i]
        rec.send_columns(
            f"{base}/estimate",
            idx,
            rr.Transform3D.columns(
                translation=np.column_stack([e[:, :2], np.zeros(len(t))]), quaternion=_quat_xyzw(e[:, 2])
            ),
        )
        slot = log["slots"][:, i] if "slots" in log else lp[:, :2] - offsets[i]
        rec.send_columns(
            f"{base}/slot", idx, rr.Points3D.columns(positions=np.column_stack([slot, np.full(len(t), 0.01)]))
        )
        ts, strips = _strip_rows(t, p[:, :2], _PATH_HZ)
        rec.send_columns(f"{base}/path", [rr.TimeColumn(TIMELINE, duration=ts)], rr.LineStrips3D.columns(strips=strips))
        if "odom_pose" in log and not np.array_equal(log["odom_pose"][:, i], p):  # sensing = odometry
            o = log["odom_pose"][:, i]
            ts, strips = _strip_rows(t, o[:, :2], _PATH_HZ)
            rec.send_columns(
                f"{base}/odometry_path", [rr.TimeColumn(TIMELINE, duration=ts)], rr.LineStrips3D.columns(strips=strips)
            )
            drift = np.hypot(o[:, 0] - p[:, 0], o[:, 1] - p[:, 1])
            rec.send_columns(f"/follower/{i + 1}/odometry_drift", idx, rr.Scalars.columns(scalars=drift))
        for leaf, fn, _names in _SERIES:
            vals = np.asarray(fn(log, i), dtype=float)
            rec.send_columns(
                f"/follower/{i + 1}/{leaf}",
                idx,
                rr.Scalars.columns(scalars=vals).partition(lengths=np.full(len(t), vals.shape[1])),
            )


def _label(summary: Mapping[str, Any]) -> str:
    return f"{summary.get('scenario', '')} {summary.get('plant', '')} {summary.get('method', '')}".strip()


#: bytes per write of run.rrd (signals are handled between writes)
_WRITE_CHUNK = 1 << 20


def write(result: Any, out: Path, **_: Any) -> str:
    """The registered output ``rrd`` (:mod:`~bioform_mj.outputs.registry`): ``out/run.rrd``; returns the line the
    CLI prints.

    Parameters
    ----------
    result : RunResult
        The finished run.
    out : Path
        The run folder.
    """
    t0 = time.perf_counter()
    write_rrd(result, Path(out) / "run.rrd")
    return f"run.rrd written in {time.perf_counter() - t0:.1f} s"


def write_rrd(result: Any, path: str | Path) -> Path:
    """Write ``run.rrd`` of a :class:`~bioform_mj.run.simulate.RunResult` atomically; returns the path.

    The recording goes to rerun's in-memory binary stream and is written by Python, 1 MiB at a time,
    under a temporary name in the target's directory, renamed once complete (the stream flushed and
    closed: its footer written), so ``path`` is complete or absent. Writing in Python (not rerun's own
    file sink, a thread of its own) makes a full disk or ``ulimit -f`` an ``OSError`` at once (a
    :class:`~bioform_mj.core.errors.WriteFailed`, one ``error:`` line, the temporary file removed) and
    leaves SIGINT/SIGTERM to interrupt between chunks (rerun's sink ignored both for over 10 min on a
    full disk, issue 28).
    """
    import rerun as rr

    from bioform_mj.outputs.files import atomic_path

    path = Path(path)
    n = result.log["pose"].shape[1]
    rec = rr.RecordingStream(APP_ID, send_properties=True)
    stream = rec.binary_stream()
    try:
        rec.send_blueprint(blueprint(n), make_active=False, make_default=True)
        _log_static(rec, n, result.summary, _label(result.summary), result.log.get("obstacles"))
        send_log(rec, result.log)
    finally:
        rec.disconnect()  # closes the stream: its footer written
    data = memoryview(stream.read(flush=True) or b"")  # one read: the footer's checksum covers the stream
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        for k in range(0, len(data), _WRITE_CHUNK):  # Python writes: an OSError at once, signals between chunks
            fh.write(data[k : k + _WRITE_CHUNK])
        fh.flush()
        os.fsync(fh.fileno())  # a full disk that defers its error to the flush says it here, not after the rename
    return path


class RerunLive:
    """Observer streaming a run to a rerun viewer while it runs (spawned, or at ``url``).

    ``period`` s of simulated time between samples (default ``1/30``); everything logged
    per sample is the current state (no history beyond the growing paths).
    """

    def __init__(self, *, spawn: bool = False, url: str | None = None, period: float = 1 / 30) -> None:
        if not spawn and url is None:
            raise ValueError("RerunLive needs spawn=True or a url")
        self.period = float(period)
        self.spawn = spawn
        self.url = url
        self.rec: Any = None
        self.error: str | None = None
        self._paths: list[list[np.ndarray]] = []
        self._lpath: list[np.ndarray] = []

    def start(self, run: Any) -> None:
        """Open the stream (spawning a viewer if asked) and log the static parts."""
        import rerun as rr

        n = run.scenario.n
        self.rec = rr.RecordingStream(APP_ID)
        try:
            if self.spawn:
                _viewer_on_path()
                self.rec.spawn(default_blueprint=blueprint(n))
            else:
                self.rec.connect_grpc(self.url, default_blueprint=blueprint(n))
            sc = run.scenario
            from bioform_mj.formation.obstacles import to_rows

            obstacles = to_rows(getattr(run.plant, "obstacles", None) or [])
            _log_static(self.rec, n, None, f"{sc.name} {sc.plant.kind} {sc.method} (live)", obstacles)
        except Exception as exc:  # noqa: BLE001 - a viewer that cannot be reached must not stop the run
            self._fail(exc)
        self._paths = [[] for _ in range(n)]
        self._lpath = []

    def _fail(self, exc: BaseException) -> None:
        where = "a spawned viewer" if self.spawn else self.url
        self.error = f"rerun stream to {where} failed: {' '.join(str(exc).split())[:200]}"
        if self.rec is not None:
            try:
                self.rec.disconnect()
            except Exception:  # noqa: BLE001
                pass
        self.rec = None

    def sample(self, run: Any) -> None:
        """Log the current state (transforms, slots, paths, one value of every series)."""
        if self.rec is None:
            return
        try:
            self._sample(run)
        except Exception as exc:  # noqa: BLE001
            self._fail(exc)

    def _sample(self, run: Any) -> None:
        import rerun as rr

        rec = self.rec
        row = state_row(run)
        rec.set_time(TIMELINE, duration=float(run.t))
        lp = row["leader_pose"][0]
        rec.log("/world/leader", rr.Transform3D(translation=[lp[0], lp[1], 0.0], quaternion=_quat_xyzw(lp[2:3])[0]))
        self._lpath.append(np.array([lp[0], lp[1], 0.01]))
        rec.log("/world/paths/leader", rr.LineStrips3D([np.array(self._lpath[-_PATH_POINTS:])]))
        for i in range(len(self._paths)):
            base = f"/world/follower/{i + 1}"
            p, e, s = row["pose"][0, i], row["est_pose"][0, i], row["slots"][0, i]
            rec.log(f"{base}/robot", rr.Transform3D(translation=[p[0], p[1], 0.0], quaternion=_quat_xyzw(p[2:3])[0]))
            rec.log(f"{base}/estimate", rr.Transform3D(translation=[e[0], e[1], 0.0], quaternion=_quat_xyzw(e[2:3])[0]))
            rec.log(f"{base}/slot", rr.Points3D([[s[0], s[1], 0.01]]))
            self._paths[i].append(np.array([p[0], p[1], 0.01]))
            rec.log(f"{base}/path", rr.LineStrips3D([np.array(self._paths[i][-_PATH_POINTS:])]))
            for leaf, fn, _ in _SERIES:
                rec.log(f"/follower/{i + 1}/{leaf}", rr.Scalars(np.asarray(fn(row, i), dtype=float)[0]))

    def finish(self, run: Any, timeout_s: float = 10.0) -> None:
        """Flush what is buffered (at most ``timeout_s`` s) and close the stream."""
        if self.rec is None:
            return
        try:
            self.rec.flush(timeout_sec=timeout_s)
        except Exception as exc:  # noqa: BLE001
            self._fail(exc)
            return
        self.rec.disconnect()
        self.rec = None


def state_row(run: Any) -> dict[str, np.ndarray]:
    """The log channels of one instant of a live run (:class:`~bioform_mj.run.simulate.RunState`), with a time
    axis of 1."""
    sig = run.stack.signals()
    n = run.pose.shape[0]

    def get(name: str, shape: tuple[int, ...]) -> np.ndarray:
        v = sig.get(name)
        return np.full(shape, np.nan) if v is None else np.asarray(v, dtype=float)

    lp = np.asarray(run.leader_pose, dtype=float)
    pose = np.asarray(run.pose, dtype=float)
    est = get("est_pose", (n, 3))
    slots = np.asarray(run.slots, dtype=float)
    row = {
        "t": np.array([run.t]),
        "leader_pose": lp,
        "leader_vel": np.asarray(run.leader_vel, dtype=float),
        "pose": pose,
        "vel": np.asarray(run.vel, dtype=float),
        "est_pose": est,
        "est_vel": get("est_vel", (n, 2)),
        "cmd": get("cmd", (n, 2)),
        "tau": get("tau", (n, 2)),
        "tau_min": get("tau", (n, 2)),
        "tau_max": get("tau", (n, 2)),  # live: the instant's torque
        "c_hat": get("c_hat", (n, 2)),
        "c_true": np.asarray(run.plant.c_true(), dtype=float),
        "vs": get("vs", (n,)),
        "tracking_error": get("tracking_error", (n, 3)),
        "formation_error": np.linalg.norm(pose[:, :2] - slots, axis=1),
        "estimation_error": np.linalg.norm(est[:, :2] - lp[None, :2], axis=1),
        "slots": slots,
    }
    return {k: (v if k == "t" else v[None]) for k, v in row.items()}


def read_entities(path: str | Path) -> dict[str, int]:
    """Entity path → number of temporal rows in an ``.rrd`` (static-only entities: 0), read with rerun's own reader."""
    import rerun as rr

    rows: dict[str, int] = {}
    for chunk in rr.chunk.RrdReader(str(path)).stream().to_chunks():
        ent = chunk.entity_path
        rows[ent] = rows.get(ent, 0) + (0 if chunk.is_static else chunk.num_rows)
    return rows
