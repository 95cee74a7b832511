"""Batch engine on MuJoCo Warp (needs the optional ``warp-lang`` and ``mujoco-warp``: the ``gpu`` extra).

* :mod:`.samesource`: the control equations' one source, compiled for Warp (and numba);
* :mod:`.device` (the Warp equations, per-world columns, structs, device functions), :mod:`.stack` (the
  control stack's steps), :mod:`.step` (the control kernel: one thread per world), :mod:`.plant_kernels`
  (DC-motor feed, events, sensing), :mod:`.tables` (host-side tables), :mod:`.probe` (the physics probe),
  :mod:`.runner` (:class:`~.runner.BatchRun`, :func:`~.runner.run_batch`);
* :mod:`.backend`: the sweep/bench entry points and the up-front refusals (exit 2);
* :mod:`.bench`: closed loop against replayed-input physics;
* :mod:`.agreement`: the per-world agreement criterion with the CPU engine (needs no Warp).

Importing this package imports nothing optional; see ``docs/warp_engine.md``.
"""
