"""`bioform run --rosbag`: the run as a ROS 2 bag, read back with rosbags' own reader and compared with
log.npz number by number; the 3-D state the log gains (simulate(full_state=True)) leaves every other
channel as it was; bad input says how to install the extra; --overwrite knows the bag folder."""

from __future__ import annotations

import importlib.util
import json
import warnings

import numpy as np
import pytest

from bioform_mj.cli.main import main
from bioform_mj.outputs.fullstate import quat_of_rpy, quat_of_yaw, rpy_of_quat
from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load

needs_rosbags = pytest.mark.skipif(importlib.util.find_spec("rosbags") is None, reason="the ros extra is not installed")


def _read(bag):
    """{topic: [(log time ns, message)]} and the connections, with rosbags' reader and jazzy's typestore."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    out: dict[str, list] = {}
    with Reader(bag) as rd:
        conns = {c.topic: c for c in rd.connections}
        for c, t, raw in rd.messages():
            out.setdefault(c.topic, []).append((t, store.deserialize_cdr(raw, c.msgtype)))
    return out, conns, store


def _raw(bag, topic) -> list[bytes]:
    """The serialised messages of ``topic``, as stored."""
    from rosbags.rosbag2 import Reader

    with Reader(bag) as rd:
        return [bytes(raw) for _, _, raw in rd.messages(connections=[c for c in rd.connections if c.topic == topic])]


def test_metadata_yaml_reads_back_as_written():
    """The one-pass YAML writer of the bag's metadata (outputs/rosbag_write.py): what a YAML reader (ruamel,
    as rosbags reads metadata.yaml) makes of it is the data, for the strings YAML treats specially."""
    from ruamel.yaml import YAML

    from bioform_mj.outputs.rosbag_write import yaml_text

    nasty = [
        "",
        "true",
        "No",
        "null",
        "~",
        "1.0",
        "0x1F",
        "-",
        "- a",
        "a: b",
        "#x",
        "x #y",
        "'q'",
        '"dq"',
        "é ü 中",
        "line\nbreak",
        "tab\tx",
        "\x7f\x85",
        "\u2028",
        "[1]",
        "{a}",
        "@x",
        "%x",
        "*a",
        "&a",
        "!t",
        "|",
        ">",
        "/f1/joint_states",
        "RIHS01_0123abc",
        "keep_last",
        "  padded  ",
    ]
    data = {
        "version": 9,
        "flag": True,
        "none": None,
        "x": 1.5,
        "empty_list": [],
        "empty_map": {},
        "strings": nasty,
        "maps": [{"name": v, "n": i, "sub": {"deep": [v, {"k": v}]}} for i, v in enumerate(nasty)],
        "custom_data": {"bioform_mj": json.dumps({"a": nasty})},
        "weird key: x": "v",
    }
    back = YAML(typ="safe").load(yaml_text(data))
    assert back == data
    assert YAML(typ="safe").load(yaml_text([])) == [] and yaml_text("keep_last") == "keep_last"


def _stamp(m) -> int:
    return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec


def _xyzw(q) -> np.ndarray:
    return np.array([q.w, q.x, q.y, q.z])


@needs_rosbags
def test_mujoco_odometry_bag_round_trip_equals_log(tmp_path, capsys):
    """MuJoCo, dead reckoning (an IMU): every topic's messages are log.npz's numbers, bit for bit
    (quaternions: of the logged roll/pitch/yaw, to 1e-15)."""
    out = tmp_path / "run"
    argv = ["run", "paper", "--plant", "mujoco", "--duration", "0.3", "--set", 'plant.sensing="odometry"']
    assert main([*argv, "--out", str(out), "--rosbag"]) == 0
    assert "rosbag/: " in capsys.readouterr().out
    assert sorted(p.name for p in (out / "rosbag").iterdir()) == ["metadata.yaml", "rosbag.mcap"]
    assert not list(out.glob(".*tmp"))
    log = dict(np.load(out / "log.npz"))
    K = log["t"].shape[0]
    assert K == 30 and log["t_state"].shape == (K + 1,) and log["t_state"][-1] == pytest.approx(0.3, abs=1e-12)
    assert np.array_equal(log["t_state"][:K], log["t"])
    msgs, conns, store = _read(out / "rosbag")
    ns = np.rint(log["t_state"] * 1e9).astype(np.int64)

    # the topics, their counts and types (the jazzy type hashes)
    want = {"/tf_static": 1, "/clock": K + 1, "/tf": K + 1, "/leader/ground_truth/odom": K + 1}
    for f in ("f1", "f2", "f3"):
        want |= {f"/{f}/ground_truth/odom": K + 1, f"/{f}/odom": K, f"/{f}/cmd_vel": K}
        want |= {f"/{f}/joint_states": K + 1, f"/{f}/imu": K + 1, f"/{f}/leader_estimate": K}
    assert {t: len(v) for t, v in msgs.items()} == want
    assert conns["/f1/odom"].digest == store.hash_rihs01("nav_msgs/msg/Odometry")
    assert conns["/f1/imu"].msgtype == "sensor_msgs/msg/Imu"
    assert [t for t, _ in msgs["/clock"]] == ns.tolist()
    assert [m.clock.sec * 10**9 + m.clock.nanosec for _, m in msgs["/clock"]] == ns.tolist()
    static = msgs["/tf_static"][0][1].transforms
    assert [(s.header.frame_id, s.child_frame_id) for s in static][:4] == [
        ("world", "f1/odom"),
        ("world", "f2/odom"),
        ("world", "f3/odom"),
        ("world", "leader/odom"),
    ]

    for i, f in enumerate(("f1", "f2", "f3")):
        # truth: the 3-D pose (z, roll, pitch included) and the body-frame twist
        gt = [m for _, m in msgs[f"/{f}/ground_truth/odom"]]
        assert [_stamp(m) for m in gt] == ns.tolist()
        assert gt[0].header.frame_id == f"{f}/odom" and gt[0].child_frame_id == f"{f}/base_link"
        pos = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z] for m in gt])
        assert np.array_equal(pos, log["pose_3d"][:, i, :3])
        q = np.array([_xyzw(m.pose.pose.orientation) for m in gt])
        assert np.abs(q - quat_of_rpy(log["pose_3d"][:, i, 3:])).max() < 1e-15
        assert np.abs(rpy_of_quat(q) - log["pose_3d"][:, i, 3:]).max() < 1e-9
        tw = np.array([[m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.linear.z] for m in gt])
        assert np.array_equal(tw, log["twist_3d"][:, i, :3])
        assert np.array_equal([m.twist.twist.angular.z for m in gt], log["twist_3d"][:, i, 5])
        # the 3-D state is the planar log's where they overlap (the paper robot's base origin is on the
        # axle): x, y exactly, heading to 1e-12 rad; forward speed and yaw rate to 1e-4 m/s and 1e-2
        # rad/s (a chassis pitched by a few mrad: measured 2.2e-5 m/s, 6.5e-4 rad/s of 0.38 m/s, 9.3 rad/s)
        assert np.array_equal(log["pose_3d"][:K, i, :2], log["pose"][:, i, :2])
        assert np.abs(np.angle(np.exp(1j * (log["pose_3d"][:K, i, 5] - log["pose"][:, i, 2])))).max() < 1e-12
        assert np.abs(log["twist_3d"][:K, i, 0] - log["vel"][:, i, 0]).max() < 1e-4
        assert np.abs(log["twist_3d"][:K, i, 5] - log["vel"][:, i, 1]).max() < 1e-2
        # the robot stands on its wheels: z > 0 and nearly level
        assert np.all(pos[:, 2] > 0.01) and np.abs(log["pose_3d"][:, i, 3:5]).max() < 0.2
        # /tf: odom → base_link is the same pose
        tf = [m.transforms[i] for _, m in msgs["/tf"]]
        assert np.array_equal([t.transform.translation.z for t in tf], log["pose_3d"][:, i, 2])
        # the dead reckoning the controller was given
        od = [m for _, m in msgs[f"/{f}/odom"]]
        assert np.array_equal([m.pose.pose.position.x for m in od], log["odom_pose"][:, i, 0])
        assert np.array_equal([m.twist.twist.angular.z for m in od], log["odom_vel"][:, i, 1])
        # the kinematic command (Twist: no header; the bag's log time is the row's)
        cv = msgs[f"/{f}/cmd_vel"]
        assert [t for t, _ in cv] == ns[:K].tolist()
        assert np.array_equal([m.linear.x for _, m in cv], log["cmd"][:, i, 0])
        assert np.array_equal([m.angular.z for _, m in cv], log["cmd"][:, i, 1])
        # wheels: in the joints' own sense (sign), the robot file's joint names; effort = applied torque
        js = [m for _, m in msgs[f"/{f}/joint_states"]]
        sg = log["wheel_sign"][i]
        assert js[0].name == [str(x) for x in log["wheel_joints"][i]]
        assert np.array_equal(np.array([m.position for m in js]), sg * log["wheel_angle"][:, i])
        assert np.array_equal(np.array([m.velocity for m in js]), sg * log["wheel_speed"][:, i])
        assert np.array_equal(np.array([m.effort for m in js[:K]]), sg * log["tau"][:, i])
        assert js[K].effort.size == 0 and _stamp(js[K]) == ns[K]
        # the angle is the integral of the rate (trapezoid over the 0.01 s rows: within 0.05 rad of
        # 0.6 … 3.8 rad turned in 0.3 s; measured 0.013 … 0.030) and the wheels turn
        wa, ws = log["wheel_angle"][:, i], log["wheel_speed"][:, i]
        dt = np.diff(log["t_state"])[:, None]
        turned = np.concatenate([np.zeros((1, 2)), np.cumsum(dt * (ws[1:] + ws[:-1]) / 2, axis=0)])
        assert np.abs(wa - wa[0] - turned).max() < 0.05
        assert np.abs(wa - wa[0]).max() > 0.5
        # the IMU: MuJoCo's gyro and accelerometer (gravity included)
        imu = [m for _, m in msgs[f"/{f}/imu"]]
        assert np.array_equal([m.angular_velocity.z for m in imu], log["imu_gyro"][:, i, 2])
        assert np.array_equal([m.linear_acceleration.z for m in imu], log["imu_accel"][:, i, 2])
        assert imu[0].orientation_covariance[0] == -1.0 and imu[0].header.frame_id == f"{f}/imu_link"
        assert abs(np.median(log["imu_accel"][:, i, 2]) - 9.81) < 0.1  # gravity, through contact bumps
        # the follower's estimate of the leader
        le = [m for _, m in msgs[f"/{f}/leader_estimate"]]
        assert le[0].header.frame_id == "world"
        assert np.array_equal([m.pose.pose.position.y for m in le], log["est_pose"][:, i, 1])
        assert np.array_equal([m.twist.twist.linear.x for m in le], log["est_vel"][:, i, 0])
    lead = [m for _, m in msgs["/leader/ground_truth/odom"]]
    assert np.array_equal([m.pose.pose.position.x for m in lead], log["leader_state"][:, 0])
    assert np.array_equal(log["leader_state"][:K, :3], log["leader_pose"])
    assert np.array_equal(log["leader_state"][:K, 3:], log["leader_vel"])

    meta = (out / "rosbag" / "metadata.yaml").read_text()
    assert "version: 9" in meta and "storage_identifier: mcap" in meta and "transient_local" in meta
    from ruamel.yaml import YAML

    info = YAML(typ="safe").load(meta)["rosbag2_bagfile_information"]  # the metadata, read as YAML
    assert info["message_count"] == sum(len(v) for v in msgs.values())
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]} == {
        k: len(v) for k, v in msgs.items()
    }
    custom = json.loads(info["custom_data"]["bioform_mj"])
    robots = custom.pop("robots")
    assert custom == {
        "followers": 3,
        "method": "bioinspired-learning",
        "plant": "mujoco",
        "ros_distro": "jazzy",
        "scenario": "paper",
        "sensing": "odometry",
    }
    # what robot fit reads without flags: each follower's namespace, robot and what its effort is
    assert [r["namespace"] for r in robots] == ["f1", "f2", "f3"]
    assert all(r["effort"] == "applied" and r["motor"] == "ideal" and r["robot"]["model"] == "paper" for r in robots)
    assert robots[0]["effort_interval_s"] == pytest.approx([-0.009, 0.001])  # control_dt 1 ms, log_dt 10 ms
    # the numbers were written by numpy into copies of one template per topic: every message's bytes are
    # what rosbags' own serializer makes of the values read back
    for topic, items in msgs.items():
        typ = conns[topic].msgtype
        raws = _raw(out / "rosbag", topic)
        assert len(raws) == len(items)
        for (_, m), raw in zip(items, raws):
            assert bytes(store.serialize_cdr(m, typ)) == raw, topic


def test_full_state_leaves_the_log_as_it_was():
    """simulate(full_state=True) adds channels and changes none (ideal plant: planar, no wheels)."""
    sc = load("paper", plant="ideal", overrides={"sim.duration": 1.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a, b = simulate(sc), simulate(sc, full_state=True)
    assert set(a.log) < set(b.log)
    for k in a.log:
        assert np.array_equal(a.log[k], b.log[k]), k
    assert set(b.log) - set(a.log) == {
        "t_state",
        "pose_3d",
        "twist_3d",
        "wheel_angle",
        "wheel_speed",
        "leader_state",
        "wheel_sign",
        "wheel_joints",
    }
    K = a.log["t"].shape[0]
    assert K == 100 and b.log["pose_3d"].shape == (K + 1, 3, 6) and b.log["t_state"][-1] == 1.0
    assert np.array_equal(b.log["pose_3d"][:K, :, [0, 1, 5]], a.log["pose"])
    assert np.array_equal(b.log["twist_3d"][:K, :, [0, 5]], a.log["vel"])
    assert np.all(b.log["pose_3d"][:, :, 2:5] == 0.0) and np.all(np.isnan(b.log["wheel_angle"]))
    assert np.array_equal(b.log["pose_3d"][K][:, [0, 1, 5]], b.plant.x[:, :3])  # the state at T
    assert np.array_equal(b.log["leader_state"][K, :3], sc.build_leader().states(np.array([1.0]))[0][0])
    assert b.summary["sim_time_s"] == a.summary["sim_time_s"]


@needs_rosbags
def test_ideal_bag_humble(tmp_path):
    """The ideal plant's bag: no wheels (joint_states carry the torques only), no IMU, no /fI/odom;
    humble's message definitions on request."""
    from bioform_mj.outputs.rosbag import write_bag

    sc = load("paper", plant="ideal", overrides={"sim.duration": 0.5})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(sc, full_state=True)
    info = write_bag(r, tmp_path / "bag", distro="humble")
    K = r.log["t"].shape[0]
    assert info.distro == "humble" and info.messages == 1 + (3 + 3) * (K + 1) + 3 * 3 * K
    msgs, conns, _ = _read(tmp_path / "bag")
    assert "/f1/imu" not in msgs and "/f1/odom" not in msgs
    js = [m for _, m in msgs["/f2/joint_states"]]
    assert len(js) == K and js[0].position.size == 0 and js[0].velocity.size == 0
    assert np.array_equal(np.array([m.effort for m in js]), r.log["tau"][:, 1])
    gt = [m for _, m in msgs["/f3/ground_truth/odom"]]
    assert np.array_equal([m.pose.pose.position.x for m in gt][:K], r.log["pose"][:, 2, 0])
    assert [m.pose.pose.position.z for m in gt] == [0.0] * (K + 1)
    with pytest.raises(FileExistsError):
        write_bag(r, tmp_path / "bag")
    # an absolute start: every stamp and log time shifted by it
    t0 = 1_764_633_600_000_000_000  # 2025-12-02 00:00 UTC, ns
    write_bag(r, tmp_path / "bag", start_ns=t0, overwrite=True)
    shifted, _, _ = _read(tmp_path / "bag")
    clock = shifted["/clock"]
    assert clock[0][0] == t0 and clock[-1][0] == t0 + 500_000_000
    assert [m.clock.sec * 10**9 + m.clock.nanosec for _, m in clock] == [t for t, _ in clock]
    assert _stamp(shifted["/f1/ground_truth/odom"][7][1]) == t0 + 70_000_000
    with pytest.raises(ValueError, match="full_state=True"):
        write_bag(simulate(sc), tmp_path / "bag2")
    assert not (tmp_path / "bag2").exists() and not list(tmp_path.glob(".*tmp"))


@needs_rosbags
def test_a_layouts_later_bags_equal_a_first_bag(tmp_path):
    """The layout caches (outputs/rosbag.py _LAYOUTS: templates and field offsets; outputs/rosbag_write.py
    PLANS: the chunk buffer with its constant bytes, the numbers' addresses relative to their arrays) change
    no byte: run B's bag written right after run A's (the same layout, other numbers: every cache used)
    equals B's bag written with the caches emptied, and so does B's log with an array laid out otherwise
    (Fortran order: its numbers then found afresh, as converted copies); so does A's after warm_up(like=its
    scenario), with its layout found made."""
    import types

    import bioform_mj.outputs.rosbag as rosbag
    import bioform_mj.outputs.rosbag_write as rw

    over = {"sim.duration": 4.0}  # 400 rows: three chunks, the middle one from the full-chunk buffer
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ra = simulate(load("paper", plant="ideal", overrides=over), full_state=True)
        jitter = {**over, "formation.init_jitter": 0.2, "sim.seed": 5}
        rb = simulate(load("paper", plant="ideal", overrides=jitter), full_state=True)
    assert not np.array_equal(ra.log["pose_3d"], rb.log["pose_3d"])

    def bag(r, name: str, fresh: bool) -> tuple[bytes, bytes]:
        if fresh:
            rosbag._LAYOUTS.clear()
            rw.PLANS.clear()
        rosbag.write_bag(r, tmp_path / name / "bag")
        return (tmp_path / name / "bag" / "bag.mcap").read_bytes(), (
            tmp_path / name / "bag" / "metadata.yaml"
        ).read_bytes()

    a = bag(ra, "a", True)
    b_later = bag(rb, "b_later", False)
    assert len(rosbag._LAYOUTS) == 1 and len(rw.PLANS) == 1
    assert all(p.full is not None and p.rel is not None for p in rw.PLANS.values())  # read in place, by offsets
    b_first = bag(rb, "b_first", True)
    assert b_later == b_first and a[0] != b_first[0] and len(a[0]) == len(b_first[0])
    fortran = {**rb.log, "pose_3d": np.asfortranarray(rb.log["pose_3d"])}
    other = types.SimpleNamespace(log=fortran, summary=rb.summary, scenario=rb.scenario)
    assert bag(other, "b_fortran", False) == b_first
    assert all(p.rel is None for p in rw.PLANS.values())  # pose_3d's numbers were copies this time
    # warm_up of the run's scenario (bioform run --rosbag): the run's bag then finds its layout's templates
    # and chunk buffer made (no new entry in either cache), and is the same bag
    rosbag._LAYOUTS.clear()
    rw.PLANS.clear()
    rosbag.warm_up(like=load("paper", plant="ideal", overrides=over))
    layouts, plans = set(rosbag._LAYOUTS), set(rw.PLANS)
    assert bag(ra, "a_warm", False) == a
    assert set(rosbag._LAYOUTS) == layouts and set(rw.PLANS) == plans


def test_rosbag_without_the_extra_says_how_to_install(tmp_path, capsys, monkeypatch):
    """--rosbag with rosbags missing: exit 2 before any work, one error: line naming the extra."""
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "rosbags" else real(name, *a))
    out = tmp_path / "run"
    assert main(["run", "paper", "--duration", "0.1", "--out", str(out), "--rosbag"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --rosbag needs the ros extra")
    assert "pip install 'bioform-mj[ros]'" in err[0]
    assert not out.exists()
    assert main(["run", "paper", "--duration", "0.1", "--out", str(out), "--ros-distro", "humble"]) == 2
    assert "--ros-distro only applies to --rosbag" in capsys.readouterr().err


@needs_rosbags
def test_rosbag_with_a_broken_install_fails_before_the_run(tmp_path, capsys, monkeypatch):
    """rosbags importable but failing: exit 2 before the run, one error: line, nothing written."""
    from bioform_mj.outputs import rosbag

    def broken(distro):
        raise ImportError("no module named rosbags.typesys.stores.ros2_jazzy")

    monkeypatch.setattr(rosbag, "_messages", broken)
    out = tmp_path / "run"
    assert main(["run", "paper", "--duration", "0.1", "--out", str(out), "--rosbag"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --rosbag: the rosbags package does not work (ImportError")
    assert not out.exists()


@needs_rosbags
def test_overwrite_replaces_the_bag_folder(tmp_path, capsys):
    """rosbag/ is a run's folder: refused without --overwrite, replaced with it; a stale temporary
    bag folder is cleared; a foreign file inside rosbag/ makes the folder not ours."""
    out = tmp_path / "run"
    argv = ["run", "paper", "--duration", "0.1", "--out", str(out), "--quiet"]
    assert main([*argv, "--rosbag"]) == 0
    first = (out / "rosbag" / "rosbag.mcap").stat().st_mtime_ns
    (out / ".rosbag.abc123.tmp").mkdir()
    (out / ".rosbag.abc123.tmp" / "half.mcap").write_bytes(b"x")
    assert main([*argv, "--rosbag"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main([*argv, "--rosbag", "--overwrite"]) == 0
    assert (out / "rosbag" / "rosbag.mcap").stat().st_mtime_ns >= first
    assert not (out / ".rosbag.abc123.tmp").exists()
    assert main([*argv, "--overwrite"]) == 0  # no bag asked: the old one is gone with the old run
    assert not (out / "rosbag").exists()
    (out / "rosbag").mkdir()
    (out / "rosbag" / "notes.txt").write_text("mine")
    assert main([*argv, "--overwrite"]) == 2
    assert "not a run's" in capsys.readouterr().err


def test_mujoco_3d_state_same_from_the_compiled_chunk_and_step_by_step():
    """MuJoCo: the compiled chunk copies each row's raw state (plants/mujoco/kernels.py: copy_row),
    the step-by-step loop samples it as an observer; the 3-D channels agree bit for bit, and the
    other channels are those of a run without full_state."""
    sc = load("paper", plant="mujoco", overrides={"sim.duration": 0.3, "plant.sensing": "odometry"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = simulate(sc, full_state=True, engine="compiled")
        b = simulate(sc, full_state=True, engine="stepwise")
        c = simulate(sc, engine="compiled")
    assert a.summary["engine"] == "compiled" and b.summary["engine"] == "stepwise"
    assert set(a.log) == set(b.log) and "imu_gyro" in a.log
    for k in a.log:
        assert np.array_equal(a.log[k], b.log[k]), k
    for k in c.log:
        assert np.array_equal(a.log[k], c.log[k]), k
    assert not np.isnan(a.log["pose_3d"]).any() and not np.isnan(a.log["wheel_speed"]).any()
    assert a.plant.row_state.shape == (0, 0)  # the plant copies no rows after the run


def _mcap_records(data: bytes, at: int, stop: int):
    """(offset, opcode, body) of the MCAP records in ``data[at:stop]``, read by the MCAP specification's
    framing (opcode u8, length u64, body), nothing of this project's writer."""
    import struct

    while at < stop:
        op, n = struct.unpack_from("<BQ", data, at)
        yield at, op, data[at + 9 : at + 9 + n]
        at += 9 + n


def _mcap_string(body: bytes, at: int) -> tuple[str, int]:
    import struct

    (n,) = struct.unpack_from("<I", body, at)
    return body[at + 4 : at + 4 + n].decode(), at + 4 + n


@needs_rosbags
def test_many_chunk_bag_is_a_consistent_mcap(tmp_path):
    """A bag of many chunks (ideal plant, 10 s: 7 chunks, the 5 between the first and the last each written
    from one buffer by outputs/rosbag_write.py's FullChunk), read record by record as the MCAP
    specification frames it: every message index entry points at a message of its channel and log time in
    its chunk and every message is indexed once; each chunk's time range and size are its messages'; the
    summary's chunk indexes point at those chunks and their message indexes; the statistics count what is
    there; and the messages, in file order, are those rosbags' reader returns, each topic stamped at the
    log's samples."""
    import struct

    from rosbags.rosbag2 import Reader

    from bioform_mj.outputs.rosbag import write_bag

    sc = load("paper", plant="ideal", overrides={"sim.duration": 10.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate(sc, full_state=True)
    write_bag(r, tmp_path / "bag")
    data = (tmp_path / "bag" / "bag.mcap").read_bytes()
    magic = b"\x89MCAP0\r\n"
    assert data[:8] == magic and data[-8:] == magic
    summary_start, summary_offsets, _ = struct.unpack_from("<QQI", data, len(data) - 8 - 20)

    chunks, messages, counts = {}, [], {}
    at_index: dict[int, tuple[int, int]] = {}  # offset of a message index record -> (its channel, its chunk)
    last_chunk = None
    for off, op, body in _mcap_records(data, 8, summary_start):
        if op == 0x06:  # a chunk: its records, uncompressed
            t0, t1, size, crc = struct.unpack_from("<QQQI", body, 0)
            comp, p = _mcap_string(body, 28)
            (n,) = struct.unpack_from("<Q", body, p)
            recs = body[p + 8 : p + 8 + n]
            assert comp == "" and crc == 0 and size == n == len(recs)
            inside = {}
            for roff, rop, rbody in _mcap_records(recs, 0, len(recs)):
                if rop == 0x05:
                    ch, _, log_t, pub_t = struct.unpack_from("<HIQQ", rbody, 0)
                    assert pub_t == log_t
                    inside[roff] = (ch, log_t)
                    messages.append((ch, log_t, bytes(rbody[22:])))
                    counts[ch] = counts.get(ch, 0) + 1
            times = [t for _, t in inside.values()]
            assert (t0, t1) == (min(times), max(times))
            chunks[off] = {"length": 9 + len(body), "inside": inside, "indexed": set(), "times": (t0, t1)}
            last_chunk = off
        elif op == 0x07:  # a message index of the chunk before it
            ch, n = struct.unpack_from("<HI", body, 0)
            pairs = np.frombuffer(body[6 : 6 + n], "<u8").reshape(-1, 2)
            c = chunks[last_chunk]
            for log_t, roff in pairs.tolist():
                assert c["inside"][roff] == (ch, log_t)
                assert roff not in c["indexed"]
                c["indexed"].add(roff)
            at_index[off] = (ch, last_chunk)
    for c in chunks.values():
        assert c["indexed"] == set(c["inside"])
    assert len(chunks) == 7

    seen, stats = set(), None
    for _, op, body in _mcap_records(data, summary_start, summary_offsets):
        if op == 0x08:
            t0, t1, start, length, n = struct.unpack_from("<QQQQI", body, 0)
            assert chunks[start]["length"] == length and chunks[start]["times"] == (t0, t1)
            for i in range(n // 10):
                ch, ioff = struct.unpack_from("<HQ", body, 36 + 10 * i)
                assert at_index[ioff] == (ch, start)
            seen.add(start)
        elif op == 0x0B:
            stats = body
    assert seen == set(chunks)
    total, _, _, _, _, n_chunks, t_first, t_last, n = struct.unpack_from("<QHIIIIQQI", stats, 0)
    assert total == len(messages) and n_chunks == len(chunks)
    assert dict(struct.iter_unpack("<HQ", stats[46 : 46 + n])) == counts
    assert (t_first, t_last) == (min(t for _, t, _ in messages), max(t for _, t, _ in messages))

    with Reader(tmp_path / "bag") as rd:
        topic = {c.id: c.topic for c in rd.connections}
        read = [(c.topic, t, bytes(raw)) for c, t, raw in rd.messages()]
    assert read == [(topic[ch], t, raw) for ch, t, raw in messages]
    ns = np.rint(r.log["t_state"] * 1e9).astype(np.int64).tolist()
    K = r.log["t"].shape[0]
    assert K == 1000
    for name in ("/clock", "/f2/ground_truth/odom", "/f3/cmd_vel"):
        assert [t for tp, t, _ in read if tp == name] == (ns if name != "/f3/cmd_vel" else ns[:K])


def test_planar_quaternions_have_the_general_formulas_bits():
    """quat_of_rpy with every roll and pitch +0.0 computes only the yaw's cosine and sine (the ideal plant, the
    leader, the estimates: outputs/rosbag.py's templates; quat_of_yaw): its bits, signed zeros included, are
    those of the four products of cr, sr, cp, sp, cy, sy computed here from scratch; -0.0 or a nonzero roll or
    pitch takes the general products."""
    rng = np.random.default_rng(7)
    special = [
        0.0,
        -0.0,
        np.pi,
        -np.pi,
        2 * np.pi,
        -2 * np.pi,
        3 * np.pi,
        1e300,
        -1e300,
        5e-324,
        -5e-324,
        np.nan,
        np.inf,
    ]
    yaw = np.concatenate([rng.normal(size=4000) * 4.0, special])

    def general(rpy):
        h = np.asarray(rpy, dtype=float) * 0.5
        r, p, y = h[..., 0], h[..., 1], h[..., 2]
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        return np.stack(
            [
                cr * cp * cy + sr * sp * sy,
                sr * cp * cy - cr * sp * sy,
                cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy,
            ],
            axis=-1,
        )

    with np.errstate(invalid="ignore"):
        for rpy in (
            np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=-1),
            np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=-1).reshape(-1, 1, 3)[:, [0, 0, 0]],
            np.stack([np.full_like(yaw, -0.0), np.zeros_like(yaw), yaw], axis=-1),
            np.stack([np.zeros_like(yaw), rng.normal(size=yaw.size) * 0.1, yaw], axis=-1),
        ):
            got, want = quat_of_rpy(rpy), general(rpy)
            assert got.shape == want.shape == (*rpy.shape[:-1], 4)
            assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
        planar = np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=-1)
        for one in (yaw, yaw.reshape(-1, 1)[:, [0, 0]], yaw[3]):  # quat_of_yaw (the headings), one yaw too
            want = general(np.stack([np.zeros_like(one), np.zeros_like(one), one], axis=-1))
            assert np.array_equal(quat_of_yaw(one).view(np.uint64), want.view(np.uint64))
        tiny = planar.copy()
        tiny[:, 0] = 5e-324  # its half is +0.0: the general products, the same bits as the planar ones
        assert np.array_equal(quat_of_rpy(tiny).view(np.uint64), general(planar).view(np.uint64))
    # yaw/2 = 0.05, 2, -2, -0, 3.5: cos(yaw/2) > 0, < 0, < 0, > 0, < 0; sin's sign bit clear, clear, set, set, set
    q = quat_of_rpy(np.stack([np.zeros(5), np.zeros(5), [0.1, 4.0, -4.0, -0.0, 7.0]], axis=-1))
    assert np.signbit(q[:, 1]).tolist() == [False, True, False, False, False]  # x = (+0·cy) − (+0·sy)
    assert np.signbit(q[:, 2]).tolist() == [False, False, True, False, True]  # y = (+0·cy) + (+0·sy)
    assert np.signbit(q[:, 3]).tolist() == [False, False, True, True, True]  # z = sy − (+0·cy)


def test_number_sources_and_the_compiled_pass_write_numpys_bytes():
    """The bulk writer's numbers (outputs/rosbag_write.py: number_sources, Numbers, and the compiled pass
    outputs/rosbag_kernel.py: place): each field's values land at its (unaligned) byte offset in each
    sample's row as np.asarray(values, dtype).tobytes() gives them, for <f8, <u8, <i4 (wrapping) and <u4,
    from selections of C-contiguous arrays (read in place, at their elements' addresses: no copy), a
    Fortran-ordered and a big-endian array, float32 and int32 values, a reversed slice (copies); nothing
    else in the buffer changes."""
    from bioform_mj.outputs.rosbag_write import Numbers, number_sources

    rng = np.random.default_rng(3)
    S = 50
    pose = rng.normal(size=(S, 3, 6))
    ints = rng.integers(-(2**40), 2**40, size=(S, 2))
    stamps = np.arange(S, dtype=np.int64) * 1_000_000_007 + 2**35
    fort = np.asfortranarray(rng.normal(size=(S, 4)))
    big = rng.normal(size=S).astype(">f8")
    f32 = rng.normal(size=S).astype(np.float32)
    i32 = rng.integers(-(2**31), 2**31, size=S).astype(np.int32)
    rev = rng.normal(size=S + 5)
    fields = [  # (dtype, array, idx)
        ("<f8", pose, (slice(None), 1, 2)),
        ("<f8", pose, (slice(None), 2, 5)),
        ("<f8", pose, (slice(2, None), 0, 0)),
        ("<u8", stamps, ()),
        ("<i4", ints, (slice(None), 0)),
        ("<u4", ints, (slice(None), 1)),
        ("<f8", fort, (slice(None), 3)),
        ("<f8", big, ()),
        ("<f8", f32, ()),
        ("<i4", i32, ()),
        ("<f8", rev, (slice(None, None, -1),)),
    ]
    values = [(dt, a[idx] if idx else a, (a, idx)) for dt, a, idx in fields]
    K = 40
    keep, addr, step = number_sources([v[0] for v in values], [v[1] for v in values], [v[2] for v in values], K)
    at = pose.ctypes.data
    assert (addr[0], step[0]) == (at + 8 * (6 + 2), 8 * 18)  # pose's own words, in place: [:, 1, 2]
    assert (addr[2], step[2]) == (at + 8 * 36, 8 * 18)  # [2:, 0, 0]: element (2, 0, 0) of pose
    assert (addr[3], step[3]) == (stamps.ctypes.data, 8)
    assert any(a is pose for a in keep) and any(a is stamps for a in keep)
    lies_in = [[a for a in keep if a.ctypes.data <= x < a.ctypes.data + a.nbytes] for x in addr]
    assert all(len(k) == 1 for k in lies_in)  # every address in one array the numbers hold
    copied = [k for k, (dt, a, idx) in enumerate(fields) if not any(b is a for b in lies_in[k])]
    assert copied == [6, 7, 8, 9, 10]  # Fortran, big-endian, float32, int32, reversed: converted copies
    B, rows, j0 = 1 + 8 * len(fields) + 13, 7, 30
    dst = [1 + 9 * k for k in range(len(fields))]  # every offset odd: unaligned
    wide = [np.dtype(dt).itemsize == 8 for dt, _, _ in values]
    numbers = Numbers(keep, addr, step, dst, np.full(len(dst), B), wide)
    buf = np.full(rows * B + 5, 0xA5, np.uint8)
    numbers.fill(buf, j0, rows - 1)
    want = np.full(rows * B + 5, 0xA5, np.uint8)
    for r in range(rows - 1):
        for d, (dt, vals, _) in zip(dst, values):
            b = np.frombuffer(np.asarray(vals[j0 + r : j0 + r + 1], dtype=dt).tobytes(), np.uint8)
            want[r * B + d : r * B + d + b.size] = b
    assert np.array_equal(buf, want)


def test_a_topics_last_record_has_numpys_bytes():
    """The end of the run's record of a topic (outputs/rosbag.py: _Topic.record_at, written with struct): the
    header, then the template with each field's value at sample j as np.asarray(values, dtype).tobytes()
    gives it: a NaN's payload and -0.0 kept, integers wrapped to 4 or 8 bytes, float32 widened, floats cast
    to <i4 by numpy."""
    import struct

    from bioform_mj.outputs.rosbag import _Topic
    from bioform_mj.outputs.rosbag_write import MSG_HEAD

    nan = np.frombuffer(struct.pack("<Q", 0x7FF8_0000_DEAD_BEEF), np.float64)
    cols = {
        "<f8": [np.array([1.5, -0.0]), np.concatenate([nan, nan]), np.array([0.1, 2.5], np.float32)],
        "<i4": [np.array([-(2**40) - 3, 5]), np.array([3.7, -2.2])],
        "<u4": [np.array([2**33 + 7, -1])],
        "<u8": [np.array([-5, 2**62], np.int64)],
    }
    fields, off = [], 3
    for dt, arrays in cols.items():
        for a in arrays:
            fields.append((off, dt, a, (a, ())))
            off += np.dtype(dt).itemsize + 1
    tp = _Topic("/x", "std_msgs/msg/Empty", np.arange(2), np.full(off + 2, 0x5A, np.uint8), fields)
    stamp = 1_700_000_000_123_456_789
    for j in (0, 1):
        got = tp.record_at(7, stamp, j)
        want = bytearray(struct.pack("<BQHIQQ", 0x05, 22 + off + 2, 7, 0, stamp, stamp)) + bytes([0x5A]) * (off + 2)
        for o, dt, a, _ in fields:
            b = np.asarray(a[j : j + 1], dtype=dt).tobytes()
            want[MSG_HEAD + o : MSG_HEAD + o + len(b)] = b
        assert got == bytes(want), j


def test_reserve_allocates_the_blocks_and_leaves_the_size(tmp_path):
    """outputs/rosbag_write.reserve: the blocks of the bytes to come are allocated (Linux, where the file
    system supports fallocate) and the file's size is what was written, before and after the writes."""
    import os
    import sys

    from bioform_mj.outputs.rosbag_write import _fallocate, reserve

    fn = _fallocate()
    assert (fn is not None) == sys.platform.startswith("linux")
    supported = False
    if fn is not None:  # does this file system allocate? (ext4, xfs, btrfs, tmpfs do)
        with open(tmp_path / "probe", "xb") as g:
            supported = fn(g.fileno(), 1, 0, 4096) == 0
    data = bytes(range(256)) * 4096  # 1 MiB
    with open(tmp_path / "f", "xb") as f:
        f.write(b"head")
        reserve(f, len(data))
        f.flush()
        st = os.fstat(f.fileno())
        assert st.st_size == 4
        if supported:
            assert st.st_blocks * 512 >= len(data)  # the MiB's blocks, before a byte of it is written
        f.write(data)
    assert (tmp_path / "f").read_bytes() == b"head" + data
