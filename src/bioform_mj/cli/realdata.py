"""``bioform robot fit``, ``robot replay`` and ``robot drive-program`` (issue 29).

The robot argument and the mapping flags are ``robot check``'s (:func:`bioform_mj.cli.robot.mapping_args`),
so a robot maps the same way everywhere. Bad input (a recording without the named topics or joints, time
going backwards, NaN efforts, an unreadable bag, wheels that are not in the recording) exits 2 with one
``error:`` line before anything is written.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.cli.outdir import path_arg
from bioform_mj.core.errors import InputError
from bioform_mj.robots.sanity import one_line

__all__ = ["add_parsers", "main"]


def _robot_parser(rsub: Any, name: str, help_: str, model_help: str, recording: bool) -> argparse.ArgumentParser:
    """One subcommand with what the three share: the robot argument, ``robot check``'s mapping flags and,
    with ``recording``, the recording's flags (:func:`_recording_args`)."""
    from bioform_mj.cli.robot import mapping_args

    p = rsub.add_parser(name, help=help_)
    p.add_argument("model", help=model_help)
    mapping_args(p)
    if recording:
        _recording_args(p)
    return p


def _recording_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bag", required=True, help="the recording: a rosbag2 folder, a .mcap file or a CSV")
    p.add_argument(
        "--robot-ns",
        metavar="NS",
        help="the robot's topic namespace: /NS/joint_states, /NS/odom (else /NS/ground_truth/odom), /NS/imu "
        "(default: none, or the only one whose joint states the recording has; this project's bags: f1, f2, …)",
    )
    p.add_argument(
        "--joint-states-topic", help="sensor_msgs/JointState topic (default /joint_states, under --robot-ns)"
    )
    p.add_argument("--odom-topic", help="nav_msgs/Odometry topic (default /odom, under --robot-ns; optional)")
    p.add_argument("--imu-topic", help="sensor_msgs/Imu topic (default /imu, under --robot-ns; optional)")
    p.add_argument("--left-joint", help="the left wheel's joint name in the recording (default: the robot's)")
    p.add_argument("--right-joint", help="the right wheel's joint name in the recording (default: the robot's)")
    p.add_argument(
        "--effort-scale",
        type=float,
        metavar="K",
        help="N·m at the wheel per recorded effort unit: a driver that records motor current (A) needs its torque "
        "constant × gear ratio (× the gearbox efficiency), K = Kt·N (default 1: efforts are N·m at the wheel)",
    )
    p.add_argument(
        "--motor",
        choices=("ideal", "dc"),
        help="what the recorded effort is: 'ideal' the torque applied on the wheel joint (the motors are torque "
        "sources), 'dc' the wheel torque commanded to the robot file's <dcmotor> drives, whose back-EMF and "
        "torque-speed line are then simulated (design §8.2) (default: what this project's bag states, else ideal)",
    )
    p.add_argument(
        "--driver",
        choices=("current", "voltage"),
        help="with --motor dc: the <dcmotor>'s driver (default: the bag's, else the mapping's, else current)",
    )


def add_parsers(rsub: Any) -> None:
    """Add ``fit``, ``replay`` and ``drive-program`` to ``bioform robot``'s subparsers."""
    fit = _robot_parser(
        rsub,
        "fit",
        "fit a robot's mass, yaw inertia, wheel damping/frictionloss (and armature, caster friction) to a "
        "recording with mujoco.sysid; writes DIR/fit.json, a calibrated robot file and a figure (exit 2 bad input)",
        "shipped robot name or path to an MJCF or URDF file",
        recording=True,
    )
    fit.add_argument("--out", required=True, type=path_arg, help="output directory")
    fit.add_argument(
        "--fit",
        default=None,
        help="comma-separated parameters: mass, yaw_inertia, damping, frictionloss, armature, caster_friction "
        "(default: all but armature, which the recording cannot tell from mass, and caster_friction only of the "
        "--caster ones, and not where --caster-friction states it; given here, caster_friction fits the casters "
        "robot check finds)",
    )
    fit.add_argument(
        "--chunk",
        type=float,
        default=None,
        help="seconds simulated from each recorded state (default 2; shorter, down to 0.5, on a short recording)",
    )
    fit.add_argument("--max-chunks", type=int, default=12, help="chunks used at most, spread evenly (default 12)")
    fit.add_argument("--max-iters", type=int, default=30, help="optimiser iterations at most (default 30)")
    fit.add_argument(
        "--time-budget",
        type=float,
        default=60.0,
        help="seconds the optimiser may take; then its best point (default 60)",
    )
    fit.set_defaults(realdata_main=_fit_main)

    rep = _robot_parser(
        rsub,
        "replay",
        "drive the robot with a recording's torques open loop; report and plot the difference "
        "(published robot, and --calibrated FILE)",
        "shipped robot name or path to an MJCF or URDF file (the published one)",
        recording=True,
    )
    rep.add_argument("--calibrated", help="a calibrated robot file (robot fit's) to replay beside the published one")
    rep.add_argument("--out", type=path_arg, help="write replay.json and replay.png into this directory")
    rep.set_defaults(realdata_main=_replay_main)

    prog = _robot_parser(
        rsub,
        "drive-program",
        "print (CSV: time, left, right wheel torque in N·m) the torques to record for robot fit, within "
        "the robot's limits",
        "shipped robot name or path to an MJCF or URDF file",
        recording=False,
    )
    prog.add_argument("--seconds", type=float, default=60.0, help="length in s (default 60)")
    prog.add_argument("--rate", type=float, default=100.0, help="samples per second (default 100)")
    prog.add_argument("--accel", type=float, default=1.0, help="the largest forward acceleration, m/s² (default 1)")
    prog.add_argument("--seed", type=int, default=0, help="seed of the pulse pattern")
    prog.set_defaults(realdata_main=_program_main)


def main(args: argparse.Namespace) -> int:
    """Run the subcommand ``args`` names."""
    return args.realdata_main(args)


def _some(names: list[str], n: int = 6) -> str:
    """Up to ``n`` quoted names and how many more."""
    return ", ".join(f"'{x}'" for x in names[:n]) + (f" and {len(names) - n} more" if len(names) > n else "")


def _load(args: argparse.Namespace):
    """The robot (as robot check maps it; with ``--motor dc``, or where the bag states it, its ``<dcmotor>``
    drives taking the recorded efforts as commands) and the recording, checked against each other; returns
    ``(ref, robot, rec)`` and records in ``rec.notes`` what the effort was taken to be and why."""
    from dataclasses import replace

    from bioform_mj.cli.robot import ref_from_args
    from bioform_mj.robots.realdata.recording import PAUSE_NOTE, Topics, read_recording
    from bioform_mj.robots.realdata.simmodel import other_joints, sim_spec

    if args.driver and args.motor != "dc":
        raise InputError("--driver only applies to --motor dc")
    k = args.effort_scale
    if k is not None and not (math.isfinite(k) and k > 0):
        raise InputError(f"--effort-scale must be a number > 0, got {k}")
    ref = ref_from_args(args.model, args)
    ref = replace(ref, motor="", driver="")  # the effort's meaning decides the motors, below
    robot = sim_spec(ref)
    joints = (args.left_joint or robot.layout.wheel_joints[0], args.right_joint or robot.layout.wheel_joints[1])
    topics = Topics(args.joint_states_topic, args.odom_topic, args.imu_topic, args.robot_ns)
    moving = other_joints(robot)
    rec = read_recording(args.bag, joints, topics, moving)
    if rec.others:
        rec.notes.append(f"the angles and speeds of {', '.join(rec.others)} from the recording start each chunk")
    if unrecorded := [j for j in moving if j not in rec.others]:
        # a PMB-2 recorded without its four swivel casters' angles: yaw inertia 14 % high outside its interval,
        # weighted cost 220 after the fit (3-34 on robots without swivels); the TIAGo's mass 62.3 against 55.1
        msg = (
            f"the recording holds no angles of the robot's other moving joint(s) {_some(unrecorded)} (caster swivels "
            "and wheels, suspensions): each chunk starts them as the file puts them at rest; where the robot had them "
            "elsewhere (a swivel turned the other way) their moving there is a drag no fitted parameter holds; record "
            "them in the joint states if the robot has encoders on them"
        )
        rec.notes.append(msg)
        print(f"warning: {msg}", file=sys.stderr)
    for note in rec.notes:
        if note.startswith(PAUSE_NOTE):  # dropped messages: the fit skips them, the replay interpolates
            print(f"warning: {note}", file=sys.stderr)
    rec = _before_tipping(args, rec)
    rec.notes.extend(robot.notes)
    if k is not None and k != 1.0:
        rec.effort = rec.effort * k
        rec.notes.append(f"efforts multiplied by {k:g} (--effort-scale): taken as N·m at the wheel")
    stated = rec.stated
    if args.motor:
        motor, why = args.motor, "--motor"
    elif stated.get("effort") in ("applied", "command"):
        motor, why = ("dc" if stated["effort"] == "command" else "ideal"), "the bag's metadata (custom_data)"
    else:
        motor, why = "ideal", "the default"
    if motor == "dc":
        driver = args.driver or str(stated.get("driver") or "") or "current"
        ref = replace(ref, motor="dc", driver=driver)
        robot = sim_spec(ref)  # raises (exit 2) where the robot file has no <dcmotor> on its wheels
        rec.notes.append(
            f"efforts taken as the wheel torques commanded to the robot's <dcmotor> drives ({driver} driver; "
            f"from {why}): the motors are simulated"
        )
    else:
        rec.notes.append(f"efforts taken as the torques applied on the wheel joints (from {why})")
    if stated.get("disturbance"):
        d = stated["disturbance"]
        msg = (
            f"the recorded run applied disturbance forces (scenario [disturbance] bias {d.get('bias')}, amp "
            f"{d.get('amp')}) that no robot model holds: the fitted numbers absorb them (record with the "
            "disturbance off: --set 'disturbance.bias=[0,0]' --set 'disturbance.amp=[0,0]')"
        )
        rec.notes.append(msg)
        print(f"warning: {msg}", file=sys.stderr)
    return ref, robot, rec


def _before_tipping(args: argparse.Namespace, rec):
    """:func:`~bioform_mj.robots.realdata.recording.upright_part` of ``rec`` (one chunk, ``--chunk``, 2 s for the
    replay, needed before a tilt), its note said in a ``warning:`` line."""
    from bioform_mj.robots.realdata.recording import upright_part

    rec, note = upright_part(rec, float(getattr(args, "chunk", 2.0) or 2.0), str(args.bag))
    if note:
        print(f"warning: {note}", file=sys.stderr)
    return rec


def _signals_of_chunks(chunks, sims: list[np.ndarray] | None) -> dict[str, np.ndarray]:
    """Chunks laid end to end on the recording's time axis, NaN between them (for the figure)."""
    cols = {"left_speed": 0, "right_speed": 1, "vx": 2, "wz": 7}
    t, out = [], {k: [] for k in cols}
    for i, (t0, meas) in enumerate(zip(chunks.starts, chunks.measured)):
        data = meas.data if sims is None else sims[i]
        t.append(np.append(t0 + meas.times, np.nan))
        for k, c in cols.items():
            vals = data[:, c] if (sims is not None or chunks.weights[c] > 0) else np.full(len(meas.times), np.nan)
            out[k].append(np.append(vals, np.nan))
    res = {k: np.concatenate(v) for k, v in out.items()}
    res["t"] = np.concatenate(t)
    return res


def _rms(chunks, sims: list[np.ndarray]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, c, _unit in (
        ("left_speed", 0, "rad/s"),
        ("right_speed", 1, "rad/s"),
        ("vx", 2, "m/s"),
        ("wz", 7, "rad/s"),
    ):
        if chunks.weights[c] == 0:
            continue
        d = np.concatenate([m.data[:, c] - s[:, c] for m, s in zip(chunks.measured, sims)])
        out[f"{name}_rms"] = float(np.sqrt(np.mean(d**2)))
    return out


def _fit_main(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from mujoco import sysid

    from bioform_mj.outputs.files import check_out_dir, write_json
    from bioform_mj.robots.params import robot_truth
    from bioform_mj.robots.realdata.calibrated import assets_folder, write_calibrated
    from bioform_mj.robots.realdata.fit import (
        DEFAULT_FIT,
        FIT_PARAMETERS,
        fit,
        make_chunks,
        robot_casters,
        simulate_chunks,
    )
    from bioform_mj.robots.realdata.replay import plot_signals
    from bioform_mj.robots.realdata.simmodel import sim_spec

    out = check_out_dir(args.out, "--out")
    which = DEFAULT_FIT if args.fit is None else tuple(w.strip() for w in args.fit.split(",") if w.strip())
    unknown = [w for w in which if w not in FIT_PARAMETERS]
    if unknown:
        raise InputError(f"--fit: unknown parameter '{unknown[0]}' (expected some of: {', '.join(FIT_PARAMETERS)})")
    chunk_ok = args.chunk is None or (math.isfinite(args.chunk) and args.chunk > 0)  # inf: no chunk count
    if not (chunk_ok and args.max_chunks >= 1 and args.max_iters >= 1 and args.time_budget > 0):
        raise InputError("--chunk must be a finite number > 0, --time-budget > 0, --max-chunks and --max-iters >= 1")
    ref, robot, rec = _load(args)
    held = []
    if args.fit is None and ref.caster_friction >= 0 and ref.casters:
        # the mapping states the casters' friction (--caster-friction): held, as a published value is. Fitted by
        # default, a Fetch Freight mapped --caster base_link --caster-friction 0 (its casters roll) had its whole
        # base mesh given condim 3 and a friction search up to 1: the rollouts went NaN and the fit stopped
        which = tuple(w for w in which if w != "caster_friction")
        held.append(
            f"caster friction held at the mapping's {ref.caster_friction:g} (--caster-friction) on "
            f"{', '.join(ref.casters)}; --fit ...,caster_friction fits it"
        )
    published = sim_spec(ref)  # an untouched copy (the fit edits robot.spec)
    result, opt = fit(
        robot,
        rec,
        which,
        chunk_s=args.chunk,
        max_chunks=args.max_chunks,
        max_iters=args.max_iters,
        time_budget_s=args.time_budget,
        find_casters=args.fit is not None,
    )
    inert = [
        r["name"] for r in result.parameters if r["name"] in ("mass", "yaw_inertia") and "at the bound" in r["why"]
    ]
    if inert and args.effort_scale is None:
        hint = (
            f"{' and '.join(inert)} reached the bound of the search range: are the efforts N·m at the wheel? A "
            "recording of motor current (A) needs --effort-scale Kt·N (torque constant × gear ratio); a recording "
            "of the torques commanded to the robot file's <dcmotor>s needs --motor dc; a skid-steer robot whose "
            "other wheels are driven too is not what the fit simulates (only the mapped pair is driven, the "
            "others roll free: a Husky recorded so fitted 19.4 kg against its chassis body's 56.0 kg)"
        )
        result.notes.append(hint)
        print(f"warning: {hint}", file=sys.stderr)
    model_pub = published.spec.compile()
    model_cal = sysid.apply_param_modifiers(opt, robot.spec)
    chunks = make_chunks(published, model_pub, rec, result.chunk_s, args.max_chunks)
    sim_pub = simulate_chunks(published, chunks, model_pub)
    chunks_cal = make_chunks(robot, model_cal, rec, result.chunk_s, args.max_chunks)
    sim_cal = simulate_chunks(robot, chunks_cal, model_cal)

    out.mkdir(parents=True, exist_ok=True)
    stem = Path(ref.model).stem
    cal_path = out / f"{stem}_calibrated.xml"
    casters = robot_casters(robot, robot.spec, model_cal) if "caster_friction" in result.names else []
    made = [p for p in (cal_path, assets_folder(cal_path), out / "fit.json", out / "fit.png") if not p.exists()]
    try:
        write_calibrated(ref, robot.layout, result.parameters, casters, cal_path, str(args.bag))
        cal_ref = replace(ref, model=str(cal_path.resolve()))
        p_pub, p_cal = robot_truth(ref), robot_truth(cal_ref)
        unidentified = [r["name"] for r in result.parameters if r["status"] == "not identified"]
        negligible = [r["name"] for r in result.parameters if r["status"] == "negligible"]
        report = {
            "robot": ref.model,
            "recording": str(args.bag),
            "effort": {"motor": ref.motor or "ideal", "driver": ref.driver or None},
            "calibrated_robot": str(cal_path),
            "a": p_cal.a_eff,
            "b": p_cal.b_eff,
            "published": {"a": p_pub.a_eff, "b": p_pub.b_eff},
            "parameters": result.parameters,
            "unidentified": unidentified,
            "negligible": negligible,
            "ci95_method": "the wider of the interval from J'J and the residual variance (mujoco.sysid, widened by the "
            "residual's lag-1 autocorrelation) and the leave-one-chunk-out jackknife (CR3: the chunks as independent "
            "units, from the Jacobian, no refits; Student's t with chunks - parameters dof) (design §8.4)",
            "correlation": {"names": result.names, "matrix": np.round(result.correlation, 4).tolist()},
            "residual": {
                "published": {"cost": result.cost_published, **_rms(chunks, sim_pub)},
                "calibrated": {"cost": result.cost_calibrated, **_rms(chunks_cal, sim_cal)},
                "units": "cost: sum of squares of the residuals weighted by 1/RMS of each signal; *_rms: rad/s, m/s",
            },
            "seconds": result.seconds,
            "iterations": result.evaluations,
            "notes": held + result.notes + rec.notes,
            "mapping_flags": "the calibrated file keeps the published names: map it with the same flags",
        }
        write_json(out / "fit.json", report)
        meas = _signals_of_chunks(chunks, None)
        plot_signals(
            out / "fit.png",
            meas,
            {"published": _signals_of_chunks(chunks, sim_pub), "calibrated": _signals_of_chunks(chunks_cal, sim_cal)},
            f"{stem}: recorded vs simulated from each chunk's recorded start ({one_line(str(args.bag))})",
        )
    except BaseException:  # output files complete or absent: what this run wrote goes
        for p in made:
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
        raise
    lines = [f"fit: {one_line(stem)} to {one_line(str(args.bag))} ({rec.duration:.3g} s) in {result.seconds:.0f} s"]
    for r in result.parameters:
        ci = f"± {r['ci95_halfwidth']:.2g}" if r["ci95_halfwidth"] is not None else "± inf"
        lines.append(
            f"  {r['name']:<16} published {r['published']:<10.4g} fitted {r['fitted']:<10.4g} {ci} {r['unit']}"
            + ("" if r["status"] == "identified" else f"  {r['status'].upper()}: {r['why']}")
        )
    lines.append(
        f"  a = {p_cal.a_eff:.5g} (published {p_pub.a_eff:.5g}), b = {p_cal.b_eff:.5g} (published {p_pub.b_eff:.5g})"
    )
    lines.append(f"  residual cost {result.cost_published:.4g} published -> {result.cost_calibrated:.4g} calibrated")
    lines.append(f"  wrote {out / 'fit.json'}, {one_line(str(cal_path))}, {out / 'fit.png'}")
    print("\n".join(lines))
    if unidentified:
        print(f"warning: not identified by this recording: {', '.join(unidentified)} (see fit.json)", file=sys.stderr)
    return 0


def _replay_main(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from bioform_mj.outputs.files import check_out_dir, write_json
    from bioform_mj.robots.realdata.replay import compare, measured, plot_signals, replay
    from bioform_mj.robots.realdata.simmodel import sim_spec

    out = check_out_dir(args.out, "--out") if args.out else None
    ref, robot, rec = _load(args)
    robots = {"published": robot}
    if args.calibrated:
        if not Path(args.calibrated).is_file():
            raise InputError(f"--calibrated {args.calibrated}: no such file")
        robots["calibrated"] = sim_spec(replace(ref, model=str(Path(args.calibrated))))
    meas = measured(rec)
    sims = {name: replay(r, rec) for name, r in robots.items()}
    report = {"recording": str(args.bag), "duration_s": rec.duration}
    for name, sim in sims.items():
        report[name] = compare(meas, sim)
    lines = [
        f"replay: {one_line(Path(ref.model).stem)} open loop over {rec.duration:.3g} s of {one_line(str(args.bag))}"
    ]
    for name in sims:
        c = report[name]
        parts = [f"{k[:-4]} {v:.3g}" for k, v in c.items() if k.endswith("_rms") and v is not None]
        lines.append(
            f"  {name:<10} RMS difference: {', '.join(parts)} (rad/s, m/s)"
            + (f"; position drift {c['drift_m']:.3g} m" if "drift_m" in c else "")
        )
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "replay.json", report)
        plot_signals(out / "replay.png", meas, sims, f"open-loop replay of {args.bag}")
        lines.append(f"  wrote {out / 'replay.json'}, {out / 'replay.png'}")
    print("\n".join(lines))
    return 0


def _program_main(args: argparse.Namespace) -> int:
    from bioform_mj.cli.robot import ref_from_args
    from bioform_mj.robots.params import robot_truth
    from bioform_mj.robots.realdata.program import drive_program, program_torque

    if not (args.seconds > 0 and args.rate > 0 and args.accel > 0):
        raise InputError("--seconds, --rate and --accel must be > 0")
    ref = ref_from_args(args.model, args)
    p = robot_truth(ref)
    tau = program_torque(p, args.accel)
    prog = drive_program(tau, args.seconds, args.rate, args.seed)
    print(
        f"# drive program for {Path(ref.model).stem}: wheel torques up to {tau:.3g} N·m (forward positive), "
        f"{args.seconds:g} s at {args.rate:g} Hz; apply open loop, record /joint_states (position, velocity, "
        "effort = the applied torque), /odom and /imu"
    )
    print("time,left,right")
    sys.stdout.write("".join(f"{t:.4f},{a:.6g},{b:.6g}\n" for t, a, b in prog))
    return 0
