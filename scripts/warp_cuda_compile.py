#!/usr/bin/env python3
"""Compile the batch engine's Warp kernels for a CUDA architecture without a GPU (NVRTC, ahead of time).

A machine with no GPU still checks that the device code builds for CUDA, not only for Warp's CPU
device: ``wp.compile_aot_module`` on the batch engine's kernel modules (``batch/step.py``: ``_control``;
``batch/plant_kernels.py``: ``_delivered``, ``_sense``, ``_events``, ``_record``, ``_replay``; with them the
structs and device functions of ``batch/device.py`` they use), to PTX for
``--arch`` (90: H100/H200). It cannot check what needs a GPU (graph capture, timings). Measured on
the 2-core CI machine: ~1 min, a 7 MB PTX for sm_90.

    python scripts/warp_cuda_compile.py --arch 90 --out /tmp/aot
"""

from __future__ import annotations

import argparse
import sys
import tempfile


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", type=int, default=90, help="CUDA compute capability × 10 (90: Hopper)")
    ap.add_argument("--out", help="directory for the .cu/.ptx (default: a temporary one)")
    a = ap.parse_args()
    import warp as wp

    wp.config.quiet = True
    from bioform_mj.batch import plant_kernels, step

    out = a.out or tempfile.mkdtemp(prefix="bioform-aot-")
    files = []
    for module in (step, plant_kernels):
        try:
            files += list(wp.compile_aot_module(module, arch=a.arch, module_dir=out, use_ptx=True) or [])
        except Exception as exc:  # noqa: BLE001 - report the compiler's message in one line
            print(f"error: CUDA compile of {module.__name__} for sm_{a.arch} failed: {exc}", file=sys.stderr)
            return 1
    for f in files:
        print(f"compiled {f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
