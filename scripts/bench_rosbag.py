"""What `bioform run --rosbag` costs at the paper scenario against the run's stepping time (issue 29:
at most 20 %): the stepping without and with the 3-D sampling, the one-time warm-up that
``bioform run --rosbag`` does before the run (imports, rosbags' type store), the first write and
later ones (each into a folder with only the first bag beside it: a run writes one bag, and 15 bags of
13 MB left in the page cache made the later writes slower on a machine near its dirty-page limit). The
first write of a plant is its first bag in the process, after ``warm_up(like=its scenario)`` as
``bioform run --rosbag`` does (the ideal plant's layout then made beforehand, MuJoCo's not: its templates,
chunk buffer and connection records made in the write); the later ones find them made (a sweep's bags). Prints
one line per plant and a JSON line. Each share is given twice: in wall time (what a user
waits) and in CPU time (the write's ``time.process_time`` against the loop's ``RunResult.loop_cpu_s``: on a
machine shared with other jobs, the share that does not depend on how much of a core the process got), by
the least of the repeats and by their medians.

    PYTHONPATH=src python scripts/bench_rosbag.py [--plants ideal,mujoco] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="ideal,mujoco")
    ap.add_argument("--repeat", type=int, default=3, help="runs per variant; the minimum is reported")
    args = ap.parse_args()
    from bioform_mj.run.simulate import simulate
    from bioform_mj.scenario.loader import load

    out = {}
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cold = None
        for plant in args.plants.split(","):
            sc = load("paper", plant=plant)
            simulate(sc)  # kernels compiled / loaded
            plains = [simulate(sc) for _ in range(args.repeat)]
            plain = min(r.summary["wall_time_s"] for r in plains)
            plain_cpu = min(r.loop_cpu_s for r in plains)
            runs = [simulate(sc, full_state=True) for _ in range(args.repeat)]
            sampled = min(r.summary["wall_time_s"] for r in runs)
            from bioform_mj.outputs.rosbag import warm_up, write_bag

            # bioform run --rosbag does this before the run (imports, type store; a planar run's layout)
            setup = warm_up(like=sc)
            writes, cpus, first_cpu = [], [], None
            for i, r in enumerate(runs):
                if i > 1:  # a run writes one bag: the bags before (tens of MB of dirty page cache) are removed
                    shutil.rmtree(Path(tmp) / f"{plant}{i - 1}")
                c0, t0 = time.process_time(), time.perf_counter()
                info = write_bag(r, Path(tmp) / f"{plant}{i}")
                writes.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
            first_cpu, cpus = cpus[0], cpus[1:] or cpus  # the layout's first bag in this process
            if cold is None:
                cold, writes = writes[0], writes[1:] or writes
            warm, warm_cpu = min(writes), min(cpus)
            med_cpu, med_plain_cpu = statistics.median(cpus), statistics.median(r.loop_cpu_s for r in plains)
            out[plant] = {
                "stepping_s": plain,
                "stepping_with_sampling_s": sampled,
                "sampling_overhead": (sampled - plain) / plain,
                "warm_up_s": setup,
                "write_first_s": cold if plant == args.plants.split(",")[0] else None,
                "write_s": warm,
                "write_ratio": warm / plain,
                "stepping_cpu_s": plain_cpu,
                "write_cpu_s": warm_cpu,
                "write_cpu_ratio": warm_cpu / plain_cpu,
                "write_cpu_median_s": med_cpu,
                "write_cpu_ratio_median": med_cpu / med_plain_cpu,
                "write_first_cpu_s": first_cpu,
                "write_first_cpu_ratio": first_cpu / med_plain_cpu,
                "messages": info.messages,
                "mcap_bytes": sum(p.stat().st_size for p in (Path(tmp) / f"{plant}0").iterdir()),
            }
            o = out[plant]
            first = f", first write {cold:.3f} s after a warm-up of {setup:.3f} s" if o["write_first_s"] else ""
            print(
                f"{plant}: stepping {plain:.3f} s, with the 3-D sampling {sampled:.3f} s "
                f"(+{o['sampling_overhead']:.0%}); bag {warm:.3f} s = {o['write_ratio']:.0%} of the stepping"
                f" (CPU: {warm_cpu * 1e3:.1f} ms of {plain_cpu * 1e3:.1f} ms = {o['write_cpu_ratio']:.0%}; medians"
                f" {med_cpu * 1e3:.1f} of {med_plain_cpu * 1e3:.1f} ms = {o['write_cpu_ratio_median']:.0%};"
                f" the layout's first bag {first_cpu * 1e3:.1f} ms = {o['write_first_cpu_ratio']:.0%})"
                f"{first}; {info.messages} messages, {o['mcap_bytes'] / 1e6:.1f} MB"
            )
    import os

    load = os.getloadavg()[0]
    shares = ", ".join(
        f"{p} {o['write_ratio']:.0%} (CPU {o['write_cpu_ratio']:.0%}, median {o['write_cpu_ratio_median']:.0%})"
        for p, o in out.items()
    )
    print(f"bag write / stepping, one process, machine load {load:.1f}: {shares} (issue 29: at most 20 %)")
    out["load_average"] = load
    print(json.dumps(out))


if __name__ == "__main__":
    main()
