"""The public API documents every argument (design §18): each public function of ``bioform_mj.__all__``, and each
public method with arguments of its public classes, has a numpydoc ``Parameters`` section naming every parameter,
as python-control's docstring test asks of its API."""

from __future__ import annotations

import inspect
import re

import pytest

import bioform_mj as bf


def _documented(doc: str) -> set[str]:
    """Names listed in a docstring's ``Parameters`` section (``name`` or ``name : type`` at the section's indent)."""
    m = re.search(
        r"^([ \t]*)Parameters\n[ \t]*-{3,}\n(.*?)(?:\n[ \t]*\n[ \t]*[A-Z][a-z]+\n[ \t]*-{3,}|\Z)", doc, re.S | re.M
    )
    if not m:
        return set()
    indent = len(m.group(1))
    names = set()
    for line in m.group(2).splitlines():
        if line.strip() and len(line) - len(line.lstrip()) == indent:
            names |= {n.strip() for n in line.split(":")[0].split(",")}
    return names


def _callables():
    for name in bf.__all__:
        obj = getattr(bf, name)
        if inspect.isfunction(obj):
            yield name, obj
        elif inspect.isclass(obj) and obj.__module__.startswith("bioform_mj") and not getattr(obj, "_is_protocol", 0):
            for mname, meth in vars(obj).items():
                if not mname.startswith("_") and inspect.isfunction(meth):
                    yield f"{name}.{mname}", meth


def _params(fn) -> list[str]:
    return [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]


def test_the_section_reader_reads_a_numpydoc_section():
    doc = "Do.\n\nParameters\n----------\na, b\n    two.\nc : int\n    one.\n\nReturns\n-------\nx\n"
    assert _documented(doc) == {"a", "b", "c"}
    assert _documented("Do a thing; ``a``: one.") == set()


@pytest.mark.parametrize(
    "name, fn", [c for c in _callables() if _params(c[1])], ids=lambda v: v if isinstance(v, str) else ""
)
def test_every_public_argument_is_documented(name, fn):
    missing = set(_params(fn)) - _documented(inspect.getdoc(fn) or "")
    assert not missing, f"{name}: no Parameters entry for {sorted(missing)}"


def test_the_public_api_has_functions_with_arguments():
    assert {"load", "simulate"} <= {n for n, f in _callables() if _params(f)}


def test_unknown_keyword_arguments_are_refused():
    with pytest.raises(TypeError):
        bf.load("paper", plnat="ideal")  # type: ignore[call-arg]
