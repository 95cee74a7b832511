"""Frames of the formation environment (``render_mode = "rgb_array"``; design §20).

The pictures are those of ``bioform run --video`` (:mod:`bioform_mj.outputs.video`): the same
posed scene (the MuJoCo plant's own model, or the scenario's robots composed for the ideal
plant), the same trails, halos, slot discs and caption, drawn by the same functions. Only the
camera differs: ``--video`` smooths its automatic camera over the whole run, known in advance;
an environment knows only the frames so far, so the camera follows the last second of them.

``render_mode = "human"`` shows the same frames in a matplotlib window (:class:`HumanWindow`): with a
display and an interactive backend (``MPLBACKEND=TkAgg``, Qt, ...); where matplotlib has none (no display:
its ``agg`` backend) it warns once that nothing is shown, and ``render()`` still returns None.

Off-screen OpenGL: ``MUJOCO_GL=egl`` (works here, with Mesa's llvmpipe or a GPU's EGL) or
``osmesa``, set before MuJoCo is first imported; without one, :meth:`EnvRenderer.frame` raises
:class:`~bioform_mj.outputs.gl.GLUnavailable` (a ``ValueError``-free ``InputError``) saying so.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

#: frame size, pixels (``bioform run --video``'s default)
WIDTH, HEIGHT = 960, 540


class _Window:
    """The last ``size`` frames of a capture, as :func:`~bioform_mj.outputs.video.auto_camera_path` reads them."""

    def __init__(self, capture: Any, size: int) -> None:
        for name in ("t", "pose", "vel", "leader", "slots"):
            setattr(self, name, getattr(capture, name)[-size:])
        self.fps = capture.fps

    def __len__(self) -> int:
        return len(self.t)


class EnvRenderer:
    """Renders the environment's current state; one per environment, its frames kept per episode
    (the trails grow with them). ``width`` × ``height`` pixels; ``fps``: frames per second of
    simulated time the caller means to take (the camera smooths over one second of them)."""

    def __init__(
        self, env: Any, width: int = WIDTH, height: int = HEIGHT, fps: float = 30.0, window: bool = False
    ) -> None:
        from bioform_mj.outputs.gl import make_renderer
        from bioform_mj.outputs.video import Caption, FrameCapture, Replay, follower_rgb
        from bioform_mj.robots.scene import robot_unit

        self.width, self.height = int(width), int(height)
        self.capture = FrameCapture(fps)
        self._sample(env)
        self.replay = Replay(SimpleNamespace(scenario=env._sc, plant=env._plant), self.capture)
        self.renderer, self.fast = make_renderer(self.replay.model, self.width, self.height)
        self.caption = Caption(self.height)
        self.colors = [follower_rgb(i) for i in range(env.n)]
        self.line_px = max(2.0, self.height / 200)
        self.unit = robot_unit(self.replay.half_track)
        self._fresh = True  # the capture's one frame is the state now: frame() draws it without sampling
        self.window = HumanWindow(env.metadata.get("render_fps", fps)) if window else None

    def _sample(self, env: Any) -> None:
        """Append the environment's state now to the capture (as ``FrameCapture.sample`` does in a run)."""
        from bioform_mj.assess.outcomes import slots_of

        c, k = self.capture, env.k
        lp = env.L_pose[k]
        c.t.append(k * env.dt)
        c.pose.append(np.array(env._pose, dtype=float))
        c.vel.append(np.array(env._vel, dtype=float))
        c.leader.append(np.array(lp, dtype=float))
        c.slots.append(np.array(slots_of(env._sc, lp), dtype=float))
        if hasattr(env._plant, "model"):
            c.qpos.append(env._plant.data.qpos.copy())

    def new_episode(self, env: Any) -> None:
        """Forget the last episode's frames (its trails)."""
        for name in ("t", "pose", "vel", "leader", "slots", "qpos"):
            getattr(self.capture, name).clear()
        if hasattr(self.replay, "wheel"):
            self.replay.wheel[:] = 0.0
        self._fresh = False

    def frame(self, env: Any) -> np.ndarray:
        """The picture of the environment now, ``(height, width, 3)`` uint8."""
        import mujoco

        from bioform_mj.outputs.video import AZIMUTH, ELEVATION, LEADER_RGB, Trails, add_geoms, auto_camera_path

        if not self._fresh:
            self._sample(env)
        self._fresh = False
        cap, sc, r = self.capture, env._sc, self.renderer
        k = len(cap) - 1
        self.replay.pose(k, cap)
        fovy = float(self.replay.model.vis.global_.fovy)
        win = _Window(cap, max(1, int(round(cap.fps))))
        centers, dists = auto_camera_path(win, fovy, self.width / self.height, unit=self.unit)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.azimuth, cam.elevation = AZIMUTH, ELEVATION
        cam.lookat[:] = centers[-1]
        cam.distance = float(dists[-1])
        r.update_scene(self.replay.data, camera=cam)
        if self.fast:
            r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        add_geoms(r, cap, Trails(cap, tol=0.015 * self.unit), k, line_px=self.line_px, unit=self.unit)
        img = r.render()
        fe = np.linalg.norm(cap.pose[k][:, :2] - cap.slots[k], axis=1)
        lines = [
            [(f"t = {cap.t[k]:5.2f} s   {sc.method}   {sc.plant.kind} plant", (1.0, 1.0, 1.0))],
            [("leader", LEADER_RGB)] + [(f"   F{i + 1} {fe[i]:.2f} m", self.colors[i]) for i in range(env.n)],
        ]
        return np.ascontiguousarray(self.caption.draw(img, lines), dtype=np.uint8)

    def show(self, env: Any) -> np.ndarray | None:
        """``render()``'s result: the frame (``rgb_array``), or None after showing it in the window (``human``)."""
        if self.window is None:
            return self.frame(env)
        if self.window.interactive:
            self.window.show(self.frame(env))
        return None

    def close(self) -> None:
        """Free the OpenGL context (and close the window)."""
        self.renderer.close()
        if self.window is not None:
            self.window.close()


class HumanWindow:
    """``render_mode = "human"``: frames shown in one matplotlib figure, paced at ``fps`` frames per second
    of wall time at most. ``interactive``: whether matplotlib's backend can show a window; where it cannot
    (no display: ``agg``), a ``UserWarning`` says so once and :meth:`show` is not called."""

    def __init__(self, fps: float) -> None:
        import warnings

        import matplotlib
        from matplotlib.backends import BackendFilter, backend_registry

        self.backend = str(matplotlib.get_backend()).lower()
        self.interactive = self.backend in backend_registry.list_builtin(BackendFilter.INTERACTIVE)
        self.pause = 1.0 / float(fps)
        self.fig = self.image = None
        if not self.interactive:
            warnings.warn(
                f"render_mode='human' shows frames in a matplotlib window, but matplotlib's backend is "
                f"{self.backend!r} (no display here): nothing is shown; use render_mode='rgb_array' and write "
                "the frames to a video (docs/envs.md)",
                UserWarning,
                stacklevel=4,
            )

    def show(self, frame: np.ndarray) -> None:
        import matplotlib.pyplot as plt

        if self.fig is None or not plt.fignum_exists(self.fig.number):
            self.fig, ax = plt.subplots(figsize=(frame.shape[1] / 100, frame.shape[0] / 100), dpi=100)
            ax.set_position((0, 0, 1, 1))
            ax.set_axis_off()
            self.image = ax.imshow(frame)
        else:
            self.image.set_data(frame)
        plt.pause(self.pause)

    def close(self) -> None:
        if self.fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self.fig)
            self.fig = None
