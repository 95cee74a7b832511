"""The Python API at the package's top level, and the log as a tidy table."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bioform_mj as bf

ROOT = Path(__file__).resolve().parent.parent


def test_import_is_cheap_and_the_names_are_lazy():
    code = (
        "import sys, bioform_mj as bf; heavy = [m for m in ('numba', 'mujoco', 'bioform_mj.run.simulate') "
        "if m in sys.modules]; "
        "print(heavy); print(bf.simulate.__module__, bf.load.__module__, bf.RunResult.__name__, bf.Controller.__name__)"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    heavy, names = out.stdout.splitlines()
    assert heavy == "[]"  # import bioform_mj loads neither numba nor MuJoCo nor the simulator
    assert (
        names == "bioform_mj.run.simulate bioform_mj.scenario.loader RunResult Controller"
    )  # scenario.py re-exports it
    with pytest.raises(AttributeError, match="no_such_name"):
        bf.no_such_name  # noqa: B018


def test_top_level_names_are_the_modules_objects():
    from bioform_mj import scenario
    from bioform_mj.control import base
    from bioform_mj.run import simulate as sim

    assert bf.load is scenario.load and bf.simulate is sim.simulate and bf.RunResult is sim.RunResult
    assert bf.Controller is base.Controller and bf.Scenario is scenario.Scenario
    assert set(bf.__all__) <= set(dir(bf))


@pytest.fixture(scope="module")
def short_run():
    return bf.simulate(bf.load("paper", ["sim.duration=0.5"], plant="ideal"))


def test_table_has_one_row_per_sample_and_follower_with_units(short_run):
    res = short_run
    K, n = res.log["t"].shape[0], res.scenario.n
    tbl = res.table()
    assert tbl.num_rows == K * n == 50 * 3  # rows at t = 0, 0.01, ..., 0.49 s
    assert tbl.column_names[:2] == ["t_s", "follower"]
    fol = tbl["follower"].to_numpy()
    assert np.array_equal(fol, np.tile([1, 2, 3], K))
    assert np.array_equal(tbl["t_s"].to_numpy(), np.repeat(res.log["t"], n))
    # a per-follower channel, component by component, and a scalar one
    assert np.array_equal(tbl["pose_theta_rad"].to_numpy().reshape(K, n), res.log["pose"][:, :, 2])
    assert np.array_equal(tbl["tau_right_Nm"].to_numpy().reshape(K, n), res.log["tau"][:, :, 1])
    assert np.array_equal(tbl["formation_error_m"].to_numpy().reshape(K, n), res.log["formation_error"])
    # the leader's channels repeat on every follower's row
    lx = tbl["leader_pose_x_m"].to_numpy().reshape(K, n)
    assert np.array_equal(lx, np.repeat(res.log["leader_pose"][:, 0:1], n, axis=1))
    assert tbl.schema.field("vel_w_rad_s").metadata[b"unit"] == b"rad/s"
    assert tbl.schema.field("c_hat_b").metadata[b"unit"] == b"1/(kg*m^2)"
    assert tbl.schema.metadata[b"method"] == b"bioinspired-learning"
    assert res.to_arrow is not None and res.to_arrow().num_rows == tbl.num_rows


def test_summary_is_a_plain_dict(short_run):
    import json

    s = short_run.summary
    assert isinstance(s, dict) and len(s["followers"]) == 3
    assert json.loads(json.dumps(s, default=str))["followers"][0]["outcome"] == s["followers"][0]["outcome"]
    # the final error is at t = 0.5 s, the last log row at 0.49 s: within 10 ms of motion (measured 0.021 m)
    fe = short_run.log["formation_error"][-1]
    final = np.array([f["final_formation_error_m"] for f in s["followers"]])
    assert np.all(np.abs(final - fe) < 0.05) and np.all(final > 3)


def test_pandas_and_polars_frames_when_installed(short_run):
    try:
        import pandas  # noqa: F401
    except ImportError:
        pandas = None
    if pandas is not None:
        df = short_run.to_pandas()
        assert len(df) == 150 and df.groupby("follower")["formation_error_m"].count().tolist() == [50, 50, 50]
    else:
        with pytest.raises(ImportError, match=r"needs pandas, which is not installed: pip install pandas"):
            short_run.to_pandas()
    try:
        import polars  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match=r"needs polars, which is not installed: pip install polars"):
            short_run.to_polars()
    else:
        assert short_run.to_polars().height == 150


def test_a_missing_frame_library_says_how_to_install_it(short_run, monkeypatch):
    """Without pandas, to_pandas() names the fix, not pyarrow's internal import (also where pandas is installed)."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pandas" else real(name, *a))
    with pytest.raises(ModuleNotFoundError, match=r"to_pandas\(\) needs pandas.*pip install pandas") as exc:
        short_run.to_pandas()
    assert exc.value.name == "pandas"
