"""Which settings and render modes each environment takes: one table (docs/gym.md, "Options").

How this works: every environment is configured by :class:`~skeye.gym.flight.FlightSettings`'
fields, but some of them act only through the camera or the pilot's pad detector:

- :data:`VISION_SETTINGS` tune the pad detector, whose detections only PadLanding observes;
- :data:`CAMERA_SETTINGS` choose the downward camera, which PadLanding looks through and which
  Hover and GoTo (no camera by default) only render, with ``render_mode="rgb_array"``.

:func:`check_settings` refuses such a setting, given a value other than its default, where the
environment would ignore it, naming the setting and the environment (an option that does
nothing must not look as if it did). :func:`check_render_mode` refuses a render mode the
environment does not offer, naming the ones it does. Both raise
:class:`~skeye.errors.ConfigError` before anything is loaded.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any

from skeye.errors import ConfigError
from skeye.gym.flight import FlightSettings
from skeye.gym.tasks import Task
from skeye.robots.camera_model import PROFILES
from skeye.values import is_number

VISION_SETTINGS = ("vision_latency_s", "calibration")
"""The pilot's pad detector: its latency and calibration (PadLanding observes it)."""
CAMERA_SETTINGS = ("camera", "camera_name")
"""The downward camera: PadLanding's eyes; Hover and GoTo only render it."""
RENDER_MODE = "rgb_array"
"""The one render mode: the downward camera's newest frame (where there is a camera)."""
_DEFAULTS = {f.name: f.default for f in fields(FlightSettings)}


def env_id(task: Task, vector: bool = False) -> str:
    """The environment's id as registered (``skeye/Hover-v0``), and, for the native vector
    environment, that it is the batched one."""
    name = f"skeye/{task.name}-v0"
    return f"the batched {name}" if vector else name


def settings_used(task: Task, renders: bool) -> tuple[str, ...]:
    """The camera and vision settings this environment acts on (``renders``: it renders
    its camera, ``render_mode`` given)."""
    if task.needs_camera:
        return CAMERA_SETTINGS + VISION_SETTINGS
    return CAMERA_SETTINGS if renders else ()


def check_settings(task: Task, settings: Mapping[str, Any], *, renders: bool,
                   vector: bool = False) -> None:
    """Refuse a camera or vision setting (other than its default) the environment ignores."""
    used = settings_used(task, renders)
    where = env_id(task, vector)
    for name in (*CAMERA_SETTINGS, *VISION_SETTINGS):
        if name not in settings or name in used or _is_default(name, settings[name]):
            continue
        if name in VISION_SETTINGS:
            why = "it tunes the pilot's pad detector, whose detections only PadLanding observes"
        elif vector:
            why = "it renders nothing"
        else:
            why = f"it has a camera only to render it, with render_mode={RENDER_MODE!r}"
        raise ConfigError(f"{name} {settings[name]!r} would do nothing in {where}: {why}")


def check_render_mode(task: Task, render_mode: Any, has_camera: bool, *,
                      vector: bool = False) -> None:
    """Refuse a render mode the environment does not offer, naming those it does."""
    if render_mode is None or (has_camera and not vector and render_mode == RENDER_MODE):
        return
    where = env_id(task, vector)
    if vector:
        offers = "offers no render mode"
    elif has_camera:
        offers = f"offers render_mode {RENDER_MODE!r} (its downward camera's newest frame)"
    else:
        offers = (f"has no camera, so it offers no render mode (with camera="
                  f"{' or '.join(map(repr, PROFILES))} it offers {RENDER_MODE!r})")
    note = ""
    if render_mode == RENDER_MODE and not vector:
        note = (f" (gymnasium.make asks for {RENDER_MODE!r} when given 'human' or "
                f"'{RENDER_MODE}_list')")
    raise ConfigError(f"{where} {offers}; got render_mode={render_mode!r}{note}")


def _is_default(name: str, value: Any) -> bool:
    default = _DEFAULTS[name]
    if default is None:
        return value is None
    if isinstance(default, str):  # the camera's name is looked up ignoring case
        return isinstance(value, str) and (
            value.lower() == default.lower() if name == "camera_name" else value == default)
    return is_number(value) and value == default
