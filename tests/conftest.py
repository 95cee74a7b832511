"""Shared fixtures: the paper scenario's Table I on the ideal plant is run once per session."""

from __future__ import annotations

import atexit
import functools
import os
import re
import shutil
import tempfile
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# the pre-run robot check's cache (design §14.2): per test session, not the user's ~/.cache/bioform_mj
if "BIOFORM_CACHE_DIR" not in os.environ:
    _CACHE = tempfile.mkdtemp(prefix="bioform-test-cache-")
    os.environ["BIOFORM_CACHE_DIR"] = _CACHE
    atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)  # one per session (and per xdist worker): not left


# Ray's folder (sessions, and the cluster `ray start` records): per test session, so that a cluster left on the
# machine is never joined by a test's sweep, and the head-lost test's record is not seen by anyone else
if "RAY_TMPDIR" not in os.environ:
    _RAY_TMP = tempfile.mkdtemp(prefix="bf-ray-")  # short: Ray's socket paths live below it (107-byte limit)
    os.environ["RAY_TMPDIR"] = _RAY_TMP
    atexit.register(shutil.rmtree, _RAY_TMP, ignore_errors=True)


#: test modules whose sweeps may start Ray or stop every Ray cluster: one worker runs them one after another
_JOB_MODULES = {"test_jobs_sweep.py", "test_jobs_resume.py", "test_jobs_sweep_interrupts.py", "test_jobs_calibrate.py"}

#: what a test module builds once for all its tests: a module-, class- or package-scoped fixture, a cached helper
_BUILT_ONCE = re.compile(r"""scope=["'](?:module|class|package)["']|functools\.(?:cache|lru_cache)\b""")


@functools.cache
def _builds_once(path: Path) -> bool:
    """Whether the test module at ``path`` builds something once for its tests (:data:`_BUILT_ONCE`)."""
    try:
        return _BUILT_ONCE.search(path.read_text(encoding="utf-8")) is not None
    except OSError:
        return False


def xdist_unit(nodeid: str, root: Path) -> str:
    """The work unit of the test ``nodeid`` under ``make test``'s pytest-xdist (``-n 2 --dist loadgroup``): a
    worker runs a unit's tests one after another.

    - ``"ray"``: every test that starts a Ray cluster, and the long-job modules (two Ray clusters started 1 s apart
      from both workers were seen: local clusters on one machine share Ray's fixed ports; ``ray stop --force`` in
      the head-lost test ends every cluster on the machine);
    - the module's path, for a module that builds something once for its tests (a module fixture of 10-30 s, e.g.
      the Warp batch runs or the realdata fit): on one worker it is built once, not once per worker;
    - else the test itself (plain load balancing).
    """
    path = nodeid.split("::", 1)[0].split("@", 1)[0]
    if path.rsplit("/", 1)[-1] in _JOB_MODULES or "ray" in nodeid.lower().replace("array", ""):
        return "ray"
    if _builds_once(root / path):
        return path
    return nodeid


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` with the work units of :func:`xdist_unit`. pytest-xdist's own loadgroup reads a group
    from a suffix it writes onto each test's node id, which pytest >= 9.2 no longer takes (pytest-xdist issue
    1386): its ``xdist_group`` marks are ignored and every test is a unit of its own. This scheduler asks nothing of
    the node ids. xdist sends the units with most tests first, then the single tests in collection order."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    root = Path(str(config.rootpath))

    class _UnitScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return xdist_unit(nodeid, root)

    return _UnitScheduling(config, log)


@pytest.fixture(scope="session")
def table1_ideal(tmp_path_factory):
    """``bioform table1 paper --plant ideal`` through the CLI; returns (out_dir, table dict, logs)."""
    import json

    from bioform_mj.cli.main import main

    out = tmp_path_factory.mktemp("table1_ideal")
    code = main(["table1", "paper", "--plant", "ideal", "--out", str(out), "--quiet"])
    assert code == 0
    table = json.loads((out / "table1.json").read_text())
    return out, table
