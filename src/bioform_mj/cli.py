"""The ``bioform`` command (SPEC §10).

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
    run.add_argument("--video", action="store_true", help="write video.mp4 (MuJoCo plant)")
    run.add_argument("--rrd", action="store_true", help="write run.rrd (rerun recording)")
    run.add_argument("--figures", action="store_true", help="write figures/*.png")

    t1 = sub.add_parser("table1", help="run the four methods and write table1.json / table1.md")
    _scenario_args(t1)
    t1.add_argument("--out", type=Path, help="output directory (default: runs/table1-<plant>)")
    t1.add_argument("--figures", action="store_true", help="write figures/*.png comparing the methods")

    ident = sub.add_parser("identify", help="system identification of a robot MJCF: formula vs measured a, b")
    ident.add_argument("model", help="shipped robot name or path to an MJCF file")
    ident.add_argument("--out", type=Path, help="write the result as JSON to this file")

    sub.add_parser("presets", help="list the shipped scenario presets")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``bioform`` console script; returns the exit code."""
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


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "presets":
        from .scenario import preset_names

        print("\n".join(preset_names()))
        return EXIT_OK
    if args.command == "identify":
        return _identify(args)
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
    """Create the output directory (after validation, so bad input writes nothing)."""
    path = Path(out) if out is not None else Path("runs") / default
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"output directory '{path}' cannot be created: {exc.strerror}") from None
    if not path.is_dir() or not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"output directory '{path}' is not a writable directory")
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
    from .outputs.files import write_json, write_npz, write_text
    from .sim import simulate

    out = _prepare_out(args.out, f"{sc.name}-{sc.plant.kind}-{sc.method}")
    observers: list[Any] = []
    result = simulate(sc, observers=observers, progress=_progress(not args.quiet, f"{sc.name} {sc.method}"))
    write_npz(out / "log.npz", result.log)
    if sc.plant.kind == "mujoco":
        write_text(out / "scene.xml", result.plant.model_xml())
    if args.figures:
        from .outputs.figures import run_figures

        run_figures(result.log, result.summary, out / "figures")
    write_json(out / "summary.json", result.summary)
    if result.diverged is not None:
        print(f"error: simulation diverged: {result.diverged}; log kept in {out}", file=sys.stderr)
        return EXIT_DIVERGED
    if not args.quiet:
        _print_summary(result.summary, out)
    return EXIT_OK


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
    from .table1 import markdown, run_table1

    out = _prepare_out(args.out, f"table1-{sc.plant.kind}")
    results = {}

    def keep(m, res):
        results[m] = res
        if not args.quiet:
            print(f"  {m}: done in {res.summary['wall_time_s']:.1f} s", file=sys.stderr)

    table = run_table1(sc, on_result=keep)
    if args.figures:
        from .outputs.figures import table1_figures

        table1_figures({m: r.log for m, r in results.items()}, table, out / "figures")
    write_json(out / "table1.json", table)
    md = markdown(table)
    write_text(out / "table1.md", md)
    diverged = [m for m, r in results.items() if r.diverged is not None]
    if not args.quiet:
        print(md)
        print(f"outputs in {out}/")
    if diverged:
        print(f"error: simulation diverged for {', '.join(diverged)}: {results[diverged[0]].diverged}", file=sys.stderr)
        return EXIT_DIVERGED
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
