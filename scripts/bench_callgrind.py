#!/usr/bin/env python3
"""What a control step costs beyond ``mj_step``, counted (not timed): bare replay and closed loop under callgrind.

``bioform bench`` times the two, and on a shared machine a time scatters; instruction counts and a simulated cache
do not. This runs, in one process under ``valgrind --tool=callgrind`` (instrumentation switched on around the two
timed calls only): the bench's recording run on ``--preset``, then the bare replay (``jobs.bench.replayer``) and the
closed loop (``simulate`` on the same plant), each dumped apart. For each it prints, per control step, the
instructions (Ir), simulated L1 instruction / data read misses (I1mr, D1mr; 32 KiB 8-way each, 1 MiB last level)
and mispredicted conditional branches (Bcm) of the compiled kernel that calls ``mj_step`` (the replay or
``run_chunk``), split into ``mj_step`` itself and the rest (our code: the kernel's own code and each callee; numba's
JIT code has no symbol names, so callees are shown by address with their calls per step). docs/findings/performance.md
("The gap at n = 3") reads these numbers.

Needs ``valgrind`` with its headers (``valgrind/callgrind.h``) and a C compiler (``cc``): the switch and the dumps
are callgrind client requests, compiled into a small library called through ``ctypes``. Slow: ~30 s of CPU before
the first dump (imports, plant, recording run under valgrind), ~1 min per simulated second of the paper scene.

Usage: ``PYTHONPATH=src python scripts/bench_callgrind.py [--preset paper] [--duration 1]``.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

_C = r"""
#include <valgrind/callgrind.h>
void cg_start(void) { CALLGRIND_START_INSTRUMENTATION; }
void cg_stop(void) { CALLGRIND_STOP_INSTRUMENTATION; }
void cg_zero(void) { CALLGRIND_ZERO_STATS; }
void cg_dump(const char *s) { CALLGRIND_DUMP_STATS_AT(s); }
"""
_EV = ("Ir", "I1mr", "D1mr", "Bcm")


def inside(lib_path: str, preset: str, duration: float) -> None:
    """Under callgrind: record, then one bare replay and one closed loop, each between a zero and a dump."""
    import numpy as np
    from numba.core.runtime import nrt

    from bioform_mj.core.errors import quiet_outcomes
    from bioform_mj.jobs.bench import record_run, replayer
    from bioform_mj.run.looptime import loop_times
    from bioform_mj.run.simulate import make_plant
    from bioform_mj.scenario.loader import load

    lib = ctypes.CDLL(lib_path)
    lib.cg_dump.argtypes = [ctypes.c_char_p]
    warnings.simplefilter("ignore")  # the presets' demand warnings: not this probe's report
    sc = load(preset, overrides=[f"sim.duration={duration}"], plant="mujoco")
    plant = make_plant(sc)
    with quiet_outcomes():
        rc, rx, q = record_run(sc, plant)
        replay = replayer(plant, rc, rx)
        replay()  # both once untimed: kernels loaded, caches of the process warm
        loop_times(sc, 1, plant=plant)
        addrs = [nrt.rtsys.library.get_pointer_to_function(f) for f in ("NRT_incref", "NRT_decref")]
        Path(f"{lib_path}.nrt").write_text(" ".join(hex(a) for a in addrs))
        for tag in ("bare", "loop"):
            lib.cg_start()
            lib.cg_zero()
            if tag == "bare":
                replay()
            else:
                loop_times(sc, 1, plant=plant)
            lib.cg_dump(tag.encode())
            lib.cg_stop()
            dq = float(np.abs(plant.data.qpos - q).max())
            print(f"{tag}: final qpos vs the recording run, max abs difference {dq:.1e}", flush=True)


def parse(path: Path) -> tuple[dict[str, str], dict[str, list[int]], dict[tuple[str, str], tuple[int, list[int]]]]:
    """A callgrind dump: function names by id, each function's own cost, and each call arc's (calls, inclusive
    cost), costs in the order of :data:`_EV`."""
    names: dict[str, str] = {}
    own: dict[str, list[int]] = {}
    arcs: dict[tuple[str, str], tuple[int, list[int]]] = {}
    ev: list[str] = []
    fn = cfn = ""
    calls = -1
    for line in path.read_text().splitlines():
        if line.startswith("events:"):
            ev = line.split()[1:]
            continue
        m = re.match(r"^(c?fn)=\((\d+)\)(?: (.*))?$", line)
        if m:
            kind, idx, name = m.groups()
            if name:
                names[idx] = name
            if kind == "fn":
                fn = idx
            else:
                cfn = idx
            continue
        if line.startswith("calls="):
            calls = int(line.split()[0][6:])
            continue
        if fn and re.match(r"^[+-]?\d|^\*", line):
            vals = [int(x) for x in line.split()[1:]] + [0] * len(ev)
            cost = [vals[ev.index(e)] for e in _EV]
            if calls >= 0:
                c0, a0 = arcs.get((fn, cfn), (0, [0] * len(_EV)))
                arcs[(fn, cfn)] = (c0 + calls, [x + y for x, y in zip(a0, cost)])
                calls = -1
            else:
                own[fn] = [x + y for x, y in zip(own.get(fn, [0] * len(_EV)), cost)]
    return names, own, arcs


def report(path: Path, tag: str, nrt: tuple[int, int]) -> None:
    """Per control step: the kernel that calls ``mj_step`` most, split into ``mj_step`` and the rest; and the calls
    of numba's reference counting (``nrt``: the addresses of ``NRT_incref``, ``NRT_decref``) in the whole dump."""
    names, own, arcs = parse(path)
    step_ids = {i for i, n in names.items() if n == "mj_step"}
    callers = [(c, fn) for (fn, cf), (c, _) in arcs.items() if cf in step_ids]
    steps, kern = max(callers)
    out = {cf: v for (fn, cf), v in arcs.items() if fn == kern and cf != kern}
    step_cost = [sum(v[1][k] for cf, v in out.items() if cf in step_ids) for k in range(len(_EV))]
    total = [own.get(kern, [0] * len(_EV))[k] + sum(v[1][k] for v in out.values()) for k in range(len(_EV))]

    def row(label: str, cost: list[int], calls: str = "") -> str:
        return f"  {label:28s} {calls:>8s} " + " ".join(f"{e} {c / steps:9.0f}" for e, c in zip(_EV, cost))

    print(f"{tag}: {steps} mj_step calls from one kernel; per step (each value / {steps}):")
    print(row("kernel, all", total))
    print(row("mj_step", step_cost))
    print(row("the rest (our code)", [t - s for t, s in zip(total, step_cost)]))
    print(row("  kernel's own code", own.get(kern, [0] * len(_EV))))
    for cf, (c, cost) in sorted(out.items(), key=lambda kv: -kv[1][1][0]):
        if cf not in step_ids and cost[0] > steps * 50:
            print(row(f"  {names.get(cf, '?')[:26]}", cost, f"{c / steps:.1f}/st"))
    # numba's NRT_incref/NRT_decref: JIT code (no symbol: callgrind names it by address), one copy in the process;
    # their calls from the kernel and the unnamed (JIT) functions it reaches, and from anywhere in the dump
    reach, todo = {kern}, [kern]
    while todo:
        f = todo.pop()
        for fn, cf in arcs:
            if fn == f and cf not in reach and names.get(cf, "").startswith("0x"):
                reach.add(cf)
                todo.append(cf)
    for label, addr in zip(("NRT_incref", "NRT_decref"), nrt):
        ids = {i for i, nm in names.items() if nm == f"0x{addr:016x}"}
        c = sum(v[0] for (fn, cf), v in arcs.items() if cf in ids and fn in reach)
        c_all = sum(v[0] for (fn, cf), v in arcs.items() if cf in ids)
        cost = [sum(v[1][k] for (fn, cf), v in arcs.items() if cf in ids and fn in reach) for k in range(len(_EV))]
        print(row(f"  {label}", cost, f"{c / steps:.1f}/st") + f"  (whole dump {c_all / steps:.1f}/st)")


def run_callgrind(tmp: str, script: str, args: list[str]) -> tuple[Path, Path, tuple[int, int]] | None:
    """Build the helper library (:data:`_C`) in ``tmp`` and run ``python script --inside LIB *args`` under
    callgrind with the simulated caches (I1, D1 32 KiB 8-way, LL 1 MiB 8-way, 64 B lines), measuring only where
    the script toggles collection. Returns the dump's path stem (``.1``, ``.2``: one per toggled part), the
    library's path and numba's ``NRT_incref``/``NRT_decref`` addresses; None (an ``error:`` line) if it failed."""
    src, lib = Path(tmp, "cgctl.c"), Path(tmp, "cgctl.so")
    src.write_text(_C)
    subprocess.run([shutil.which("cc") or "cc", "-O2", "-shared", "-fPIC", "-o", str(lib), str(src)], check=True)
    out = Path(tmp, "cg.out")
    cmd = [shutil.which("valgrind") or "valgrind", "--tool=callgrind", "--instr-atstart=no", "--cache-sim=yes"]
    cmd += ["--branch-sim=yes", "--I1=32768,8,64", "--D1=32768,8,64", "--LL=1048576,8,64"]
    cmd += [f"--callgrind-out-file={out}", sys.executable, script, "--inside", str(lib), *args]
    proc = subprocess.run(cmd, stderr=subprocess.DEVNULL, env=dict(os.environ))
    if proc.returncode != 0:
        print(f"error: the run under valgrind failed (exit {proc.returncode})", file=sys.stderr)
        return None
    return out, lib, tuple(int(x, 16) for x in Path(f"{lib}.nrt").read_text().split())  # type: ignore[return-value]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="paper")
    ap.add_argument("--duration", type=float, default=1.0, help="sim.duration, s (default 1)")
    ap.add_argument("--keep", help="copy the two callgrind dumps into this folder (callgrind_annotate reads them)")
    ap.add_argument("--inside", help=argparse.SUPPRESS)  # the run under valgrind: the helper library's path
    a = ap.parse_args(argv)
    if a.inside:
        inside(a.inside, a.preset, a.duration)
        return 0
    if shutil.which("cc") is None or shutil.which("valgrind") is None:
        print("error: needs valgrind and a C compiler (cc) on PATH", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        got = run_callgrind(tmp, __file__, ["--preset", a.preset, "--duration", str(a.duration)])
        if got is None:
            return 1
        out, _, nrt = got
        print(f"{a.preset}, {a.duration:g} s; simulated caches: I1 and D1 32 KiB 8-way, LL 1 MiB 8-way, 64 B lines")
        report(Path(f"{out}.1"), "bare replay", nrt)
        report(Path(f"{out}.2"), "closed loop", nrt)
        if a.keep:
            Path(a.keep).mkdir(parents=True, exist_ok=True)
            for i, tag in ((1, "bare"), (2, "loop")):
                shutil.copy(f"{out}.{i}", Path(a.keep, f"callgrind.{tag}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
