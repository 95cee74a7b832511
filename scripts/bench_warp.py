#!/usr/bin/env python3
"""Benchmark of the MuJoCo Warp batch engine: closed loop vs physics alone (replayed inputs),
and the CPU engine. A thin wrapper of :mod:`bioform_mj.batch.bench` (``bioform bench --backend warp``).

    python scripts/bench_warp.py --device cuda --worlds 1024,4096,32768 --duration 1 --json $OUT/warp.json
"""

import sys

from bioform_mj.batch.bench import main

if __name__ == "__main__":
    sys.exit(main())
