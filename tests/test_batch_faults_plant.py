"""Actuator faults and pushes on the batch engine (MuJoCo Warp, Warp's CPU device): each world its own
``faults.actuator`` / ``faults.push`` rows (and its own ``actuator_known``) in one batch, against
``sim.simulate`` of each world's scenario (which runs ``faults.Faults`` stepwise).

Per world the criterion of issue 13 (``batch.agreement``): final formation error within 1 mm, ``ĉ``
within 0.5 %, total velocity error within 1 %; every follower here meets it outright (measured
numbers in the test). Beyond the summaries, every control step's inputs are compared: the chassis
``xfrc_applied`` the device wrote (``BatchRun.record``) against the CPU plant's, and the wheel
``ctrl`` against the reduced limits, so a fault ignored, late, early, or applied to another world or
follower fails here.

Pushes act on followers 1 and 3: follower 2 of this scene is float32-sensitive after a push (a
200 N push at seed 1 gives a CPU float32 spread of 79 % in ``ĉ``; 40 N still 0.28 %), which
would test the scene, not the engine (design §11)."""

import dataclasses

import numpy as np
import pytest

wp = pytest.importorskip("warp")
pytest.importorskip("mujoco_warp")

from bioform_mj.batch.agreement import TOLERANCES, differences  # noqa: E402
from bioform_mj.run.simulate import make_plant, simulate  # noqa: E402
from bioform_mj.scenario.loader import load  # noqa: E402

wp.config.quiet = True
BASE = {"plant.kind": "mujoco", "sim.duration": 0.5, "formation.init_jitter": 0.05}
TAU = 5.0  # N·m, the paper robot's wheel torque limit
#: per world: its faults and seed (control_dt = 1 ms: t = 0.1 s is control step 100)
WORLDS = [
    # (a) follower 1 at 20 % in [0.1, 0.35) s, the controller told
    {"faults.actuator": [[1, 0.1, 0.35, 0.2]], "faults.actuator_known": True, "sim.seed": 0},
    # (b) the same row not told, and two overlapping rows on follower 3: 50 % in [0.2, 0.3),
    # 30 % in [0.25, 0.45) → limits 2.5, 1.5, 1.5 N·m over [200, 250), [250, 300), [300, 450)
    {
        "faults.actuator": [[1, 0.1, 0.35, 0.2], [3, 0.2, 0.3, 0.5], [3, 0.25, 0.45, 0.3]],
        "faults.actuator_known": False,
        "sim.seed": 0,
    },
    # (c) a push on follower 1, steps [100, 300)
    {"faults.push": [[1, 0.1, 0.2, 40.0, -40.0, 1.0]], "sim.seed": 1},
    # (c') two pushes on follower 3: the second (t = 0.2505 s → step 251, between control steps)
    # replaces the first, which would have lasted to step 400; it ends at step 351
    {"faults.push": [[3, 0.1, 0.3, 40.0, 40.0, 1.0], [3, 0.2505, 0.1, -60.0, 20.0, -1.0]], "sim.seed": 3},
    {"sim.seed": 1},  # no fault (the tables' padding rows)
]


def _scenarios():
    return [load("paper", {**BASE, **w}) for w in WORLDS]


def _cpu(sc):
    """``sim.simulate`` (stepwise) recording each control period's ``ctrl`` (N, nu) and chassis
    ``xfrc_applied`` (N, n, 6) as the plant got them."""
    plant = make_plant(sc)
    step, ctrl, xfrc = plant.step, [], []

    def recording_step(tau, t):
        step(tau, t)
        ctrl.append(plant.data.ctrl.copy())
        xfrc.append(plant.data.xfrc_applied[plant._base].copy())

    plant.step = recording_step
    summary = simulate(sc, plant=plant, engine="stepwise").summary
    return summary, np.array(ctrl), np.array(xfrc), plant


@pytest.fixture(scope="module")
def runs():
    """The batch (summaries of a full run, then the inputs of every control step) and the CPU runs."""
    from bioform_mj.batch.runner import BatchRun

    scs = _scenarios()
    b = BatchRun(scs, device="cpu")
    res = b.summaries(b.run())
    b.record()
    rec_ctrl, rec_xfrc = b.rec_ctrl.numpy(), b.rec_xfrc.numpy()  # (N, W, nu), (N, W, n, 6)
    cpu = [_cpu(sc) for sc in scs]
    return scs, b, res, rec_ctrl, rec_xfrc, cpu


def test_plant_faults_are_supported_and_not_part_of_the_scene():
    from bioform_mj.batch.backend import group_key
    from bioform_mj.batch.support import unsupported

    scs = _scenarios()
    assert all(unsupported(sc) is None for sc in scs)
    assert len({group_key(sc) for sc in scs}) == 1  # one batch for different faults
    # with the network faults too (tests/test_batch_faults_comm.py)
    sc = load("paper", {**BASE, "faults.push": [[1, 0.1, 0.2, 40.0, 0.0, 0.0]], "faults.packet_loss": 0.1})
    assert unsupported(sc) is None


def test_fault_tables_resolve_times_as_the_cpu_loop():
    """Row times to control steps by ``Faults.step``'s own comparisons at ``t = k dt``."""
    from bioform_mj.batch.tables import plant_fault_tables

    scs = _scenarios()
    tab = plant_fault_tables(scs, 500, 1e-3)
    assert tab["act_i"].shape == (5, 3) and tab["push_i"].shape == (5, 2)
    np.testing.assert_array_equal(tab["act_known"], [1, 0, 1, 1, 1])
    np.testing.assert_array_equal(tab["act_i"][1], [0, 2, 2])
    np.testing.assert_array_equal(tab["act_k0"][1], [100, 200, 250])
    np.testing.assert_array_equal(tab["act_k1"][1], [350, 300, 450])
    np.testing.assert_array_equal(tab["act_i"][0], [0, -1, -1])  # padding: never active
    assert np.all(tab["act_k0"][0, 1:] == 501)
    np.testing.assert_array_equal(tab["push_i"][3], [2, 2])
    np.testing.assert_array_equal(tab["push_k0"][3], [100, 251])
    np.testing.assert_array_equal(tab["push_k1"][3], [400, 351])
    np.testing.assert_array_equal(tab["push_w"][3, 1], [-60.0, 20.0, -1.0])
    np.testing.assert_array_equal(tab["push_i"][4], [-1, -1])
    # rows sorted by t (stable), as Faults: the later row of equal t is started last (replaces)
    sc = load("paper", {**BASE, "faults.push": [[2, 0.3, 0.1, 1.0, 0, 0], [2, 0.1, 0.1, 2.0, 0, 0]]})
    tab = plant_fault_tables([sc], 500, 1e-3)
    np.testing.assert_array_equal(tab["push_k0"][0], [100, 300])
    np.testing.assert_array_equal(tab["push_w"][0, :, 0], [2.0, 1.0])


def test_plant_faults_per_world_match_cpu_engine(runs):
    scs, _, res, _, _, cpu = runs
    worst = dict.fromkeys(TOLERANCES, 0.0)
    for w, (r, (ref, *_)) in enumerate(zip(res, cpu)):
        assert not r["diverged"], r["diverged_reason"]
        assert ref["diverged"] is None
        for i, d in enumerate(differences(ref, r)):
            for k, tol in TOLERANCES.items():
                worst[k] = max(worst[k], d[k])
                assert d[k] <= tol, (w, i + 1, k, d[k])
    # Measured (Warp CPU device), per world the largest over its followers (formation m, ĉ rel,
    # velocity error rel): (a) 9.4e-6, 2.6e-3, 6.0e-4 (b) 2.1e-6, 2.6e-6, 8.4e-6 (c) 1.3e-6, 1.4e-6,
    # 3.4e-6 (c') 2.2e-6, 1.1e-6, 1.2e-6. The 2.6e-3 is (a)'s follower 2, not faulted: the same
    # follower and seed without faults is 2.6e-3 off too, inside its CPU float32 spread 1.25e-2
    # (agreement.float32_spread, 6 draws); the faulted followers agree to ≤ 4.3e-7 (a), ≤ 2.3e-6.
    print("largest differences:", worst)


def test_faults_change_the_outcome_of_their_own_follower(runs):
    """Each fault moves its own follower's CPU outcome by far more than the tolerances and leaves the
    others as without it; the device follows (a fault ignored on the device, or applied to another
    world or follower, fails the agreement test). ``actuator_known`` matters per world."""
    scs, _, res, _, _, cpu = runs
    hit = {0: [1], 1: [1, 3], 2: [1], 3: [3]}
    for w, targets in hit.items():
        plain = simulate(dataclasses.replace(scs[w], faults=dataclasses.replace(scs[w].faults, actuator=(), push=())))
        for i, d in enumerate(differences(plain.summary, cpu[w][0])):
            big = d["c_hat_rel"] > 10 * TOLERANCES["c_hat_rel"] or d["vel_err_rel"] > 10 * TOLERANCES["vel_err_rel"]
            assert big == (i + 1 in targets), (w, i + 1, d)
    # known vs not: the same row on follower 1 of worlds (a) and (b)
    ab = differences(res[0], res[1])[0]
    print("follower 1, told vs not told:", ab)
    assert ab["c_hat_rel"] > 10 * TOLERANCES["c_hat_rel"] or ab["vel_err_rel"] > 10 * TOLERANCES["vel_err_rel"]


def test_pushes_act_in_their_steps_on_their_follower(runs):
    """Every control period's chassis force and yaw torque on the device is the CPU plant's (the
    disturbance of eq. 34 plus the push, ``MujocoPlant._apply_push``): a push one step early or late,
    on another follower or world, or not replaced, is 40–60 N off somewhere."""
    scs, b, _, _, rec_xfrc, cpu = runs
    N = b.N
    for w in range(len(scs)):
        x = cpu[w][2]
        assert x.shape == (N, 3, 6)
        dx = np.abs(rec_xfrc[:, w] - x).max()
        assert dx < 2e-3, (w, dx)  # measured ≤ 9.0e-4 N (the disturbance's heading: float32 state)
    # the push itself (the disturbance is ≤ 2.5 N here): world (c) follower 1 in steps [100, 300)
    f = np.abs(rec_xfrc[:, 2, :, :2]).max(axis=-1)  # (N, n) N
    k = np.arange(N)
    on = (k >= 100) & (k < 300)
    assert np.all(f[on, 0] > 30) and np.all(f[~on, 0] < 3) and np.all(f[:, 1:] < 3)
    assert np.all(np.abs(rec_xfrc[on, 2, 0, 5] - 1.0) < 0.3)  # tz = 1 N·m (+ the disturbance's yaw)
    # world (c'): follower 3 pushed by the first row in [100, 251), by the second in [251, 351), then nothing
    fx = rec_xfrc[:, 3, 2, 0]
    assert np.all(np.abs(fx[100:251] - 40.0) < 3) and np.all(np.abs(fx[251:351] + 60.0) < 3)
    assert np.all(np.abs(fx[:100]) < 3) and np.all(np.abs(fx[351:]) < 3)
    assert np.all(np.abs(rec_xfrc[:, 3, :2, :2]) < 3)
    for w in (0, 1, 4):  # no pushes: the disturbance only
        assert np.all(np.abs(rec_xfrc[:, w, :, :2]) < 3)


def test_actuator_limits_act_in_their_steps_on_their_follower(runs):
    """The device's wheel ``ctrl`` (torque motors: N·m) stays within the reduced limit exactly in the
    fault's control steps, on its follower, and reaches the nominal one just outside them; the CPU's
    does the same."""
    scs, b, _, rec_ctrl, _, cpu = runs
    ids = np.asarray(b.plant._ctrl)  # (n, 2) the wheels' actuator ids
    k = np.arange(b.N)
    # world, follower, [(k0, k1, limit N·m)]
    cases = [
        (0, 0, [(100, 350, 0.2 * TAU)]),
        (1, 0, [(100, 350, 0.2 * TAU)]),
        (1, 2, [(200, 250, 0.5 * TAU), (250, 450, 0.3 * TAU)]),
    ]
    for w, i, windows in cases:
        for u in (rec_ctrl[:, w], cpu[w][1]):
            tau = np.abs(u[:, ids[i]]).max(axis=1)  # (N,)
            faulted = np.zeros(b.N, bool)
            for k0, k1, lim in windows:
                assert tau[k0:k1].max() <= lim * (1 + 1e-6), (w, i, k0, tau[k0:k1].max())
                assert tau[k0:k1].max() >= lim * (1 - 1e-6)  # the reduced limit is reached
                faulted |= (k >= k0) & (k < k1)
            k0, k1 = windows[0][0], windows[-1][1]
            assert tau[k0 - 10 : k0].max() > 0.9 * TAU and tau[k1 : k1 + 10].max() > 0.9 * TAU, (w, i)
        for j in range(3):  # the other followers keep the nominal limit
            if j != i and all(c[:2] != (w, j) for c in cases):
                assert np.abs(rec_ctrl[:, w][:, ids[j]]).max() > 0.9 * TAU
    # world (c) (pushes only) and (no fault): nominal limits
    for w in (2, 3, 4):
        assert np.abs(rec_ctrl[100:350, w][:, ids[0]]).max() > 0.9 * TAU
