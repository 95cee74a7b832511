"""Every feature the batch engine runs, at once, in one batch (Warp's CPU device): DC motors fed
the delivered torque, odometry sensing with gyro noise and bias, offsets in the leader's frame on
a turning leader, timed payload events and per-step faults (network, noise, actuator, push)
differing per world, each world also with its own seed and command-derivative mode. Each world
agrees with ``sim.simulate`` of its own scenario by the project's per-world criterion
(``batch/agreement.py``, design §11: issue 13's tolerances, or 2 × the world's own float32
spread), and ``odometry_drift_m`` within 1 mm. The features compose: a kernel that dropped one
of them in combination would fail here although its own test passes."""

import numpy as np
import pytest

wp = pytest.importorskip("warp")
pytest.importorskip("mujoco_warp")

from bioform_mj.batch.agreement import TOLERANCES, differences, float32_spread, judge  # noqa: E402
from bioform_mj.scenario.loader import load  # noqa: E402

wp.config.quiet = True

BASE = (
    "plant.kind=mujoco",
    "sim.duration=0.4",
    "sim.control_dt=0.01",  # 100 Hz: an encoder count is a small kick (tests/test_batch_odometry.py)
    "sim.log_dt=0.01",
    "formation.init_jitter=0.05",
    'plant.robots=[{model="paper", motor="dc", driver="voltage"}]',
    "plant.sensing=odometry",
    "plant.encoder_cpr=4096",
    "plant.gyro_noise=0.01",
    "plant.gyro_bias=0.005",
    "formation.frame=leader",
    "leader.kind=circle",
    "leader.x0=0",
    "leader.y0=8",
    "leader.radius=5",
    "leader.speed=1",
)
#: per world: seed, derivative mode, events and per-step faults
WORLDS = [
    (
        0,
        "difference",
        [
            'events=[{kind="payload", follower=2, time=0.15, mass=8.0, inertia=0.2}]',
            "faults.packet_loss=0.2",
            "faults.delay=0.02",
        ],
    ),
    (1, "analytic", ["faults.actuator=[[2,0.1,0.3,0.5]]", "faults.push=[[3,0.1,0.1,40.0,0.0,1.0]]"]),
    (
        2,
        "filter",
        [
            'events=[{kind="payload", follower=1, time=0.0, mass=3.0, inertia=0.05}]',
            "faults.noise_pose=[0.01,0.01,0.01]",
            "faults.link_fail=[[1,2,0.1,0.25]]",
        ],
    ),
]


@pytest.mark.slow  # ≥ 7 s warm here (make test keeps to the fast set; make test-slow runs it)
def test_all_device_features_in_one_batch_agree_per_world():
    from bioform_mj.batch.runner import run_batch
    from bioform_mj.batch.support import unsupported

    scs = [load("paper", overrides=[*BASE, f"sim.seed={s}", f"torque.derivative={m}", *ev]) for s, m, ev in WORLDS]
    assert all(unsupported(sc) is None for sc in scs)
    res = run_batch(scs, device="cpu")
    finals, outright = [], []
    for w, (sc, r) in enumerate(zip(scs, res)):
        assert not r["diverged"], r["diverged_reason"]
        ref, spread = float32_spread(sc, realisations=4, seed=w)
        diff = differences(ref, r)
        for i, (d, s, v) in enumerate(zip(diff, spread, judge(diff, spread))):
            assert v["ok"], (w, i, d, s)
            outright.append(all(v[k] == "tolerance" for k in TOLERANCES))
        for a, b in zip(r["followers"], ref["followers"], strict=True):
            assert abs(a["odometry_drift_m"] - b["odometry_drift_m"]) < 1e-3
            assert a["odometry_drift_m"] > 0.0  # the odometry ran (bias and noise: it drifts)
            np.testing.assert_allclose(a["c_true"], b["c_true"], rtol=1e-9)  # post-payload ground truth
        finals.append([f["final_formation_error_m"] for f in r["followers"]])
    # measured: all 9 followers within the tolerances outright (≤ 2.9e-6 m, ĉ ≤ 6.3e-6, velocity error
    # ≤ 3.7e-6); without the faults seed 2's follower 2 (filter) was 5.2 % off in ĉ, inside its own
    # spread of 19 % (the scene's ill-conditioned follower, design §11): one such follower is allowed
    assert sum(outright) >= len(outright) - 1, outright
    assert np.abs(np.diff(np.array(finals), axis=0)).max() > 1e-3  # three different runs
