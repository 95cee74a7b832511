"""The ``bioform`` command (design §10).

Exit codes: 0 done; 2 bad input (one ``error:`` line on stderr, no traceback, before any
work); 3 the simulation diverged (diagnosis on stderr, log kept); 130/143 interrupted by
SIGINT/SIGTERM (a message on stderr, no temporary files left, the log so far kept where the
run returned one); 1 anything else.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
from collections.abc import Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

from bioform_mj.cli.outdir import claim, default_name, out_path, path_arg, prepare_out
from bioform_mj.cli.proc import (
    _catch_signals,
    _guard_streams,
    _ignore_signals,
    _kept_beside,
    _mujoco_log,
    _silence,
    check_mujoco_distributions,
    exit_deaf,
    progress_bar,
)
from bioform_mj.cli.report import _print_summary, _record_toml, _show_robot_warnings, _warn_outcomes
from bioform_mj.control.registry import ENTRY_POINT_GROUP, parse_methods
from bioform_mj.control.stack import METHODS
from bioform_mj.core.errors import BioformError, InputError, WriteFailed
from bioform_mj.outputs.registry import OUTPUTS
from bioform_mj.plants.base import RobotModels
from bioform_mj.scenario.config import PLANTS

EXIT_OK, EXIT_OTHER, EXIT_INPUT, EXIT_DIVERGED = 0, 1, 2, 3
_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one ``error:`` line with exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def _backend_args(p: argparse.ArgumentParser, choices: tuple[str, ...], help: str) -> None:
    """``--backend`` (one of ``choices``, the first the default) and ``--device``, its Warp device."""
    p.add_argument("--backend", choices=choices, default=choices[0], help=help)
    p.add_argument("--device", help="with --backend warp: Warp device, cpu or cuda[:N] (default: cuda if present)")


def _scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="paper", help="preset name or path to a TOML file (default: paper)")
    p.add_argument("--plant", metavar="KIND", help=f"plant: {'/'.join(PLANTS)} or registered (default: the scenario's)")
    p.add_argument("--duration", type=float, help="simulated time in s (overrides sim.duration)")
    p.add_argument("--seed", type=int, help="random seed (overrides sim.seed)")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set kinematic.k1=3 (repeatable)",
    )
    p.add_argument(
        "--package-path",
        action="append",
        default=[],
        metavar="NAME=DIR",
        help="URDF robots: where package://NAME/... points (repeatable; adds to plant.package_path)",
    )
    from bioform_mj.robots.xacro_sandbox import add_flags

    add_flags(p, scenario=True)  # design §12: a xacro file is a program, run only when asked
    from bioform_mj.robots.mjcf_assets import add_flag as add_asset_root

    add_asset_root(p, scenario=True)  # design §12: an MJCF robot's files inside its folder unless granted
    p.add_argument("--quiet", action="store_true", help="no progress bar, no result lines")
    p.add_argument(
        "--control-rate",
        type=float,
        metavar="HZ",
        help="MuJoCo robots: the rate each robot's own controller commands its wheels at, Hz, the maker's figure "
        "(sets every robot's mapping key control_rate; the hardware verdict's control_rate check, design §19)",
    )
    p.add_argument(
        "--no-robot-check",
        action="store_true",
        help="MuJoCo robots: skip the robot check before the run (identification, once per robot, cached; "
        "its failures are warnings; design §14.2); sets BIOFORM_NO_ROBOT_CHECK=1",
    )


def _package_overrides(args: argparse.Namespace) -> list[str]:
    """``--package-path NAME=DIR`` as ``--set plant.package_path.NAME="DIR"`` (absolute), design §12."""
    from bioform_mj.robots.refs import package_path_from_args

    return [f"plant.package_path.{n}={json.dumps(d)}" for n, d in package_path_from_args(args.package_path)]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="bioform", description="Distributed bioinspired formation control on ideal and MuJoCo plants."
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run one scenario and write summary.json and log.npz")
    _scenario_args(run)
    run.add_argument(
        "--method",
        metavar="NAME",
        help=f"control method: {', '.join(METHODS)}, or a registered controller's name (entry points "
        f"{ENTRY_POINT_GROUP}) (default: the scenario's)",
    )
    run.add_argument(
        "--out",
        type=path_arg,
        help="output directory (default: runs/<scenario>-<plant>-<method>, with -<hash of the configuration> "
        "when --set/--duration/--seed/--package-path change it); one run per folder",
    )
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run already in --out (its files only; a folder holding other files is refused)",
    )
    run.add_argument(
        "--engine",
        choices=("auto", "compiled", "stepwise"),
        default="auto",
        help="compiled: whole chunks of control periods in machine code (needs a plant and controller with "
        "compiled kernels and no per-step faults); stepwise: one Python call per control step, same equations; "
        "auto (default): compiled where possible",
    )
    for o in OUTPUTS.values():  # the registered outputs (design §22): --video, --rrd, --figures, ...
        run.add_argument(o.flag, action="store_true", help=o.help)
    run.add_argument("--ros-distro", choices=("humble", "iron", "jazzy", "kilted"), help="the bag's (default jazzy)")
    run.add_argument("--rerun-spawn", action="store_true", help="stream the run live to a rerun viewer spawned for it")
    run.add_argument(
        "--rerun-connect",
        metavar="ADDR",
        help="stream the run live to a running rerun viewer (rerun+http://HOST:PORT/proxy, HOST:PORT or PORT)",
    )
    vid = run.add_argument_group("video options (with --video)")
    vid.add_argument("--width", type=int, help="video width in pixels, even (default 960)")
    vid.add_argument("--height", type=int, help="video height in pixels, even (default 540)")
    vid.add_argument("--fps", type=float, help="frames per second of simulated time (default 30)")
    vid.add_argument(
        "--camera",
        choices=("auto", "track", "top"),
        help="auto: free camera keeping leader, followers and slots in view (default); "
        "track/top: the scene's cameras on the formation centroid",
    )

    t1 = sub.add_parser("table1", help="run the four methods and write table1.json / table1.md")
    _scenario_args(t1)
    t1.add_argument(
        "--methods",
        default="all",
        help="comma-separated methods (the paper's or registered controllers'), or 'all': the paper's four (default)",
    )
    t1.add_argument("--out", type=path_arg, help="output directory (default: runs/table1-<plant>[-<hash>], as run)")
    t1.add_argument("--overwrite", action="store_true", help="replace the table already in --out (its files only)")
    t1.add_argument("--figures", action="store_true", help="write figures/*.png comparing the methods")

    ident = sub.add_parser("identify", help="system identification of a robot MJCF: formula vs measured a, b")
    ident.add_argument("model", help="shipped robot name or path to an MJCF or URDF file")
    ident.add_argument("--out", type=path_arg, help="write the result as JSON to this file")
    from bioform_mj.cli.robot import add_parser as _robot_parser
    from bioform_mj.cli.robot import mapping_args

    mapping_args(ident)
    rsub = _robot_parser(sub)  # bioform robot check MODEL.xml [--base B] [--left-wheel J] [--right-wheel J] [--json F]
    from .realdata import add_parsers as _realdata_parsers

    _realdata_parsers(rsub)  # bioform robot fit / replay / drive-program (issue 29)

    sw = sub.add_parser("sweep", help="many runs: methods x varied keys x seeds, on a process pool or Ray")
    _scenario_args(sw)
    sw.add_argument("--seeds", type=int, default=1, help="seeds per configuration, 0..K-1 (default 1)")
    sw.add_argument(
        "--methods",
        default="bioinspired-learning",
        help="comma-separated methods (the paper's or registered controllers'), or 'all': the paper's four "
        "(default: bioinspired-learning)",
    )
    sw.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=V1,V2,...",
        help="vary a scenario key over values (repeatable, one --vary per key: a key given twice, or also "
        "given with --set, is refused; equal values are run once; ';' separates array values)",
    )
    _backend_args(
        sw,
        ("local", "ray", "warp"),
        "local processes, Ray, or warp: every run a world of a MuJoCo Warp batch (needs pip install 'bioform-mj[gpu]')",
    )
    sw.add_argument(
        "--nconmax",
        type=int,
        help="with --backend warp: contacts per world MuJoCo Warp allocates (default 8 per robot + 16); "
        "worlds that overflow it are reported diverged",
    )
    sw.add_argument(
        "--njmax",
        type=int,
        help="with --backend warp: constraint rows per world (default 32 per robot + 16); as --nconmax",
    )
    sw.add_argument("--workers", type=int, help="parallel workers (default: CPU count)")
    sw.add_argument("--ray-address", help="Ray cluster address (default: start a local Ray)")
    sw.add_argument("--out", type=path_arg, required=True, help="sweep directory (rerunning resumes it)")
    sw.add_argument("--rosbag", action="store_true", help="also write each run as a ROS 2 bag, DIR/bags/<key>/")
    sw.add_argument("--ros-distro", choices=("humble", "iron", "jazzy", "kilted"), help="the bags' (default jazzy)")

    cal = sub.add_parser("calibrate", help="search the paper's unstated conditions for the best fit to Table I")
    cal.add_argument("target", help="what to fit: table1")
    cal.add_argument("--scenario", default="paper", help="preset name or TOML file to start from (default: paper)")
    cal.add_argument("--plant", choices=PLANTS, default="ideal")
    cal.add_argument(
        "--budget",
        type=int,
        help="evaluations in the search (default: 600 ideal, 90 mujoco; at most 100000); the count and an "
        "estimated duration are printed before the search",
    )
    cal.add_argument("--workers", type=int, help="processes (default: up to 2)")
    cal.add_argument("--seed", type=int, default=0)
    cal.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    cal.add_argument(
        "--out",
        type=path_arg,
        required=True,
        help="writes calibration.json, calibration.md and evaluations.jsonl here; one calibration per folder, "
        "rerunning the same command resumes an unfinished one",
    )
    cal.add_argument("--overwrite", action="store_true", help="replace the calibration already in --out")
    cal.add_argument("--quiet", action="store_true")

    sub.add_parser("presets", help="list the shipped scenario presets, each with its description")

    bn = sub.add_parser(
        "bench", help="closed-loop throughput against bare mj_step, n = 3, 16, 64, 256 (1024 on request)"
    )
    bn.add_argument("--sizes", default="3,16,64,256", help="comma-separated team sizes (of 3, 16, 64, 256, 1024)")
    bn.add_argument(
        "--duration", type=float, help="sim.duration per case, s, before the preset's time scale (default: per size)"
    )
    bn.add_argument(
        "--reps", type=int, default=3, help="alternated bare/loop pairs; the median pair ratio counts (default 3)"
    )
    bn.add_argument("--numpy", action="store_true", help="also time the numpy reference stack")
    bn.add_argument("--json", type=path_arg, default=Path("runs/bench.json"), help="output JSON (runs/bench.json)")
    _backend_args(
        bn,
        ("cpu", "warp"),
        "cpu: the compiled loop vs mj_step (default); warp: MuJoCo Warp batches, closed loop vs "
        "physics alone, and the CPU engine on this machine",
    )
    bn.add_argument(
        "--worlds",
        default="1024,4096,32768",
        help="with --backend warp: comma-separated world counts (default 1024,4096,32768)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``bioform`` console script; returns the exit code."""
    from bioform_mj.outputs.gl import configure_gl_env
    from bioform_mj.robots.sanity import one_line

    configure_gl_env()  # MUJOCO_GL=egl unless the user chose; before anything imports mujoco
    _show_robot_warnings()
    restore = _catch_signals()
    unguard = _guard_streams()
    from bioform_mj.assess.skip import SKIP_ENV

    skip_before = os.environ.get(SKIP_ENV)  # --no-robot-check sets it for this command only (design §14.2)
    try:
        args = build_parser().parse_args(argv)
        check_mujoco_distributions()
        return _dispatch(args)
    except InputError as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)  # one line, whatever a name holds (issue 28)
        return EXIT_INPUT
    except WriteFailed as exc:  # disk full, read-only file system, ulimit -f: the file and what was kept
        if not exc.kept:
            exc.kept = _kept_beside(exc.path)
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_OTHER
    except BioformError as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_OTHER
    except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM through _catch_signals
        _ignore_signals()
        signum = getattr(exc, "signum", signal.SIGINT)
        print(
            f"error: interrupted by {signal.Signals(signum).name}; {getattr(exc, 'kept', 'nothing written')}",
            file=sys.stderr,
        )
        return 128 + signum
    except BrokenPipeError:  # a closed pipe the stream guard did not see (a child's): never success
        _silence(sys.stdout)
        _silence(sys.stderr)
        return EXIT_OTHER
    except Exception as exc:  # noqa: BLE001 - a bug: one line, full traceback on request
        if os.environ.get("BIOFORM_DEBUG"):
            raise
        print(
            f"error: internal error {type(exc).__name__}: {exc} (set BIOFORM_DEBUG=1 for a traceback)", file=sys.stderr
        )
        return EXIT_OTHER
    finally:
        unguard()
        restore()
        if skip_before is None:
            os.environ.pop(SKIP_ENV, None)
        else:
            os.environ[SKIP_ENV] = skip_before


def entry() -> None:
    """``bioform``: :func:`main`, then exit deaf to SIGINT/SIGTERM (:func:`bioform_mj.cli.proc.exit_deaf`)."""
    exit_deaf(main)


def _dispatch(args: argparse.Namespace) -> int:
    from bioform_mj.robots.xacro_sandbox import grant_from_args

    grant_from_args(args)  # --xacro / --xacro-arg, or nothing granted (design §12)
    from bioform_mj.robots.mjcf_assets import grant_roots, roots_from_args

    roots = roots_from_args(getattr(args, "asset_root", None))
    if roots and args.command == "sweep":  # its runs are other processes, as --xacro
        raise InputError(
            'sweep --asset-root: a sweep\'s runs are other processes; write asset_roots = ["DIR"] in the '
            "robot's table of the scenario instead (design §12)"
        )
    grant_roots(roots)  # --asset-root DIR, or only each robot's own folder (design §12)
    if getattr(args, "no_robot_check", False):  # design §14.2; inherited by a sweep's worker processes
        from bioform_mj.assess.skip import SKIP_ENV

        os.environ[SKIP_ENV] = "1"
    if args.command == "presets":
        from bioform_mj.scenario.loader import preset_descriptions

        desc = preset_descriptions()
        width = max(map(len, desc))
        print("\n".join(f"{name:<{width}}  {text}" for name, text in desc.items()))
        return EXIT_OK
    from bioform_mj.core.equations import CACHE_NOTE  # a read-only home: kernels cached elsewhere, or not at all
    from bioform_mj.core.jitwatch import watch

    CACHE_NOTE and print(f"warning: {CACHE_NOTE}", file=sys.stderr)  # its paths as repr: one line
    # a compile said before it happens, terminal or not (numba's cache index missed; design §2); --quiet: not said
    say = not getattr(args, "quiet", False)
    stop_watch = watch(lambda burst: say and print(burst.line(), file=sys.stderr, flush=True))
    try:
        return _dispatch_work(args)
    finally:
        stop_watch()


def _dispatch_work(args: argparse.Namespace) -> int:
    with _mujoco_log() as mjlog:
        if args.command == "identify":
            from bioform_mj.cli.robot import identify_command

            return identify_command(args)
        if args.command == "robot" and getattr(args, "realdata_main", None):
            from bioform_mj.cli.robot import cli_terms

            try:
                return args.realdata_main(args)  # robot fit / replay / drive-program (issue 29)
            except InputError as exc:  # a robot's mapping in the flags' terms (issue 28)
                raise InputError(cli_terms(str(exc))) from None
        if args.command == "robot":
            from bioform_mj.cli.robot import main as robot_main

            return robot_main(args)
        if args.command == "sweep":
            return _sweep(args)
        if args.command == "bench":
            from bioform_mj.jobs import bench

            return bench.run(args)
        if args.command == "calibrate":
            return _calibrate(args)
        sc = _load(args)
        if args.command == "run":
            return _run(args, sc, mjlog)
        return _table1(args, sc, mjlog)


def _load(args: argparse.Namespace):
    import bioform_mj.run  # noqa: F401 - registers the resolver of formation.scale/time_scale = "auto" (design §0)
    from bioform_mj.scenario.loader import load

    overrides = list(args.overrides)
    if args.duration is not None:
        overrides.append(f"sim.duration={args.duration!r}")
    if args.seed is not None:
        overrides.append(f"sim.seed={args.seed}")
    overrides += _package_overrides(args)
    rate = getattr(args, "control_rate", None)
    if rate is not None and not (math.isfinite(rate) and rate > 0):  # before any work (design §17)
        raise InputError(f"--control-rate must be a finite number > 0 (Hz), got {rate}")
    sc = load(args.scenario, overrides, method=getattr(args, "method", None), plant=args.plant)
    import dataclasses

    from bioform_mj.robots.xacro_sandbox import fold_grant

    robots = fold_grant(sc.plant.robots)  # --xacro/--xacro-arg into the tables: resolved.toml reproduces (§12)
    if rate is not None:  # design §19: every robot's mapping key control_rate
        robots = tuple(dataclasses.replace(r, control_rate=float(rate)) for r in robots)
    if robots != tuple(sc.plant.robots):
        sc = dataclasses.replace(sc, plant=dataclasses.replace(sc.plant, robots=robots))
    return sc


def _run(args: argparse.Namespace, sc, mjlog) -> int:
    video_opts = None
    if args.video:
        from bioform_mj.outputs.video import VideoOptions

        video_opts = VideoOptions(
            **{
                k: v
                for k, v in (("width", args.width), ("height", args.height), ("fps", args.fps), ("camera", args.camera))
                if v is not None
            }
        )
        video_opts.validate()
    else:
        given = [f"--{k}" for k in ("width", "height", "fps", "camera") if getattr(args, k) is not None]
        if given:
            raise InputError(f"{', '.join(given)} only apply to --video")
    if args.rosbag or args.ros_distro:  # before any work: the ros extra is installed (else: how to install it)
        from bioform_mj.outputs.rosbag import check_args

        check_args(args.rosbag, args.ros_distro, sc)
    live_url = None
    if args.rerun_spawn and args.rerun_connect:
        raise InputError("--rerun-spawn and --rerun-connect exclude each other")
    if args.rerun_connect:
        from bioform_mj.outputs.rerun_log import connect_url

        live_url = connect_url(args.rerun_connect)
    if args.rerun_spawn:
        from bioform_mj.outputs.rerun_log import check_can_spawn

        check_can_spawn()
    rundir = claim(args.out, default_name(args, sc, f"{sc.name}-{sc.plant.kind}-{sc.method}"), args.overwrite)
    with rundir:  # created and locked from here on (exit 2 if another run holds it); lock released at the end
        try:
            return _run_in(args, sc, mjlog, rundir.path, {"video": video_opts, "rosbag": args.ros_distro}, live_url)
        finally:
            if rundir.written:  # MuJoCo's warnings join a run's files (a folder left empty is removed)
                mjlog.write(rundir.path)


def _run_in(args: argparse.Namespace, sc, mjlog, out: Path, options: dict[str, Any], live_url) -> int:

    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.outputs.files import write_json, write_npz, write_text
    from bioform_mj.outputs.progress import progress_bar
    from bioform_mj.run.simulate import simulate

    observers: list[Any] = []  # none unless asked: the loop then has no per-step observer cost
    live = None
    chosen = [o for o in OUTPUTS.values() if getattr(args, o.dest, False)]  # the registered outputs asked for
    watchers = {o.name: o.watch(options.get(o.name)) for o in chosen}  # the video's snapshots (rendered after)
    observers += [w for w in watchers.values() if w is not None]
    if args.rerun_spawn or live_url:
        from bioform_mj.outputs.rerun_log import RerunLive

        live = RerunLive(spawn=args.rerun_spawn, url=live_url, period=max(sc.sim.log_dt, 1 / 30))
        observers.append(live)
    interrupted: KeyboardInterrupt | None = None
    failed: Exception | None = None
    try:
        with (
            progress_bar(f"{sc.name} {sc.method}", not args.quiet) as cb,
            quiet_outcomes(),  # said once, by _warn_outcomes after the files
        ):
            result = simulate(sc, observers=observers, progress=cb, engine=args.engine, full_state=args.rosbag)
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM mid-run: keep what the loop returns with it
        result = getattr(exc, "result", None)
        if result is None:
            exc.kept = "no log kept (the run was stopped before it returned a result)"  # type: ignore[attr-defined]
            raise
        interrupted = exc
    except Exception as exc:  # an observer (video capture, live viewer) raised mid-run: keep its log
        result = getattr(exc, "result", None)
        if result is None:
            raise
        failed = exc
    if interrupted is None and getattr(result, "interrupted", None) is not None:  # or a result that says so
        interrupted = result.interrupted
    if interrupted is not None and not result.summary.get("interrupted"):
        result.summary["interrupted"] = {
            "signal": signal.Signals(getattr(interrupted, "signum", 2)).name,
            "time_s": result.summary.get("sim_time_s"),
        }
    write_npz(out / "log.npz", result.log)
    if isinstance(result.plant, RobotModels):  # design §22: a scene of robot models (the MuJoCo plant)
        from bioform_mj.outputs.scenexml import write_scene

        write_scene(out, result.plant.model_xml())  # design §12: assets/ beside it, loads on its own
    from bioform_mj.outputs.summary_paths import (
        relative_paths,  # design §10: no absolute path of the machine in the run's files
    )

    record = relative_paths(result.summary, out)
    write_json(out / "summary.json", record)
    write_text(out / "resolved.toml", _record_toml(record))
    mjlog.write(out)
    if failed is not None:
        r = result.summary.get("raised") or {}
        print(
            f"error: {r.get('by', 'the run')} raised {type(failed).__name__}: {failed} at t = "
            f"{r.get('time_s', 0):g} s; log so far kept in {out} (summary.json, log.npz)",
            file=sys.stderr,
        )
        return EXIT_OTHER
    if interrupted is not None:
        _ignore_signals()
        signum = getattr(interrupted, "signum", signal.SIGINT)
        print(
            f"error: interrupted by {signal.Signals(signum).name} at t = {result.summary.get('sim_time_s', 0):g} s; "
            f"log so far kept in {out} (summary.json, log.npz)",
            file=sys.stderr,
        )
        return 128 + signum

    problems: list[str] = []  # what was asked for and could not be made: error lines, exit 2
    notes: list[str] = []
    try:
        for o in chosen:  # design §22: each registered output's writer, in the registry's order
            bar = o.files[0] if o.files else o.name
            show = progress_bar(bar, not args.quiet, unit=o.progress_unit) if o.progress_unit else nullcontext()
            try:
                with show as cb:
                    notes.append(o.write(result, out, watchers[o.name], options.get(o.name), progress=cb))
            except InputError as exc:  # what it cannot make (the video: no OpenGL context, nothing to show)
                problems.append(str(exc))
    except KeyboardInterrupt as exc:  # while writing the extras: the run itself is complete
        exc.kept = (
            f"the run completed: summary.json and log.npz are in {out}; "  # type: ignore[attr-defined]
            f"{', '.join(n.split(':')[0].split(' ')[0] for n in notes) or 'no extra output'} written, "
            "the rest not"
        )
        raise
    if live is not None and live.error:
        problems.append(live.error)
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    _warn_outcomes(result.summary)
    hw = result.summary.get("hardware")
    if hw is not None and not problems:  # design §19: one line, a warning when it would not run on the robots
        from bioform_mj.assess.hardware import line

        if hw["verdict"] == "fail":
            print(f"warning: {line(hw)}", file=sys.stderr)
        elif not args.quiet:
            print(line(hw))
    if result.diverged is not None:
        print(f"error: simulation diverged: {result.diverged}; log kept in {out}", file=sys.stderr)
        return EXIT_DIVERGED
    if not args.quiet:
        for note in notes:
            print(note)
        _print_summary(result.summary, out)
    return EXIT_INPUT if problems else EXIT_OK


def _table1(args: argparse.Namespace, sc, mjlog) -> int:
    rundir = claim(args.out, default_name(args, sc, f"table1-{sc.plant.kind}"), args.overwrite)
    with rundir:
        try:
            return _table1_in(args, sc, rundir.path)
        finally:
            if rundir.written:  # MuJoCo's warnings join a run's files (a folder left empty is removed)
                mjlog.write(rundir.path)


def _table1_in(args: argparse.Namespace, sc, out: Path) -> int:
    from bioform_mj.jobs.table1 import PAPER_TABLE1, markdown, run_table1
    from bioform_mj.outputs.files import write_json, write_text
    from bioform_mj.outputs.progress import progress_bar

    results = {}
    methods = parse_methods(args.methods, "--methods")

    with progress_bar(f"table1 {sc.name} {sc.plant.kind}", not args.quiet) as cb:

        def keep(m, res):
            results[m] = res
            if not args.quiet:
                line = f"  {m}: done in {res.summary['wall_time_s']:.1f} s"
                cb.write(line) if cb is not None else print(line, file=sys.stderr)

        def per_method(m: str):  # one bar over the runs: method i of k fills [i/k, (i+1)/k]
            i, total = methods.index(m), len(methods)

            def part(k: int, n: int) -> None:
                cb(i * n + k, total * n)

            part.phase = cb.phase  # type: ignore[attr-defined]  # (kernels loading/compiling)
            return part

        try:
            table = run_table1(sc, on_result=keep, progress=None if cb is None else per_method, methods=methods)
        except KeyboardInterrupt as exc:
            done = ", ".join(results) or "none"
            exc.kept = f"no table written (methods finished: {done})"  # type: ignore[attr-defined]
            raise
    write_json(out / "table1.json", table)
    md = markdown(table)
    write_text(out / "table1.md", md)
    if args.figures:
        from bioform_mj.outputs.figures import table1_figures

        figs = table1_figures(results, out / "figures", PAPER_TABLE1)
        if not args.quiet:
            print(f"figures/: {len(figs)} PNGs")
    diverged = [m for m, r in results.items() if r.diverged is not None]
    if not args.quiet:
        print(md)
        print(f"outputs in {out}/")
    if diverged:
        print(f"error: simulation diverged for {', '.join(diverged)}: {results[diverged[0]].diverged}", file=sys.stderr)
        return EXIT_DIVERGED
    return EXIT_OK


def _sweep(args: argparse.Namespace) -> int:
    import shlex

    from bioform_mj.jobs.runner import check_workers
    from bioform_mj.jobs.sweep import SweepInterrupted, expand, sweep

    methods = parse_methods(args.methods, "--methods")
    check_workers(args.workers, args.backend == "local" or not args.ray_address)  # this machine: 8 per CPU
    for flag, val in (("--device", args.device), ("--nconmax", args.nconmax), ("--njmax", args.njmax)):
        if val is not None and args.backend != "warp":
            raise InputError(f"{flag} applies to --backend warp only")
    for flag, val in (("--nconmax", args.nconmax), ("--njmax", args.njmax)):
        if val is not None and val < 1:
            raise InputError(f"{flag} must be >= 1, got {val}")
    if args.backend == "warp":  # before any work: the extra, then the device
        from bioform_mj.batch.backend import require_warp, resolve_device

        require_warp()
        args.device = resolve_device(args.device)
    overrides = list(args.overrides)
    if args.duration is not None:
        overrides.append(f"sim.duration={args.duration!r}")
    overrides += _package_overrides(args)
    specs = expand(args.scenario, args.seeds, methods, args.vary, overrides, plant=args.plant, seed0=args.seed or 0)
    if args.backend == "warp":  # unsupported features, device memory: before anything is written
        from bioform_mj.batch.backend import plan

        plan(specs, args.device, nconmax=args.nconmax, njmax=args.njmax)
    if args.backend == "ray":  # nothing listening there: exit 2 in seconds, naming the address
        from bioform_mj.jobs.ray_backend import check_ray_address

        check_ray_address(args.ray_address)
    elif args.ray_address is not None:
        raise InputError("--ray-address applies to --backend ray only")
    out = prepare_out(args.out, "sweep")
    from bioform_mj.outputs.rundir import check_sweep_dir

    check_sweep_dir(out)
    rosbag = (args.ros_distro or "jazzy") if args.rosbag else None
    if args.ros_distro and not args.rosbag:
        raise InputError("--ros-distro only applies to --rosbag")
    if rosbag is not None:  # the extra, the backend, the disk: before any work
        from bioform_mj.jobs.sweepbags import check_bags

        check_bags(specs, out, args.backend, rosbag)
    out.mkdir(parents=True, exist_ok=True)
    progress = progress_bar(not args.quiet, "sweep")
    try:
        res = sweep(
            specs,
            out,
            backend=args.backend,
            workers=args.workers,
            ray_address=args.ray_address,
            progress=progress,
            device=args.device,
            nconmax=args.nconmax,
            njmax=args.njmax,
            note=None if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True)),
            rosbag=rosbag,
        )
    except WriteFailed as exc:  # disk full, read-only, ulimit -f: the finished rows are kept, resumable
        runs = out / "runs"
        done = sum(1 for p in runs.glob("*.json")) if runs.is_dir() else 0
        exc.kept = f"{done} finished row(s) kept in {runs}/; free space, then rerun the same command to resume"
        raise
    except SweepInterrupted as exc:
        # the same command resumes: finished rows are skipped by their content key
        cmd = ["bioform", "sweep", args.scenario]
        for flag, val in (("--plant", args.plant), ("--duration", args.duration), ("--seed", args.seed)):
            if val is not None:
                cmd += [flag, str(val)]
        for ov in args.overrides:
            cmd += ["--set", ov]
        cmd += ["--seeds", str(args.seeds), "--methods", args.methods]
        for v in args.vary:
            cmd += ["--vary", v]
        cmd += ["--backend", args.backend]
        for flag, val in (
            ("--device", args.device),
            ("--nconmax", args.nconmax),
            ("--njmax", args.njmax),
            ("--workers", args.workers),
            ("--ray-address", args.ray_address),
        ):
            if val is not None:
                cmd += [flag, str(val)]
        cmd += ["--out", str(out)] + (["--rosbag"] if args.rosbag else [])
        cmd += ["--ros-distro", args.ros_distro] if args.ros_distro else []
        if args.quiet:
            cmd.append("--quiet")
        if progress is not None:
            sys.stderr.write("\n")
        print(f"{exc}; finished rows kept in {out}/runs/. Resume with:\n  {shlex.join(cmd)}", file=sys.stderr)
        return 128 + exc.signum
    tm = res["timing"]
    if tm["workers_died"]:
        print(
            f"warning: {tm['workers_died']} run(s) failed because their worker process died (see 'error' in "
            f"{out}/runs.csv); rerun the sweep to retry them",
            file=sys.stderr,
        )
    if not args.quiet:
        rate = (
            f", {tm['wall_s']:.1f} s, {tm['runs_per_s']:.2f} runs/s on {tm['workers']} worker(s)"
            if tm["runs_per_s"]
            else ""
        )
        died = f", {tm['workers_died']} worker(s) died (rerun to retry)" if tm["workers_died"] else ""
        print(f"{tm['runs']} runs ({res['ran']} run now, {res['skipped']} already done{rate}{died})")
        print((out / "stats.md").read_text(encoding="utf-8"))
        print(f"outputs in {out}/ (runs.csv, runs.parquet, stats.json, stats.md, sweep.json)")
    return EXIT_OK


def _calibrate(args: argparse.Namespace) -> int:
    from bioform_mj.jobs import calibrate as cal
    from bioform_mj.outputs.rundir import CALIBRATION_FILES, RunDir

    # every input, the budget's estimate and the folder checked before any work (exit 2)
    cal.check_inputs(args.target, args.plant, args.budget, args.scenario, args.overrides, args.workers)
    rundir = RunDir(
        out_path(args.out, "calibration"),
        overwrite=args.overwrite,
        what="calibration folder",
        files=CALIBRATION_FILES,
        resumable=frozenset({cal.EVALUATIONS_FILE, cal.PARTIAL_FILE, "MUJOCO_LOG.TXT"}),
    ).check()
    with rundir:  # one calibration per folder (flock); --overwrite clears an earlier one's files
        out = rundir.path
        try:
            rep = cal.calibrate(
                args.target,
                plant=args.plant,
                budget=args.budget,
                source=args.scenario,
                overrides=args.overrides,
                workers=args.workers,
                seed=args.seed,
                progress=progress_bar(not args.quiet, "calibrate"),
                out=out,
                note=None if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True)),
            )
        except cal.CalibrationInterrupted as exc:
            _ignore_signals()
            print(f"error: {exc}", file=sys.stderr, flush=True)
            return 128 + exc.signum
        cal.write(rep, out)
    if not args.quiet:
        print(cal.markdown(rep))
        print(f"outputs in {out}/ (calibration.json, calibration.md, {cal.EVALUATIONS_FILE})")
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
