"""The ``bioform`` command (design §10).

Exit codes: 0 done; 2 bad input (one ``error:`` line on stderr, no traceback);
3 the simulation diverged (diagnosis on stderr, log kept); 1 anything else.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from .control.stack import METHODS
from .errors import BioformError, InputError
from .scenario import PLANTS

EXIT_OK, EXIT_OTHER, EXIT_INPUT, EXIT_DIVERGED = 0, 1, 2, 3


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one ``error:`` line with exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def _scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="paper", help="preset name or path to a TOML file (default: paper)")
    p.add_argument("--plant", choices=PLANTS, help="plant to drive (default: the scenario's)")
    p.add_argument("--duration", type=float, help="simulated time in s (overrides sim.duration)")
    p.add_argument("--seed", type=int, help="random seed (overrides sim.seed)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario value, e.g. --set kinematic.k1=3 (repeatable)")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no result lines")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bioform", description="Distributed bioinspired formation control on ideal and MuJoCo plants.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run one scenario and write summary.json and log.npz")
    _scenario_args(run)
    run.add_argument("--method", choices=METHODS, help="control method (default: the scenario's)")
    run.add_argument("--out", type=Path, help="output directory (default: runs/<scenario>-<plant>-<method>)")
    run.add_argument("--engine", choices=("auto", "compiled", "stepwise"), default="auto",
                     help="fused: the numba-compiled loop (default when numba imports); numpy: the reference stack")
    run.add_argument("--video", action="store_true",
                     help="write video.mp4 (off-screen MuJoCo rendering, MUJOCO_GL=egl by default; "
                          "the ideal plant is shown in a composed scene)")
    run.add_argument("--rrd", action="store_true", help="write run.rrd (rerun recording)")
    run.add_argument("--figures", action="store_true", help="write figures/*.png")
    run.add_argument("--rerun-spawn", action="store_true", help="stream the run live to a rerun viewer spawned for it")
    run.add_argument("--rerun-connect", metavar="ADDR",
                     help="stream the run live to a running rerun viewer "
                          "(rerun+http://HOST:PORT/proxy, HOST:PORT or PORT)")
    vid = run.add_argument_group("video options (with --video)")
    vid.add_argument("--width", type=int, help="video width in pixels, even (default 960)")
    vid.add_argument("--height", type=int, help="video height in pixels, even (default 540)")
    vid.add_argument("--fps", type=float, help="frames per second of simulated time (default 30)")
    vid.add_argument("--camera", choices=("auto", "track", "top"),
                     help="auto: free camera keeping leader, followers and slots in view (default); "
                          "track/top: the scene's cameras on the formation centroid")

    t1 = sub.add_parser("table1", help="run the four methods and write table1.json / table1.md")
    _scenario_args(t1)
    t1.add_argument("--out", type=Path, help="output directory (default: runs/table1-<plant>)")
    t1.add_argument("--figures", action="store_true", help="write figures/*.png comparing the methods")

    ident = sub.add_parser("identify", help="system identification of a robot MJCF: formula vs measured a, b")
    ident.add_argument("model", help="shipped robot name or path to an MJCF file")
    ident.add_argument("--out", type=Path, help="write the result as JSON to this file")

    sw = sub.add_parser("sweep", help="many runs: methods x varied keys x seeds, on a process pool or Ray")
    _scenario_args(sw)
    sw.add_argument("--seeds", type=int, default=1, help="seeds per configuration, 0..K-1 (default 1)")
    sw.add_argument("--methods", default="bioinspired-learning",
                    help="comma-separated methods, or 'all' (default: bioinspired-learning)")
    sw.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                    help="vary a scenario key over values (repeatable; ';' separates array values)")
    sw.add_argument("--backend", choices=("local", "ray"), default="local")
    sw.add_argument("--workers", type=int, help="parallel workers (default: CPU count)")
    sw.add_argument("--ray-address", help="Ray cluster address (default: start a local Ray)")
    sw.add_argument("--out", type=Path, required=True, help="sweep directory (rerunning resumes it)")

    sub.add_parser("presets", help="list the shipped scenario presets")

    bn = sub.add_parser("bench", help="closed-loop throughput against bare mj_step, n = 3, 16, 64, 256")
    bn.add_argument("--sizes", default="3,16,64,256", help="comma-separated team sizes (of 3, 16, 64, 256)")
    bn.add_argument("--duration", type=float, help="simulated seconds per case (default: per size)")
    bn.add_argument("--reps", type=int, default=2, help="repetitions; the best time counts (default 2)")
    bn.add_argument("--numpy", action="store_true", help="also time the numpy reference stack")
    bn.add_argument("--json", type=Path, default=Path("runs/bench.json"), help="output JSON (default runs/bench.json)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``bioform`` console script; returns the exit code."""
    from .outputs.gl import configure_gl_env

    configure_gl_env()  # MUJOCO_GL=egl unless the user chose; before anything imports mujoco
    try:
        args = build_parser().parse_args(argv)
        return _dispatch(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except BioformError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_OTHER
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `bioform ... | head`
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silence the flush at exit
        return EXIT_OK
    except Exception as exc:  # noqa: BLE001 - a bug: one line, full traceback on request
        if os.environ.get("BIOFORM_DEBUG"):
            raise
        print(f"error: internal error {type(exc).__name__}: {exc} (set BIOFORM_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_OTHER


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "presets":
        from .scenario import preset_names

        print("\n".join(preset_names()))
        return EXIT_OK
    if args.command == "identify":
        return _identify(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "bench":
        from . import bench

        return bench.run(args)
    sc = _load(args)
    if args.command == "run":
        return _run(args, sc)
    return _table1(args, sc)


def _load(args: argparse.Namespace):
    from .scenario import load

    overrides = list(args.overrides)
    if args.duration is not None:
        overrides.append(f"sim.duration={args.duration!r}")
    if args.seed is not None:
        overrides.append(f"sim.seed={args.seed}")
    return load(args.scenario, overrides, method=getattr(args, "method", None), plant=args.plant)


def _prepare_out(out: Path | None, default: str) -> Path:
    """Check that the output directory can be created or written, without creating it yet.

    Nothing is written before the run has validated its input and built its plant,
    so bad input leaves no directory behind; call ``.mkdir`` just before writing.
    """
    path = Path(out) if out is not None else Path("runs") / default
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if path.exists() and not path.is_dir():
        raise InputError(f"output directory '{path}' exists and is not a directory")
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"output directory '{path}' cannot be created: '{probe}' is not a writable directory")
    return path


def _progress(enabled: bool, label: str):
    """A progress callback drawing a bar on a terminal, or None when stderr is not one."""
    if not enabled or not sys.stderr.isatty():
        return None
    state = {"last": -1}

    def cb(k: int, n: int) -> None:
        pct = int(100 * k / max(1, n))
        if pct != state["last"]:
            state["last"] = pct
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r{label} [{bar:<25}] {pct:3d}%")
            if k >= n:
                sys.stderr.write("\n")
            sys.stderr.flush()

    return cb


def _run(args: argparse.Namespace, sc) -> int:
    import time

    from .outputs.files import write_json, write_npz, write_text
    from .outputs.progress import progress_bar
    from .sim import simulate

    video_opts = None
    if args.video:
        from .outputs.video import VideoOptions

        video_opts = VideoOptions(**{k: v for k, v in (("width", args.width), ("height", args.height),
                                                       ("fps", args.fps), ("camera", args.camera)) if v is not None})
        video_opts.validate()
    else:
        given = [f"--{k}" for k in ("width", "height", "fps", "camera") if getattr(args, k) is not None]
        if given:
            raise InputError(f"{', '.join(given)} only apply to --video")
    live_url = None
    if args.rerun_spawn and args.rerun_connect:
        raise InputError("--rerun-spawn and --rerun-connect exclude each other")
    if args.rerun_connect:
        from .outputs.rerun_log import connect_url

        live_url = connect_url(args.rerun_connect)
    if args.rerun_spawn:
        from .outputs.rerun_log import check_can_spawn

        check_can_spawn()
    out = _prepare_out(args.out, f"{sc.name}-{sc.plant.kind}-{sc.method}")

    observers: list[Any] = []  # none unless asked: the loop then has no per-step observer cost
    capture = live = None
    if video_opts is not None:
        from .outputs.video import FrameCapture

        capture = FrameCapture(video_opts.fps)  # snapshots only; frames are rendered after the loop
        observers.append(capture)
    if args.rerun_spawn or live_url:
        from .outputs.rerun_log import RerunLive

        live = RerunLive(spawn=args.rerun_spawn, url=live_url, period=max(sc.sim.log_dt, 1 / 30))
        observers.append(live)
    with progress_bar(f"{sc.name} {sc.method}", not args.quiet) as cb:
        result = simulate(sc, observers=observers, progress=cb, engine=args.engine)
    out.mkdir(parents=True, exist_ok=True)
    write_npz(out / "log.npz", result.log)
    if sc.plant.kind == "mujoco":
        write_text(out / "scene.xml", result.plant.model_xml())
    write_json(out / "summary.json", result.summary)

    problems: list[str] = []  # what was asked for and could not be made: error lines, exit 2
    notes: list[str] = []
    if args.rrd:
        from .outputs.rerun_log import write_rrd

        t0 = time.perf_counter()
        write_rrd(result, out / "run.rrd")
        notes.append(f"run.rrd written in {time.perf_counter() - t0:.1f} s")
    if args.figures:
        from .outputs.figures import run_figures

        t0 = time.perf_counter()
        figs = run_figures(result, out / "figures")
        notes.append(f"figures/: {len(figs)} PNGs in {time.perf_counter() - t0:.1f} s")
    if capture is not None:
        from .outputs.video import render_video

        try:
            with progress_bar("video.mp4", not args.quiet, unit="frame") as cb:
                info = render_video(capture, result, out / "video.mp4", video_opts, progress=cb)
            notes.append(f"video.mp4: {info.frames} frames {info.width}x{info.height} at {info.fps:g} fps "
                         f"rendered in {info.render_s:.1f} s ({info.gl_renderer or 'OpenGL'})")
        except InputError as exc:  # no OpenGL context (GLUnavailable), or nothing to show
            problems.append(str(exc))
    if live is not None and live.error:
        problems.append(live.error)
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    if result.diverged is not None:
        print(f"error: simulation diverged: {result.diverged}; log kept in {out}", file=sys.stderr)
        return EXIT_DIVERGED
    if not args.quiet:
        for note in notes:
            print(note)
        _print_summary(result.summary, out)
    return EXIT_INPUT if problems else EXIT_OK


def _print_summary(summary: dict[str, Any], out: Path) -> None:
    print(f"{summary['scenario']} / {summary['plant']} / {summary['method']}: "
          f"{summary['sim_time_s']:.2f} s simulated in {summary['wall_time_s']:.2f} s")
    for f in summary["followers"]:
        print(f"  follower {f['id']}: formation error {f['final_formation_error_m']:.4f} m, "
              f"total velocity error {f['total_velocity_error']:.2f}, "
              f"c_hat {f['c_hat'][0]:.4g}, {f['c_hat'][1]:.4g} (true {f['c_true'][0]:.4g}, {f['c_true'][1]:.4g})")
    print(f"outputs in {out}/")


def _table1(args: argparse.Namespace, sc) -> int:
    from .outputs.files import write_json, write_text
    from .outputs.progress import progress_bar
    from .table1 import markdown, run_table1

    out = _prepare_out(args.out, f"table1-{sc.plant.kind}")
    results = {}

    with progress_bar(f"table1 {sc.name} {sc.plant.kind}", not args.quiet) as cb:
        def keep(m, res):
            results[m] = res
            if not args.quiet:
                line = f"  {m}: done in {res.summary['wall_time_s']:.1f} s"
                cb.write(line) if cb is not None else print(line, file=sys.stderr)

        def per_method(m: str):  # one bar over the four runs: method i fills [i/4, (i+1)/4]
            i, total = list(METHODS).index(m), len(METHODS)
            return lambda k, n: cb(i * n + k, total * n)

        table = run_table1(sc, on_result=keep, progress=None if cb is None else per_method)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "table1.json", table)
    md = markdown(table)
    write_text(out / "table1.md", md)
    if args.figures:
        from .outputs.figures import table1_figures

        figs = table1_figures(results, out / "figures")
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
    from .sweep import expand, sweep

    methods = list(METHODS) if args.methods == "all" else [m.strip() for m in args.methods.split(",") if m.strip()]
    for m in methods:
        if m not in METHODS:
            raise InputError(f"--methods: unknown method '{m}' (expected one of: {', '.join(METHODS)}, or all)")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    overrides = list(args.overrides)
    if args.duration is not None:
        overrides.append(f"sim.duration={args.duration!r}")
    specs = expand(args.scenario, args.seeds, methods, args.vary, overrides, plant=args.plant,
                   seed0=args.seed or 0)
    out = _prepare_out(args.out, "sweep")
    out.mkdir(parents=True, exist_ok=True)
    res = sweep(specs, out, backend=args.backend, workers=args.workers, ray_address=args.ray_address,
                progress=_progress(not args.quiet, "sweep"))
    if not args.quiet:
        tm = res["timing"]
        rate = f", {tm['wall_s']:.1f} s, {tm['runs_per_s']:.2f} runs/s on {tm['workers']} worker(s)" if tm["runs_per_s"] else ""
        print(f"{len(specs)} runs ({res['ran']} run now, {res['skipped']} already done{rate})")
        print((out / "stats.md").read_text())
        print(f"outputs in {out}/ (runs.csv, stats.json, stats.md, sweep.json)")
    return EXIT_OK


def _identify(args: argparse.Namespace) -> int:
    from .identify import identify_main
    from .robots import resolve_robot

    result = identify_main(resolve_robot(args.model))
    text = json.dumps(result, indent=2)
    if args.out is not None:
        from .outputs.files import write_text

        write_text(args.out, text + "\n")
    print(text)
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
