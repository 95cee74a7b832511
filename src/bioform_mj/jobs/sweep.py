"""Monte Carlo sweeps: every combination of methods × varied keys × seeds, on forked workers or Ray.

Each run is identified by a key hashed from the *content* of its resolved scenario
(``Scenario.to_dict()`` as canonical JSON), not from the scenario's file path or the
``--set``/``--vary`` strings: an edited scenario runs again, ``k=1`` and ``k=1.0`` are one run.
Its result row is written atomically to ``DIR/runs/<key>.json`` as soon as it finishes, with
its provenance (package version, source hash, MuJoCo version, every robot file it loaded:
:mod:`bioform_mj.jobs.provenance`), so an interrupted sweep resumes by skipping keys already there
whose provenance still matches; a stale row is redone (``resume: N row(s) redone (why)`` on
stderr), a row file that cannot be read is reported (``warning:`` on stderr) and its run redone.
One sweep per folder at a time (a lock); design §16. With ``rosbag`` (``bioform sweep … --rosbag``) each
run is also written as a ROS 2 bag, ``DIR/bags/<key>/`` (:func:`bioform_mj.outputs.rosbag.write_bag`: built
under a temporary name and renamed when complete), before its row: a row is reused only where its bag is
there, and the temporary folders an interrupted or killed run left are removed when the sweep (re)starts, so
every bag is complete or absent. At the end the rows
are collected into ``DIR/runs.csv`` (one row per run: settings, seed, status, outcome,
metrics; the same rows as Parquet in ``DIR/runs.parquet``) and aggregated per group, method ×
every ``--vary`` value, into ``DIR/stats.json`` and ``DIR/stats.md``.

Processes (``backend="local"``): with more than one worker, every run is a process forked
from this one after it has loaded the compiled kernels, so a worker starts in milliseconds
with the kernels in memory. A worker that dies (SIGKILL, the OOM killer) fails only its
own row (``status = failed``, the reason in ``error``, ``worker_died = true``; a resume runs
it again) and the sweep goes on. SIGINT/SIGTERM stop the sweep: running workers are
terminated (SIGTERM, then SIGKILL after a grace period; they also die with the sweep via
``PR_SET_PDEATHSIG`` if it is killed), finished rows are kept, the tables are written for
them and :class:`SweepInterrupted` is raised. One worker (and, off Linux, every sweep) runs in
this process, where a signal abandons the run in progress. The runner is :mod:`bioform_mj.jobs.runner`
(shared with ``calibrate``); Ray is :mod:`bioform_mj.jobs.ray_backend` (a lost head raises
:class:`SweepFailed` after the tables are written).
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import hashlib
import io
import itertools
import json
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.core.errors import BioformError, InputError, quiet_outcomes
from bioform_mj.jobs.ray_backend import check_ray_address
from bioform_mj.jobs.runner import Signals as _Signals
from bioform_mj.jobs.runner import Stop as _Stop
from bioform_mj.jobs.runner import check_workers
from bioform_mj.jobs.runner import raising as _raising
from bioform_mj.jobs.runner import run_local as _run_local
from bioform_mj.outputs.files import rows_to_arrow, write_json, write_parquet, write_text
from bioform_mj.scenario.config import Scenario
from bioform_mj.scenario.loader import load, mark_checked

#: Per-follower metrics of ``summary.json`` that a sweep row carries (mean and max over followers).
METRICS = (
    "total_velocity_error",
    "final_formation_error_m",
    "rms_formation_error_m",
    "final_estimation_error_m",
    "max_abs_v_cmd",
    "peak_abs_torque",
    "saturation_fraction",
)


class SweepFailed(BioformError):
    """The sweep could not go on (its Ray head was lost); the tables cover the finished rows (exit 1)."""


class SweepInterrupted(BioformError):
    """SIGINT/SIGTERM stopped the sweep; finished rows are kept (``done`` of ``total``)."""

    def __init__(self, signum: int, done: int, total: int) -> None:
        self.signum, self.done, self.total = signum, done, total
        super().__init__(f"interrupted ({signal.Signals(signum).name}): {done} of {total} runs done")


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: scenario source, overrides (``KEY=VALUE`` strings), method, seed.

    :func:`expand` also sets ``scenario`` (the resolved scenario the run uses) and ``digest``
    (its content hash, the run's key); a spec made without them loads its scenario when it
    runs and is keyed by its settings.
    """

    source: str
    overrides: tuple[str, ...]
    method: str
    seed: int
    plant: str | None
    vary: tuple[tuple[str, str], ...]  # the varied (key, raw value) pairs, for the table
    digest: str = ""
    scenario: Scenario | None = field(default=None, compare=False, hash=False, repr=False)
    #: :func:`~bioform_mj.jobs.provenance.provenance` of the scenario: code and robot files the run depends on
    provenance: dict | None = field(default=None, compare=False, hash=False, repr=False)

    @property
    def key(self) -> str:
        """Stable identifier of the run, used as file name: the content hash when known."""
        if self.digest:
            return self.digest
        text = json.dumps([self.source, self.overrides, self.method, self.seed, self.plant], sort_keys=True)
        return hashlib.sha1(text.encode()).hexdigest()[:16]


def content_key(sc: Scenario, overrides: Sequence[str] = ()) -> str:
    """The run's key: a hash of its resolved configuration (``Scenario.to_dict()``, every value the
    overrides set included, so ``k=1`` and ``k=1.0`` are one run). What the result also depends on,
    the code and the robot files, is the row's ``provenance``, checked on resume (design §16).
    ``overrides`` is accepted for compatibility and not hashed: the resolved scenario holds its effect."""
    return seed_key(config_text(sc), sc.sim.seed)


def config_text(sc: Scenario) -> str:
    """Canonical JSON of the resolved scenario without ``sim.seed`` (~0.5 ms: computed once per configuration)."""
    d = sc.to_dict()
    d["sim"].pop("seed", None)
    return json.dumps({"scenario": d}, sort_keys=True, separators=(",", ":"), default=repr)


def seed_key(text: str, seed: int) -> str:
    """The key of the run of configuration ``text`` (:func:`config_text`) with seed ``seed`` (~1 µs)."""
    return hashlib.sha1(f"{text}\0seed={int(seed)}".encode()).hexdigest()[:16]


#: estimated bytes of one expanded run (its RunSpec with the resolved scenario, ~30 kB measured with
#: tracemalloc for the paper scenario, and its row, ~2 kB), with margin
SPEC_BYTES = 60e3


def randomness(sc: Scenario) -> list[str]:
    """The scenario keys through which ``sim.seed`` changes a run (empty: every seed gives the same run).

    The seed draws the initial-pose jitter, the random obstacle field (design §19), the gyro's noise under
    odometry sensing (design §8.3) and, inside the fault window, sensor noise and packet loss.
    """
    out = []
    if sc.formation.init_jitter > 0 or sc.formation.init_jitter_heading > 0:
        out.append("formation.init_jitter")
    if sc.obstacle_field.count > 0:
        out.append("obstacle_field")
    if sc.plant.kind == "mujoco" and sc.plant.sensing == "odometry" and sc.plant.gyro_noise > 0:
        out.append("plant.gyro_noise")
    f = sc.faults
    w0, w1 = f.window if f.window else (-np.inf, np.inf)
    if w0 < min(w1, sc.sim.duration):  # the noise/loss window overlaps the run
        if f.packet_loss > 0:
            out.append("faults.packet_loss")
        if any(v > 0 for v in f.noise_pose):
            out.append("faults.noise_pose")
        if any(v > 0 for v in f.noise_vel):
            out.append("faults.noise_vel")
    return out


def _warn(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr, flush=True)


#: configurations loaded before a sweep of many says how long checking the rest takes (trust4: 15,000 values were
#: checked for minutes in silence, ~15 ms each)
CHECK_SAMPLE = 10


def expand(
    source: str,
    seeds: int,
    methods: Sequence[str],
    vary: Sequence[str],
    overrides: Sequence[str] = (),
    plant: str | None = None,
    seed0: int = 0,
    warn: Callable[[str], None] | None = _warn,
) -> list[RunSpec]:
    """All combinations; ``vary`` items are ``KEY=V1,V2,...`` (values as in ``--set``).

    Arrays in a value list must not contain commas at the top level; use ``;`` to
    separate array values instead (``estimator.phi=[0,0];[0.1,0.1]``). Every configuration
    is loaded and validated here, so bad input fails before any run starts. ``warn`` is
    told when ``seeds > 1`` is asked of configurations that have no randomness.
    """
    if seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {seeds}")
    axes: list[list[tuple[str, str]]] = []
    given: dict[str, str] = {}
    set_keys = {o.partition("=")[0].strip() for o in overrides}
    dropped = 0
    for item in vary:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key or not raw.strip():
            raise InputError(f"--vary '{item}': expected KEY=V1,V2,... e.g. kinematic.k1=1,2,3")
        if key == "method":  # load(method=...) would override it: every run the same, silently
            raise InputError(
                f"--vary '{item}': a sweep's methods come from --methods (e.g. --methods backstepping,bioinspired)"
            )
        if key in given:  # the later list would silently replace the earlier one (design §16)
            raise InputError(
                f"--vary {key} given twice ('{given[key]}' and '{item}'): give one list of values, "
                f"e.g. --vary {key}={given[key].partition('=')[2]},{raw}"
            )
        if key == "sim.seed":  # each run's seed is set from --seed/--seeds: a varied one would be overwritten
            raise InputError("--vary sim.seed: the seeds are --seed S (the first) and --seeds K (how many)")
        if key in set_keys:
            raise InputError(f"--vary {key} and --set {key} both given: the --set value would be ignored")
        given[key] = item
        values = [v.strip() for v in (raw.split(";") if ";" in raw else raw.split(","))]
        uniq = list(dict.fromkeys(values))  # the same text twice: one value
        dropped += len(values) - len(uniq)
        axes.append([(key, v) for v in uniq])
    n_runs = len(methods) * seeds * int(np.prod([len(a) for a in axes])) if axes else len(methods) * seeds
    from bioform_mj.core.budget import fmt_bytes, require

    require(
        n_runs * SPEC_BYTES,
        f"a sweep of {n_runs} runs ({fmt_bytes(SPEC_BYTES)} per run for its configuration and row)",
        "split it (fewer --seeds or --vary values)",
    )
    specs = []
    no_random: list[str] = []
    n_configs = 0
    seen_cfg: dict[str, tuple] = {}  # configuration key (at seed0) -> the combo that has it
    same: list[str] = []
    prov_cache: dict[str, dict] = {}
    n_total, t0, checked = n_runs // seeds, time.monotonic(), 0  # many configurations: say so, with a measured rate
    for method in methods:
        for combo in itertools.product(*axes) if axes else [()]:
            checked += 1
            if checked == CHECK_SAMPLE + 1 and n_total >= 10 * CHECK_SAMPLE and warn is not None:
                left = (time.monotonic() - t0) / CHECK_SAMPLE * (n_total - CHECK_SAMPLE)
                # two significant digits under 0.1 s (fast checks read "0.0 s" and the test said so, at 2 ms each)
                more = f"{left:.1f}" if left >= 0.1 else f"{left:.2g}"
                note = f"checking {n_total} configurations before any run: about {more} s more"
                print(f"note: {note} (measured on the first {CHECK_SAMPLE})", file=sys.stderr, flush=True)
            ov = tuple(overrides) + tuple(f"{k}={v}" for k, v in combo)
            base = load(source, list(ov) + [f"sim.seed={seed0}"], method=method, plant=plant)
            text = config_text(base)
            cfg = seed_key(text, seed0)
            if cfg in seen_cfg:  # e.g. k=1 and k=1.0: the same runs, done and counted once
                first = seen_cfg[cfg]
                diff = [f"{k}={v}" for (k, v), (_, v0) in zip(combo, first) if v != v0]
                was = [f"{k}={v0}" for (k, v), (_, v0) in zip(combo, first) if v != v0]
                same.append(f"{', '.join(diff)} is {', '.join(was)}")
                continue
            seen_cfg[cfg] = combo
            n_configs += 1
            if not randomness(base):
                no_random.append(", ".join([method] + [f"{k}={v}" for k, v in combo]))
            pk = json.dumps([base.plant.kind, base.to_dict()["plant"]["robots"]], default=repr)
            if pk not in prov_cache:
                from bioform_mj.jobs.provenance import provenance

                prov_cache[pk] = provenance(base)
            for s in range(seed0, seed0 + seeds):
                # the seed is the only difference between a configuration's runs (seed0 was validated)
                sc = mark_checked(dataclasses.replace(base, sim=dataclasses.replace(base.sim, seed=s)))
                run_ov = ov + (f"sim.seed={s}",)
                label = tuple((k, unquote(v)) for k, v in combo)  # design §17: '"backstepping"' labelled backstepping
                specs.append(RunSpec(source, run_ov, method, s, plant, label, seed_key(text, s), sc, prov_cache[pk]))
    if (dropped or same) and warn is not None:
        ex = "; ".join(dict.fromkeys(same))
        note = f"{dropped} repeated value(s) in --vary" if dropped else ""
        if same:
            note += ("; " if note else "") + f"equal values give the same runs ({ex[:300]})"
        print(f"note: {note}: each distinct run is done and counted once ({len(specs)} runs)", file=sys.stderr)
    if seeds > 1 and no_random and warn is not None:
        if len(no_random) == n_configs:
            which, its = "the scenario has", "its"
        else:
            more = "; …" if len(no_random) > 3 else ""
            which = f"{len(no_random)} of {n_configs} configurations ({'; '.join(no_random[:3])}{more}) have"
            its = "their"
        warn(
            f"--seeds {seeds}: {which} no randomness (no formation.init_jitter, obstacle_field, plant.gyro_noise, "
            f"faults.noise_pose/noise_vel or faults.packet_loss), so {its} {seeds} seeds give identical runs"
        )
    return specs


def unquote(value: str) -> str:
    """A ``--vary`` value as its label: one pair of matching outer quotes removed (``'"a"'`` → ``a``),
    as TOML reads a quoted string; anything else unchanged."""
    v = value.strip()
    if len(v) >= 2 and v[0] == v[-1] and v[0] in "\"'":
        return v[1:-1]
    return v


# ------------------------------------------------------------------------------------------
# One run


def _base_row(spec: RunSpec) -> dict[str, Any]:
    row: dict[str, Any] = {"key": spec.key, "method": spec.method, "seed": spec.seed}
    row.update({k: v for k, v in spec.vary})
    if spec.provenance is not None:
        row["provenance"] = spec.provenance
    return row


def run_one(spec: RunSpec, bags: Path | None = None, distro: str | None = None) -> dict[str, Any]:
    """Run one spec; never raises: a failure becomes a row with ``status = failed`` and the error.
    ``bags``: also write the run as the ROS 2 bag ``bags/<key>`` (``distro``'s messages; row ``rosbag``:
    its path relative to the sweep folder, ``rosbag_write_s``: seconds)."""
    row = _base_row(spec)
    try:
        from bioform_mj.run.simulate import simulate

        sc = (
            spec.scenario
            if spec.scenario is not None
            else load(spec.source, list(spec.overrides), method=spec.method, plant=spec.plant)
        )
        if "provenance" not in row:
            from bioform_mj.jobs.provenance import provenance

            row["provenance"] = provenance(sc)
        with quiet_outcomes():  # the row tabulates the outcomes: no warning per run (design §18.1)
            res = simulate(sc, full_state=bags is not None)
        s = res.summary
        row["plant"] = s["plant"]
        div = s.get("diverged")
        row["status"] = "diverged" if div is not None else "ok"
        row["error"] = div["message"] if div is not None else ""
        row["diverged_at_s"] = div["time_s"] if div is not None else None
        from bioform_mj.assess.outcomes import outcome_kinds

        fo = [f.get("outcome") for f in s["followers"]]
        if all(o is not None for o in fo):  # every outcome of each follower: "ok;lost+slipping;ok" (design §14)
            row["follower_outcomes"] = ";".join("+".join(outcome_kinds(f)) or "ok" for f in s["followers"])
        bad = sorted({k for f in s["followers"] for k in outcome_kinds(f)})
        row["outcome"] = "diverged" if div is not None else (",".join(bad) if bad else "ok")
        rc = s.get("robot_check")  # design §14.2: what robot check fails the robots for (once per robot)
        if rc is not None:
            row["robot_check"] = (
                "skipped"
                if rc["skipped"]
                else " | ".join(
                    r["verdict"] + (": " + "; ".join(r["fail_reasons"]) if r["fail_reasons"] else "")
                    for r in rc["robots"]
                )
            )
        row["sim_time_s"] = s["sim_time_s"]
        row["wall_time_s"] = s["wall_time_s"]
        for m in METRICS:
            vals = np.array([f[m] for f in s["followers"]], dtype=float)
            row[f"{m}_mean"] = float(np.mean(vals))
            row[f"{m}_max"] = float(np.max(vals))
        ch = np.array([f["c_hat_rel_error"] for f in s["followers"]], dtype=float)
        row["c_hat_abs_rel_error_max"] = float(np.max(np.abs(ch)))
        _contact_columns(row, s["followers"])
        if bags is not None:
            from bioform_mj.outputs.rosbag import DEFAULT_DISTRO, write_bag

            info = write_bag(res, bags / spec.key, distro=distro or DEFAULT_DISTRO, overwrite=True)
            row["rosbag"] = f"{bags.name}/{spec.key}"
            row["rosbag_write_s"] = info.write_s
    except Exception as exc:  # noqa: BLE001 - a failed run must not sink the sweep
        row["status"] = "failed"
        row["outcome"] = "failed"
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _contact_columns(row: dict[str, Any], followers: list[dict[str, Any]]) -> None:
    """Design §19 (MuJoCo runs): ``min_separation_m`` (the least over followers; empty when no robot
    came within range), ``collisions`` (contact events with robots and obstacles, summed over
    followers: a robot–robot touch counts for both) and ``collided`` (followers that touched)."""
    if not followers or "robot_contacts" not in followers[0]:
        return
    seps = [f["min_separation_m"] for f in followers if f.get("min_separation_m") is not None]
    row["min_separation_m"] = float(min(seps)) if seps else None
    row["collisions"] = int(sum(f["robot_contacts"] + f["obstacle_contacts"] for f in followers))
    row["collided"] = int(sum(1 for f in followers if f["robot_contacts"] + f["obstacle_contacts"] > 0))


def _died_row(spec: RunSpec, reason: str) -> dict[str, Any]:
    """The row of a run whose worker process died; a resume runs it again."""
    row = _base_row(spec)
    row.update(status="failed", outcome="failed", error=f"worker died: {reason}", worker_died=True)
    return row


# ------------------------------------------------------------------------------------------
# The sweep


def _read_row(
    path: Path, spec: RunSpec, warn: Callable[[str], None] | None, redo: Callable[[dict], str | None] | None = None
) -> dict[str, Any] | None:
    """A finished row from an earlier invocation, or None when the run must be done (again):
    missing, unreadable or damaged, its worker died, or ``redo(row)`` gives a reason (said on stderr)."""
    from bioform_mj.robots.sanity import not_regular  # a FIFO named like a row hung the resume (issue 28)

    try:
        if not_regular(path):
            raise OSError(0, "not a regular file")
        text = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        problem = f"cannot be read ({exc.strerror or exc})"
    else:
        try:
            row = json.loads(text)
        except ValueError as exc:
            problem = f"is damaged ({exc})"
        else:
            if isinstance(row, dict) and row.get("key") == spec.key and "status" in row:
                if row.get("worker_died"):
                    return None
                why = redo(row) if redo is not None else None
                if why is None:
                    return row
                if warn is not None:
                    warn(f"row file '{path}': {why}; its run is redone")
                return None
            problem = "is damaged (not a row of this run)"
    if warn is not None:
        warn(f"row file '{path}' {problem}; its run is redone")
    return None


def _run_warp(
    todo: list[RunSpec], groups: Any, device: str, sig: _Signals, done: Callable[[dict], None], capacity: dict
) -> None:
    """The runs as worlds of MuJoCo Warp batches (:mod:`bioform_mj.batch.backend`), one batch per scene;
    ``capacity``: ``nconmax``/``njmax`` per world (None: the batch engine's defaults)."""
    from bioform_mj.batch.backend import run_warp

    def failed(sp: RunSpec, msg: str) -> dict[str, Any]:
        return {**_base_row(sp), "status": "failed", "outcome": "failed", "error": msg}

    try:
        with _raising(sig):
            run_warp(
                groups,
                device,
                _base_row,
                METRICS,
                done,
                stop=lambda: sig.signum is not None,
                failed_row=failed,
                **capacity,
            )
    except _Stop:
        return


def sweep(
    specs: list[RunSpec],
    out: Path,
    backend: str = "local",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    warn: Callable[[str], None] | None = _warn,
    device: str | None = None,
    nconmax: int | None = None,
    njmax: int | None = None,
    note: Callable[[str], None] | None = None,
    rosbag: str | None = None,
) -> dict[str, Any]:
    """Run ``specs`` (skipping those already in ``out/runs``), then write the table and statistics.
    ``rosbag``: a ROS 2 distribution (:data:`bioform_mj.outputs.rosbag.DISTROS`): every run is also
    written as the bag ``out/bags/<key>`` (module docstring); None: no bags.

    ``backend="warp"`` runs them as worlds of MuJoCo Warp batches on ``device`` (default: the
    GPU if there is one); every spec is checked first (feature support, device memory); ``nconmax``,
    ``njmax``: MuJoCo Warp's contact / constraint-row capacity per world (None: the defaults).
    Raises :class:`SweepInterrupted` after SIGINT/SIGTERM, with the finished rows kept and
    the tables written for them. A finished row is reused when its key (the resolved configuration)
    and its provenance (code, versions, robot files) match; otherwise it is redone and a
    ``resume: N row(s) redone (why)`` line said on stderr. One sweep per folder: a second one
    raises :class:`~bioform_mj.outputs.rundir.FolderBusy` (exit 2). ``note(text)`` is told the
    run count and an estimated duration before any run starts.
    """
    if backend not in ("local", "ray", "warp"):
        raise InputError(f"unknown backend '{backend}' (expected local, ray or warp)")
    check_workers(workers, backend == "local" or not ray_address)  # forked, or a local Ray of `workers` CPUs
    if backend == "warp":
        from bioform_mj.batch.backend import require_warp, resolve_device

        require_warp()
        device = resolve_device(device)
    from bioform_mj.outputs.rundir import check_sweep_dir, folder_lock

    if backend == "ray":  # a closed address: exit 2 in seconds, before anything is written
        check_ray_address(ray_address)
    out = Path(out)
    if rosbag is not None:
        from bioform_mj.jobs.sweepbags import check_bags

        check_bags(specs, out, backend, rosbag)
    check_sweep_dir(out)
    out.mkdir(parents=True, exist_ok=True)
    with folder_lock(out, "sweep directory", "running a sweep there"):  # one sweep per folder (exit 2)
        return _sweep_locked(
            specs, out, backend, workers, ray_address, progress, warn, device, nconmax, njmax, note, rosbag
        )


def check_same_sweep(out: Path, keys: set[str]) -> None:
    """InputError (exit 2) when ``out/runs`` holds rows that are no run of this sweep (``keys``): another
    sweep's (a different configuration, method or seed), whose statistics this one would overwrite. A
    resume, or the same sweep with more runs (more seeds, another value), passes (design §16)."""
    runs_dir = out / "runs"
    try:
        names = [n for n in os.listdir(runs_dir) if n.endswith(".json") and not n.startswith(".")]
    except (FileNotFoundError, NotADirectoryError):
        return
    foreign = sorted(n[: -len(".json")] for n in names if n[: -len(".json")] not in keys)
    if not foreign:
        return
    desc = ""
    from bioform_mj.robots.sanity import not_regular

    try:  # what the first of them was, for the message (a damaged file, a FIFO: said as such, never read)
        first = runs_dir / f"{foreign[0]}.json"
        if not_regular(first):
            raise OSError(0, "not a regular file")
        with open(first, "rb") as fh:
            row = json.loads(fh.read(1 << 20))
        labels = {k: v for k, v in row.items() if k not in ("key", "provenance") and not isinstance(v, (dict, list))}
        shown = ["method", "seed", *(k for k in labels if "." in k)]
        desc = ", e.g. " + ", ".join(f"{k}={labels[k]}" for k in shown if k in labels)
    except (OSError, ValueError, AttributeError):
        desc = f", e.g. '{foreign[0]}.json'"
    raise InputError(
        f"sweep directory '{out}' holds another sweep's rows: {len(foreign)} of its {len(names)} rows are no run "
        f"of this sweep{desc} (a different configuration, method or seed; its statistics would be overwritten). "
        f"To resume that sweep, rerun its own command; to run this one, choose another --out (or remove '{out}'); "
        "the same command whose resolved configuration changed since (another version's defaults) counts as another"
    )


#: estimated cost of a run on one core (design §16): µs per follower and control step, and seconds
#: of setup per run; measured on the development machine (paper / large16 presets, compiled loop:
#: ideal 0.4-0.9 µs, MuJoCo 8-11 µs, 5 / 70 ms setup). The ETA printed before a sweep uses them.
COST_US_PER_ROBOT_STEP = {"ideal": 1.0, "mujoco": 12.0}
COST_SETUP_S = {"ideal": 0.01, "mujoco": 0.1}


def estimate_seconds(specs: Sequence[RunSpec]) -> float:
    """Estimated single-core seconds of ``specs`` (:data:`COST_US_PER_ROBOT_STEP`, :data:`COST_SETUP_S`)."""
    total = 0.0
    for sp in specs:
        sc = sp.scenario
        if sc is None:
            continue
        kind = sc.plant.kind if sc.plant.kind in COST_SETUP_S else "mujoco"
        steps = sc.sim.duration / sc.sim.control_dt
        total += COST_SETUP_S[kind] + steps * sc.n * COST_US_PER_ROBOT_STEP[kind] * 1e-6
    return total


def _stale(row: dict[str, Any], sp: RunSpec, backend: str, nconmax: int | None, njmax: int | None) -> list[str]:
    """Why a finished row must be redone under this sweep (empty: keep it)."""
    from bioform_mj.batch.backend import capacity_redo

    why = capacity_redo(row, backend, nconmax, njmax)
    if why is not None:
        return [why]
    was = "warp" if row.get("backend") == "warp" else "local"
    now = "warp" if backend == "warp" else "local"
    if was != now:  # float32 MuJoCo Warp and C MuJoCo give different numbers (design §11)
        return [f"it ran on the {was} engine, this sweep runs the {now} one"]
    if sp.provenance is None:
        return []
    from bioform_mj.jobs.provenance import differences

    return differences(row.get("provenance"), sp.provenance)


def _sweep_locked(
    specs: list[RunSpec],
    out: Path,
    backend: str,
    workers: int | None,
    ray_address: str | None,
    progress: Callable[[int, int], None] | None,
    warn: Callable[[str], None] | None,
    device: str | None,
    nconmax: int | None,
    njmax: int | None,
    note: Callable[[str], None] | None,
    rosbag: str | None = None,
) -> dict[str, Any]:
    from bioform_mj.jobs.sweepbags import clean_bags

    runs_dir = out / "runs"
    bags = out / "bags" if rosbag is not None else None
    if bags is not None and (n_left := clean_bags(bags)):
        print(f"resume: {n_left} half-written bag(s) of an interrupted run removed", file=sys.stderr, flush=True)
    rows: dict[str, dict[str, Any]] = {}
    todo: list[RunSpec] = []
    keys = list(dict.fromkeys(sp.key for sp in specs))  # identical runs (same content) run once
    check_same_sweep(out, set(keys))  # another sweep's rows: refused, saying how to proceed (design §16)
    seen: set[str] = set()
    redone: dict[str, int] = {}
    for sp in specs:
        if sp.key in seen:
            continue
        seen.add(sp.key)
        row = _read_row(runs_dir / f"{sp.key}.json", sp, warn)
        why = _stale(row, sp, backend, nconmax, njmax) if row is not None else []
        if row is not None and bags is not None and not (bags / sp.key / "metadata.yaml").is_file():
            why.append("its bag is missing (--rosbag)")
        if why:
            reason = "; ".join(why[:3]) + (f"; and {len(why) - 3} more" if len(why) > 3 else "")
            redone[reason] = redone.get(reason, 0) + 1
            row = None
        if row is None:
            todo.append(sp)
        else:
            # the row's labels are this sweep's: its content key says the run is the same, whatever
            # sweep (--set or --vary) produced it (design §16)
            row.update({k: v for k, v in sp.vary})
            rows[sp.key] = row
    for reason, k in redone.items():
        print(f"resume: {k} row(s) redone ({reason})", file=sys.stderr, flush=True)
    groups = None
    if backend == "warp":
        from bioform_mj.batch.backend import plan

        # InputError before any work: unsupported feature, memory
        groups = plan(todo, device, nconmax=nconmax, njmax=njmax)
        workers = 1
    runs_dir.mkdir(parents=True, exist_ok=True)
    workers = workers or os.cpu_count() or 1
    skipped = len(rows)
    if note is not None:
        eta = ""
        if todo and backend != "warp":
            from bioform_mj.core.budget import fmt_seconds

            est = estimate_seconds(todo) / max(1, min(workers, len(todo)))
            eta = f"; estimated {fmt_seconds(est)} (a cost model of the compiled loop, not a measurement)"
        note(f"sweep: {len(keys)} runs ({skipped} already done, {len(todo)} to run) on {workers} worker(s){eta}")

    def done(row: dict) -> None:
        write_json(runs_dir / f"{row['key']}.json", row)
        rows[row["key"]] = row
        if progress is not None:
            progress(len(rows), len(keys))

    if progress is not None:
        progress(len(rows), len(keys))
    t0 = time.perf_counter()
    failure: str | None = None
    if bags is not None:
        bags.mkdir(parents=True, exist_ok=True)
    one = functools.partial(run_one, bags=bags, distro=rosbag) if bags is not None else run_one
    with _Signals() as sig:
        if backend == "local":
            _run_local(todo, workers, sig, done, fn=one, died=_died_row)
        elif backend == "warp":
            _run_warp(todo, groups, device, sig, done, {"nconmax": nconmax, "njmax": njmax})
        else:
            from bioform_mj.jobs.ray_backend import run_ray

            def failed(sp: RunSpec, msg: str) -> dict[str, Any]:
                return {**_base_row(sp), "status": "failed", "outcome": "failed", "error": msg}

            failure = run_ray(todo, workers, ray_address, sig, done, one, _died_row, failed)
        wall = time.perf_counter() - t0
        if bags is not None:  # a worker stopped mid-write leaves its temporary folder: no half bag stays
            clean_bags(bags)
        ran = len(rows) - skipped
        interrupted = sig.signum
        # the tables are written before the handlers are restored: a second signal cannot cut them short
        got = [rows[k] for k in keys if k in rows]
        group_by = ["method"] + list(dict.fromkeys(k for sp in specs for k, _ in sp.vary))
        timing = {
            "backend": backend,
            "workers": workers,
            **({"device": device} if backend == "warp" else {}),
            "ran": ran,
            "skipped": skipped,
            "wall_s": wall,
            "runs_per_s": ran / wall if ran and wall > 0 else None,
            "runs": len(keys),
            "done": len(got),
            "complete": len(got) == len(keys),
            "interrupted": None if interrupted is None else signal.Signals(interrupted).name,
            "workers_died": sum(1 for r in got if r.get("worker_died")),
            "rosbag": rosbag,
        }
        write_json(out / "sweep.json", timing)
        write_text(out / "runs.csv", to_csv(got))
        write_parquet(
            out / "runs.parquet", rows_to_arrow([{k: v for k, v in r.items() if k not in _NOT_IN_CSV} for r in got])
        )
        stats = aggregate(got, group_by)
        write_json(out / "stats.json", stats)
        note = (
            ""
            if len(got) == len(keys)
            else f"\n**Incomplete: {len(got)} of {len(keys)} runs done** (rerun the sweep to resume).\n"
        )
        write_text(out / "stats.md", stats_markdown(stats) + note)
    if interrupted is not None:
        raise SweepInterrupted(interrupted, len(got), len(keys))
    if failure is not None:
        raise SweepFailed(
            f"{failure} after {len(got)} of {len(keys)} runs: runs.csv and the statistics cover the finished "
            f"rows (kept in {out}/runs/); rerun the same command to resume"
        )
    return {"rows": got, "stats": stats, "ran": ran, "skipped": skipped, "timing": timing}


#: row fields kept in the row files only (nested records, not table cells)
_NOT_IN_CSV = ("provenance",)


def to_csv(rows: list[dict[str, Any]]) -> str:
    """Rows → CSV text with the union of their columns (pandas/polars ``read_csv`` open it)."""
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols and c not in _NOT_IN_CSV]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: "" if r.get(c) is None else r.get(c) for c in cols})
    return buf.getvalue()


def aggregate(rows: list[dict[str, Any]], group_by: Sequence[str] = ("method",)) -> dict[str, Any]:
    """Per group (one per distinct value of ``group_by``, e.g. method and every varied key): run counts
    by status and by outcome, and mean/std/p5/p50/p95 of every metric column over runs that finished
    (``status = ok``, whatever their outcome)."""
    group_by = list(group_by)
    order: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        order.setdefault(tuple(str(r.get(k, "")) for k in group_by), []).append(r)
    groups = []
    for gkey, rs in order.items():
        ok = [r for r in rs if r.get("status") == "ok"]
        outcomes: dict[str, int] = {}
        for r in rs:
            o = r.get("outcome") or r.get("status", "?")
            outcomes[o] = outcomes.get(o, 0) + 1
        entry: dict[str, Any] = dict(zip(group_by, gkey))
        entry.update(
            {
                "runs": len(rs),
                "ok": len(ok),
                "diverged": sum(r.get("status") == "diverged" for r in rs),
                "failed": sum(r.get("status") == "failed" for r in rs),
                "outcomes": outcomes,
                "metrics": {},
            }
        )
        cols = [c for c in (ok[0] if ok else {}) if c.endswith(("_mean", "_max"))]
        for c in cols:
            v = np.array([r[c] for r in ok], dtype=float)
            entry["metrics"][c] = {
                "mean": float(v.mean()),
                "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
                "p5": float(np.percentile(v, 5)),
                "p50": float(np.percentile(v, 50)),
                "p95": float(np.percentile(v, 95)),
            }
        groups.append(entry)
    return {"group_by": group_by, "groups": groups}


def stats_markdown(stats: dict[str, Any]) -> str:
    """The headline statistics as a Markdown table, one row per group."""
    gb = stats["group_by"]
    head = [
        *gb,
        "runs (ok/diverged/failed)",
        "outcomes",
        "total velocity error, mean ± std",
        "final formation error max [m], p50 (p95)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for e in stats["groups"]:
        tv = e["metrics"].get("total_velocity_error_mean")
        fe = e["metrics"].get("final_formation_error_m_max")
        tv_s = f"{tv['mean']:.3g} ± {tv['std']:.2g}" if tv else "–"
        fe_s = f"{fe['p50']:.3g} ({fe['p95']:.3g})" if fe else "–"
        oc = ", ".join(f"{k} {v}" for k, v in sorted(e["outcomes"].items(), key=lambda kv: (kv[0] != "ok", kv[0])))
        cells = [str(e[k]) for k in gb] + [f"{e['runs']} ({e['ok']}/{e['diverged']}/{e['failed']})", oc, tv_s, fe_s]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
