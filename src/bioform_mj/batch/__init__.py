"""Batch engine on MuJoCo Warp (prototype; needs the optional ``warp-lang`` and ``mujoco-warp``).

* :mod:`.samesource`: the control equations' one source, compiled for Warp (and numba);
* :mod:`.engine`: many worlds of a composed scene, observed/driven by Warp kernels;
* :mod:`.standin_equations`: stand-in for ``control/equations.py`` until it lands.

Importing this package imports nothing optional; see ``docs/warp_engine.md``.
"""
