"""A griffe extension for the API reference (``mkdocs.yml``): the package's docstrings cross-reference
with Sphinx roles (``:func:`~bioform_mj.run.simulate.simulate```), which mkdocstrings' Markdown would print as
they stand; this turns each into inline code (``simulate``; the full path without ``~``)."""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const):`(~?)([^`]+)`")


def plain_roles(text: str) -> str:
    """``:role:`~a.b.c``` → ```c```, ``:role:`a.b.c``` → ```a.b.c```."""
    return ROLE.sub(lambda m: f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`", text)


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring as the objects are loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain_roles(obj.docstring.value)
