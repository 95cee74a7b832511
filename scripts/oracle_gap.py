#!/usr/bin/env python3
"""How far the compiled engine is from the numpy oracle (tests/oracle.py) over the 20 s paper run.

Prints the largest logged pose difference (m) and the largest relative ``ĉ`` difference per
method. The two are different code (numpy's SIMD transcendental functions against libm's), so
they agree to rounding, not bit for bit; the test bound is 1e-9 relative. Run it with
``NPY_DISABLE_CPU_FEATURES="AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL
AVX512_SPR X86_V4"`` to see the gap without numpy's AVX-512 paths.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests"))

from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load
from test_run_engines import oracle_run  # noqa: E402

for method in ("bioinspired-learning", "backstepping"):
    sc = load("paper", method=method)
    res = simulate(sc)
    rows, c_hat, _ = oracle_run(sc)
    got = np.array([f["c_hat"] for f in res.summary["followers"]])
    print(
        f"{method}: max |pose - oracle| = {np.abs(res.log['pose'] - rows).max():.2g} m, "
        f"max |c_hat / oracle - 1| = {np.abs(got / c_hat - 1).max():.2g}"
    )
