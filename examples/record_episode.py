#!/usr/bin/env python3
"""Record an episode of the formation environment as a video and as a rerun recording.

The frames are the environment's ``render_mode="rgb_array"`` frames (the renderer of ``bioform run
--video``; needs off-screen OpenGL: ``MUJOCO_GL=egl``); the policy here is the paper's controller
(``ControllerPolicy``), any ``obs dict -> action dict`` callable will do. The rerun recording holds
each frame and each follower's formation error (m) on the ``sim_time`` timeline (s):

    MUJOCO_GL=egl .venv/bin/python examples/record_episode.py --out runs/episode
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported

import mediapy  # noqa: E402
import rerun as rr  # noqa: E402

from bioform_mj.envs import ControllerPolicy, parallel_env  # noqa: E402
from bioform_mj.outputs.video import set_ffmpeg  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", choices=("ideal", "mujoco"), default="mujoco")
    ap.add_argument("--duration", type=float, default=3.0, help="episode length, s")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("runs/episode"))
    a = ap.parse_args()
    ov = [f"plant.kind={a.plant}", "sim.control_dt=0.01", f"sim.duration={a.duration}"]
    env = parallel_env(a.scenario, action="torque", overrides=ov, render_mode="rgb_array")
    policy = ControllerPolicy(env)
    a.out.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("bioform_episode")
    rec.save(str(a.out / "episode.rrd"))

    obs, _ = env.reset(seed=a.seed)
    policy.reset()
    frames = []
    while True:
        frame = env.render()
        frames.append(frame)
        rec.set_time("sim_time", duration=env.k * env.dt)
        rec.log("frame", rr.Image(frame))
        for i, e in enumerate(env._formation_error(env.k)):
            rec.log(f"follower/{i + 1}/formation_error", rr.Scalars(float(e)))
        if not env.agents:
            break
        obs, *_ = env.step(policy(obs))
    rec.flush()
    env.close()
    set_ffmpeg()
    mediapy.write_video(a.out / "episode.mp4", frames, fps=round(1 / env.dt))
    print(f"{len(frames)} frames: {a.out / 'episode.mp4'}, {a.out / 'episode.rrd'}")


if __name__ == "__main__":
    main()
