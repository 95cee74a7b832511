"""What `bioform run --rosbag` costs at the paper scenario against the run's stepping time (issue 29:
at most 20 %): the stepping without and with the 3-D sampling, the one-time warm-up that
``bioform run --rosbag`` does before the run (imports, rosbags' type store), the first write and
later ones (each into a folder with only the first bag beside it: a run writes one bag, and 15 bags of
13 MB left in the page cache made the later writes slower on a machine near its dirty-page limit). Prints
one line per plant and a JSON line. Each share is given twice: in wall time (what a user
waits) and in CPU time (the write's ``time.process_time`` against the loop's ``RunResult.loop_cpu_s``: on a
machine shared with other jobs, the share that does not depend on how much of a core the process got).

    PYTHONPATH=src python scripts/bench_rosbag.py [--plants ideal,mujoco] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import shutil
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

            if cold is None:  # bioform run --rosbag does this before the run (imports, type store)
                setup = warm_up()
            writes, cpus = [], []
            for i, r in enumerate(runs):
                if i > 1:  # a run writes one bag: the bags before (tens of MB of dirty page cache) are removed
                    shutil.rmtree(Path(tmp) / f"{plant}{i - 1}")
                c0, t0 = time.process_time(), time.perf_counter()
                info = write_bag(r, Path(tmp) / f"{plant}{i}")
                writes.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
            if cold is None:
                cold, writes, cpus = writes[0], writes[1:] or writes, cpus[1:] or cpus
            warm, warm_cpu = min(writes), min(cpus)
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
                "messages": info.messages,
                "mcap_bytes": sum(p.stat().st_size for p in (Path(tmp) / f"{plant}0").iterdir()),
            }
            o = out[plant]
            first = f", first write {cold:.3f} s after a warm-up of {setup:.3f} s" if o["write_first_s"] else ""
            print(
                f"{plant}: stepping {plain:.3f} s, with the 3-D sampling {sampled:.3f} s "
                f"(+{o['sampling_overhead']:.0%}); bag {warm:.3f} s = {o['write_ratio']:.0%} of the stepping"
                f" (CPU: {warm_cpu * 1e3:.1f} ms of {plain_cpu * 1e3:.1f} ms = {o['write_cpu_ratio']:.0%})"
                f"{first}; {info.messages} messages, {o['mcap_bytes'] / 1e6:.1f} MB"
            )
    import os

    load = os.getloadavg()[0]
    shares = ", ".join(f"{p} {o['write_ratio']:.0%} (CPU {o['write_cpu_ratio']:.0%})" for p, o in out.items())
    print(f"bag write / stepping, one process, machine load {load:.1f}: {shares} (issue 29: at most 20 %)")
    out["load_average"] = load
    print(json.dumps(out))


if __name__ == "__main__":
    main()
