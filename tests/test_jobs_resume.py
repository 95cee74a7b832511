"""Long jobs a user can trust (issue 19): resume never reuses stale work, one sweep per folder, a
repeated --vary refused, equal values run once, memory estimated before it is spent (each refusal
run under ``ulimit -v`` so that a regression cannot take the machine down), calibrate stops cleanly
and resumes, a closed Ray address fails fast."""

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
from bioform_mj.core import codehash
from bioform_mj.jobs import provenance
from bioform_mj.jobs import sweep as sweep_mod
from bioform_mj.jobs.sweep import expand, sweep
from bioform_mj.robots.refs import models_dir

SRC = str(Path(sweep_mod.__file__).resolve().parents[1])
#: address-space limit for the memory refusals: a normal start of the CLI (numba, LLVM, MuJoCo, Warp on
#: the CPU) runs under it (a 1-run Warp sweep was checked at 2 GB), a runaway allocation of tens of GB fails
ULIMIT_KB = 4_000_000


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _cli(args: list[str], timeout: float = 120, ulimit_kb: int | None = ULIMIT_KB) -> subprocess.CompletedProcess:
    """``bioform ARGS`` in a subprocess, under ``ulimit -v``."""
    cmd = " ".join(["exec", sys.executable, "-m", "bioform_mj.cli", *(f"'{a}'" for a in args)])
    if ulimit_kb:
        cmd = f"ulimit -v {ulimit_kb}; {cmd}"
    return subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=timeout, env=_env())


def _error_lines(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("error:")]


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "runs.csv") as fh:
        return list(csv.DictReader(fh))


# ------------------------------------------------------------------------------------------ resume key


def _included_robot(tmp_path: Path, mass: float) -> tuple[Path, Path]:
    """The paper robot split in two files: ``robot.xml`` includes ``robot_body.xml`` (chassis mass ``mass``)."""
    text = (models_dir() / "paper_robot.xml").read_text()
    assert 'mass="23.5"' in text
    body = tmp_path / "robot_body.xml"
    body.write_text(text.replace('mass="23.5"', f'mass="{mass}"'))
    main_file = tmp_path / "robot.xml"
    main_file.write_text('<mujoco model="wrapped">\n  <include file="robot_body.xml"/>\n</mujoco>\n')
    return main_file, body


def test_model_files_walks_includes_and_meshes(tmp_path):
    main_file, body = _included_robot(tmp_path, 23.5)
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "a.stl").write_bytes(b"solid a\nendsolid a\n")
    extra = tmp_path / "assets.xml"
    extra.write_text('<mujoco><compiler meshdir="meshes"/><asset><mesh name="m" file="a.stl"/></asset></mujoco>\n')
    main_file.write_text(
        '<mujoco model="wrapped">\n  <include file="assets.xml"/>\n  <include file="robot_body.xml"/>\n</mujoco>\n'
    )
    files = provenance.model_files(main_file)
    want = {str(p.resolve()) for p in (main_file, body, extra, tmp_path / "meshes" / "a.stl")}
    assert set(files) == want
    assert all(len(h) == 16 for h in files.values())
    before = files[str((tmp_path / "meshes" / "a.stl").resolve())]
    time.sleep(0.01)
    (tmp_path / "meshes" / "a.stl").write_bytes(b"solid b\nendsolid b\n")
    assert provenance.model_files(main_file)[str((tmp_path / "meshes" / "a.stl").resolve())] != before


def test_resume_after_editing_an_included_robot_file_redoes_rows(tmp_path, capsys):
    robot, body = _included_robot(tmp_path, 23.5)
    out = tmp_path / "sw"
    ov = [f'plant.robots=["{robot}"]', "sim.duration=1.0"]
    first = sweep(expand("paper", 1, ["bioinspired"], [], ov, plant="mujoco", warn=None), out, workers=1)
    assert first["ran"] == 1 and first["rows"][0]["status"] == "ok"
    assert sweep(expand("paper", 1, ["bioinspired"], [], ov, plant="mujoco", warn=None), out, workers=1)["ran"] == 0
    body.write_text(body.read_text().replace('mass="23.5"', 'mass="40"'))  # the top-level file is unchanged
    capsys.readouterr()
    again = sweep(expand("paper", 1, ["bioinspired"], [], ov, plant="mujoco", warn=None), out, workers=1)
    err = capsys.readouterr().err
    assert again["ran"] == 1 and again["skipped"] == 0
    assert f"resume: 1 row(s) redone (robot file changed: {body.resolve()})" in err
    # the redone row is the edited robot's result, as a fresh folder gives it
    fresh = sweep(expand("paper", 1, ["bioinspired"], [], ov, plant="mujoco", warn=None), tmp_path / "f", workers=1)
    m = "final_formation_error_m_max"
    assert again["rows"][0][m] == fresh["rows"][0][m] != first["rows"][0][m]


def test_resume_after_a_code_change_redoes_rows(tmp_path, monkeypatch, capsys):
    out = tmp_path / "sw"
    args = ("paper", 2, ["bioinspired"], [], ["sim.duration=0.2", "formation.init_jitter=0.1"])
    assert sweep(expand(*args, plant="ideal", warn=None), out, workers=1)["ran"] == 2
    monkeypatch.setattr(provenance, "code_hash", lambda: "0123456789abcdef")  # as an edit of an equation would
    capsys.readouterr()
    again = sweep(expand(*args, plant="ideal", warn=None), out, workers=1)
    assert again["ran"] == 2 and again["skipped"] == 0
    assert "resume: 2 row(s) redone (code changed (source hash of bioform_mj))" in capsys.readouterr().err
    assert all(r["provenance"]["code"] == "0123456789abcdef" for r in again["rows"])


def test_code_hash_covers_every_source_file_and_is_cached():
    codehash.source_digest.cache_clear()
    codehash.code_hash.cache_clear()
    t0 = time.perf_counter()
    h = provenance.code_hash()
    first_ms = (time.perf_counter() - t0) * 1e3
    t0 = time.perf_counter()
    assert provenance.code_hash() == h and len(h) == 16
    assert (time.perf_counter() - t0) * 1e3 < 0.1  # cached per process
    assert first_ms < 50, f"code hash took {first_ms:.1f} ms"


def test_resume_key_of_a_1000_row_folder_costs_under_50_ms(tmp_path):
    """The resume key of a 1,000-run sweep (the configuration hashed once, 1,000 seed keys, and each
    finished row's provenance compared) costs < 50 ms; reading the row files is timed beside it. The
    folder is built cheaply: the row of one run written under 1,000 keys."""
    out = tmp_path / "sw"
    specs = expand("paper", 1000, ["bioinspired"], [], ["sim.duration=0.1"], plant="ideal", warn=None)
    assert len({sp.key for sp in specs}) == 1000
    assert all(sp.key == sweep_mod.content_key(sp.scenario) for sp in specs[:5])  # the fast path is the key
    row = sweep_mod.run_one(specs[0])
    (out / "runs").mkdir(parents=True)
    for sp in specs:
        (out / "runs" / f"{sp.key}.json").write_text(json.dumps({**row, "key": sp.key, "seed": sp.seed}))
    key_s = read_s = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        got = [sweep_mod._read_row(out / "runs" / f"{sp.key}.json", sp, None) for sp in specs]
        t1 = time.perf_counter()
        text = sweep_mod.config_text(specs[0].scenario)
        keys = [sweep_mod.seed_key(text, sp.seed) for sp in specs]
        stale = [sweep_mod._stale(r, sp, "local", None, None) for r, sp in zip(got, specs)]
        t2 = time.perf_counter()
        read_s, key_s = min(read_s, t1 - t0), min(key_s, t2 - t1)
    assert keys == [sp.key for sp in specs]
    assert not any(stale) and all(r is not None for r in got)
    print(f"resume key, 1000 rows: {key_s * 1e3:.1f} ms (reading the row files: {read_s * 1e3:.1f} ms)")
    assert key_s < 0.050, f"{key_s * 1e3:.1f} ms"


# ------------------------------------------------------------------------------------------ folder, --vary


def test_a_second_sweep_into_a_busy_folder_is_refused(tmp_path, capsys):
    out = tmp_path / "sw"
    out.mkdir()
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; from bioform_mj.outputs.rundir import take_lock; "
            "take_lock(Path(sys.argv[1])); print('locked', flush=True); time.sleep(60)",
            str(out),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        code = main(["sweep", "paper", "--plant", "ideal", "--duration", "0.1", "--out", str(out), "--quiet"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2
        assert len(err) == 1 and err[0].startswith("error:") and str(out) in err[0]
        assert f"process {holder.pid}" in err[0] and "sweep" in err[0]
        assert not (out / "runs").exists()
    finally:
        holder.kill()
        holder.wait()
    # the lock dies with its holder: the sweep runs now
    assert main(["sweep", "paper", "--plant", "ideal", "--duration", "0.1", "--out", str(out), "--quiet"]) == 0


def test_a_sweep_into_another_sweeps_folder_is_refused_unless_the_same(tmp_path, capsys):
    """Issue 28: a sweep into a folder holding another sweep's rows (here k1 = 1, 2) is refused, exit 2, one line
    that says how to proceed, its rows and statistics untouched; the same sweep (resume) and the same sweep with
    one more value (k1 = 1, 2, 3: its 2 rows reused, 1 run) pass."""
    out = tmp_path / "sw"
    base = ["sweep", "paper", "--plant", "ideal", "--duration", "0.1", "--out", str(out), "--quiet"]
    assert main([*base, "--vary", "kinematic.k1=1,2"]) == 0
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in [*out.iterdir(), *(out / "runs").iterdir()] if p.is_file()}
    code = main([*base, "--vary", "kinematic.k1=5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: sweep directory '{out}' holds another sweep's rows: 2 of its 2 rows"), err
    assert "kinematic.k1=1" in err[0] and "rerun its own command" in err[0] and "choose another --out" in err[0]
    after = {p.name: p.read_bytes() for p in [*out.iterdir(), *(out / "runs").iterdir()] if p.is_file()}
    assert after == before  # nothing rewritten, the statistics included
    assert main([*base, "--vary", "kinematic.k1=1,2"]) == 0  # resume: the same sweep
    assert "0 run now" in capsys.readouterr().err or len(list((out / "runs").iterdir())) == 2
    assert main([*base, "--vary", "kinematic.k1=1,2,3"]) == 0  # the same sweep, one value more
    assert len(list((out / "runs").glob("*.json"))) == 3


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--vary", "kinematic.k1=1,2", "--vary", "kinematic.k1=3"], "--vary kinematic.k1 given twice"),
        (["--set", "kinematic.k1=2", "--vary", "kinematic.k1=1,3"], "--vary kinematic.k1 and --set kinematic.k1"),
        (["--vary", "sim.seed=1,2"], "--vary sim.seed: the seeds are --seed"),
    ],
)
def test_repeated_or_clashing_vary_is_refused(tmp_path, capsys, extra, needle):
    out = tmp_path / "sw"
    assert main(["sweep", "paper", "--plant", "ideal", "--duration", "0.1", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and needle in err[0]
    assert not out.exists()


def test_equal_vary_values_run_once_with_a_note(tmp_path, capsys):
    out = tmp_path / "sw"
    argv = ["sweep", "paper", "--plant", "ideal", "--duration", "0.2", "--vary", "kinematic.k1=1,1,1.0,2"]
    assert main(argv + ["--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "note:" in err and "kinematic.k1=1.0 is kinematic.k1=1" in err and "1 repeated value" in err
    rows = _rows(out)
    assert sorted(r["kinematic.k1"] for r in rows) == ["1", "2"]
    stats = json.loads((out / "stats.json").read_text())
    assert [(g["kinematic.k1"], g["runs"]) for g in stats["groups"]] == [("1", 1), ("2", 1)]


def test_set_then_vary_into_one_folder_labels_and_groups_every_row(tmp_path, capsys):
    """issue 20: the --set run's row is reused by the --vary sweep and carries its varied value."""
    out = tmp_path / "sw"
    base = ["sweep", "paper", "--plant", "ideal", "--duration", "0.2", "--seeds", "2"]
    base += ["--set", "formation.init_jitter=0.1", "--out", str(out), "--quiet"]
    assert main(base + ["--set", "kinematic.k1=2"]) == 0
    assert main(base + ["--vary", "kinematic.k1=1,2"]) == 0
    timing = json.loads((out / "sweep.json").read_text())
    assert timing["skipped"] == 2 and timing["ran"] == 2  # the k1 = 2 rows were reused
    rows = _rows(out)
    assert sorted(r["kinematic.k1"] for r in rows) == ["1", "1", "2", "2"]
    stats = json.loads((out / "stats.json").read_text())
    assert [(g["kinematic.k1"], g["runs"]) for g in stats["groups"]] == [("1", 2), ("2", 2)]
    e1, e2 = (g["metrics"]["total_velocity_error_mean"]["mean"] for g in stats["groups"])
    assert e1 != e2


# ------------------------------------------------------------------------------------------ memory


def _big_team(tmp_path: Path, n: int) -> Path:
    offs = ",".join(f"[{-1.0 * (i // 100 + 1)},{0.5 * (i % 100)}]" for i in range(n))
    p = tmp_path / "big.toml"
    p.write_text(
        f'name = "big"\n[sim]\nduration = 0.1\n[plant]\nkind = "mujoco"\n[graph]\nkind = "chain"\n'
        f"[formation]\noffsets = [{offs}]\n"
    )
    return p


def _refused(res: subprocess.CompletedProcess, *needles: str) -> str:
    errs = _error_lines(res.stderr)
    assert res.returncode == 2, res.stderr[-2000:]
    assert len(errs) == 1 and ("needs about" in errs[0] or "needed" in errs[0]), res.stderr[-2000:]
    assert "Traceback" not in res.stderr and "MemoryError" not in res.stderr
    for n in needles:
        assert n in errs[0], errs[0]
    return errs[0]


def test_5000_mujoco_followers_refused_with_an_estimate(tmp_path):
    res = _cli(["run", str(_big_team(tmp_path, 5000)), "--out", str(tmp_path / "r"), "--quiet"])
    line = _refused(res, "5000 followers", "GB")
    assert not (tmp_path / "r").exists()
    # the estimate: 18.4 MB + 457 kB n + 2523 B n² = 65.4 GB at n = 5000
    assert "65.4 GB" in line


def test_a_sweep_too_large_for_memory_is_refused_before_it_expands(tmp_path):
    t0 = time.perf_counter()
    res = _cli(["sweep", "paper", "--plant", "ideal", "--seeds", "100000000", "--out", str(tmp_path / "s")])
    _refused(res, "100000000 runs")
    assert time.perf_counter() - t0 < 30


@pytest.mark.parametrize(
    "flag,value,needle",
    [("--nconmax", "1000000000", "nconmax 1000000000"), ("--njmax", "100000000000", "njmax 100000000000")],
)
def test_warp_capacity_beyond_memory_is_refused(tmp_path, flag, value, needle):
    pytest.importorskip("mujoco_warp")
    out = tmp_path / "s"
    args = ["sweep", "paper", "--plant", "mujoco", "--duration", "0.05", "--backend", "warp", "--device", "cpu"]
    res = _cli(args + [flag, value, "--out", str(out), "--quiet"])
    _refused(res, needle)
    assert not (out / "runs").exists()


def test_warp_bench_worlds_beyond_memory_is_refused(tmp_path):
    pytest.importorskip("mujoco_warp")
    js = tmp_path / "b.json"
    res = _cli(["bench", "--backend", "warp", "--device", "cpu", "--worlds", "100000000", "--json", str(js)])
    _refused(res, "--worlds 100000000", "worlds fit")
    assert not js.exists()


# ------------------------------------------------------------------------------------------ Ray


def test_closed_ray_address_exits_2_within_seconds(tmp_path):
    pytest.importorskip("ray")
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "s"
    t0 = time.perf_counter()
    res = _cli(
        ["sweep", "paper", "--plant", "ideal", "--duration", "0.1", "--backend", "ray"]
        + ["--ray-address", f"127.0.0.1:{port}", "--out", str(out)],
        timeout=60,
        ulimit_kb=None,
    )
    took = time.perf_counter() - t0
    errs = _error_lines(res.stderr)
    assert res.returncode == 2, res.stderr[-2000:]
    assert took < 10, f"{took:.1f} s"
    assert len(errs) == 1 and f"127.0.0.1:{port}" in errs[0] and "RAY_AUTH_MODE=token" in errs[0]
    assert not (out / "runs").exists()


def _recorded(tmp_path: Path, address: str) -> Path:
    """A Ray folder whose ``ray_current_cluster`` records ``address``, as ``ray start --head`` leaves it."""
    (tmp_path / "raytmp" / "ray").mkdir(parents=True)
    (tmp_path / "raytmp" / "ray" / "ray_current_cluster").write_text(address)
    return tmp_path / "raytmp"


def test_a_live_recorded_ray_cluster_is_named_not_joined(tmp_path, monkeypatch):
    """A cluster `ray start` left running: the local sweep refuses in seconds, naming it and the two ways on
    (ray.init() without an address would join it and then refuse num_cpus, or die with its head)."""
    import socket

    from bioform_mj.core.errors import InputError
    from bioform_mj.jobs.ray_backend import check_ray_address, local_cluster

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    with socket.socket() as srv:
        srv.bind(("127.0.0.1", 0))
        srv.listen(4)
        port = srv.getsockname()[1]
        monkeypatch.setenv("RAY_TMPDIR", str(_recorded(tmp_path, f"127.0.0.1:{port}")))
        with pytest.raises(InputError) as e:
            check_ray_address(None)
    msg = str(e.value)
    assert f"runs on this machine at 127.0.0.1:{port}" in msg and f"--ray-address 127.0.0.1:{port}" in msg
    assert "ray stop" in msg and "ray_current_cluster" in msg
    # the same record once the cluster is gone (a stale file): a local cluster of the sweep's own
    assert local_cluster() == ("local", None)
    check_ray_address(None)


def test_ray_address_variable_is_joined_and_checked(tmp_path, monkeypatch):
    """$RAY_ADDRESS (Ray's own convention) is the address a sweep without --ray-address joins; closed: exit 2
    naming the variable."""
    import socket

    from bioform_mj.core.errors import InputError
    from bioform_mj.jobs.ray_backend import check_ray_address, local_cluster

    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))  # nothing recorded
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert local_cluster() == ("local", None)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
    assert local_cluster() == ("env", f"127.0.0.1:{port}")
    with pytest.raises(InputError, match=rf"^RAY_ADDRESS 127\.0\.0\.1:{port}: cannot connect"):
        check_ray_address(None)


# ------------------------------------------------------------------------------------------ calibrate


def _calibrate_proc(out: Path, budget: int = 40, extra: tuple[str, ...] = ()) -> subprocess.Popen:
    # 20 s simulated per method: ~0.3 s per evaluation on the ideal plant, long enough to be caught mid-way
    cmd = [sys.executable, "-m", "bioform_mj.cli", "calibrate", "table1", "--budget", str(budget)]
    cmd += ["--workers", "2", "--out", str(out), "--quiet", *extra]
    return subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), start_new_session=True
    )


def _group_alive(pgid: int) -> list[int]:
    alive = []
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            fields = (p / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(p.name))
    return alive


def _evaluations(out: Path) -> list[dict]:
    lines = (out / "evaluations.jsonl").read_text().splitlines()
    head = json.loads(lines[0])
    assert head["kind"] == "bioform calibrate evaluations"
    return [json.loads(x) for x in lines[1:]]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, fork")
@pytest.mark.parametrize("to_group", [True, False], ids=["SIGINT-group", "SIGTERM-main"])
def test_calibrate_stops_on_a_signal_keeps_evaluations_and_resumes(tmp_path, to_group):
    pytest.importorskip("scipy")
    out = tmp_path / "cal"
    proc = _calibrate_proc(out)
    deadline = time.time() + 120
    while time.time() < deadline:
        ev = out / "evaluations.jsonl"
        if ev.exists() and len(ev.read_text().splitlines()) >= 4:  # header + the default + 2 in the pool
            break
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()[1]
    sig = signal.SIGINT if to_group else signal.SIGTERM
    t0 = time.perf_counter()
    if to_group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    took = time.perf_counter() - t0
    assert proc.returncode == 128 + sig, err
    assert took < 10, f"{took:.1f} s to stop"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    errs = _error_lines(err)
    assert len(errs) == 1 and "interrupted" in errs[0] and "evaluations.jsonl" in errs[0] and "resume" in errs[0]
    for _ in range(40):
        if not _group_alive(proc.pid):
            break
        time.sleep(0.05)
    assert not _group_alive(proc.pid), "calibrate workers outlived it"
    done = _evaluations(out)
    assert 3 <= len(done) < 40 + 30
    assert all("objective" in e and "conditions" in e for e in done)
    best = json.loads((out / "calibration.partial.json").read_text())
    assert best["objective"] == pytest.approx(min(e["objective"] for e in done))
    if to_group:  # the same command resumes: the evaluations kept are not computed again
        res = subprocess.run(
            [sys.executable, "-m", "bioform_mj.cli", "calibrate", "table1", "--budget", "12", "--workers", "2"]
            + ["--out", str(out), "--quiet"],
            capture_output=True,
            text=True,
            timeout=300,
            env=_env(),
        )
        assert res.returncode == 0, res.stderr[-2000:]
        rep = json.loads((out / "calibration.json").read_text())
        assert rep["evaluations"]["reused"] >= min(len(done), 12)
        assert not (out / "calibration.partial.json").exists()


def test_calibrate_refuses_a_folder_holding_another_kind_of_run(tmp_path, capsys):
    pytest.importorskip("scipy")
    out = tmp_path / "r"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    for extra in ([], ["--overwrite"]):
        assert main(["calibrate", "table1", "--budget", "2", "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "summary.json" in err[0] and "another kind of run" in err[0]
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]


def test_calibrate_refuses_an_absurd_budget_with_an_estimate(tmp_path, capsys):
    pytest.importorskip("scipy")
    out = tmp_path / "c"
    t0 = time.perf_counter()
    assert main(["calibrate", "table1", "--budget", "1000000000000", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert time.perf_counter() - t0 < 5
    assert len(err) == 1 and err[0].startswith("error:") and "--budget 1000000000000" in err[0]
    assert "estimated" in err[0] and "days" in err[0]
    assert not out.exists()


def test_calibrate_prints_count_and_eta_without_a_terminal(tmp_path):
    pytest.importorskip("scipy")
    out = tmp_path / "c"
    # 2 s simulated per method, not the preset's 20 s: the line and the refusal are what is checked, and the
    # search's ~25 evaluations (3 + the sensitivity's) took 8.5 s of CPU at 20 s, 3.7 s at 2 s
    res = subprocess.run(
        [sys.executable, "-m", "bioform_mj.cli", "calibrate", "table1", "--budget", "3", "--workers", "1"]
        + ["--set", "sim.duration=2", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        env=_env(),
    )
    assert res.returncode == 0, res.stderr[-2000:]
    line = next(ln for ln in res.stderr.splitlines() if ln.startswith("calibrate:"))
    assert "3 evaluations" in line and "estimated" in line
    # a complete calibration is another run: refused without --overwrite, replaced with it
    again = _cli(["calibrate", "table1", "--budget", "3", "--set", "sim.duration=2", "--out", str(out)], ulimit_kb=None)
    assert again.returncode == 2 and "--overwrite" in _error_lines(again.stderr)[0]


@pytest.mark.slow
def test_ray_head_lost_mid_sweep_writes_the_tables_and_resumes(tmp_path):
    """A head started with ``ray start --head`` (token auth: RAY_AUTH_MODE=token) killed mid-sweep: an
    ``error:`` line, exit 1, runs.csv covering the finished rows (measured: 17 s from the kill to the exit)."""
    pytest.importorskip("ray")
    import shutil
    import socket

    ray_cli = shutil.which("ray") or str(Path(sys.executable).parent / "ray")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**_env(), "RAY_AUTH_MODE": "token"}
    head = ["--head", "--port", str(port), "--num-cpus", "2", "--include-dashboard", "false"]
    subprocess.run([ray_cli, "start", *head, "--disable-usage-stats"], env=env, capture_output=True, timeout=120)
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "bioform_mj.cli", "sweep", "paper", "--plant", "ideal", "--duration", "20"]
    cmd += ["--seeds", "300", "--set", "formation.init_jitter=0.1", "--backend", "ray"]
    cmd += ["--ray-address", f"127.0.0.1:{port}", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.time() + 120
        while (
            time.time() < deadline and len(list((out / "runs").glob("*.json")) if (out / "runs").exists() else []) < 3
        ):
            time.sleep(0.2)
        subprocess.run([ray_cli, "stop", "--force"], env=env, capture_output=True, timeout=60)
        _, err = proc.communicate(timeout=90)
    finally:
        proc.kill()
        subprocess.run([ray_cli, "stop", "--force"], env=env, capture_output=True, timeout=60)
    errs = _error_lines(err)
    assert proc.returncode == 1, err[-2000:]
    assert len(errs) == 1 and "was lost" in errs[0] and "rerun the same command" in errs[0], err[-3000:]
    finished = list((out / "runs").glob("*.json"))
    assert 3 <= len(finished) < 300
    assert len(_rows(out)) == len(finished)
    assert json.loads((out / "sweep.json").read_text())["complete"] is False


def test_a_sweep_refuses_a_folder_holding_another_kind_of_run(tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    (out / "calibration.json").write_text("{}")
    assert main(["sweep", "paper", "--plant", "ideal", "--duration", "0.1", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another kind of run (calibration.json)" in err[0]
    assert sorted(p.name for p in out.iterdir()) == ["calibration.json"]


def test_sigint_while_ray_connects_stops_in_seconds(tmp_path):
    """A port that accepts connections and never answers: ray.init would wait; Ctrl-C stops the sweep."""
    pytest.importorskip("ray")
    import socket

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    port = srv.getsockname()[1]
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "bioform_mj.cli", "sweep", "paper", "--plant", "ideal", "--duration", "0.1"]
    cmd += ["--backend", "ray", "--ray-address", f"127.0.0.1:{port}", "--out", str(out), "--quiet"]
    try:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), start_new_session=True
        )
        deadline = time.time() + 60
        while time.time() < deadline and not (out / "runs").exists():  # past the probe: connecting
            time.sleep(0.05)
        time.sleep(1.0)
        assert proc.poll() is None
        t0 = time.perf_counter()
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        took = time.perf_counter() - t0
    finally:
        srv.close()
    assert proc.returncode == 130, err[-2000:]
    assert took < 5, f"{took:.1f} s"
    assert "interrupted (SIGINT)" in err and "Resume with:" in err


def test_calibration_folder_resumes_unfinished_and_overwrites_finished(tmp_path):
    from bioform_mj.core.errors import InputError
    from bioform_mj.outputs.rundir import CALIBRATION_FILES, RunDir

    resumable = frozenset({"evaluations.jsonl", "calibration.partial.json"})
    out = tmp_path / "c"
    out.mkdir()
    (out / "evaluations.jsonl").write_text("{}\n")
    (out / "calibration.partial.json").write_text("{}")
    with RunDir(out, files=CALIBRATION_FILES, resumable=resumable).check():  # unfinished: resumed, kept
        assert (out / "evaluations.jsonl").exists()
    (out / "calibration.json").write_text("{}")
    with pytest.raises(InputError, match="--overwrite"):
        RunDir(out, files=CALIBRATION_FILES, resumable=resumable).check()
    with RunDir(out, overwrite=True, files=CALIBRATION_FILES, resumable=resumable).check():
        assert sorted(p.name for p in out.iterdir()) == [".bioform.lock"]  # exactly its files removed
    (out / "table1.json").write_text("{}")
    with pytest.raises(InputError, match="another kind of run"):
        RunDir(out, overwrite=True, files=CALIBRATION_FILES, resumable=resumable).check()


def test_evaluations_file_skips_a_cut_line_and_refuses_another_calibration(tmp_path):
    pytest.importorskip("scipy")
    from bioform_mj.core.errors import InputError
    from bioform_mj.jobs import calibrate as cal
    from bioform_mj.scenario.loader import load

    base = load("paper", plant="ideal")
    ctx = cal._context(base, "table1", "ideal", 0)
    c = cal.scenario_conditions(base)
    ev = {"conditions": c, "objective": 0.123456789012345}
    path = tmp_path / cal.EVALUATIONS_FILE
    head = json.dumps({"kind": "bioform calibrate evaluations", "context": ctx})
    path.write_text(head + "\n" + json.dumps(ev) + "\n" + json.dumps(ev)[:17])  # SIGKILL mid-line
    got = cal.load_evaluations(path, ctx)
    assert list(got.values()) == [ev]  # the float comes back bit for bit: a resumed search replays it
    with pytest.raises(InputError, match="seed"):
        cal.load_evaluations(path, cal._context(base, "table1", "ideal", 1))
    other = load("paper", plant="ideal", overrides=["kinematic.k1=3"])
    with pytest.raises(InputError, match="scenario"):
        cal.load_evaluations(path, cal._context(other, "table1", "ideal", 0))


def test_fifo_row_files_are_never_read(tmp_path):
    """A FIFO named like a row in ``runs/`` (a foreign one, whose description the refusal quotes, or this
    sweep's own, read on resume) blocked the sweep forever (issue 28): the refusal names the file unread, and a
    resume redoes the row it cannot read. In a process of its own with a timeout: a regression hangs, never passes."""
    src = str(Path(__file__).resolve().parents[1] / "src")
    (tmp_path / "runs").mkdir()
    os.mkfifo(tmp_path / "runs" / "x0.json")
    code = (
        "import sys, types; from pathlib import Path\n"
        "from bioform_mj.core.errors import InputError\n"
        "from bioform_mj.jobs import sweep\n"
        f"out = Path({str(tmp_path)!r})\n"
        "try:\n    sweep.check_same_sweep(out, {'k'})\nexcept InputError as exc:\n    print(exc)\n"
        "said = []\n"
        "row = sweep._read_row(out / 'runs' / 'x0.json', types.SimpleNamespace(key='x0'), said.append)\n"
        "print(row, said)\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": src}, capture_output=True, text=True, timeout=60
    )
    lines = res.stdout.strip().splitlines()
    assert res.returncode == 0 and len(lines) == 2, res.stderr
    assert "holds another sweep's rows: 1 of its 1 rows" in lines[0] and "e.g. 'x0.json'" in lines[0], lines
    said = f"row file '{tmp_path / 'runs' / 'x0.json'}' cannot be read (not a regular file); its run is redone"
    assert lines[1] == f'None ["{said}"]', lines
