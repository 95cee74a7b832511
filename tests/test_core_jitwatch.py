"""A compile is said before it happens, from numba's cache index (core/jitwatch.py; issue 28, item 5).

A tiny cached kernel in a temporary module and a temporary ``NUMBA_CACHE_DIR``: the watch sees a burst exactly
when numba's index has no entry for the call's signature (a first call; a new signature), and none when the
index has it (a second call; a new process loading it from disk)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

KERNEL = """
import numba

@numba.njit(cache=True)
def twice(x):
    return 2 * x
"""

DRIVER = """
import json, sys
sys.path.insert(0, sys.argv[1])
from bioform_mj.core.jitwatch import watch
seen = []
stop = watch(lambda b: seen.append(b.line()), gap_s=0.0)
import tinykernel
from bioform_mj.core.jitwatch import precompile
out = []
for a in sys.argv[2:]:
    if a.startswith("pre:"):  # compiled for the type of the number, not called
        precompile(tinykernel.twice, complex(a[4:]))
    else:
        out.append(tinykernel.twice(int(a)) if a.isdigit() else tinykernel.twice(float(a)))
bursts = stop()
print(json.dumps({"out": out, "lines": seen, "kernels": [b.kernels for b in bursts],
                  "seconds": [b.seconds for b in bursts]}))
"""


def _run(tmp_path: Path, *args: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT / "src"))
    cmd = [sys.executable, "-c", DRIVER, str(tmp_path / "mod"), *args]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # three processes importing numba: ~5 s of CPU
def test_a_burst_exactly_where_the_cache_index_misses(tmp_path):
    (tmp_path / "mod").mkdir()
    (tmp_path / "mod" / "tinykernel.py").write_text(KERNEL)
    first = _run(tmp_path, "3", "4")  # one compile (int64), the second call finds it compiled
    assert first["out"] == [6, 8]
    assert first["kernels"] == [["tinykernel.twice"]]
    assert 0 < first["seconds"][0] < 60
    (line,) = first["lines"]
    assert line.startswith("compiling the loop once (about ") and str(tmp_path / "cache") in line
    again = _run(tmp_path, "5")  # a new process: numba's index has int64, loaded from disk, nothing said
    assert again["out"] == [10] and again["kernels"] == [] and again["lines"] == []
    other = _run(tmp_path, "5", "2.5")  # float64 is not in the index: one burst, for that signature only
    assert other["out"] == [10, 5.0] and other["kernels"] == [["tinykernel.twice"]] and len(other["lines"]) == 1
    # this cache holds none of the package's own kernels: the line is a first run's, whatever compiles
    assert other["lines"][0].startswith("compiling the loop once (about ")
    pre = _run(tmp_path, "pre:1")  # precompile: a burst for complex128, nothing called
    assert pre["out"] == [] and pre["kernels"] == [["tinykernel.twice"]]
    nbi = list((tmp_path / "cache").rglob("*.nbi"))
    assert len(nbi) == 1  # one index, three signatures in it: what the watch read its answer from


def test_the_line_says_first_run_or_option_and_the_estimate():
    from bioform_mj.core.jitwatch import COMPILE_S, CompileBurst, estimate_s

    first = CompileBurst("m.k", "/c/numba-x", True, 193.0).line()
    assert first == "compiling the loop once (about 160-226 s; cached in /c/numba-x)"
    assert CompileBurst("m.k", "/c", False, 76.0, continued=True).line().startswith("compiling, continued")
    later = CompileBurst("m.k", "/c/numba-x", False, 76.0).line()
    assert later.startswith("compiling the kernels of an option") and "about 76 s" in later
    # the estimate is the measured one of the longest matching prefix
    assert estimate_s("bioform_mj.control.kernel.control_step") == COMPILE_S["bioform_mj"]
    assert estimate_s("bioform_mj.plants.mujoco.kernels.observe") == COMPILE_S["bioform_mj.plants.mujoco"]
    assert estimate_s("bioform_mj.plants.mujoco.kernels.run_chunk") == 76.0
    assert estimate_s("bioform_mj.plants.mujoco.kernels.run_chunkX") == COMPILE_S["bioform_mj.plants.mujoco"]
    assert estimate_s("tinykernel.twice") == 30.0
