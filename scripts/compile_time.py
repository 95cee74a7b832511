"""Where numba compiles, and for how long (issue 28: "compile time said"; core/jitwatch.py's COMPILE_S).

Each case is one ``bioform`` command (0.2 s simulated) in a fresh process, all sharing one empty numba cache
folder (``$NUMBA_CACHE_DIR`` = a temporary folder), in order: the first case compiles the loop, a later case
compiles only what its options need beyond what the cases before it compiled. Prints, per case, the wall time
of the process, the compile bursts numba's ``"numba:compile"`` event saw (core/jitwatch.py), their seconds and
the top-level kernels compiled, and then the same cases again against the now warm cache.

    python scripts/compile_time.py [--cases ideal,mujoco,...] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

CASES: dict[str, list[str]] = {
    "ideal": ["run", "paper", "--plant", "ideal"],
    "mujoco": ["run", "paper", "--plant", "mujoco"],
    "backstepping": ["run", "paper", "--plant", "mujoco", "--method", "backstepping"],
    "bioinspired": ["run", "paper", "--plant", "ideal", "--method", "bioinspired"],
    "learning": ["run", "paper", "--plant", "ideal", "--method", "learning"],
    "stepwise": ["run", "paper", "--plant", "ideal", "--engine", "stepwise"],
    "odometry": ["run", "paper", "--plant", "mujoco", "--set", 'plant.sensing="odometry"'],
    "fault_delay": ["run", "fault_delay"],
    "cbf": ["run", "paper", "--plant", "ideal", "--set", 'safety.filter="cbf"'],
    "rrd": ["run", "paper", "--plant", "mujoco", "--rrd"],
}

DRIVER = """
import json, sys, time
t0 = time.monotonic()
from bioform_mj.core.jitwatch import watch
stop = watch(lambda b: None)
from bioform_mj.cli.main import main
rc = main(sys.argv[1:])
bursts = stop()
print(json.dumps({"rc": rc, "wall_s": time.monotonic() - t0,
    "bursts": [{"first": b.first, "seconds": b.seconds, "kernels": b.kernels} for b in bursts]}))
"""


def run_case(argv: list[str], out: str, env: dict[str, str]) -> dict:
    """One case in a fresh process; its JSON line."""
    cmd = [sys.executable, "-c", DRIVER, *argv, "--duration", "0.2", "--quiet", "--out", out]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    line = p.stdout.strip().splitlines()[-1] if p.stdout.strip() else "{}"
    try:
        rec = json.loads(line)
    except json.JSONDecodeError:
        rec = {"rc": p.returncode, "error": p.stderr.strip()[-500:]}
    rec["stderr_compile_lines"] = [ln for ln in p.stderr.splitlines() if ln.startswith("compiling")]
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated, in order (default: all)")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    names = args.cases.split(",")
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"error: unknown cases {unknown}; known: {', '.join(CASES)}", file=sys.stderr)
        return 2
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, "numba"))
        for rnd in ("cold", "warm"):
            for i, name in enumerate(names):
                t0 = time.monotonic()
                rec = run_case(CASES[name], os.path.join(tmp, f"{rnd}-{i}"), env)
                rec["process_s"] = time.monotonic() - t0
                results[f"{rnd}:{name}"] = rec
                comp = sum(b["seconds"] for b in rec.get("bursts", []))
                kern = sorted({k.rsplit(".", 1)[-1] for b in rec.get("bursts", []) for k in b["kernels"]})
                print(
                    f"{rnd:4} {name:12} rc={rec.get('rc')} process {rec['process_s']:6.1f} s, "
                    f"compiling {comp:6.1f} s in {len(rec.get('bursts', []))} burst(s) "
                    f"{rec.get('stderr_compile_lines')} kernels {kern}",
                    flush=True,
                )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
