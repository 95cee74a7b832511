"""numba's cache shared by every copy of the same source, and safe where the source differs (core/jitcache.py;
issue 28: ``make demo`` on a second clone reuses the kernels the first compiled).

Whole copies of the package in temporary folders (two "clones"), one ``NUMBA_CACHE_DIR``: a kernel compiled by
one copy loads in the other without a compile; a copy whose kernel's text differs compiles its own and computes
its own result, even where the cache folder's key is forced to be the same (the stamp alone guards it: numba's
index key hashes the bytecode, which a changed constant leaves as it was); two processes filling one empty
cache at once leave it whole."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "src" / "bioform_mj"

#: argv: the copy's src folder, "same-key" or "" ; prints what wrap(4.0) gave and which kernels compiled
DRIVER = """
import json, sys
sys.path.insert(0, sys.argv[1])
if sys.argv[2] == "same-key":  # every copy in one cache folder, whatever its kernel hash
    import bioform_mj.core.codehash as ch
    ch.kernel_hash = lambda: "fixed"
from bioform_mj.core.jitwatch import watch
stop = watch(lambda b: None, gap_s=0.0)
from bioform_mj.core import equations
out = equations.wrap(4.0)
print(json.dumps({"out": out, "file": equations.__file__, "kernels": [b.kernels for b in stop()]}))
"""


def _clone(tmp_path: Path, name: str) -> Path:
    src = tmp_path / name / "src"
    shutil.copytree(PKG, src / "bioform_mj", ignore=shutil.ignore_patterns("__pycache__"))
    return src


def _run(src: Path, cache: Path, mode: str = "") -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("PYTHONPATH", None)
    p = subprocess.run(
        [sys.executable, "-c", DRIVER, str(src), mode], capture_output=True, text=True, env=env, timeout=300
    )
    assert p.returncode == 0, p.stderr[-2000:]
    rec = json.loads(p.stdout.strip().splitlines()[-1])
    assert rec["file"].startswith(str(src))  # this copy's code ran, not the checkout's
    return rec


WRAP = "bioform_mj.core.equations.wrap"


def _edit_wrap(src: Path) -> None:
    """wrap(a) = pi - (pi - a) % (3π) instead of 2π: the same bytecode, another constant."""
    f = src / "bioform_mj" / "core" / "equations.py"
    text = f.read_text()
    new, n = re.subn(r"return pi - \(pi - a\) % \(2\.0 \* pi\)", "return pi - (pi - a) % (3.0 * pi)", text)
    assert n == 1
    f.write_text(new)


@pytest.mark.slow  # five processes importing numba, each compiling or loading one kernel: ~15 s of CPU
def test_a_second_clone_loads_the_first_ones_kernels_and_a_changed_one_compiles(tmp_path):
    import numba

    cache = tmp_path / "cache"
    a, b, c = _clone(tmp_path, "a"), _clone(tmp_path, "b"), _clone(tmp_path, "c")
    first = _run(a, cache)
    assert first["kernels"] == [[WRAP]] and first["out"] == pytest.approx(4.0 - 2 * math.pi)
    second = _run(b, cache)  # another path, the same text: loaded, nothing compiled
    assert second == {**first, "kernels": [], "file": second["file"]}
    folders = sorted(p.name for p in next(cache.iterdir()).iterdir())
    # one folder for both copies, named by the path inside the package (and numba's version)
    assert folders == [f"bioform_mj.core-numba{numba.__version__}"]
    # a changed file in the same folder (the folder's key forced equal): the stamp misses, it compiles its own
    _edit_wrap(c)
    base = _run(a, cache, "same-key")
    assert base["kernels"] == [[WRAP]]  # a new folder, "numba-fixed"
    changed = _run(c, cache, "same-key")
    assert changed["kernels"] == [[WRAP]]  # not a's kernel loaded from the index
    assert changed["out"] == pytest.approx(math.pi - (math.pi - 4.0) % (3.0 * math.pi))  # c's own constant
    assert abs(changed["out"] - first["out"]) > 1.0
    again = _run(a, cache, "same-key")  # c's index replaced a's: a compiles again and gets its own answer
    assert again["kernels"] == [[WRAP]] and again["out"] == first["out"]


@pytest.mark.slow  # three processes importing numba
def test_two_processes_filling_one_cache_at_once_leave_it_whole(tmp_path):
    cache = tmp_path / "cache"
    a, b = _clone(tmp_path, "a"), _clone(tmp_path, "b")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("PYTHONPATH", None)
    procs = [
        subprocess.Popen([sys.executable, "-c", DRIVER, str(s), ""], stdout=subprocess.PIPE, text=True, env=env)
        for s in (a, b)
    ]
    outs = [json.loads(p.communicate(timeout=300)[0].strip().splitlines()[-1]) for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert {o["out"] for o in outs} == {4.0 - 2 * math.pi}
    assert not list(cache.rglob("*.tmp.*"))  # every write renamed into place, none left half-written
    third = _run(a, cache)  # what they wrote loads: no compile, the same answer
    assert third["kernels"] == [] and third["out"] == outs[0]["out"]


def test_every_module_with_a_cached_kernel_is_in_the_cache_key():
    """A kernel calls kernels of other files (numba links them in): a change in any must change the cache folder's
    key, or a caller's cached code keeps the callee's old text."""
    from bioform_mj.core.codehash import KERNEL_SOURCES, PACKAGE_ROOT

    keyed = {f for pat in KERNEL_SOURCES for f in PACKAGE_ROOT.glob(pat)}
    with_kernels = {f for f in PACKAGE_ROOT.rglob("*.py") if re.search(r"^\s*@njit\b", f.read_text(), re.M)}
    assert len(with_kernels) >= 10
    assert with_kernels <= keyed, sorted(str(f.relative_to(PACKAGE_ROOT)) for f in with_kernels - keyed)


def test_the_locator_files_the_package_by_relative_path_and_leaves_others_to_numba(tmp_path):
    import numba

    from bioform_mj.core.jitcache import PackageLocator, cache_subpath

    v = numba.__version__
    assert cache_subpath(str(PKG / "plants" / "mujoco" / "kernels.py")) == f"bioform_mj.plants.mujoco-numba{v}"
    assert cache_subpath(str(PKG / "core" / "equations.py")) == f"bioform_mj.core-numba{v}"
    assert cache_subpath(str(tmp_path / "elsewhere.py")) is None
    (tmp_path / "elsewhere.py").write_text("def f():\n    return 1\n")

    def f() -> int:
        return 1

    assert PackageLocator.from_function(f, str(tmp_path / "elsewhere.py")) is None  # numba's own locators


GUARDED = """
from bioform_mj.core.equations import njit

@njit
def plus_one(x):
    return x + 1
"""

GUARD_DRIVER = """
import json, sys
sys.path.insert(0, sys.argv[1])
from bioform_mj.core.jitwatch import watch
stop = watch(lambda b: None, gap_s=0.0)
import guardk
out = [guardk.plus_one(int(a)) if a.isdigit() else guardk.plus_one(float(a)) for a in sys.argv[2:]]
print(json.dumps({"out": out, "kernels": [b.kernels for b in stop()]}))
"""


def _guard_run(tmp_path: Path, *args: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(ROOT / "src"))
    p = subprocess.run(
        [sys.executable, "-c", GUARD_DRIVER, str(tmp_path / "mod"), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # two processes importing numba
def test_an_index_entry_naming_another_signatures_code_compiles_instead(tmp_path):
    """What two processes saving two signatures of one kernel at once could leave without the lock: the index
    maps int64 to float64's machine code and back. Loading it would run one signature's code on the other's
    arguments; the guarded cache compiles both again and answers right."""
    import pickle

    (tmp_path / "mod").mkdir()
    (tmp_path / "mod" / "guardk.py").write_text(GUARDED)
    first = _guard_run(tmp_path, "1", "2.5")
    assert first["out"] == [2, 3.5] and len(first["kernels"]) == 2
    (index,) = (tmp_path / "cache").rglob("guardk.plus_one-*.nbi")
    assert len(list(index.parent.glob("guardk.plus_one-*.lock"))) == 1  # saved under the kernel's lock
    with open(index, "rb") as fh:
        version = pickle.load(fh)
        stamp, overloads = pickle.loads(fh.read())
    (k1, d1), (k2, d2) = overloads.items()
    with open(index, "wb") as fh:  # the two data files swapped
        pickle.dump(version, fh, protocol=-1)
        fh.write(pickle.dumps((stamp, {k1: d2, k2: d1}), protocol=-1))
    again = _guard_run(tmp_path, "2.5", "1")
    assert again["out"] == [3.5, 2]
    assert [k for b in again["kernels"] for k in b] == ["guardk.plus_one", "guardk.plus_one"]
    fixed = _guard_run(tmp_path, "2.5", "1")  # both saved again: loaded, right
    assert fixed == {"out": [3.5, 2], "kernels": []}
