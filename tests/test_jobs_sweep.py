"""Sweeps: local pool vs Ray give identical metrics; resume skips finished runs; failures are recorded."""

from __future__ import annotations

import csv
import json

import pytest

from bioform_mj.cli.main import main
from bioform_mj.jobs.sweep import expand, run_one, sweep

ARGS = [
    "--seeds",
    "2",
    "--methods",
    "bioinspired,bioinspired-learning",
    "--duration",
    "0.5",
    "--set",
    "formation.init_jitter=0.3",
    "--vary",
    "kinematic.k1=1,2",
    "--quiet",
]


def _rows(out):
    with open(out / "runs.csv") as fh:
        return sorted(csv.DictReader(fh), key=lambda r: r["key"])


def _metrics(rows):
    return [{k: v for k, v in r.items() if k != "wall_time_s"} for r in rows]


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep_local")
    assert main(["sweep", "paper", *ARGS, "--workers", "2", "--out", str(out)]) == 0
    return out


def test_local_sweep_table_and_stats(local_sweep):
    rows = _rows(local_sweep)
    assert len(rows) == 8
    assert {r["status"] for r in rows} == {"ok"}
    assert {r["kinematic.k1"] for r in rows} == {"1", "2"}
    # different seeds differ (initial-pose jitter is on), same settings otherwise
    by = {(r["method"], r["kinematic.k1"], r["seed"]): float(r["total_velocity_error_mean"]) for r in rows}
    assert by[("bioinspired", "1", "0")] != by[("bioinspired", "1", "1")]
    stats = json.loads((local_sweep / "stats.json").read_text())
    # one group per (method, varied value), not merged per method
    assert stats["group_by"] == ["method", "kinematic.k1"]
    groups = {(g["method"], g["kinematic.k1"]): g for g in stats["groups"]}
    assert set(groups) == {(m, k) for m in ("bioinspired", "bioinspired-learning") for k in ("1", "2")}
    g = groups[("bioinspired", "2")]
    assert g["runs"] == 2 and g["ok"] == 2 and g["outcomes"] == {"ok": 2}
    m = g["metrics"]["total_velocity_error_mean"]
    vals = [by[k] for k in by if k[:2] == ("bioinspired", "2")]
    assert m["mean"] == pytest.approx(sum(vals) / 2)
    assert m["p5"] <= m["p50"] <= m["p95"]
    md = (local_sweep / "stats.md").read_text().splitlines()
    assert md[0].startswith("| method | kinematic.k1 | runs") and "outcomes" in md[0]
    body = [ln for ln in md[2:] if ln.startswith("| ")]
    assert len(body) == 4
    assert any(ln.startswith("| bioinspired-learning | 2 | 2 (2/0/0) | ok 2 |") for ln in body)


def test_serial_equals_parallel(local_sweep, tmp_path):
    out = tmp_path / "serial"
    assert main(["sweep", "paper", *ARGS, "--workers", "1", "--out", str(out)]) == 0
    assert _metrics(_rows(out)) == _metrics(_rows(local_sweep))


def test_ray_backend_matches_local(local_sweep, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ray"
    assert main(["sweep", "paper", *ARGS, "--backend", "ray", "--workers", "2", "--out", str(out)]) == 0
    assert _metrics(_rows(out)) == _metrics(_rows(local_sweep))


def test_resume_skips_finished_runs(tmp_path):
    specs = expand("paper", 2, ["bioinspired"], [], ["sim.duration=0.3"])
    out = tmp_path / "resume"
    first = sweep(specs[:1], out, workers=1)
    assert first["ran"] == 1
    stamp = (out / "runs" / f"{specs[0].key}.json").stat().st_mtime_ns
    second = sweep(specs, out, workers=1)
    assert second["ran"] == 1 and second["skipped"] == 1
    assert (out / "runs" / f"{specs[0].key}.json").stat().st_mtime_ns == stamp
    assert len(second["rows"]) == 2


def test_failed_run_recorded_not_fatal(tmp_path):
    good = expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.3"])
    bad = [type(good[0])("paper", ("sim.duration=0.3", "kinematic.k1=-1"), "bioinspired", 0, None, ())]
    row = run_one(bad[0])
    assert row["status"] == "failed" and "kinematic.k1" in row["error"]
    res = sweep(good + bad, tmp_path / "mixed", workers=1)
    assert sorted(r["status"] for r in res["rows"]) == ["failed", "ok"]
    (g,) = res["stats"]["groups"]
    assert g["method"] == "bioinspired" and g["failed"] == 1 and g["outcomes"] == {"ok": 1, "failed": 1}


def test_sweep_bad_vary_exit_2(tmp_path, capsys):
    assert main(["sweep", "paper", "--vary", "kinematic.k1", "--out", str(tmp_path / "x")]) == 2
    assert "--vary" in capsys.readouterr().err
    assert main(["sweep", "paper", "--vary", "kinematic.k1=1,-2", "--out", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "y").exists()


def test_runs_parquet_holds_the_same_rows_as_runs_csv(local_sweep):
    """runs.parquet beside runs.csv: same rows and columns, typed (numbers as float64/int64, not text)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    tbl = pq.read_table(local_sweep / "runs.parquet")
    rows = _rows(local_sweep)
    assert tbl.num_rows == len(rows) == 8
    with open(local_sweep / "runs.csv") as fh:
        assert tbl.column_names == next(csv.reader(fh))
    assert tbl.schema.field("seed").type == pa.int64()
    assert tbl.schema.field("total_velocity_error_mean").type == pa.float64()
    by_key = {r["key"]: r for r in tbl.to_pylist()}
    for r in rows:
        p = by_key[r["key"]]
        assert p["method"] == r["method"] and str(p["seed"]) == r["seed"]
        assert p["total_velocity_error_mean"] == float(r["total_velocity_error_mean"])  # repr round-trips
        assert str(p["kinematic.k1"]) == r["kinematic.k1"]  # the varied value as written
