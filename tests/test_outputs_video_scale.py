"""Video markers and camera framing scale with the robots: a TurtleBot team is drawn as the paper's is."""

from __future__ import annotations

import numpy as np
import pytest

from bioform_mj.robots.scene import robot_unit


def test_robot_unit_is_the_half_track_relative_to_the_paper_robot():
    assert robot_unit([0.2, 0.2, 0.2]) == 1.0
    assert robot_unit([0.08, 0.08, 0.08]) == pytest.approx(0.4)  # tb3
    assert robot_unit([0.2, 0.09, 0.2]) == 1.0  # hetero: the median robot


@pytest.fixture(scope="module")
def tb3_frames():
    from bioform_mj.outputs.gl import GLUnavailable, probe

    try:
        probe()
    except GLUnavailable as exc:
        pytest.skip(f"no OpenGL context in this process ({exc})")
    from bioform_mj.outputs.video import FrameCapture
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    sc = load("tb3", ["sim.duration=0.5"], plant="mujoco")
    cap = FrameCapture(fps=10)
    res = simulate(sc, observers=[cap])
    return cap, res


def _segment(fr, k, unit):
    """Segmentation of frame ``k`` as the video draws it, decorations included, with ``unit`` for the
    markers and the camera; returns (pixels per robot, pixels of each robot's halo, robot pixel columns)."""
    import mujoco

    from bioform_mj.outputs.video import Trails, add_geoms, auto_camera_path
    from bioform_mj.robots.scene import follower_prefix

    cap, r, m = fr.capture, fr.renderer, fr.replay.model
    fovy = float(m.vis.global_.fovy)
    centers, dists = auto_camera_path(cap, fovy, fr.options.width / fr.options.height, unit=unit)
    fr.replay.pose(k, cap)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.azimuth, cam.elevation = fr.camera.azimuth, fr.camera.elevation
    cam.lookat[:], cam.distance = centers[k], dists[k]
    r.update_scene(fr.replay.data, camera=cam)
    first = r.scene.ngeom
    add_geoms(r, cap, Trails(cap, tol=0.015 * unit), k, line_px=2.0, unit=unit)
    n = cap.pose[k].shape[0]
    for j in range(first, r.scene.ngeom):  # mark each follower's halo: a disc of radius 0.3 unit at its pose
        g = r.scene.geoms[j]
        g.segid = j
        g.objtype, g.objid = int(mujoco.mjtObj.mjOBJ_UNKNOWN), -100
        if g.type == mujoco.mjtGeom.mjGEOM_CYLINDER and abs(g.size[0] - 0.3 * unit) < 1e-6:
            d = np.linalg.norm(cap.pose[k][:, :2] - np.array(g.pos[:2]), axis=1)
            if d.min() < 1e-4:  # mjvGeom holds float32
                g.objid = 1000 + int(d.argmin())
    r.enable_segmentation_rendering()
    try:
        seg = r.render()
    finally:
        r.disable_segmentation_rendering()
    body_of = m.geom_bodyid
    names = [m.body(b).name for b in range(m.nbody)]
    robot_px, halo_px, cols = [], [], []
    for i in range(n):
        pre = follower_prefix(i)
        geoms = [g for g in range(m.ngeom) if names[body_of[g]].startswith(pre)]
        mask = (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & np.isin(seg[..., 0], geoms)
        robot_px.append(int(mask.sum()))
        cols.append(np.flatnonzero(mask.any(axis=0)))
        halo_px.append(int((seg[..., 0] == 1000 + i).sum()))
    return np.array(robot_px), np.array(halo_px), cols


def test_tb3_robots_are_visible_and_not_swamped_by_their_halos(tb3_frames):
    from bioform_mj.outputs.video import FrameRenderer, VideoOptions

    cap, res = tb3_frames
    fr = FrameRenderer(cap, res, VideoOptions(width=480, height=270))
    try:
        assert fr.unit == pytest.approx(0.4)  # tb3's half track 0.08 m against the paper robot's 0.2 m
        k = len(cap) - 1
        rgb = fr.frame(k)
        assert rgb.shape == (270, 480, 3) and rgb.std() > 10
        robot, halo, cols = _segment(fr, k, fr.unit)
        old_robot, old_halo, _cols = _segment(fr, k, 1.0)  # the fixed paper-scale sizes
    finally:
        fr.close()
    # every robot shows (measured 327-444 pixels at 480 x 270); its visible halo ring is a rim of it (958-1279 px)
    assert np.all(robot >= 150), robot
    assert np.all(halo <= 4.0 * robot), (halo, robot)
    # the formation fills a good part of the frame (robot columns from the leftmost to the rightmost robot)
    span = max(c.max() for c in cols) - min(c.min() for c in cols)
    assert span >= 0.3 * 480, span  # measured 217 px
    # the paper-scale sizes (halo 0.3 m, slot 0.18 m, 1 m margin) hid robots under their discs: 0 pixels
    assert old_robot.min() < 0.25 * robot.min(), (old_robot, old_halo)
