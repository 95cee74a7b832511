"""What the project checks about its dependencies at startup (design §17).

MuJoCo 4 ships its Python package ``mujoco/`` from several distributions: ``mujoco`` (from 4.0
on a metapackage that also installs ``mujoco/__init__.py``), ``mujoco-core`` (the engine and
bindings) and ``mujoco-studio`` (the viewer). Each ``mujoco`` release requires the same
release of the others (``mujoco 4.0.0`` requires ``mujoco-core==4.0.0``), but nothing stops
a resolver from installing ``mujoco`` 3.x (everything in one wheel) beside ``mujoco-core``
4.x, for instance ``mujoco-core>=4.0.1`` with ``mujoco-warp`` (which requires the ``mujoco``
name): pip then writes both into the same ``mujoco/`` folder, one over the other, without a
word. :func:`mujoco_distribution_problem` finds that from package metadata alone (no import
of MuJoCo, ~1 ms), and the CLI refuses to start on it (exit 2).
"""

from __future__ import annotations

import functools
import importlib.metadata as md

#: the distributions that install files into the ``mujoco/`` package (MuJoCo 4 split)
MUJOCO_DISTRIBUTIONS = ("mujoco", "mujoco-core", "mujoco-studio")
#: the release ``pyproject.toml`` pins (``mujoco==``): what the fix in the error message installs
MUJOCO_RELEASE = "4.0.0"


def installed_versions(names: tuple[str, ...] = MUJOCO_DISTRIBUTIONS) -> dict[str, str]:
    """``{distribution: version}`` of those of ``names`` that are installed."""
    out: dict[str, str] = {}
    for name in names:
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            continue
    return out


def mujoco_distribution_problem(versions: dict[str, str] | None = None) -> str | None:
    """None when the distributions installing ``mujoco/`` are one release, else the problem and its fix.

    ``versions``: ``{distribution: version}`` (default: what is installed). Every one of
    :data:`MUJOCO_DISTRIBUTIONS` that is installed must have the same version (a ``mujoco``
    3.x, which carries everything itself, must be alone: any ``mujoco-core`` beside it is 4.x).
    """
    v = installed_versions() if versions is None else dict(versions)
    if len(v) <= 1:
        return None
    if len(set(v.values())) == 1:
        return None
    listed = ", ".join(f"{k} {ver}" for k, ver in v.items())
    fix = f"pip uninstall -y {' '.join(v)} && pip install 'mujoco=={MUJOCO_RELEASE}'"
    return (
        f"the installed MuJoCo is inconsistent: {listed} all install the 'mujoco' Python package, "
        f"one over the other; make them one release, e.g. {fix}"
    )


@functools.cache
def check_mujoco_once() -> None:
    """Raise :class:`~bioform_mj.core.errors.InputError` when :func:`mujoco_distribution_problem`
    finds one; once per process (``scene.compile_scene`` calls it: the Python API's startup check)."""
    problem = mujoco_distribution_problem()
    if problem:
        from bioform_mj.core.errors import InputError

        raise InputError(problem)
