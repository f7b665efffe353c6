"""Landing-pad mode of the onboard computer: the stored PAD_MODE and the PAD report.

How this works: ``PadController`` keeps what ground control asked for (PAD_MODE: mode,
deadband, maximum correction speed) and the latest pad estimate. The pilot calls ``report()``
for every PAD packet. ``skeye pilot --images`` feeds it: ``skeye.pilot.vision.PadVision`` runs
the detector on every camera frame and calls ``on_frame``; without camera images nothing is
fed and ``report()`` says ``found=0`` (nothing here invents a detection). A pad landing (LAND)
ends with the touchdown: the mode goes back to OFF (``landing_finished``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, replace

from skeye.wire.packet_units import PadModeSi, PadSi, pad_mode_to_si, pad_report_from_si
from skeye.wire.packets import PadAction, PadMode, PadReport


@dataclass(frozen=True)
class PadObservation:
    """One camera frame's pad estimate, in SI (body FRD offsets of the pad centre)."""

    frame_time_s: float
    found: bool
    rings: int = 0  # bit per identified ring
    dx_m: float = 0.0
    dy_m: float = 0.0
    height_m: float = 0.0
    quality: float = 0.0  # 0..1


class PadController:
    """Stored pad mode and latest estimate; the hook the vision pipeline feeds.

    For each camera frame, ``PadVision`` calls ``on_frame(observation)`` with the detector's
    estimate (``skeye.vision``'s result converted to a ``PadObservation``: pad centre offset in
    metres in the body frame, height, identified rings, quality). ``report()`` carries it in
    PAD packets, and ``mode`` says what the navigation does with it (OFF: nothing; HOLD: keep
    the pad centre within ``deadband_m`` at up to ``max_speed_m_s``; LAND: the same, descending
    onto it, until the touchdown ends the mode). Without images no frame is fed and the PAD
    packet reports ``found=0``.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._settings = PadModeSi(PadAction.OFF, deadband_m=0.0, max_speed_m_s=0.0)
        self._latest: PadObservation | None = None
        self._too_slow = False
        self._listeners: list[Callable[[PadObservation], None]] = []

    @property
    def settings(self) -> PadModeSi:
        """The last PAD_MODE accepted, in SI."""
        return self._settings

    @property
    def mode(self) -> PadAction:
        return self._settings.mode

    def set_mode(self, msg: PadMode) -> None:
        """Store a PAD_MODE command (the codec already checked its ranges)."""
        with self._lock:
            self._settings = pad_mode_to_si(msg)

    def landing_finished(self) -> None:
        """The vehicle touched down: a pad landing (LAND) is over, so the mode ends (OFF,
        as PX4's precision landing ends with the landing). HOLD and OFF stay as they are."""
        with self._lock:
            if self._settings.mode is PadAction.LAND:
                self._settings = replace(self._settings, mode=PadAction.OFF)

    def stop(self) -> None:
        """HOLD, or the sticks took over (any pad mode is an automatic mode they end): mode
        OFF, as PX4's precision landing ends when the sticks override it or Hold is chosen."""
        with self._lock:
            self._settings = replace(self._settings, mode=PadAction.OFF)

    def on_frame(self, observation: PadObservation) -> None:
        """Record the estimate from one camera frame (called by the vision pipeline) and hand
        it to every listener (the MAVLink endpoint's LANDING_TARGET); listeners must not block."""
        with self._lock:
            self._latest = observation
            listeners = list(self._listeners)
        for listener in listeners:
            listener(observation)

    def add_listener(self, listener: Callable[[PadObservation], None]) -> None:
        """Call ``listener`` with every observation ``on_frame`` records."""
        with self._lock:
            self._listeners.append(listener)

    def vision_too_slow(self, too_slow: bool) -> None:
        """The vision pipeline says whether its detections come too late to hold on (the pad
        modes then hold still): carried in every PAD packet (``vision``)."""
        with self._lock:
            self._too_slow = too_slow

    def report(self) -> PadReport:
        """The PAD packet: the latest estimate, or ``found=0`` when there is none."""
        with self._lock:
            obs, slow = self._latest, self._too_slow
        if obs is None or not obs.found:
            frame_time_s = 0.0 if obs is None else obs.frame_time_s
            return pad_report_from_si(PadSi(False, 0, 0.0, 0.0, 0.0, 0.0, frame_time_s, slow))
        return pad_report_from_si(PadSi(True, obs.rings, obs.dx_m, obs.dy_m, obs.height_m,
                                        obs.quality, obs.frame_time_s, slow))
