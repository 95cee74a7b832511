"""Imported by ``bioform sweep``'s fork server: load the compiled kernels once, before workers fork.

Forked workers inherit the loaded machine code, so none of them pays the ~0.5 s of
loading numba's cache (or compiling, the first time on a checkout) on its first run.
"""
from __future__ import annotations

from .scenario import load
from .sim import simulate

for _plant in ("ideal", "mujoco"):
    simulate(load("paper", plant=_plant, overrides=["sim.duration=0.01"]))
