"""The pilot's vision: landing-pad detection on every new camera frame, and what PAD_MODE does.

How this works: after each loop tick the pilot calls :meth:`PadVision.step`. When the robot's
camera has announced a frame newer than the last one processed (``SEN {Type Camera}``), the
newest frame is fetched from the image server (RAW, with its META header: frame number and sim
time), turned grey, and given to :func:`skeye.vision.detector.detect` with the camera's float
field of view and the INS roll and pitch, exactly as ``skeye vision detect`` does on a real
camera image. The estimate goes to the boards' :class:`PadController` (the PAD packet).

In pad modes the estimate also flies the vehicle through :class:`PadHoldLaw`: HOLD (1) keeps
the pad centre within the deadband at up to the speed limit; LAND (2) descends onto it and
hands over to the vehicle's own landing straight down. Pad navigation acts only while the
vehicle is HOLDING (after take-off, HOLD, or when a commanded motion has finished): a ground
command (velocity, move, goto) suspends it until that motion ends, and PAD_MODE 0 gives the
vehicle back with a hover. Nothing here reads the simulator's ground truth.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, replace
from typing import Any

import cv2

from skeye.errors import SkeyeError
from skeye.link.packets import NavState, PadAction
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.pad import PadObservation
from skeye.pilot.pad_hold import PadHoldLaw, PadHoldParams
from skeye.vision.detector import detect
from skeye.vision.pad import SKEYE_4, PadDefinition

log = logging.getLogger(__name__)


@dataclass
class VisionStats:
    """What the vision loop has done (for tests, benchmarks and the log)."""

    frames: int = 0
    detections: int = 0
    errors: int = 0
    last_error: str = ""


class PadVision:
    """Detector + pad navigation, driven by the pilot loop."""

    def __init__(
        self,
        boards: OnboardBoards,
        robot: Any,
        lock: threading.Lock | threading.RLock,
        *,
        fov_h_rad: float,
        pad: PadDefinition = SKEYE_4,
        params: PadHoldParams | None = None,
    ) -> None:
        self.boards = boards
        self.robot = robot
        self.lock = lock
        self.fov_h_rad = fov_h_rad
        self.pad = pad
        self.base_params = params or PadHoldParams()
        self.law = PadHoldLaw(self.base_params)
        self.stats = VisionStats()
        self._last_frame = 0
        self._mode = PadAction.OFF

    def step(self) -> None:
        """Process the newest frame if there is a new one; never raises on a bad frame."""
        camera = self.robot.camera
        latest = camera.latest
        if latest is None or latest.frame <= self._last_frame:
            return
        try:
            image = camera.image()
        except SkeyeError as exc:
            self.stats.errors += 1
            self.stats.last_error = str(exc)
            log.warning("camera frame not available: %s", exc)
            return
        if image.frame <= self._last_frame:
            return
        self._last_frame = image.frame
        ins = self.robot.ins.latest
        roll, pitch = (ins.rpy_rad[0], ins.rpy_rad[1]) if ins is not None else (0.0, 0.0)
        grey = cv2.cvtColor(image.bgr, cv2.COLOR_BGR2GRAY)
        est = detect(grey, self.fov_h_rad, self.pad, roll_rad=roll, pitch_rad=pitch)
        self.stats.frames += 1
        if est.found and est.offset_body_m is not None and est.height_m is not None:
            self.stats.detections += 1
            bits = 0
            for ring in est.rings:
                bits |= 1 << (ring - 1)
            obs = PadObservation(image.time_s, True, bits, est.offset_body_m[0],
                                 est.offset_body_m[1], est.height_m, est.quality)
        else:
            obs = PadObservation(image.time_s, False)
        with self.lock:
            self.boards.pad.on_frame(obs)
            self._navigate(obs)

    def _navigate(self, obs: PadObservation) -> None:
        boards = self.boards
        settings = boards.pad.settings
        mode = settings.mode
        if mode != self._mode:
            self._mode = mode
            self.law = PadHoldLaw(
                replace(
                    self.base_params,
                    deadband_m=settings.deadband_m or self.base_params.deadband_m,
                    max_speed_m_s=settings.max_speed_m_s or self.base_params.max_speed_m_s,
                )
            )
            if mode == PadAction.OFF and boards.state is NavState.HOLDING:
                boards.airframe.hover()
        if mode == PadAction.OFF or boards.state is not NavState.HOLDING:
            return  # landed, taking off, flying a ground command, landing, failsafe: hands off
        sp = self.law.update(obs.frame_time_s, obs.found, obs.dx_m, obs.dy_m, obs.height_m,
                             landing=mode == PadAction.LAND)
        if sp.searching:
            log.info("pad lost: holding and climbing slowly to find it")
        if sp.touchdown:
            boards.land()  # the final descent is the vehicle's own landing, straight down
            return
        boards.airframe.set_velocity(sp.forward_m_s, sp.right_m_s, sp.up_m_s, 0.0, None)
