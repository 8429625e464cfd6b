"""Headless OpenGL contexts.

lobeview renders offscreen through EGL (Mesa llvmpipe on machines without a GPU, the vendor
driver elsewhere), so screenshots and tests need no display. OpenGL 4.5 core is required
(llvmpipe in Mesa >= 20 provides it).
"""

from __future__ import annotations

import moderngl

REQUIRED_GL_VERSION = 450


class HeadlessContextError(RuntimeError):
    """No usable headless OpenGL context; the message says what to install."""


def create_headless_context(require: int = REQUIRED_GL_VERSION) -> moderngl.Context:
    """A standalone OpenGL context through EGL, checked for version ``require`` (e.g. 450)."""
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=require)
    except Exception as exc:  # moderngl raises plain Exception subclasses from glcontext
        raise HeadlessContextError(
            f"could not create a headless OpenGL {require // 100}.{require % 100 // 10} context "
            f"through EGL ({exc}). Install the EGL/Mesa libraries (Debian: apt-get install "
            "libegl1 libgl1-mesa-dri libgles2) or run on a machine with a GPU driver."
        ) from exc
    return ctx


def renderer_description(ctx: moderngl.Context) -> str:
    info = ctx.info
    return f"{info['GL_RENDERER']} ({info['GL_VENDOR']}), OpenGL {info['GL_VERSION']}"


SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swiftshader", "lavapipe")


def gpu_timer_meaningful(device: str) -> bool:
    """GL_TIME_ELAPSED measures the GPU's work on hardware; Mesa's llvmpipe rasterises on worker
    threads after the query has ended (measured: 0.4-2 ms by the query against 42-150 ms wall
    for lobe-3..19 at 640x400), so software renderers are timed by the wall clock."""
    return not any(name in device.lower() for name in SOFTWARE_RENDERERS)
