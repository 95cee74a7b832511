"""Batch engine on MuJoCo Warp (prototype; needs the optional ``warp-lang`` and ``mujoco-warp``).

* :mod:`.samesource`: the control equations' one source, compiled for Warp (and numba);
* :mod:`.engine`: many worlds of a composed scene, observed/driven by Warp kernels;
* :mod:`.control`: the control step of every world (one thread per world), and :func:`run_batch`.

Importing this package imports nothing optional; see ``docs/warp_engine.md``.
"""
