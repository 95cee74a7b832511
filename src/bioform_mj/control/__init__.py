"""The paper's control stack (no knowledge of any plant).

``equations.py``: every equation once, as scalar functions (compiled by numba);
``kernel.py``: one control step of ``n`` followers on named structures;
``stack.py``: :class:`ControlStack`, the paper's controller; ``base.py``: the
:class:`Controller` protocol a user's controller implements; ``common.py``: array helpers
for outputs. See docs/design.md.
"""
