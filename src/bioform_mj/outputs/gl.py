"""Off-screen OpenGL for MuJoCo's renderer: pick the backend before MuJoCo is imported.

MuJoCo chooses its OpenGL platform from ``MUJOCO_GL`` once, when ``mujoco`` is first
imported. :func:`configure_gl_env` must therefore run before anything imports it (the
``bioform`` command calls it first thing). It defaults to ``egl`` (headless, works on a
GPU through the vendor's EGL and on any machine through Mesa's software ``llvmpipe``)
and leaves a user's own value (``osmesa``, ``glfw``, ``egl``) alone.

MuJoCo refuses to import *at all* when ``MUJOCO_GL`` holds a value it does not know,
which would take the simulation down with the video. An unknown value is therefore
remembered here, replaced by ``disable`` (MuJoCo imports, renders nothing), and
reported by :func:`make_renderer` as :class:`GLUnavailable` only if a video is asked
for, so every other output of the run is still written.

Nothing in this module imports MuJoCo at import time.
"""

from __future__ import annotations

import os
import platform
import sys
from typing import Any

from bioform_mj.core.errors import InputError

#: Backend used when the user sets none (headless; Mesa or a GPU vendor's EGL).
DEFAULT_BACKEND = "egl"

_DISABLED = ("disable", "disabled", "off", "false", "0")
_VALID_COMMON = ("enable", "enabled", "on", "true", "1", "glfw", "")
_VALID_BY_SYSTEM = {"Linux": ("glx", "egl", "osmesa"), "Windows": ("wgl",), "Darwin": ("cgl",)}

#: The user's ``MUJOCO_GL`` when MuJoCo would refuse it (set by :func:`configure_gl_env`).
_invalid_value: str | None = None

#: Renderer strings of OpenGL implementations that run on the CPU.
_SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "software rasterizer", "lavapipe")


class GLUnavailable(InputError):
    """No OpenGL context can be made for off-screen rendering (the CLI exits 2)."""


def valid_backends() -> tuple[str, ...]:
    """The ``MUJOCO_GL`` values MuJoCo accepts on this operating system."""
    return _DISABLED + _VALID_COMMON + _VALID_BY_SYSTEM.get(platform.system(), ())


def configure_gl_env() -> None:
    """Default ``MUJOCO_GL`` to ``egl`` on Linux; neutralise a value MuJoCo would refuse.

    Call before anything imports ``mujoco``; afterwards it changes nothing that matters.
    """
    global _invalid_value
    if "mujoco" in sys.modules:  # too late: MuJoCo has chosen its platform already
        return
    value = os.environ.get("MUJOCO_GL")
    if value is None:
        if platform.system() == "Linux":
            os.environ.setdefault("MUJOCO_GL", DEFAULT_BACKEND)
        return
    if value.lower().strip() not in valid_backends():
        _invalid_value = value
        os.environ["MUJOCO_GL"] = "disable"  # mujoco imports (and simulates); rendering is refused below


def backend() -> str:
    """The ``MUJOCO_GL`` in force (``''`` when unset: MuJoCo's own default, GLFW)."""
    return os.environ.get("MUJOCO_GL", "")


def _advice() -> str:
    return (
        "set MUJOCO_GL=egl (Debian/Ubuntu packages libegl1 and libgl1-mesa-dri; a GPU driver's EGL also works) "
        "or MUJOCO_GL=osmesa (package libosmesa6), or run without --video"
    )


def make_renderer(model: Any, width: int, height: int, *, fast: bool | None = None) -> tuple[Any, bool]:
    """``(mujoco.Renderer, fast)`` of ``width`` × ``height`` pixels for ``model``, or :class:`GLUnavailable`.

    Raises the model's off-screen buffer (``vis.global_.offwidth/offheight``) if needed.
    ``fast`` turns multisampling off here (and the caller turns floor reflections off per
    scene): together they cost 3–4× on a software rasteriser for little gain at video
    size. ``None`` decides from the OpenGL implementation: on for Mesa's llvmpipe, off on
    a GPU.
    """
    if _invalid_value is not None:
        raise GLUnavailable(
            f"cannot render: MUJOCO_GL={_invalid_value!r} is not a MuJoCo OpenGL backend "
            f"(expected egl, osmesa or glfw); {_advice()}"
        )
    value = backend().lower().strip()
    if value in _DISABLED:
        raise GLUnavailable(f"cannot render: rendering is disabled by MUJOCO_GL={backend()!r}; {_advice()}")
    try:
        import mujoco

        if fast is None:
            fast = is_software(context_renderer_name())
        if fast:
            model.vis.quality.offsamples = 0  # multisampling is the dearest pass on a CPU rasteriser
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), int(width))
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), int(height))
        renderer = mujoco.Renderer(model, height=int(height), width=int(width))
        renderer.render()  # make the context current and prove it draws
    except Exception as exc:  # noqa: BLE001 - every GL platform fails in its own way
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise GLUnavailable(
            f"cannot create an OpenGL context for off-screen rendering (MUJOCO_GL="
            f"{backend() or 'unset'}: {type(exc).__name__}: {msg[:200]}); {_advice()}"
        ) from exc
    return renderer, bool(fast)


def context_renderer_name() -> str:
    """``GL_RENDERER`` of a throw-away 16 × 16 context of the current backend (raises if none can be made)."""
    import mujoco

    ctx = mujoco.GLContext(16, 16)
    try:
        ctx.make_current()
        return gl_renderer_name()
    finally:
        ctx.free()


def gl_renderer_name() -> str:
    """``GL_RENDERER`` of the current context (e.g. ``llvmpipe (LLVM 15…)``), ``''`` if unknown."""
    try:
        from OpenGL import GL

        name = GL.glGetString(GL.GL_RENDERER)
        return name.decode() if isinstance(name, bytes) else str(name or "")
    except Exception:  # noqa: BLE001 - PyOpenGL missing or no context: unknown
        return ""


def is_software(renderer_name: str) -> bool:
    """True for an OpenGL implementation that rasterises on the CPU (Mesa llvmpipe …)."""
    low = renderer_name.lower()
    return any(s in low for s in _SOFTWARE_GL)


def probe(width: int = 64, height: int = 64) -> str:
    """Make a context on a one-geom model; return ``GL_RENDERER`` or raise :class:`GLUnavailable`."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><light pos='0 0 2'/><geom type='sphere' size='0.1'/></worldbody></mujoco>"
    )
    r, _ = make_renderer(model, width, height, fast=False)
    try:
        return gl_renderer_name()
    finally:
        r.close()
