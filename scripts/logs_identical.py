#!/usr/bin/env python3
"""Are two source trees' runs the same bits? ``log.npz`` of each configuration, array by array.

Runs every configuration (a ``bioform run`` command line) once under each source tree, in a fresh process
with ``PYTHONPATH`` = that tree's ``src`` folder (the same interpreter: the one running this), and compares the
two ``log.npz``: the same array names, and per array the same dtype, shape and values (``np.array_equal``; for
floating arrays with ``equal_nan``, so NaN must sit at the same positions, and a NaN against a number differs).
A run that fails under either tree is a difference (its ``error:`` line printed). Prints one line per
configuration and exits 1 if any differs, else 0. The numba cache is each tree's own (its kernels' sources
differ: ``core/jitcache.py``); ``--cache DIR`` sets ``NUMBA_CACHE_DIR`` for both (an empty one: cold compiles).

    python scripts/logs_identical.py REF_SRC NEW_SRC [--only paper_mujoco,cbf] [--duration 3] [--keep DIR]

``REF_SRC``/``NEW_SRC``: a checkout's root or its ``src`` folder (e.g. ``/work/main`` and ``.``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: name -> (bioform run arguments, simulated seconds). The fault presets act at t = 6-9 s.
CONFIGS: dict[str, tuple[list[str], float]] = {
    "paper_mujoco": (["paper", "--plant", "mujoco"], 3.0),
    "paper_ideal": (["paper", "--plant", "ideal"], 5.0),
    "paper_ideal_stepwise": (["paper", "--plant", "ideal", "--engine", "stepwise"], 3.0),
    "paper_mujoco_stepwise": (["paper", "--plant", "mujoco", "--engine", "stepwise"], 2.0),
    "backstepping_mujoco": (["paper", "--plant", "mujoco", "--method", "backstepping"], 3.0),
    "backstepping_ideal": (["paper", "--plant", "ideal", "--method", "backstepping"], 5.0),
    "bio_learning_mujoco": (["paper", "--plant", "mujoco", "--method", "bioinspired-learning"], 3.0),
    "bio_learning_ideal": (["paper", "--plant", "ideal", "--method", "bioinspired-learning"], 5.0),
    "fault_actuator": (["fault_actuator"], 7.0),
    "fault_push": (["fault_push"], 7.0),
    "fault_delay": (["fault_delay"], 7.0),
    "odometry": (["paper", "--plant", "mujoco", "--set", 'plant.sensing="odometry"'], 3.0),
    "cbf_mujoco": (["crossing", "--set", 'safety.filter="cbf"'], 3.0),
    "cbf_ideal": (["paper", "--plant", "ideal", "--set", 'safety.filter="cbf"'], 5.0),
    "obstacles": (["obstacles"], 3.0),
    "analytic_mujoco": (["paper", "--plant", "mujoco", "--set", 'torque.derivative="analytic"'], 3.0),
    "analytic_ideal": (["paper", "--plant", "ideal", "--set", 'torque.derivative="analytic"'], 5.0),
    "difference_mujoco": (["paper", "--plant", "mujoco", "--set", 'torque.derivative="difference"'], 3.0),
    "difference_ideal": (["paper", "--plant", "ideal", "--set", 'torque.derivative="difference"'], 5.0),
    "drag_mujoco": (["paper", "--plant", "mujoco", "--set", "learner.drag=true"], 3.0),
    "drag_ideal": (["paper", "--plant", "ideal", "--set", "learner.drag=true"], 5.0),
}


def src_of(root: str) -> Path | None:
    """The folder that holds ``bioform_mj`` under ``root`` (``root/src`` or ``root`` itself); None if neither."""
    p = Path(root).resolve()
    for cand in (p / "src", p):
        if (cand / "bioform_mj" / "__init__.py").is_file():
            return cand
    return None


def run(src: Path, argv: list[str], duration: float, out: Path, cache: str | None) -> str | None:
    """One ``bioform run`` under ``src`` into ``out``; None, or its failure (the last line of stderr)."""
    env = dict(os.environ, PYTHONPATH=str(src))
    if cache:
        env["NUMBA_CACHE_DIR"] = cache
    cmd = [sys.executable, "-m", "bioform_mj.cli", "run", *argv, "--duration", str(duration), "--quiet",
           "--out", str(out)]  # fmt: skip
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if p.returncode != 0:
        lines = p.stderr.strip().splitlines() or [f"exit {p.returncode}"]
        return f"rc {p.returncode}: {lines[-1]}"
    if not (out / "log.npz").is_file():
        return "no log.npz"
    return None


def compare(a_path: Path, b_path: Path) -> list[str]:
    """The differences between two ``log.npz`` (empty: the same bits, array by array)."""
    diffs: list[str] = []
    with np.load(a_path) as a, np.load(b_path) as b:
        ka, kb = set(a.files), set(b.files)
        if ka != kb:
            diffs.append(f"arrays only in ref {sorted(ka - kb)}, only in new {sorted(kb - ka)}")
        for k in sorted(ka & kb):
            x, y = a[k], b[k]
            if x.dtype != y.dtype or x.shape != y.shape:
                diffs.append(f"{k}: {x.dtype}{x.shape} vs {y.dtype}{y.shape}")
                continue
            nan = x.dtype.kind in "fc"
            if not np.array_equal(x, y, equal_nan=nan):
                n_bad = int(np.sum(~((x == y) | (np.isnan(x) & np.isnan(y))))) if nan else int(np.sum(x != y))
                diffs.append(f"{k}: {n_bad} of {x.size} values differ")
    return diffs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ref", nargs="?", help="the reference tree (its root or src)")
    ap.add_argument("new", nargs="?", help="the tree to compare (its root or src)")
    ap.add_argument("--only", default="", help="comma-separated configuration names (default: all)")
    ap.add_argument("--duration", type=float, default=0.0, help="simulated s for every configuration (0: each its own)")
    ap.add_argument("--cache", default=None, help="NUMBA_CACHE_DIR for both trees")
    ap.add_argument("--keep", default=None, help="write the runs under this folder (default: a temporary one)")
    ap.add_argument("--list", action="store_true", help="print the configurations and exit")
    a = ap.parse_args(argv)
    if a.list:
        for name, (args, d) in CONFIGS.items():
            print(f"{name:24s} {d:4.1f} s  bioform run {' '.join(args)}")
        return 0
    if a.ref is None or a.new is None:
        print("error: give REF_SRC and NEW_SRC (or --list)", file=sys.stderr)
        return 2
    names = [s for s in a.only.split(",") if s] or list(CONFIGS)
    bad = [s for s in names if s not in CONFIGS]
    if bad:
        print(f"error: unknown configuration {bad[0]!r} (--list names them)", file=sys.stderr)
        return 2
    if a.duration < 0:
        print("error: --duration must be > 0 (or 0: each configuration's own)", file=sys.stderr)
        return 2
    ref, new = src_of(a.ref), src_of(a.new)
    if ref is None or new is None:  # bad input: one line, exit 2, before any run
        print(f"error: no bioform_mj package under {a.ref if ref is None else a.new}", file=sys.stderr)
        return 2
    tmp = tempfile.TemporaryDirectory(prefix="logs_identical-") if a.keep is None else None
    base = Path(a.keep if a.keep is not None else tmp.name)  # type: ignore[union-attr]
    failed = 0
    for name in names:
        args, d = CONFIGS[name]
        dur = a.duration or d
        outs = [base / tag / name for tag in ("ref", "new")]
        errs = [run(src, args, dur, out, a.cache) for src, out in zip((ref, new), outs)]
        if any(errs):
            failed += 1
            print(f"DIFF  {name}: run failed: ref {errs[0] or 'ok'}; new {errs[1] or 'ok'}", flush=True)
            continue
        diffs = compare(outs[0] / "log.npz", outs[1] / "log.npz")
        with np.load(outs[0] / "log.npz") as z:
            n_arr, rows = len(z.files), z[z.files[0]].shape[0] if z.files else 0
        if diffs:
            failed += 1
            print(f"DIFF  {name}: " + "; ".join(diffs), flush=True)
        else:
            print(f"same  {name}: {n_arr} arrays, {rows} rows, {dur:g} s simulated", flush=True)
    if tmp is not None:
        tmp.cleanup()
    print(f"{len(names) - failed} of {len(names)} configurations bit-identical")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
