"""Sweeps a user can trust (issue 11): interrupts, dead workers, stale or damaged rows, grouping, outcomes."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bioform_mj.cli.main import main
from bioform_mj.core.errors import InputError
from bioform_mj.jobs import sweep as sweep_mod
from bioform_mj.jobs.sweep import RunSpec, expand, randomness, run_one, sweep
from bioform_mj.scenario.loader import load

SRC = str(Path(sweep_mod.__file__).resolve().parents[1])


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "runs.csv") as fh:
        return list(csv.DictReader(fh))


def _children(pid: int) -> set[int]:
    """Direct children of ``pid`` (Linux /proc)."""
    kids = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:
            pass
    return kids


def _descendants(pid: int) -> set[int]:
    out, todo = set(), [pid]
    while todo:
        kids = _children(todo.pop()) - out
        out |= kids
        todo += kids
    return out


def _alive(pids: set[int]) -> list[int]:
    """Those of ``pids`` that still run (zombies do not)."""
    alive = []
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.append(p)
    return alive


def _alive_with(marker: str) -> list[int]:
    """Processes (not zombies) whose command line contains ``marker``: forked workers keep the sweep's."""
    found = []
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            cmd = (p / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (p / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if marker in cmd and state != "Z":
            found.append(int(p.name))
    return found


# ideal plant, 20 s simulated: ~40 ms per run, so 80 runs keep two workers busy for more than a second
N_LONG = 80
LONG = ["--plant", "ideal", "--duration", "20", "--set", "formation.init_jitter=0.2", "--quiet"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and fork")
@pytest.mark.parametrize(
    "sig,workers,backend",
    [
        (signal.SIGINT, 2, "local"),
        (signal.SIGTERM, 2, "local"),
        (signal.SIGINT, 1, "local"),
        (signal.SIGTERM, 2, "ray"),
    ],
)
def test_signal_stops_sweep_keeps_rows_no_orphans(tmp_path, sig, workers, backend):
    if backend == "ray":
        pytest.importorskip("ray")
    out = tmp_path / f"sw_{sig.name}_{workers}_{backend}"
    cmd = [
        sys.executable,
        "-m",
        "bioform_mj.cli",
        "sweep",
        "paper",
        "--seeds",
        str(N_LONG if backend == "local" else 400),
        "--workers",
        str(workers),
        "--backend",
        backend,
        *LONG,
        "--out",
        str(out),
    ]
    # its own process group: SIGINT goes to the whole group, as Ctrl-C in a terminal does
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), start_new_session=True
    )
    runs = out / "runs"
    deadline = time.time() + 90
    while time.time() < deadline and (len(list(runs.glob("*.json"))) if runs.exists() else 0) < 3:
        time.sleep(0.02)
    kids: set[int] = set()
    for _ in range(50):  # signal while workers are mid-run
        kids = _descendants(proc.pid)
        if len(kids) >= 2 or workers == 1:
            break
        time.sleep(0.01)
    if backend == "ray" and proc.poll() is not None:  # ended before any signal: nothing of its subject to test
        err = proc.communicate(timeout=30)[1]
        if "Ray head" in err and "was lost" in err:  # Ray's own head died under load (seen once at load ~3 on 2 cores)
            pytest.skip(f"the Ray head died before the signal was sent: {err.strip().splitlines()[-1][:200]}")
        pytest.fail(f"the sweep ended before the signal: {err[-2000:]}")
    t0 = time.perf_counter()
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:  # `kill PID`: the sweep alone
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    stop_s = time.perf_counter() - t0
    assert proc.returncode == 128 + sig, err
    # Ray ends its raylet and workers on the way out: 1.5-5.05 s measured at load 12-13 on this 2-core machine
    assert stop_s < (5 if backend == "local" else 10), f"took {stop_s:.1f} s to stop"
    assert "interrupted" in err and "Resume with:" in err and str(out) in err
    if workers > 1:
        assert len(kids) >= 2, "no workers were running when the signal landed"
    for _ in range(40):  # local workers are reaped before the sweep exits; Ray's may take a moment
        if not _alive(kids) and not _alive_with(str(out)):
            break
        time.sleep(0.05)
    assert not _alive(kids), "worker processes outlived the sweep"
    assert not _alive_with(str(out)), "worker processes outlived the sweep"
    finished = {f.name: f.stat().st_mtime_ns for f in runs.glob("*.json")}
    assert 3 <= len(finished) < (N_LONG if backend == "local" else 400)
    assert all(json.loads((runs / n).read_text())["status"] == "ok" for n in finished)
    assert not list(runs.glob(".*.tmp"))
    timing = json.loads((out / "sweep.json").read_text())
    assert timing["interrupted"] == sig.name and timing["complete"] is False and timing["done"] == len(finished)
    assert len(_rows(out)) == len(finished)  # the tables cover the finished rows
    if (
        sig == signal.SIGINT and workers == 2 and backend == "local"
    ):  # the printed command resumes; finished rows are not rerun
        resume = err.split("Resume with:")[1].strip().splitlines()[0].split()
        assert resume[:2] == ["bioform", "sweep"]
        res = subprocess.run(
            [sys.executable, "-m", "bioform_mj.cli", *resume[1:]],
            capture_output=True,
            text=True,
            timeout=120,
            env=_env(),
        )
        assert res.returncode == 0, res.stderr
        assert {f.name: f.stat().st_mtime_ns for f in runs.glob("*.json") if f.name in finished} == finished
        assert len(_rows(out)) == N_LONG
        timing = json.loads((out / "sweep.json").read_text())
        assert timing["skipped"] == len(finished) and timing["ran"] == N_LONG - len(finished)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="forked workers")
def test_dead_worker_fails_its_row_only(tmp_path, monkeypatch):
    """A worker killed by SIGKILL (as by the OOM killer) fails its row with the reason; the rest run."""
    real = sweep_mod.run_one

    def dying(spec):
        if spec.seed == 1:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(spec)

    monkeypatch.setattr(sweep_mod, "run_one", dying)  # forked workers inherit the patch
    specs = expand("paper", 4, ["bioinspired"], [], ["sim.duration=0.5", "formation.init_jitter=0.1"], plant="ideal")
    out = tmp_path / "dead"
    res = sweep(specs, out, workers=2)
    by_seed = {r["seed"]: r for r in res["rows"]}
    assert sorted(by_seed) == [0, 1, 2, 3]
    assert by_seed[1]["status"] == "failed" and "SIGKILL" in by_seed[1]["error"] and by_seed[1]["worker_died"]
    assert all(by_seed[s]["status"] == "ok" for s in (0, 2, 3))
    assert res["timing"]["workers_died"] == 1
    assert {r["seed"]: r["status"] for r in _rows(out)} == {"0": "ok", "1": "failed", "2": "ok", "3": "ok"}
    # a resume retries the run whose worker died, and only that one
    monkeypatch.setattr(sweep_mod, "run_one", real)
    again = sweep(specs, out, workers=2)
    assert again["ran"] == 1 and again["skipped"] == 3
    assert {r["status"] for r in again["rows"]} == {"ok"}


def test_dead_worker_via_cli_warns(tmp_path, monkeypatch, capsys):
    real = sweep_mod.run_one
    monkeypatch.setattr(
        sweep_mod, "run_one", lambda spec: os.kill(os.getpid(), signal.SIGKILL) if spec.seed == 0 else real(spec)
    )
    out = tmp_path / "cli"
    assert (
        main(
            [
                "sweep",
                "paper",
                "--plant",
                "ideal",
                "--duration",
                "0.3",
                "--seeds",
                "2",
                "--workers",
                "2",
                "--set",
                "formation.init_jitter=0.1",
                "--quiet",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "warning:" in err and "worker process died" in err


def _write_scenario(path: Path, k1: float) -> None:
    path.write_text(f'name = "edited"\n[sim]\nduration = 0.3\n[kinematic]\nk1 = {k1}\n')


def test_resume_keys_on_content_not_path(tmp_path):
    scen = tmp_path / "s.toml"
    _write_scenario(scen, 1.0)
    out = tmp_path / "sw"
    first = sweep(expand(str(scen), 1, ["bioinspired"], [], plant="ideal"), out, workers=1)
    assert first["ran"] == 1
    # same content: skipped
    again = sweep(expand(str(scen), 1, ["bioinspired"], [], plant="ideal"), out, workers=1)
    assert again["ran"] == 0 and again["skipped"] == 1
    # the same content at another path is the same run
    moved = tmp_path / "elsewhere.toml"
    _write_scenario(moved, 1.0)
    assert sweep(expand(str(moved), 1, ["bioinspired"], [], plant="ideal"), out, workers=1)["ran"] == 0
    # edited file at the same path: another sweep (its key changed): refused in the old folder, whose rows it
    # would not resume, and run in a new one, where the result reflects the edit
    _write_scenario(scen, 2.0)
    with pytest.raises(InputError, match="holds another sweep's rows"):
        sweep(expand(str(scen), 1, ["bioinspired"], [], plant="ideal"), out, workers=1)
    edited = sweep(expand(str(scen), 1, ["bioinspired"], [], plant="ideal"), tmp_path / "sw2", workers=1)
    assert edited["ran"] == 1 and edited["skipped"] == 0
    assert edited["rows"][0]["total_velocity_error_mean"] != first["rows"][0]["total_velocity_error_mean"]
    # an override that changes the resolved content also changes the key; a method too
    a = expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.3"], warn=None)[0]
    b = expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.4"], warn=None)[0]
    c = expand("paper", 1, ["backstepping"], [], ["sim.duration=0.3"], warn=None)[0]
    assert len({a.key, b.key, c.key}) == 3
    assert a.key == expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.3"], warn=None)[0].key


def test_package_version_change_redoes_rows(tmp_path, monkeypatch, capsys):
    """The version is part of a row's provenance: a resume under another version redoes the row, saying why."""
    from bioform_mj.jobs import provenance

    out = tmp_path / "sw"
    args = ("paper", 1, ["bioinspired"], [], ["sim.duration=0.2"])
    assert sweep(expand(*args, plant="ideal", warn=None), out, workers=1)["ran"] == 1
    assert sweep(expand(*args, plant="ideal", warn=None), out, workers=1)["ran"] == 0
    monkeypatch.setattr(provenance, "__version__", "999.0")
    capsys.readouterr()
    again = sweep(expand(*args, plant="ideal", warn=None), out, workers=1)
    assert again["ran"] == 1 and again["skipped"] == 0
    assert "resume: 1 row(s) redone (package version changed: 0.1.0 -> 999.0)" in capsys.readouterr().err
    assert again["rows"][0]["provenance"]["version"] == "999.0"


@pytest.mark.parametrize("damage", ["truncate", "garbage", "wrong_key"])
def test_damaged_row_redone_with_warning(tmp_path, capsys, damage):
    out = tmp_path / "sw"
    args = [
        "sweep",
        "paper",
        "--plant",
        "ideal",
        "--duration",
        "0.3",
        "--seeds",
        "3",
        "--workers",
        "1",
        "--set",
        "formation.init_jitter=0.1",
        "--quiet",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    files = sorted((out / "runs").glob("*.json"))
    victim = files[1]
    good = victim.read_text()
    if damage == "truncate":
        victim.write_text(good[: len(good) // 2])
    elif damage == "garbage":
        victim.write_bytes(b"\0\xff\0")
    else:
        victim.write_text(files[0].read_text())
    capsys.readouterr()
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and victim.name in err and "redone" in err
    timing = json.loads((out / "sweep.json").read_text())
    assert timing["ran"] == 1 and timing["skipped"] == 2
    assert json.loads(victim.read_text()) == {
        **json.loads(good),
        "wall_time_s": json.loads(victim.read_text())["wall_time_s"],
    }
    assert len(_rows(out)) == 3
    assert main(args) == 0  # repaired: no warning, nothing to run
    assert "warning" not in capsys.readouterr().err
    assert json.loads((out / "sweep.json").read_text())["ran"] == 0


def test_stats_group_by_every_varied_key(tmp_path):
    out = tmp_path / "g"
    assert (
        main(
            [
                "sweep",
                "paper",
                "--plant",
                "ideal",
                "--duration",
                "0.3",
                "--seeds",
                "2",
                "--workers",
                "2",
                "--set",
                "formation.init_jitter=0.1",
                "--methods",
                "bioinspired,backstepping",
                "--vary",
                "kinematic.k1=1,2",
                "--vary",
                "learner.k4=[6,50];[6,500]",
                "--quiet",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    stats = json.loads((out / "stats.json").read_text())
    assert stats["group_by"] == ["method", "kinematic.k1", "learner.k4"]
    keys = [(g["method"], g["kinematic.k1"], g["learner.k4"]) for g in stats["groups"]]
    assert len(keys) == len(set(keys)) == 8 and all(g["runs"] == 2 for g in stats["groups"])
    md = (out / "stats.md").read_text().splitlines()
    assert md[0].startswith("| method | kinematic.k1 | learner.k4 |")
    assert sum(ln.startswith("| backstepping | 2 | [6,500] |") for ln in md) == 1
    assert len([ln for ln in md[2:] if ln.startswith("| ")]) == 8


def test_seed_warning_only_without_randomness(tmp_path, capsys):
    base = ["sweep", "paper", "--plant", "ideal", "--duration", "0.2", "--workers", "1", "--quiet"]
    assert main([*base, "--seeds", "2", "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "--seeds 2" in err and "identical runs" in err
    rows = _rows(tmp_path / "a")
    assert rows[0]["total_velocity_error_mean"] == rows[1]["total_velocity_error_mean"]  # the warning is right
    assert main([*base, "--seeds", "2", "--set", "formation.init_jitter=0.1", "--out", str(tmp_path / "b")]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main([*base, "--seeds", "1", "--out", str(tmp_path / "c")]) == 0
    assert "warning" not in capsys.readouterr().err
    # a varied jitter: only the configurations without it are named
    assert main([*base, "--seeds", "2", "--vary", "formation.init_jitter=0,0.1", "--out", str(tmp_path / "d")]) == 0
    err = capsys.readouterr().err
    assert "1 of 2 configurations" in err and "formation.init_jitter=0" in err


def test_randomness_sources():
    assert randomness(load("paper")) == []
    assert randomness(load("paper", ["formation.init_jitter=0.1"])) == ["formation.init_jitter"]
    assert randomness(load("paper", ["faults.packet_loss=0.2"])) == ["faults.packet_loss"]
    assert randomness(load("paper", ["faults.noise_pose=[0.01,0,0]"])) == ["faults.noise_pose"]
    assert randomness(load("paper", ["faults.noise_vel=[0,0.01]"])) == ["faults.noise_vel"]
    # noise in a window after the run ends never draws
    assert randomness(load("paper", ["faults.noise_vel=[0,0.01]", "sim.duration=5", "faults.window=[6,8]"])) == []
    # the obstacle field and the gyro's noise are drawn from the seed too: seeds differ (the warning said otherwise)
    assert randomness(load("obstacles")) == ["obstacle_field"]
    a, b = (load("obstacles", [f"sim.seed={s}"]).obstacle_list() for s in (0, 1))
    assert min(abs(p.x - q.x) + abs(p.y - q.y) for p, q in zip(a[-8:], b[-8:])) > 1e-3  # the field moved
    gyro = ["plant.sensing='odometry'", "plant.gyro_noise=0.01"]
    assert randomness(load("tb3", gyro)) == ["plant.gyro_noise"]
    assert randomness(load("tb3", gyro[:1])) == []  # odometry without noise is deterministic


def test_diverged_run_marked_in_tables(tmp_path):
    specs = expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.5"], plant="ideal")
    bad = expand("paper", 1, ["backstepping"], [], ["sim.duration=0.5", "limits.speed=0.05"], plant="ideal")
    res = sweep(specs + bad, tmp_path / "div", workers=1)
    by = {r["method"]: r for r in _rows(tmp_path / "div")}
    assert by["backstepping"]["status"] == "diverged" and by["backstepping"]["outcome"] == "diverged"
    assert float(by["backstepping"]["diverged_at_s"]) < 0.5
    assert by["bioinspired"]["outcome"] == "ok" and by["bioinspired"]["diverged_at_s"] == ""
    groups = {g["method"]: g for g in res["stats"]["groups"]}
    assert groups["backstepping"]["outcomes"] == {"diverged": 1}
    md = (tmp_path / "div" / "stats.md").read_text()
    assert "| backstepping | 1 (0/1/0) | diverged 1 |" in md


def test_follower_outcomes_when_summary_has_them(monkeypatch):
    from bioform_mj.run import simulate as sim

    real = sim.simulate

    def with_outcomes(sc, *a, **k):
        res = real(sc, *a, **k)
        for f, o in zip(res.summary["followers"], ["ok", "tipped", "lost"]):
            f["outcome"] = o
        return res

    spec = expand("paper", 1, ["bioinspired"], [], ["sim.duration=0.2"], plant="ideal")[0]
    row = run_one(spec)
    assert row["outcome"] == "ok" and row["follower_outcomes"] == "ok;ok;ok"
    monkeypatch.setattr(sim, "simulate", with_outcomes)
    row = run_one(spec)
    assert row["follower_outcomes"] == "ok;tipped;lost" and row["outcome"] == "lost,tipped"


def test_spec_without_digest_still_runs():
    """A RunSpec made by hand (no resolved scenario) loads its scenario and is keyed by its settings."""
    sp = RunSpec("paper", ("sim.duration=0.2",), "bioinspired", 0, "ideal", ())
    row = run_one(sp)
    assert row["status"] == "ok" and row["key"] == sp.key and len(sp.key) == 16
