"""MuJoCo's OpenGL backend, picked before MuJoCo is imported (it reads ``MUJOCO_GL`` once).

An explicit ``MUJOCO_GL`` wins; otherwise GLFW when a display is set, EGL when there is none
(Mesa's software EGL on a headless machine, the NVIDIA driver on a GPU one), and OSMesa when
only that is installed. :mod:`skeye.sim.cameras` reports a failure to render with the backend's
name and what to install. Every module that imports ``mujoco`` imports this one first, so only
a process that runs the simulator has ``MUJOCO_GL`` set by skeye.
"""

from __future__ import annotations

import ctypes.util
import os


def choose_gl_backend() -> str:
    """Set ``MUJOCO_GL`` if unset and return the backend in use."""
    chosen = os.environ.get("MUJOCO_GL")
    if chosen:
        return chosen
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        chosen = "glfw"
    elif ctypes.util.find_library("EGL"):
        chosen = "egl"
    elif ctypes.util.find_library("OSMesa"):
        chosen = "osmesa"
    else:
        chosen = "egl"
    os.environ["MUJOCO_GL"] = chosen
    if chosen == "osmesa":
        os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    elif chosen == "egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    return chosen


GL_BACKEND = choose_gl_backend()
