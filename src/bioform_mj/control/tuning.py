"""The robot the paper's gains were tuned for, on the control floor and light (numpy-free), so that the scenario's
defaults (``scenario/config.py``: ``plant.c_true``) and the learner's gain scaling (``control/params.py``,
``learner.gain_scaling = "c_hat0"``) read one definition without importing the compiled stack."""

from __future__ import annotations

#: the robot the paper's learner gains were tuned for: ``c = (a, b)`` of Sec. IV, m/(s²·N·m) and rad/(s²·N·m)
PAPER_C = (0.4, 10.0)
