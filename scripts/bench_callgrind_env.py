#!/usr/bin/env python3
"""What an environment step costs, counted (not timed): ``env.step`` under callgrind (issue 30).

The counterpart of ``scripts/bench_callgrind.py`` for the learning environment (design §20): one process under
``valgrind --tool=callgrind``, instrumentation on around ``--steps`` calls of ``env.step`` only (constant
velocity actions, after an untimed episode that loads the kernels), then per environment step: all
instructions (Ir: Python's ``step`` and the compiled period), those inside ``mj_step``, and the calls of
numba's reference counting (``NRT_incref``, ``NRT_decref``) in the whole dump. The kernels are compiled (or
loaded) by a run outside valgrind first: compiling under valgrind takes many minutes.

Needs ``valgrind`` with its headers and ``cc`` (as ``bench_callgrind.py``). Usage:
``PYTHONPATH=src python scripts/bench_callgrind_env.py [--plant mujoco] [--control-dt 0.001] [--steps 2000]``.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_callgrind import _EV, parse, run_callgrind  # noqa: E402


def kernel_addresses() -> dict[str, str]:
    """The entry address of every compiled specialisation of the package's kernels (numba's JIT code has no
    symbols: callgrind names a function by its address) -> ``module.function``."""
    from numba.core.registry import CPUDispatcher

    out: dict[str, str] = {}
    for mod in list(sys.modules.values()):
        if not getattr(mod, "__name__", "").startswith("bioform_mj"):
            continue
        for name, obj in list(vars(mod).items()):
            if isinstance(obj, CPUDispatcher):
                for cres in obj.overloads.values():
                    try:
                        addr = cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
                    except Exception:  # noqa: BLE001 - a specialisation without native code: skipped
                        continue
                    if addr:
                        out[f"0x{addr:016x}"] = f"{obj.py_func.__module__.split('.')[-1]}.{name}"
    return out


def episode(a: argparse.Namespace, lib_path: str | None) -> None:
    """An untimed episode, then (under callgrind: ``lib_path``) ``a.steps`` instrumented steps."""
    import numpy as np
    from numba.core.runtime import nrt

    from bioform_mj.envs import parallel_env

    warnings.simplefilter("ignore")
    dur = max(2.0 * a.steps * a.control_dt, 0.5)
    ov = [f"sim.duration={dur}", f"sim.control_dt={a.control_dt}", f"plant.kind={a.plant}"]
    env = parallel_env(a.scenario, action="velocity", overrides=ov)
    for seed in (0, 1):
        env.reset(seed=seed)
        act = {ag: np.array([0.2, 0.1]) for ag in env.agents}
        if seed == 0:  # the kernels loaded (or compiled), the first steps' work done once
            for _ in range(50 if lib_path else 10**9):
                if not env.agents:
                    break
                env.step(act)
            continue
        if lib_path is None:
            return
        for _ in range(20):
            env.step(act)
        lib = ctypes.CDLL(lib_path)
        lib.cg_dump.argtypes = [ctypes.c_char_p]
        addrs = [nrt.rtsys.library.get_pointer_to_function(f) for f in ("NRT_incref", "NRT_decref")]
        Path(f"{lib_path}.nrt").write_text(" ".join(hex(x) for x in addrs))
        Path(f"{lib_path}.names").write_text(json.dumps(kernel_addresses()))
        lib.cg_start()
        lib.cg_zero()
        for _ in range(a.steps):
            env.step(act)
        lib.cg_dump(b"env")
        lib.cg_stop()
        print(f"stepped {a.steps}, agents left {len(env.agents)}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--plant", default="mujoco")
    ap.add_argument("--control-dt", type=float, default=0.001)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--inside", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.steps < 1 or a.control_dt <= 0:
        print("error: --steps must be >= 1 and --control-dt > 0", file=sys.stderr)
        return 2
    if a.inside:
        episode(a, a.inside)
        return 0
    if shutil.which("cc") is None or shutil.which("valgrind") is None:
        print("error: needs valgrind and a C compiler (cc) on PATH", file=sys.stderr)
        return 2
    episode(a, None)  # compile (or load) the kernels outside valgrind
    with tempfile.TemporaryDirectory() as tmp:
        args = [
            "--scenario",
            a.scenario,
            "--plant",
            a.plant,
            "--control-dt",
            str(a.control_dt),
            "--steps",
            str(a.steps),
        ]
        got = run_callgrind(tmp, __file__, args)
        if got is None:
            return 1
        out, lib, nrt = got
        names, own, arcs = parse(Path(f"{out}.1"))
        total = sum(v[0] for v in own.values())
        step_ids = {i for i, nm in names.items() if nm == "mj_step"}
        mj = sum(v[1][0] for (fn, cf), v in arcs.items() if cf in step_ids and fn not in step_ids)
        n = a.steps
        print(f"{a.scenario}, plant {a.plant}, control_dt {a.control_dt:g} s, {n} env steps; per env step:")
        print(f"  {_EV[0]} all {total / n:10.0f}   in mj_step {mj / n:10.0f}   the rest {(total - mj) / n:10.0f}")
        known = json.loads(Path(f"{lib}.names").read_text())
        for label, addr in zip(("NRT_incref", "NRT_decref"), nrt):
            ids = {i for i, nm in names.items() if nm == f"0x{addr:016x}"}
            c = sum(v[0] for (fn, cf), v in arcs.items() if cf in ids)
            print(f"  {label} calls {c / n:.1f}; by caller (a kernel's entry address, or the JIT code's page):")
            by: dict[str, int] = {}
            for (fn, cf), v in arcs.items():
                if cf in ids:
                    nm = names.get(fn, "?")
                    key = known.get(nm, nm)
                    by[key] = by.get(key, 0) + v[0]
            for key, cnt in sorted(by.items(), key=lambda kv: -kv[1]):
                if cnt >= n * 0.5:
                    print(f"    {key:40s} {cnt / n:7.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
