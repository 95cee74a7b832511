"""``video.mp4`` of a run: captured during the loop as cheap state snapshots, rendered afterwards.

:class:`FrameCapture` is an :class:`~bioform_mj.run.simulate.Observer` with ``period = 1/fps`` s of
simulated time: each call copies a few arrays (the robots' poses and, on the MuJoCo plant,
the whole ``qpos``), a few microseconds, so the loop pays nothing for the picture and
``summary.json``'s ``wall_time_s`` stays the loop's own time. :func:`render_video` then
replays the snapshots through ``mujoco.Renderer`` off-screen (see :mod:`.gl`) and pipes
the frames to ffmpeg (from ``imageio-ffmpeg``, no system ffmpeg needed) via mediapy.

The MuJoCo plant is replayed in its own compiled model (wheels turn as simulated); the
ideal plant has no scene, so one is composed for it (:func:`bioform_mj.robots.scene.build_scene`
with the scenario's robot MJCF, wheels turned from the logged ``υ, ω``).

Each frame shows the robots, the leader's ghost and every follower's formation slot
(scene mocaps), coloured trails of each robot's path and of the leader's, the formation
shape (leader → slots) and a caption with time, method, plant and formation errors. The
default camera (``auto``) is a free camera that keeps the leader, the followers and the
slots in view; ``track`` and ``top`` are the scene's cameras riding on the centroid.
"""

from __future__ import annotations

import importlib.util
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from bioform_mj.core.errors import InputError
from bioform_mj.outputs.figures import LEADER_RGB, follower_rgb
from bioform_mj.outputs.files import atomic_path

log = logging.getLogger(__name__)

#: ``--camera`` choices: a free camera fitted to the formation, or the scene's cameras.
CAMERAS = ("auto", "track", "top")

AZIMUTH = 15.0  # deg, auto camera: behind the formation (the leader drives along +x), a little to its right
ELEVATION = -55.0  # deg, looking down
_MARGIN = 1.0  # m kept in view around every robot, the leader and every slot (× robot_unit)


@dataclass(frozen=True)
class VideoOptions:
    """Video size (pixels), frame rate (frames per second of simulated time) and camera."""

    width: int = 960
    height: int = 540
    fps: float = 30.0
    camera: str = "auto"

    def validate(self) -> VideoOptions:
        """Raise :class:`InputError` for sizes ffmpeg's ``yuv420p`` cannot take or an unknown camera."""
        for name, v in (("width", self.width), ("height", self.height)):
            if not (16 <= v <= 4096) or v % 2:
                raise InputError(f"--{name} must be an even number of pixels in 16..4096, got {v}")
        if not (np.isfinite(self.fps) and 1 <= self.fps <= 240):
            raise InputError(f"--fps must be in 1..240 frames per second, got {self.fps:g}")
        if self.camera not in CAMERAS:
            raise InputError(f"--camera must be one of {', '.join(CAMERAS)}, got '{self.camera}'")
        return self


@runtime_checkable
class _MujocoScene(Protocol):
    """A plant whose state is a MuJoCo scene (its ``qpos`` is captured as is; this floor knows no plant, design §0)."""

    model: Any
    data: Any


class FrameCapture:
    """Observer that snapshots the robots every ``1/fps`` s of simulated time (no rendering)."""

    def __init__(self, fps: float = 30.0) -> None:
        self.period = 1.0 / float(fps)  # s of simulated time between frames
        self.fps = float(fps)
        self.t: list[float] = []
        self.pose: list[np.ndarray] = []  # (n, 3) [x m, y m, θ rad]
        self.vel: list[np.ndarray] = []  # (n, 2) [υ m/s, ω rad/s]
        self.leader: list[np.ndarray] = []  # (3,) true leader pose
        self.slots: list[np.ndarray] = []  # (n, 2) formation slots, m
        self.qpos: list[np.ndarray] = []  # MuJoCo plant only: the full qpos
        self._data: Any = None

    def start(self, run: Any) -> None:
        """Note whether the plant is a MuJoCo one (its ``qpos`` is then captured as is)."""
        plant = run.plant
        self._data = plant.data if isinstance(plant, _MujocoScene) else None

    def sample(self, run: Any) -> None:
        """Copy the state of this instant (a few small arrays)."""
        self.t.append(float(run.t))
        self.pose.append(np.array(run.pose, dtype=float))
        self.vel.append(np.array(run.vel, dtype=float))
        self.leader.append(np.array(run.leader_pose, dtype=float))
        self.slots.append(np.array(run.slots, dtype=float))
        if self._data is not None:
            self.qpos.append(self._data.qpos.copy())

    def finish(self, run: Any) -> None:
        """Nothing to do: frames are rendered by :func:`render_video` after the run."""
        self._data = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class VideoInfo:
    """What :func:`render_video` wrote."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    render_s: float  # wall time of rendering and encoding, s
    gl_renderer: str


# ---------------------------------------------------------------------------- scene for the replay
class Replay:
    """A compiled model and data posed from snapshots (the plant's own model or a composed one)."""

    def __init__(self, result: Any, capture: FrameCapture) -> None:
        import mujoco

        from bioform_mj.robots.analysis import layout_of
        from bioform_mj.robots.scene import Markers, build_scene, compile_scene, follower_prefix

        self.mujoco = mujoco
        sc = result.scenario
        n = sc.n
        self.n = n
        plant = result.plant
        self.live_qpos = bool(capture.qpos)
        if self.live_qpos:
            self.model = plant.model
        else:  # ideal plant: compose a scene with the scenario's robot for the looks
            from bioform_mj.robots.entries import resolve_robot

            robots = list(sc.plant.robots) * (n if len(sc.plant.robots) == 1 else 1)
            spec = build_scene([resolve_robot(r) for r in robots], np.asarray(sc.initial_poses(), float))
            self.model, _ = compile_scene(spec)
        m = self.model
        self.data = mujoco.MjData(m)
        mujoco.mj_forward(m, self.data)
        self.markers = Markers(m, n)
        prefixes = [follower_prefix(i) for i in range(n)]
        lays = [layout_of(m, p) for p in prefixes]  # the robot's own names, mapped (design §8)
        self.half_track = np.array([lay.half_track for lay in lays], dtype=float)  # m, per follower
        base = [m.body(lay.base).id for lay in lays]
        self.base_q = np.array([m.jnt_qposadr[m.body_jntadr[b]] for b in base])  # free joint qpos address
        self.base_z = np.array([m.qpos0[a + 2] for a in self.base_q])
        if not self.live_qpos:
            self.wheel_q = np.array([[m.jnt_qposadr[m.joint(j).id] for j in lay.wheel_joints] for lay in lays])
            self.sign = np.array([lay.wheel_sign for lay in lays], dtype=float)
            self.axle = np.array([lay.axle for lay in lays], dtype=float)  # the logged pose is the axle's
            self.r = np.array([lay.wheel_radius for lay in lays])
            self.l = np.array([lay.half_track for lay in lays])
            self.wheel = np.zeros((n, 2))  # accumulated wheel angles, rad

    def pose(self, k: int, capture: FrameCapture) -> None:
        """Set the model's state to snapshot ``k`` and compute the kinematics and cameras."""
        mj, m, d = self.mujoco, self.model, self.data
        if self.live_qpos:
            d.qpos[:] = capture.qpos[k]
        else:
            pose = capture.pose[k]
            if k > 0:  # wheels from the logged velocities (trapezoid over the frame interval)
                dt = capture.t[k] - capture.t[k - 1]
                v = 0.5 * (capture.vel[k] + capture.vel[k - 1])
                self.wheel[:, 0] += (v[:, 0] - v[:, 1] * self.l) / self.r * dt
                self.wheel[:, 1] += (v[:, 0] + v[:, 1] * self.l) / self.r * dt
            for i, a in enumerate(self.base_q):
                th = pose[i, 2]
                c, s = np.cos(th), np.sin(th)
                ax, ay = self.axle[i, 0], self.axle[i, 1]
                d.qpos[a : a + 7] = (
                    pose[i, 0] - (c * ax - s * ay),
                    pose[i, 1] - (s * ax + c * ay),
                    self.base_z[i],
                    np.cos(th / 2),
                    0.0,
                    0.0,
                    np.sin(th / 2),
                )
                d.qpos[self.wheel_q[i]] = self.sign[i] * self.wheel[i]
        self.markers.place(d, capture.leader[k], capture.slots[k], capture.pose[k][:, :2].mean(axis=0))
        mj.mj_kinematics(m, d)
        mj.mj_camlight(m, d)


# ---------------------------------------------------------------------------- camera
def _camera_basis(az_deg: float, el_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MuJoCo free camera: forward, right and up unit vectors for azimuth/elevation in degrees."""
    az, el = np.radians(az_deg), np.radians(el_deg)
    fwd = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return fwd, right, up


def auto_camera_path(
    capture: FrameCapture,
    fovy_deg: float,
    aspect: float,
    azimuth: float = AZIMUTH,
    elevation: float = ELEVATION,
    unit: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``lookat`` (K, 3) and ``distance`` (K,) m of a free camera that shows everyone.

    Each frame's requirement is the smallest distance at which every follower, the leader
    and every slot, each with a ``_MARGIN × unit`` m disc around it
    (``unit``: :func:`bioform_mj.robots.scene.robot_unit`),
    lies inside the frustum, the camera looking at the middle of their extent on the ground. A centred moving average
    (±1 s) of the look-at point and a moving maximum then average of the distance make
    the path smooth while still containing everyone.
    """
    K = len(capture)
    fwd, right, up = _camera_basis(azimuth, elevation)
    ground_fwd = np.array([fwd[0], fwd[1], 0.0]) / np.hypot(fwd[0], fwd[1])
    tan_v = np.tan(np.radians(fovy_deg) / 2)
    tan_h = tan_v * aspect
    pts = [
        np.column_stack(
            [
                np.vstack([capture.pose[k][:, :2], capture.leader[k][None, :2], capture.slots[k]]),
                np.zeros(2 * capture.pose[k].shape[0] + 1),
            ]
        )
        for k in range(K)
    ]
    centers = np.zeros((K, 3))
    for k in range(K):
        u, w = pts[k] @ right, pts[k] @ ground_fwd  # ground coordinates across and along the view
        centers[k] = 0.5 * (u.min() + u.max()) * right + 0.5 * (w.min() + w.max()) * ground_fwd
    win = max(1, int(round(capture.fps)))  # ±1 s
    centers = _moving_average(centers, win)
    need = np.zeros(K)
    for k in range(K):
        rel = np.vstack([pts[k], pts[k] + [0.0, 0.0, 0.3 * unit]]) - centers[k]
        depth = rel @ fwd
        need[k] = max(
            np.max((np.abs(rel @ right) + _MARGIN * unit) / tan_h - depth),
            np.max((np.abs(rel @ up) + _MARGIN * unit) / tan_v - depth),
            2.0 * unit,
        )
    need = _moving_max(need, win)
    dist = np.maximum(_moving_average(need[:, None], win)[:, 0], need)
    return centers, dist


def _moving_average(x: np.ndarray, half: int) -> np.ndarray:
    """Centred moving average over ``2·half + 1`` rows, edges padded with the end values."""
    if len(x) <= 1:
        return x.copy()
    pad = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)])
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), pad]), axis=0)
    return (c[2 * half + 1 :] - c[: -2 * half - 1]) / (2 * half + 1)


def _moving_max(x: np.ndarray, half: int) -> np.ndarray:
    """Centred moving maximum over ``2·half + 1`` samples."""
    out = np.empty_like(x)
    for k in range(len(x)):
        out[k] = x[max(0, k - half) : k + half + 1].max()
    return out


# ---------------------------------------------------------------------------- decorations
class Trails:
    """Paths of the leader and each follower, simplified as they grow (one new point per frame).

    A point is kept when dropping it would move the polyline by more than ``tol`` m (its
    chord error), so straight stretches cost one segment and curves as many as they need:
    ~50 segments per 20 m path instead of 600, which matters to a software rasteriser
    (each segment is a draw call).
    """

    def __init__(self, capture: FrameCapture, tol: float = 0.015) -> None:
        lead = np.array([p[:2] for p in capture.leader])[:, None, :]  # (K, 1, 2)
        foll = np.array([p[:, :2] for p in capture.pose])  # (K, n, 2)
        self.xy = np.concatenate([lead, foll], axis=1).transpose(1, 0, 2)  # (tracks, K, 2)
        self.kept: list[list[int]] = [[0] for _ in range(self.xy.shape[0])]
        self.tol = tol
        self.k = 0

    def advance(self, k: int) -> None:
        """Take in frames up to ``k`` (call with increasing ``k``)."""
        while self.k < k:
            self.k += 1
            j = self.k
            for tr, kept in enumerate(self.kept):
                a = self.xy[tr, kept[-1]]
                b = self.xy[tr, j]
                mid = self.xy[tr, kept[-1] + 1 : j]  # the points the chord a→b would skip
                if len(mid):
                    ab = b - a
                    L = float(np.hypot(*ab))
                    if L < 1e-9:
                        dev = float(np.max(np.hypot(*(mid - a).T)))
                    else:
                        dev = float(np.max(np.abs(ab[0] * (mid[:, 1] - a[1]) - ab[1] * (mid[:, 0] - a[0])))) / L
                    if dev > self.tol:
                        kept.append(j - 1)

    def polyline(self, track: int, k: int) -> np.ndarray:
        """Points (m, 2) of track ``track`` (0 = leader, i + 1 = follower i) up to frame ``k``."""
        idx = [i for i in self.kept[track] if i < k] + [k]
        return self.xy[track, idx]


def add_geoms(renderer: Any, capture: FrameCapture, trails: Trails, k: int, line_px: float, unit: float = 1.0) -> None:
    """Trails, formation shape and robot halos, appended to the renderer's scene after ``update_scene``.

    Disc radii are the paper-scale sizes (halo 0.3 m, slot 0.18 m, leader 0.3 m) × ``unit``
    (:func:`bioform_mj.robots.scene.robot_unit`): a halo is 1.5 half tracks, a slot disc 0.9, whatever the robot's size.

    Trails are ``mjGEOM_LINE`` connectors (``line_px`` pixels wide): a capsule per segment
    costs ~25× more triangles, which a software rasteriser feels (0.3 s per frame).
    """
    import mujoco

    scn = renderer.scene
    trails.advance(k)
    eye = np.eye(3).ravel()
    zero3 = np.zeros(3)
    line = int(mujoco.mjtGeom.mjGEOM_LINE)
    cyl = int(mujoco.mjtGeom.mjGEOM_CYLINDER)
    decor = int(mujoco.mjtCatBit.mjCAT_DECOR)
    z = 0.012

    def segments(p3: np.ndarray, rgba: np.ndarray, width: float) -> bool:
        keep = np.linalg.norm(np.diff(p3, axis=0), axis=1) > 1e-6
        for a, b in zip(p3[:-1][keep], p3[1:][keep]):
            if scn.ngeom >= scn.maxgeom:
                return False
            g = scn.geoms[scn.ngeom]
            mujoco.mjv_initGeom(g, line, zero3, zero3, eye, rgba)
            g.category = decor
            mujoco.mjv_connector(g, line, width, a, b)
            scn.ngeom += 1
        return True

    def disc(xy: np.ndarray, radius: float, height: float, rgba: np.ndarray) -> None:
        if scn.ngeom >= scn.maxgeom:
            return
        g = scn.geoms[scn.ngeom]
        mujoco.mjv_initGeom(g, cyl, np.array([radius, radius, height]), np.array([xy[0], xy[1], height]), eye, rgba)
        g.category = decor
        scn.ngeom += 1

    n = capture.pose[0].shape[0]
    tracks = [(trails.polyline(0, k), np.array([*LEADER_RGB, 0.95], np.float32))]
    for i in range(n):
        tracks.append((trails.polyline(i + 1, k), np.array([*follower_rgb(i), 0.95], np.float32)))
    for xy, rgba in tracks:
        if not segments(np.column_stack([xy, np.full(len(xy), z)]), rgba, line_px):
            return
    lp = capture.leader[k]
    white = np.array([1.0, 1.0, 1.0, 0.5], np.float32)
    for i in range(n):
        slot = capture.slots[k][i]
        segments(np.array([[lp[0], lp[1], z], [slot[0], slot[1], z]]), white, max(1.0, 0.5 * line_px))
        rgb = follower_rgb(i)
        disc(capture.pose[k][i, :2], 0.3 * unit, 0.003, np.array([*rgb, 0.3], np.float32))  # halo under the robot
        disc(slot, 0.18 * unit, 0.003, np.array([*rgb, 0.45], np.float32))  # its slot, in its colour
    disc(lp[:2], 0.3 * unit, 0.003, np.array([*LEADER_RGB, 0.3], np.float32))


# ---------------------------------------------------------------------------- caption
def _font_path() -> str | None:
    """DejaVu Sans shipped with matplotlib (a dependency), found without importing matplotlib."""
    spec = importlib.util.find_spec("matplotlib")
    if spec is None or not spec.submodule_search_locations:
        return None
    path = Path(list(spec.submodule_search_locations)[0]) / "mpl-data" / "fonts" / "ttf" / "DejaVuSans.ttf"
    return str(path) if path.is_file() else None


class Caption:
    """Text box in the top-left corner, drawn with Pillow onto the frame (a few ms)."""

    def __init__(self, height: int) -> None:
        from PIL import ImageFont

        size = max(11, int(round(height / 30)))
        path = _font_path()
        try:
            self.font = ImageFont.truetype(path, size) if path else ImageFont.load_default(size=size)
        except Exception:  # noqa: BLE001 - an old Pillow without a sized default font
            self.font = ImageFont.load_default()
        self.size = size

    def draw(self, img: np.ndarray, lines: list[list[tuple[str, tuple[float, float, float]]]]) -> np.ndarray:
        """Return ``img`` with ``lines`` drawn on a translucent dark box; a line is ``[(text, rgb 0..1), …]``."""
        from PIL import Image, ImageDraw

        pil = Image.fromarray(img)
        draw = ImageDraw.Draw(pil, "RGBA")
        pad = self.size // 2
        line_h = int(self.size * 1.35)
        widths = [sum(draw.textlength(t, font=self.font) for t, _ in line) for line in lines]
        draw.rectangle([0, 0, int(max(widths)) + 2 * pad, line_h * len(lines) + 2 * pad], fill=(0, 0, 0, 150))
        for j, line in enumerate(lines):
            x = float(pad)
            for text, rgb in line:
                draw.text((x, pad + j * line_h), text, font=self.font, fill=tuple(int(255 * c) for c in rgb))
                x += draw.textlength(text, font=self.font)
        return np.asarray(pil)


# ---------------------------------------------------------------------------- render
def set_ffmpeg() -> None:
    """Point mediapy at the ffmpeg shipped by ``imageio-ffmpeg`` (no system ffmpeg needed)."""
    import mediapy

    try:
        import imageio_ffmpeg

        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())
    except Exception:  # noqa: BLE001 - fall back on an ffmpeg on PATH
        log.debug("imageio-ffmpeg unavailable; mediapy uses ffmpeg from PATH")


class FrameRenderer:
    """Renders frame ``k`` of a capture: replayed state, camera, trails and caption (an RGB uint8 array).

    Raises :class:`~bioform_mj.outputs.gl.GLUnavailable` when no OpenGL context can be made.
    Frames must be asked for in increasing order (the trails grow with them); ``close()`` frees
    the OpenGL context.
    """

    def __init__(self, capture: FrameCapture, result: Any, options: VideoOptions) -> None:
        import mujoco

        from bioform_mj.outputs.gl import gl_renderer_name, make_renderer

        if len(capture) == 0:
            raise InputError("no frames to render: the run ended before its first frame")
        self.capture, self.options, self.sc = capture, options, result.scenario
        self.replay = Replay(result, capture)
        self.renderer, self.fast = make_renderer(self.replay.model, options.width, options.height)
        self.gl_renderer = gl_renderer_name()
        self.caption = Caption(options.height)
        self.colors = [follower_rgb(i) for i in range(self.sc.n)]
        self.line_px = max(2.0, options.height / 200)  # trail width, pixels
        from bioform_mj.robots.scene import robot_unit

        self.unit = robot_unit(self.replay.half_track)  # markers and margins at the robots' size (design §9)
        self.trails = Trails(capture, tol=0.015 * self.unit)
        self.centers: np.ndarray | None = None
        if options.camera == "auto":
            fovy = float(self.replay.model.vis.global_.fovy)
            self.centers, self.dists = auto_camera_path(capture, fovy, options.width / options.height, unit=self.unit)
            self.camera: Any = mujoco.MjvCamera()
            self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
            self.camera.azimuth, self.camera.elevation = AZIMUTH, ELEVATION
        else:
            self.camera = options.camera

    def frame(self, k: int) -> np.ndarray:
        """The picture of snapshot ``k``, ``(height, width, 3)`` uint8."""
        import mujoco

        cap, sc, r = self.capture, self.sc, self.renderer
        self.replay.pose(k, cap)
        if self.centers is not None:
            self.camera.lookat[:] = self.centers[k]
            self.camera.distance = self.dists[k]
        r.update_scene(self.replay.data, camera=self.camera)
        if self.fast:  # invisible from these cameras, or not worth a CPU rasteriser's time
            r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        add_geoms(r, cap, self.trails, k, line_px=self.line_px, unit=self.unit)
        img = r.render()
        fe = np.linalg.norm(cap.pose[k][:, :2] - cap.slots[k], axis=1)
        lines = [
            [(f"t = {cap.t[k]:5.2f} s   {sc.method}   {sc.plant.kind} plant", (1.0, 1.0, 1.0))],
            [("leader", LEADER_RGB)] + [(f"   F{i + 1} {fe[i]:.2f} m", self.colors[i]) for i in range(sc.n)],
        ]
        return self.caption.draw(img, lines)

    def close(self) -> None:
        """Free the OpenGL context."""
        self.renderer.close()


def render_video(
    capture: FrameCapture,
    result: Any,
    path: str | Path,
    options: VideoOptions,
    progress: Callable[[int, int], None] | None = None,
) -> VideoInfo:
    """Render the snapshots of ``capture`` (from the run ``result``) into an H.264 MP4 at ``path``.

    Frames are piped to ffmpeg as they are rendered (it encodes in parallel). Written to a
    temporary name and renamed: ``path`` is complete or absent. Raises
    :class:`~bioform_mj.outputs.gl.GLUnavailable` when no OpenGL context can be made.
    """
    import mediapy

    t0 = time.perf_counter()
    path = Path(path)
    frames = FrameRenderer(capture, result, options)
    K = len(capture)
    try:
        set_ffmpeg()
        with atomic_path(path) as tmp:
            with mediapy.VideoWriter(
                tmp,
                shape=(options.height, options.width),
                fps=options.fps,
                codec="h264",
                crf=23,
                ffmpeg_args=["-preset", "veryfast", "-movflags", "+faststart", "-f", "mp4"],
            ) as writer:
                for k in range(K):
                    writer.add_image(frames.frame(k))
                    if progress is not None:
                        progress(k + 1, K)
    finally:
        frames.close()
    return VideoInfo(path, K, options.width, options.height, options.fps, time.perf_counter() - t0, frames.gl_renderer)


def frame_capture(options: VideoOptions) -> FrameCapture:
    """The observer of the registered output ``video`` (:mod:`~bioform_mj.outputs.registry`): snapshots at the
    video's frame rate.

    Parameters
    ----------
    options : VideoOptions
        The video's size, frame rate (frames per second of simulated time) and camera.
    """
    return FrameCapture(options.fps)


def write_video(result: Any, out: Path, watcher: FrameCapture, options: VideoOptions, progress: Any = None) -> str:
    """The registered output ``video``: render ``out/video.mp4`` from the snapshots ``watcher`` took; returns the
    line the CLI prints.

    Parameters
    ----------
    result : RunResult
        The finished run.
    out : Path
        The run folder.
    watcher : FrameCapture
        What :func:`frame_capture` made before the run.
    options : VideoOptions
        The video's size, frame rate and camera.
    progress : callable or None
        ``progress(k, K)`` after each of the ``K`` frames.
    """
    info = render_video(watcher, result, Path(out) / "video.mp4", options, progress=progress)
    return (
        f"video.mp4: {info.frames} frames {info.width}x{info.height} at {info.fps:g} fps "
        f"rendered in {info.render_s:.1f} s ({info.gl_renderer or 'OpenGL'})"
    )


def write_still(
    capture: FrameCapture, result: Any, path: str | Path, options: VideoOptions, t: float | None = None
) -> Path:
    """Write one frame (the snapshot nearest to ``t`` s, default the last) as a PNG, atomically."""
    import mediapy

    k_want = len(capture) - 1 if t is None else int(np.argmin(np.abs(np.asarray(capture.t) - t)))
    frames = FrameRenderer(capture, result, options)
    try:
        img = frames.frame(k_want)  # the trails take in every snapshot up to k_want
    finally:
        frames.close()
    path = Path(path)
    with atomic_path(path) as tmp:
        mediapy.write_image(tmp, img, fmt="png")
    return path


def read_video(path: str | Path) -> np.ndarray:
    """Decode an MP4 into ``(frames, height, width, 3)`` uint8, with imageio-ffmpeg's reader.

    Not mediapy's: mediapy 1.2.7 passes ``-vsync``, which ffmpeg 9 (the one imageio-ffmpeg
    0.8 bundles) removed, so its reader fails there (design §17). imageio-ffmpeg's reader
    passes no ``-vsync``.
    """
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(path))
    try:
        meta = next(gen)
        w, h = meta["size"]
        frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen]
    finally:
        gen.close()
    return np.stack(frames) if frames else np.zeros((0, h, w, 3), np.uint8)
