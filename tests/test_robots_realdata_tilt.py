"""A recording whose robot lifted off its wheels or tipped over (issue 29, "never silent"): ``robot fit`` and
``robot replay`` use only the part before the body tilted more than ``TIP_DEG`` and say so; where less than one
chunk comes before it, one ``error:`` line and exit 2. The recording is the test-only recorder's (no project
code); the tilt is written into its odometry, a rotation about the body x axis from t = 3 s."""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

sys.path.insert(0, str(Path(__file__).parent))
import realdata_recorder as rr  # noqa: E402
from bioform_mj.cli import main as cli  # noqa: E402
from bioform_mj.robots.realdata.recording import TIP_DEG, Recording, tipped_at  # noqa: E402

TRUTH = rr.Truth(payload_kg=0.3, damping=(0.002, 0.0025), frictionloss=(0.004, 0.003))


def _roll(deg: float) -> np.ndarray:
    """A unit quaternion (w, x, y, z) turning by ``deg`` about x, composed with a yaw of 40° (z)."""
    r, y = math.radians(deg) / 2, math.radians(40.0) / 2
    qz = np.array([math.cos(y), 0.0, 0.0, math.sin(y)])
    qx = np.array([math.cos(r), math.sin(r), 0.0, 0.0])
    w1, x1, y1, z1 = qz
    w2, x2, y2, z2 = qx
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])  # fmt: skip


def test_tilt_is_the_angle_of_the_roll_whatever_the_yaw():
    t = np.arange(6.0)
    tilts = [0.0, 1.0, 5.0, TIP_DEG + 2.0, 90.0, 30.0]
    pose = np.array([[0, 0, 0, *_roll(d)] for d in tilts])
    z = np.zeros((6, 2))
    rec = Recording("x", ("l", "r"), t, z, z, z, t, np.zeros((6, 6)), pose)
    at, worst = tipped_at(rec)
    assert at == 3.0 and worst == pytest.approx(90.0, abs=1e-9)
    upright = Recording("x", ("l", "r"), t[:3], z[:3], z[:3], z[:3], t[:3], np.zeros((3, 6)), pose[:3])
    assert tipped_at(upright) is None
    no_orientation = Recording("x", ("l", "r"), t, z, z, z, t, np.zeros((6, 6)), np.zeros((6, 7)))
    assert tipped_at(no_orientation) is None  # a driver that publishes no orientation: nothing said


@pytest.fixture(scope="module")
def tipped_bag(tmp_path_factory) -> Path:
    """6 s of the tb3 at its own torques; its odometry rolls 45° from t = 3 s."""
    model = rr.true_model(rr.MODELS / "tb3_robot.xml", TRUTH)
    sim = rr.simulate(model, TRUTH, 6.0, 0.02, 3)
    late = sim["t"] >= 3.0
    sim["quat"][late] = _roll(45.0)
    p = tmp_path_factory.mktemp("tilt") / "bag"
    rr.write_bag(p, sim, TRUTH, seed=4)
    return p


def test_replay_uses_the_part_before_the_tilt_and_says_so(tipped_bag, capsys):
    assert cli.main(["robot", "replay", "tb3", "--bag", str(tipped_bag)]) == 0
    out, err = capsys.readouterr()
    (warn,) = [ln for ln in err.splitlines() if "tilted" in ln]
    assert warn.startswith("warning: ") and "45°" in warn
    t_tip = float(re.search(r"at t = ([0-9.]+) s", warn).group(1))
    assert 3.0 <= t_tip <= 3.02  # the first odometry sample rolled (100 Hz)
    used = float(re.search(r"open loop over ([0-9.]+) s", out).group(1))
    assert used == pytest.approx(t_tip - 0.1, abs=0.011)  # the part before, less 0.1 s before the threshold


def test_fit_refuses_when_less_than_a_chunk_comes_before_the_tilt(tipped_bag, tmp_path, capsys):
    out = tmp_path / "fit"
    assert cli.main(["robot", "fit", "tb3", "--bag", str(tipped_bag), "--chunk", "3", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "tilted more than" in err[0], err
    assert not out.exists()
