#!/usr/bin/env python3
"""Same as ``bioform bench``: closed-loop throughput against bare ``mj_step`` for n = 3, 16, 64, 256.

Usage: ``python scripts/bench.py [--sizes 3,16,64,256] [--json runs/bench.json]``.
"""

from bioform_mj.jobs.bench import main

if __name__ == "__main__":
    raise SystemExit(main())
