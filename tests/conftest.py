"""Shared fixtures: the paper scenario's Table I on the ideal plant is run once per session."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

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


def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``make test`` runs two workers, ``--dist loadgroup``), the tests that start a Ray
    cluster run one after another on one worker: two local clusters on one machine share Ray's fixed ports
    (the dashboard agent's, the client server's). Without xdist the mark does nothing."""
    for item in items:
        # the long-job test modules too: two Ray clusters started 1 s apart from both workers were seen, and
        # `ray stop --force` (the head-lost test) ends every cluster on the machine
        jobs = item.nodeid.split("::")[0].rsplit("/", 1)[-1] in _JOB_MODULES
        if jobs or "ray" in item.nodeid.lower().replace("array", ""):
            item.add_marker(pytest.mark.xdist_group("ray"))


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
