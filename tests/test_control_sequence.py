"""The compiled chunks' copies of the control step stay ``kernel.stack_step`` (design §2).

Both plants' ``run_chunk`` repeat ``stack_step``'s three lines (``stack_head`` → the safety filter under
``kn.cbf`` → ``stack_tail``) on arrays bound before their step loop, rather than call a shared helper (which
would cost a reference count per array argument and step: control/kernel.py). These tests catch the copies
drifting apart: by their code (the calls, their order, the condition, the arrays each call is given, then
``engine.after_step`` and the log row) and by their bits (each plant's compiled loop against the step-by-step
loop, which calls ``control_step`` → ``stack_step``, with the safety filter acting).
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from bioform_mj.run.simulate import simulate
from bioform_mj.scenario.loader import load
from crossing import CROSSING

PKG = Path(__file__).resolve().parent.parent / "src" / "bioform_mj"
STEP = ("stack_head", "safety_filter", "stack_tail")
CHUNKS = {"ideal": "plants/ideal.py", "mujoco": "plants/mujoco/kernels.py"}


def _function(rel: str, name: str) -> ast.FunctionDef:
    tree = ast.parse((PKG / rel).read_text(encoding="utf-8"))
    return next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == name)


def _calls(fn: ast.FunctionDef, names: tuple[str, ...]) -> list[tuple[str, ast.Call, str | None]]:
    """The calls of ``names`` in ``fn`` in source order, each with the test of the innermost ``if`` around it."""
    out: list[tuple[str, ast.Call, str | None]] = []

    def visit(node: ast.AST, cond: str | None) -> None:
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in names:
            out.append((node.func.id, node, cond))
        for field, value in ast.iter_fields(node):
            inner = ast.unparse(node.test) if isinstance(node, ast.If) and field in ("body", "orelse") else cond
            for child in value if isinstance(value, list) else [value]:
                if isinstance(child, ast.AST):
                    visit(child, inner)

    visit(fn, None)
    return sorted(out, key=lambda t: (t[1].lineno, t[1].col_offset))


def _arg(a: ast.expr) -> str:
    """An argument as the array or number it names: ``s.cmd`` and a chunk's ``cmd`` bound from it alike."""
    return a.attr if isinstance(a, ast.Attribute) else ast.unparse(a)


def test_the_stack_step_is_head_filter_tail():
    calls = _calls(_function("control/kernel.py", "stack_step"), STEP)
    assert [(n, cond) for n, _, cond in calls] == [("stack_head", None), ("safety_filter", "kn.cbf"),
                                                   ("stack_tail", None)]  # fmt: skip


@pytest.mark.parametrize("plant", list(CHUNKS))
def test_each_chunk_repeats_the_stack_step_call_for_call(plant):
    ref = _calls(_function("control/kernel.py", "stack_step"), STEP)
    got = _calls(_function(CHUNKS[plant], "run_chunk"), (*STEP, "after_step", "record"))
    # the step, then the engine's bookkeeping and the log row, once each, in this order, the filter under
    # kn.cbf, the rest under the chunk's own condition (a step that is not the last)
    assert [n for n, _, _ in got] == [*STEP, "after_step", "record"]
    conds = [cond for _, _, cond in got]
    assert conds[1] == "kn.cbf" and conds[4] == "status == ROW"
    assert conds[0] == conds[2] == conds[3] == "k + 1 < N"
    for (name, r, _), (_, c, _) in zip(ref, got):
        ra, ca = [_arg(a) for a in r.args], [_arg(a) for a in c.args]
        assert len(ra) == len(ca), name
        if name == "stack_head":  # the leader's pose and velocities: the chunk reads them from its table at k+1
            assert ca[:4] == ra[:4] and ca[9:] == [ca[9], ca[10]], name
            assert ca[4:9] == [f"L_pose[k_, {i}]" for i in range(3)] + [f"L_vel[k_, {i}]" for i in range(2)]
        elif name == "safety_filter":
            assert ca[1:] == ra[1:], name
        else:
            assert ca[:3] == ra[:3], name
    # the filter and the torque law see what the head saw: the same measured pose and velocities
    head, filt, tail = (c for _, c, _ in got[:3])
    measured = [_arg(a) for a in head.args[9:]]
    assert _arg(filt.args[0]) == measured[0]
    assert [_arg(a) for a in tail.args[3:]] == measured
    if plant == "ideal":
        assert measured == ["pose", "vel"]
    else:  # the odometry or the truth (sen.on), while after_step keeps the truth
        assert measured == ["mpose", "mvel"]
        after = got[3][1]
        assert [_arg(a) for a in after.args[3:5]] == ["pose", "vel"]


@pytest.mark.parametrize("plant", ["ideal", "mujoco"])
def test_compiled_chunk_and_control_step_same_bits_with_the_filter_acting(plant):
    """The crossing scene (followers swapping sides) with the safety filter: the filter changes the commands
    (so a chunk that skipped it, or filtered the wrong pose, would differ), and the compiled chunk and the
    step-by-step loop (``control_step``) agree bit for bit, every log array."""
    over = {**CROSSING, "plant.kind": plant, "sim.duration": 1.5, "safety.distance": 0.05}
    off = simulate(load("paper", over))
    sc = load("paper", {**over, "safety.filter": "cbf"})
    a, b = simulate(sc, engine="compiled"), simulate(sc, engine="stepwise")
    assert a.summary["engine"] == "compiled" and b.summary["engine"] == "stepwise"
    assert not np.array_equal(a.log["cmd"], off.log["cmd"])  # the filter acted
    assert a.log.keys() == b.log.keys()
    for k in a.log:
        assert np.array_equal(a.log[k], b.log[k], equal_nan=a.log[k].dtype.kind == "f"), k


def _gains(flag: str | None):
    """A :class:`Gains` whose numbers are all different (the booleans: only ``flag`` True), its arrays empty."""
    from typing import get_type_hints

    from bioform_mj.control.kernel import Gains

    hints = get_type_hints(Gains)
    vals = {}
    for i, f in enumerate(Gains._fields):
        t = hints[f]
        vals[f] = (
            np.zeros((1, 2)) if t is np.ndarray else (f == flag) if t is bool else t(i + 1) + (0.5 if t is float else 0)
        )
    return Gains(**vals)


@pytest.mark.parametrize("flag", ["bio", "learning", "steer", "leader_frame", "cbf"])
def test_knobs_are_the_gains_numbers_field_by_field(flag):
    """``kernel.knobs`` (compiled) gives every number of the gains in its own place, named as in :data:`KNOBS`."""
    from bioform_mj.control.kernel import KNOBS, knobs

    g = _gains(flag)
    kn = knobs(g)  # compiled
    assert kn._fields == KNOBS
    assert tuple(kn) == tuple(getattr(g, f) for f in KNOBS)
    assert len(set(tuple(kn)) - {True, False}) == len(KNOBS) - 5  # the numbers all differ: an order is seen
