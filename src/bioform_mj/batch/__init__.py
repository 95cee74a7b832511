"""Batch engine on MuJoCo Warp (needs the optional ``warp-lang`` and ``mujoco-warp``: the ``gpu`` extra).

* :mod:`.samesource`: the control equations' one source, compiled for Warp (and numba);
* :mod:`.control`: the control step of every world (one thread per world), :class:`~.control.BatchRun`
  and :func:`~.control.run_batch`;
* :mod:`.backend`: the sweep/bench entry points and the up-front refusals (exit 2);
* :mod:`.bench`: closed loop against replayed-input physics;
* :mod:`.agreement`: the per-world agreement criterion with the CPU engine (needs no Warp).

Importing this package imports nothing optional; see ``docs/warp_engine.md``.
"""
