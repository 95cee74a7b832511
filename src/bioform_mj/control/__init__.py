"""The paper's control stack as vectorised numpy pieces (no knowledge of any plant).

Arrays are shaped ``(n, …)`` over followers. ``stack.ControlStack`` chains them into
one control step: estimator (eqs. 12–13), bioinspired/backstepping kinematics
(eqs. 27–33), online learner (eq. 37) and sliding-mode torque law (eqs. 38–39).
"""
