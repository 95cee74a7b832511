"""Monte Carlo sweeps: every combination of methods × varied keys × seeds, on a process pool or Ray.

Each run is identified by a key derived from its settings; its result row is written
atomically to ``DIR/runs/<key>.json`` as soon as it finishes, so an interrupted sweep
resumes by skipping keys already there. At the end the rows are collected into
``DIR/runs.csv`` (one row per run: settings, seed, status, metrics) and aggregated per
method into ``DIR/stats.json`` and ``DIR/stats.md``.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .errors import InputError
from .outputs.files import write_json, write_text
from .scenario import load

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


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: scenario source, overrides (``KEY=VALUE`` strings), method, seed."""

    source: str
    overrides: tuple[str, ...]
    method: str
    seed: int
    plant: str | None
    vary: tuple[tuple[str, str], ...]  # the varied (key, raw value) pairs, for the table

    @property
    def key(self) -> str:
        """Stable identifier of the run (its settings hashed), used as file name."""
        text = json.dumps([self.source, self.overrides, self.method, self.seed, self.plant], sort_keys=True)
        return hashlib.sha1(text.encode()).hexdigest()[:16]


def expand(source: str, seeds: int, methods: Sequence[str], vary: Sequence[str], overrides: Sequence[str] = (),
           plant: str | None = None, seed0: int = 0) -> list[RunSpec]:
    """All combinations; ``vary`` items are ``KEY=V1,V2,...`` (values as in ``--set``).

    Arrays in a value list must not contain commas at the top level; use ``;`` to
    separate array values instead (``estimator.phi=[0,0];[0.1,0.1]``).
    """
    if seeds < 1:
        raise InputError(f"--seeds must be >= 1, got {seeds}")
    axes: list[list[tuple[str, str]]] = []
    for item in vary:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip() or not raw.strip():
            raise InputError(f"--vary '{item}': expected KEY=V1,V2,... e.g. kinematic.k1=1,2,3")
        values = raw.split(";") if ";" in raw else raw.split(",")
        axes.append([(key.strip(), v.strip()) for v in values])
    specs = []
    for method in methods:
        for combo in itertools.product(*axes) if axes else [()]:
            ov = tuple(overrides) + tuple(f"{k}={v}" for k, v in combo)
            for s in range(seed0, seed0 + seeds):
                specs.append(RunSpec(source, ov + (f"sim.seed={s}",), method, s, plant, tuple(combo)))
    # validate every distinct configuration up front: bad input fails before any run starts
    seen = set()
    for sp in specs:
        sig = (sp.overrides[:-1], sp.method)
        if sig not in seen:
            seen.add(sig)
            load(sp.source, list(sp.overrides), method=sp.method, plant=sp.plant)
    return specs


def run_one(spec: RunSpec) -> dict[str, Any]:
    """Run one spec; never raises: a failure becomes a row with ``status = failed`` and the error."""
    row: dict[str, Any] = {"key": spec.key, "method": spec.method, "seed": spec.seed}
    row.update({k: v for k, v in spec.vary})
    try:
        from .sim import simulate

        sc = load(spec.source, list(spec.overrides), method=spec.method, plant=spec.plant)
        res = simulate(sc)
        s = res.summary
        row["plant"] = s["plant"]
        row["status"] = "diverged" if res.diverged is not None else "ok"
        row["error"] = s["diverged"]["message"] if res.diverged is not None else ""
        row["sim_time_s"] = s["sim_time_s"]
        row["wall_time_s"] = s["wall_time_s"]
        for m in METRICS:
            vals = np.array([f[m] for f in s["followers"]], dtype=float)
            row[f"{m}_mean"] = float(np.mean(vals))
            row[f"{m}_max"] = float(np.max(vals))
        ch = np.array([f["c_hat_rel_error"] for f in s["followers"]], dtype=float)
        row["c_hat_abs_rel_error_max"] = float(np.max(np.abs(ch)))
    except Exception as exc:  # noqa: BLE001 - a failed run must not sink the sweep
        row["status"] = "failed"
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _load_kernels() -> None:
    """Run both compiled loops for a moment, so that numba's cached machine code is loaded
    in this process (and inherited by forked workers instead of loaded once per worker)."""
    from .scenario import load
    from .sim import simulate

    for plant in ("ideal", "mujoco"):
        simulate(load("paper", plant=plant, overrides=["sim.duration=0.01"]))


def _run_local(todo: list[RunSpec], workers: int, done: Callable[[dict], None]) -> None:
    if workers <= 1:
        for sp in todo:
            done(run_one(sp))
        return
    import concurrent.futures as cf
    import multiprocessing as mp

    if sys.platform.startswith("linux"):
        # fork after loading MuJoCo, numba and the compiled kernels here: workers start in
        # milliseconds instead of ~2 s each (spawn). This process runs no threads of its own
        # at this point (the progress bar has no monitor thread), so fork is safe.
        _load_kernels()

        ctx = mp.get_context("fork")
    else:  # pragma: no cover - macOS/Windows
        ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [pool.submit(run_one, sp) for sp in todo]
        for fut in cf.as_completed(futures):
            done(fut.result())


def _run_ray(todo: list[RunSpec], workers: int, address: str | None, done: Callable[[dict], None]) -> None:
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray needs Ray: pip install 'bioform-mj[ray]'") from None
    started = False
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {"address": address, "include_dashboard": False, "log_to_driver": False}
        if address is None:
            kwargs["num_cpus"] = workers
        ray.init(**kwargs)
        started = True
    try:
        remote = ray.remote(num_cpus=1)(run_one)
        pending = [remote.remote(sp) for sp in todo]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for r in ready:
                done(ray.get(r))
    finally:
        if started:
            ray.shutdown()


def sweep(specs: list[RunSpec], out: Path, backend: str = "local", workers: int | None = None,
          ray_address: str | None = None, progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Run ``specs`` (skipping those already in ``out/runs``), then write the table and statistics."""
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    todo = [sp for sp in specs if not (runs_dir / f"{sp.key}.json").exists()]
    workers = workers or os.cpu_count() or 1
    count = {"n": len(specs) - len(todo)}

    def done(row: dict) -> None:
        write_json(runs_dir / f"{row['key']}.json", row)
        count["n"] += 1
        if progress is not None:
            progress(count["n"], len(specs))

    if progress is not None:
        progress(count["n"], len(specs))
    t0 = time.perf_counter()
    if backend == "local":
        _run_local(todo, workers, done)
    elif backend == "ray":
        _run_ray(todo, workers, ray_address, done)
    else:
        raise InputError(f"unknown backend '{backend}' (expected local or ray)")
    wall = time.perf_counter() - t0
    rows = [json.loads((runs_dir / f"{sp.key}.json").read_text()) for sp in specs]
    timing = {"backend": backend, "workers": workers, "ran": len(todo), "skipped": len(specs) - len(todo),
              "wall_s": wall, "runs_per_s": len(todo) / wall if todo and wall > 0 else None}
    write_json(out / "sweep.json", timing)
    write_text(out / "runs.csv", to_csv(rows))
    stats = aggregate(rows)
    write_json(out / "stats.json", stats)
    write_text(out / "stats.md", stats_markdown(stats))
    return {"rows": rows, "stats": stats, "ran": len(todo), "skipped": len(specs) - len(todo), "timing": timing}


def to_csv(rows: list[dict[str, Any]]) -> str:
    """Rows → CSV text with the union of their columns (pandas/polars ``read_csv`` open it)."""
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in cols})
    return buf.getvalue()


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per method: run counts by status and mean/std/p5/p50/p95 of every metric column over ok runs."""
    out: dict[str, Any] = {}
    for method in sorted({r["method"] for r in rows}):
        rs = [r for r in rows if r["method"] == method]
        ok = [r for r in rs if r.get("status") == "ok"]
        entry: dict[str, Any] = {"runs": len(rs), "ok": len(ok), "diverged": sum(r.get("status") == "diverged" for r in rs),
                                 "failed": sum(r.get("status") == "failed" for r in rs), "metrics": {}}
        cols = [c for c in (ok[0] if ok else {}) if c.endswith(("_mean", "_max"))]
        for c in cols:
            v = np.array([r[c] for r in ok], dtype=float)
            entry["metrics"][c] = {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
                                   "p5": float(np.percentile(v, 5)), "p50": float(np.percentile(v, 50)),
                                   "p95": float(np.percentile(v, 95))}
        out[method] = entry
    return out


def stats_markdown(stats: dict[str, Any]) -> str:
    """The headline statistics as a Markdown table."""
    lines = ["| method | runs (ok/diverged/failed) | total velocity error, mean ± std | final formation error max [m], p50 (p95) |",
             "|---|---|---|---|"]
    for m, e in stats.items():
        tv = e["metrics"].get("total_velocity_error_mean")
        fe = e["metrics"].get("final_formation_error_m_max")
        tv_s = f"{tv['mean']:.3g} ± {tv['std']:.2g}" if tv else "–"
        fe_s = f"{fe['p50']:.3g} ({fe['p95']:.3g})" if fe else "–"
        lines.append(f"| {m} | {e['runs']} ({e['ok']}/{e['diverged']}/{e['failed']}) | {tv_s} | {fe_s} |")
    return "\n".join(lines) + "\n"
