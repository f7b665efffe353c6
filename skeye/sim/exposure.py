"""A webcam's auto-exposure: each frame's exposure time and gain from the frames before it.

How this works (docs/camera.md, "Auto-exposure"): the rendered image stands for the signal at
the camera model's nominal settings (``exposure_s``, ``gain``). Auto-exposure scales it by a
brightness factor ``b`` (1 at the nominal settings) that it steers so that a frame's mean luma
reaches ``ae_target_dn``. After each frame it meters (mean luma over the frame, before noise) it
sets a new goal, ``b_goal = b * ae_target_dn / mean``, and ``log b`` relaxes towards
``log b_goal`` as a first-order lag with time constant ``ae_time_constant_s`` in sim time: the
frame after a change of scene is still exposed for the scene before (the lag of a real
camera's control loop, which also meters the frames it has already read out). ``b`` becomes
settings by exposure priority: the exposure time first (``exposure_s * b`` within
``exposure_min_s .. exposure_max_s``: motion blur grows as the light falls), then the analog
gain (within 1 .. ``gain_max``: noise grows); ``b`` is held to what the two limits allow.

The state advances only when a frame is metered, in frame order, by the time elapsed since the
last metered frame: a camera whose frames are not all rendered (nobody asked for them) still
follows the same lag in sim time, from the frames it did render.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from skeye.robots.camera_model import CameraModel


@dataclass(frozen=True)
class Exposure:
    """One frame's settings: exposure time (s), analog gain, and its brightness relative to
    the camera model's nominal settings (1.0 at ``exposure_s`` and ``gain``)."""

    exposure_s: float
    gain: float
    brightness: float


def nominal(model: CameraModel) -> Exposure:
    """The model's fixed settings (auto-exposure off, or before the first metered frame)."""
    return Exposure(model.exposure_s, model.gain, 1.0)


def settings(model: CameraModel, brightness: float) -> Exposure:
    """Exposure priority: the exposure time carries ``brightness`` within its range, then the
    gain; the result's ``brightness`` is what the two limits allow."""
    e0, g0 = model.exposure_s, model.gain
    if e0 > 0.0:
        exposure = min(max(e0 * brightness, model.exposure_min_s), model.exposure_max_s)
        gain = min(max(g0 * brightness * e0 / exposure, 1.0), model.gain_max)
        return Exposure(exposure, gain, exposure * gain / (e0 * g0))
    gain = min(max(g0 * brightness, 1.0), model.gain_max)  # no exposure time modelled
    return Exposure(0.0, gain, gain / g0)


class AutoExposure:
    """One camera's auto-exposure state (see the module comment). Not thread-safe: the render
    thread owns it."""

    def __init__(self, model: CameraModel) -> None:
        self.model = model
        low, high = settings(model, 0.0).brightness, settings(model, math.inf).brightness
        self._log_min = math.log(max(low, 1e-9))
        self._log_max = math.log(high)
        self._log_b = 0.0  # at the last metered frame
        self._log_goal = 0.0
        self._time_s: float | None = None

    def exposure_at(self, time_s: float) -> Exposure:
        """The settings of a frame captured at ``time_s`` (not before the last metered one)."""
        if not self.model.auto_exposure:
            return nominal(self.model)
        log_b = self._log_b
        if self._time_s is not None and time_s > self._time_s:
            decay = math.exp(-(time_s - self._time_s) / self.model.ae_time_constant_s)
            log_b = self._log_goal + (self._log_b - self._log_goal) * decay
        return settings(self.model, math.exp(log_b))

    def metered(self, time_s: float, exposure: Exposure, mean_dn: float) -> None:
        """The frame captured at ``time_s`` with ``exposure`` had this mean level (before noise):
        the next frames steer from it."""
        if not self.model.auto_exposure:
            return
        if self._time_s is not None and time_s < self._time_s:
            return  # an older frame rendered late: the loop has moved on
        log_b = math.log(max(exposure.brightness, 1e-9))
        goal = log_b + math.log(self.model.ae_target_dn / max(mean_dn, 0.5))
        self._log_b = log_b
        self._log_goal = min(max(goal, self._log_min), self._log_max)
        self._time_s = time_s
