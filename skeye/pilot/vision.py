"""The pilot's vision: landing-pad detection on every new camera frame, and what PAD_MODE does.

How this works: the vision runs on its own worker thread (:class:`skeye.workers.Worker`), never
in the pilot's control loop. When the robot's camera has announced a frame newer than the last
one processed (``SEN {Type Camera}``), the worker fetches the newest frame from the image server
(RAW, with its META header: frame number and sim time), turns it grey and gives it to
:func:`skeye.vision.detector.detect` with the camera's float field of view and the INS roll and
pitch, exactly as ``skeye vision detect`` does on a real camera image. The estimate goes into a
bounded queue (the oldest is dropped when it is full); the control loop's :meth:`PadVision.step`
drains it into the boards' :class:`PadController` (the PAD packet) without ever waiting on the
camera. A camera error (timeout, reset, refused, image server restarted, a device unplugged)
counts as "pad not seen" for that frame, and the pad modes hold still (no search) until a
frame comes again (``stats.camera_lost``); the camera reconnects on the next frame, and since
a failed request drops its connection, a late frame never answers a later request. No value
kills the worker: an attitude the camera cannot look at the ground through (roll or pitch not
finite, or at or beyond 90 deg: a tumbling vehicle) is "pad not seen" without running the
detector, and any other failure on one frame is counted in :class:`VisionStats` (``errors``,
``last_error``), logged once per kind (one line for skeye's own errors, which name their
cause; with a traceback for any other exception, a bug), and that frame is "pad not seen"; the
worker goes on with the next. When the pilot re-attaches to a new robot,
:meth:`PadVision.rebind` points the vision at it. In lockstep the loop waits for the
detector's result on the frame of the step it just made, however long it takes, so a run is
the same on any machine at any load (the simulator is paused meanwhile, so nothing flies
unwatched); only a detector still not done after ``lockstep_wait_s`` (``LOCKSTEP_WAIT_S``, a
hang guard) stops the step with :class:`VisionStalled` naming the frame, never a flight that
goes on without it.

Frame times (docs/pilot.md, "Frame times"): by default a frame's time is when it reached the
pilot, as a host sees a USB webcam's frames: the control loop notes the sim time at which each
frame's announcement arrived (plus a configurable, seeded host jitter), and the capture latency
stays unknown to it, so the camera and the IMU disagree as on a real vehicle. ``frame_time =
"capture"`` uses the simulator's exact capture time instead (the comparison case).
``pad_source = "truth"`` (``skeye pilot --pad-source truth``) replaces each detection with the
pad's offset from the simulator's ground truth at the frame's time, the frames still fetched
and detected so the timing is the same: what the vision run would do with a perfect detector.
It reads ground truth, so it is a comparison mode, named so, never a way to fly.

Latency (docs/pilot.md, "Vision latency"): each observation is used ``latency_s`` after its
frame's time (configured, or measured, or as soon as it is done), and the pad hold flies on
it predicted to now: the control loop records the INS pose every tick (:class:`PoseHistory`),
places each detection in the estimate's world frame with the pose at its capture time, and
every control period computes the pad's offset from the pose now. A detection more than
``max_latency_s`` late is refused and said (``stats.too_slow``, a warning): the vehicle holds
still until detections are in time again.

In pad modes the estimate also flies the vehicle through :class:`PadHoldLaw`: HOLD (1) keeps
the pad centre within the deadband at up to the speed limit; LAND (2) descends onto it and
hands over to the vehicle's own landing straight down. Pad navigation acts only while the
vehicle is HOLDING (after take-off, HOLD, or when a commanded motion has finished): a ground
command (velocity, move, goto) suspends it until that motion ends, and PAD_MODE 0 gives the
vehicle back with a hover. Its set-points are limited at the flight envelope's edge
(``OnboardBoards.fly_velocity``): a search does not climb through the ceiling. Nothing here
reads the simulator's ground truth.

With a video sink attached (:meth:`PadVision.attach_video`: the pilot's video port,
:mod:`skeye.pilot.video_server`), every frame the worker looked at goes there too, with the
detector's full result (:func:`wire_detection`), so ground control shows exactly what the
vehicle saw and detected. Handing it over never waits.
"""

from __future__ import annotations

import logging
import math
import queue
import random
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import cv2

from skeye.errors import InvalidArgument, SkeyeError
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.pad import PadObservation
from skeye.pilot.pad_hold import (
    CONTROL_PERIOD_S,
    PadHoldLaw,
    PadHoldParams,
    design_delay,
    loop_gains,
)
from skeye.pilot.pad_track import PadFix, Pose, PoseHistory, locate_pad, offset_now
from skeye.pilot.video_server import CameraFrame
from skeye.vision.calibration import CameraCalibration
from skeye.vision.detector import NOT_FOUND, PadEstimate, detect
from skeye.vision.pad import SKEYE_4, PadDefinition
from skeye.wire.packets import NavState, PadAction
from skeye.wire.video import Detection, RingEllipse
from skeye.workers import Worker

log = logging.getLogger(__name__)


def wire_detection(est: PadEstimate, roll_rad: float | None,
                   pitch_rad: float | None) -> Detection:
    """The detector's estimate as the video protocol carries it (docs/protocols/video.md)."""

    def pair(p: tuple[float, float] | None) -> tuple[float, float] | None:
        return None if p is None else (float(p[0]), float(p[1]))

    return Detection(
        found=bool(est.found),
        center_px=pair(est.center_px),
        height_m=None if est.height_m is None else float(est.height_m),
        offset_cam_m=pair(est.offset_cam_m),
        offset_body_m=pair(est.offset_body_m),
        rings=tuple(int(r) for r in est.rings),
        ellipses=tuple(
            RingEllipse(int(e.ring), e.border, (float(e.center_px[0]), float(e.center_px[1])),
                        (float(e.semi_axes_px[0]), float(e.semi_axes_px[1])),
                        float(e.angle_rad))
            for e in est.ellipses
        ),
        quality=float(est.quality),
        roll_rad=roll_rad,
        pitch_rad=pitch_rad,
    )


class VisionStalled(SkeyeError):
    """In lockstep, the detector was not done with the step's frame after ``lockstep_wait_s``:
    the step stops here rather than fly on without that frame's detection (which it would
    apply a period or more late: another flight, chosen by the machine's load)."""


@dataclass
class VisionStats:
    """What the vision loop has done (for tests, benchmarks and the log)."""

    frames: int = 0
    detections: int = 0
    errors: int = 0
    last_error: str = ""
    video_errors: int = 0  # frames the video port could not carry (logged)
    applied: int = 0  # observations handed to the boards and the pad hold
    processing_s: float = 0.0  # the newest frame's fetch + detection time (wall clock)
    latency_s: float = 0.0  # capture to use of the newest observation applied (sim time)
    max_latency_s: float = 0.0
    too_slow: str = ""  # why the vision is too slow to hold on (empty while it is not)
    too_slow_count: int = 0  # observations refused for being too old
    bad_attitude: int = 0  # frames not looked at: the attitude points the camera off the ground
    camera_lost: str = ""  # why the camera gives no frames (empty while it does)


def looks_at_ground(roll_rad: float, pitch_rad: float) -> bool:
    """Whether a downward camera at this attitude sees the ground plane at all: roll and pitch
    finite and within (-90, 90) deg, the detector's domain."""
    limit = math.pi / 2
    return (math.isfinite(roll_rad) and math.isfinite(pitch_rad)
            and abs(roll_rad) < limit and abs(pitch_rad) < limit)


PAD_SOURCES = ("vision", "truth")
"""Where pad observations come from: the detector, or (for comparison only) ground truth."""
CAMERA_BELOW_CENTRE_M = 0.035  # the Hummingbird's downward camera mount (robot file)
PAD_SURFACE_M = 0.001  # the pad's printed surface above the ground (docs/landing-pad.md)
FRAME_TIMES = ("arrival", "capture")
"""What a frame's time is to the pilot: when it arrived (a host's view), or its exact capture."""
ARRIVALS_KEPT = 64  # frames whose arrival time is remembered

MAX_VISION_LATENCY_S = 1.0
"""Observations older than this when they arrive are too slow to hold on (docs/pilot.md):
the prediction flies on the estimator's motion over the latency, and the onboard estimate's
velocity error (a few cm/s, docs/physics.md) makes it wrong by the pad-hold deadband (5 cm)
after about a second."""

VISION_RECOVERY_S = 1.0
"""Once too slow, the vision counts as in time again only after its detections have all been
in time for this long (sim time): one late detection among prompt ones does not flip the pad
modes between holding still and navigating (a design choice, docs/pilot.md)."""

LOCKSTEP_WAIT_S = 120.0
"""In lockstep, how long (wall clock) the loop waits for the detector's result on a frame
before it raises :class:`VisionStalled`: a guard against a hung detector, not a deadline a
slow machine may miss. The fetch of a frame includes its render in ``skeye.gym``, which the
simulator's camera system gives up on after 60 s (``skeye.sim.render.RENDER_TIMEOUT_S``), and a
lockstep pilot's image client after at least 70 s
(``skeye.control.connection.LOCKSTEP_IMAGE_TIMEOUT_S``); this outlasts both. Measured 2026-11-28
(webcam profile, software GL, pure Python, 2 cores): a PadLanding-v0 episode's first frame
(the renderer's first) took 3.1 s at load 7 and 5.3 s at load 13.5; at load 17 it took more
than the 5 s this was until then."""

WARNING_REPEAT_S = 60.0
"""At most one "too slow" warning a minute in the log; the ones held back are counted."""


class RateLimited:
    """At most one message per ``period_s`` (``clock``: wall seconds); :meth:`say` returns the
    text to log, with how many were held back since the last one, or None to hold it back."""

    def __init__(self, period_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.period_s = period_s
        self._clock = clock
        self._said_at = -math.inf
        self._held = 0

    def say(self, text: str) -> str | None:
        now = self._clock()
        if now - self._said_at < self.period_s:
            self._held += 1
            return None
        held = (f" ({self._held} more such in the last {now - self._said_at:.0f} s)"
                if self._held else "")
        self._said_at, self._held = now, 0
        return text + held


@dataclass
class LateVision:
    """Whether the vision is too slow to hold on, with hysteresis: one late detection turns
    it on at once (safety first: the pad modes hold still); only ``recovery_s`` of detections
    all in time turn it off. :meth:`update` returns the new state when it changes, else None."""

    recovery_s: float = VISION_RECOVERY_S
    on: bool = False
    in_time_since_s: float | None = None

    def update(self, late: bool, now_s: float) -> bool | None:
        if late:
            self.in_time_since_s = None
            if self.on:
                return None
            self.on = True
            return True
        if not self.on:
            return None
        if self.in_time_since_s is None or now_s < self.in_time_since_s:
            # (a clock that went back, a restarted simulator under a re-attached pilot, counts
            # from now: kept, the old clock's time held the flag on until the new one passed it)
            self.in_time_since_s = now_s
        if now_s - self.in_time_since_s < self.recovery_s - 1e-9:
            return None
        self.on, self.in_time_since_s = False, None
        return False


class PadVision:
    """Detector + pad navigation: a worker thread detects, the pilot loop navigates.

    ``latency_s``: when a detection is used, in sim time after its frame's capture: 0 applies
    it as soon as the detector is done (the real delay in realtime, none in lockstep); N > 0
    applies it at capture + N (in lockstep the detector is then busy until that time and takes
    the newest frame after it, as a real pipeline does); None ("measured") uses each frame's
    measured processing time (wall clock) as its latency in lockstep. ``predict``: fly on the
    pad offset predicted to now from each detection's capture pose (:mod:`skeye.pilot.pad_track`);
    False flies on the detections as they arrive (the comparison case). ``lockstep_wait_s``: in
    lockstep, how long :meth:`step` waits for a frame's detection before it raises
    :class:`VisionStalled` (wall clock; :data:`LOCKSTEP_WAIT_S`).
    """

    def __init__(
        self,
        boards: OnboardBoards,
        robot: Any,
        lock: threading.Lock | threading.RLock,
        *,
        fov_h_rad: float,
        pad: PadDefinition = SKEYE_4,
        params: PadHoldParams | None = None,
        lockstep: bool = False,
        lockstep_wait_s: float = LOCKSTEP_WAIT_S,
        queue_size: int = 4,
        calibration: CameraCalibration | None = None,
        latency_s: float | None = 0.0,
        predict: bool = True,
        max_latency_s: float = MAX_VISION_LATENCY_S,
        frame_time: str = "arrival",
        frame_jitter_s: float = 0.0,
        seed: int = 0,
        pad_source: str = "vision",
    ) -> None:
        if queue_size < 1 or not lockstep_wait_s > 0:
            raise InvalidArgument(f"queue_size >= 1 and lockstep_wait_s > 0 needed "
                             f"({queue_size}, {lockstep_wait_s})")
        if latency_s is not None and not (math.isfinite(latency_s) and latency_s >= 0):
            raise InvalidArgument(f"vision latency must be >= 0 s, got {latency_s!r}")
        if not (math.isfinite(max_latency_s) and max_latency_s > 0):
            raise InvalidArgument(f"max vision latency must be > 0 s, got {max_latency_s!r}")
        if frame_time not in FRAME_TIMES:
            raise InvalidArgument(f"frame time must be one of {', '.join(FRAME_TIMES)}, "
                                  f"got {frame_time!r}")
        if not (math.isfinite(frame_jitter_s) and 0.0 <= frame_jitter_s <= 1.0):
            raise InvalidArgument(f"frame jitter must be 0..1 s, got {frame_jitter_s!r}")
        if pad_source not in PAD_SOURCES:
            raise InvalidArgument(f"pad source must be one of {', '.join(PAD_SOURCES)}, "
                                  f"got {pad_source!r}")
        self.pad_source = pad_source
        self._truth: list[tuple[float, float, float, float, float]] = []  # t, n, e, d, yaw
        self.frame_time = frame_time
        self.frame_jitter_s = frame_jitter_s
        self._jitter_rng = random.Random(seed)
        self._arrivals: dict[int, float] = {}  # frame number -> when the pilot saw it (sim)
        self._arrivals_lock = threading.Lock()
        self.boards = boards
        self.robot = robot
        self.lock = lock
        self.fov_h_rad = fov_h_rad
        self.calibration = calibration  # skeye calibrate's camera.toml; None: ideal pinhole
        self.pad = pad
        self.latency_s = latency_s
        self.predict = predict
        self.max_latency_s = max_latency_s
        self._explicit_gains = params is not None
        self.base_params = params or PadHoldParams()
        self.law = PadHoldLaw(self.base_params)
        self.stats = VisionStats()
        self._late = LateVision()
        self._warnings = RateLimited(WARNING_REPEAT_S)  # the "too slow" warnings
        self.lockstep = lockstep
        self.lockstep_wait_s = lockstep_wait_s
        self.history = PoseHistory(max_latency_s + 1.0)
        self._last_frame = 0
        self._mode = PadAction.OFF
        self._observations: queue.Queue[tuple[PadObservation, float]] = queue.Queue(queue_size)
        self._kick = threading.Event()
        self._stop = threading.Event()
        self._done = threading.Condition()
        self._attempted = 0  # newest announced frame the worker has dealt with
        self._permitted: Any = None  # lockstep: the frame the worker takes (as the loop saw it)
        self._busy_until_s = -math.inf  # lockstep: the detector's result is not out before
        self._pending: list[tuple[float, PadObservation]] = []  # (apply at, observation)
        self._fix: PadFix | None = None  # the pad where the newest detection put it
        self._missed_since_s: float | None = None  # capture time of the first miss since
        self._newest_capture_s = -math.inf
        self._last_nav_s = -math.inf
        self._worker: Worker | None = None
        self._video: Callable[[CameraFrame], None] | None = None

    def rebind(self, robot: Any) -> None:
        """Look through ``robot``'s camera from now on (the pilot re-attached to a new robot):
        its frame numbers start again, and nothing seen through the old one is kept."""
        with self._done:
            self.robot = robot
            self._last_frame = 0
            self._attempted = 0
            self._permitted = None
            self._busy_until_s = -math.inf
            self._pending = []
            self._fix = None
            self._missed_since_s = None
            self._newest_capture_s = -math.inf
            self._last_nav_s = -math.inf
            self.history = PoseHistory(self.max_latency_s + 1.0)
        self._frames_on_demand()  # (not under _done: it may wait for the camera's lock)
        while True:
            try:
                self._observations.get_nowait()
            except queue.Empty:
                break

    def _frames_on_demand(self) -> None:
        """Lockstep with a given latency: the simulator renders only the frames the detector
        takes (it takes the newest whenever it is free, a few of a 30 frames/s camera's), not
        every frame ahead; a camera that can say so (the simulator's, through ``--images``) is
        told. A realtime vision keeps every frame rendered ahead (it wants the newest at once),
        and so does a ``measured`` latency: a frame's fetch is part of the time it measures, and
        waiting for the simulator's render there would count the simulator's work as the
        vehicle's."""
        tell = getattr(self.robot.camera, "set_prerender", None)
        if self.lockstep and self.latency_s is not None and tell is not None:
            tell(False)

    def attach_video(self, sink: Callable[[CameraFrame], None] | None) -> None:
        """Hand every frame looked at, with its detection, to ``sink`` (it must not block)."""
        self._video = sink

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> PadVision:
        if self._worker is None:
            self._frames_on_demand()
            self._worker = Worker(self._run, "pilot-vision", on_error=self._on_error).start()
        return self

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the worker (idempotent). Its camera is closed first: a frame request waiting
        on a silent image server (a frozen simulator) fails at once instead of holding the
        worker for the camera's timeout."""
        self._stop.set()
        self._kick.set()
        with self._done:  # a loop waiting for a detection in lockstep goes on at once
            self._done.notify_all()
        close_camera = getattr(getattr(self.robot, "camera", None), "close", None)
        if close_camera is not None:
            close_camera()
        if self._worker is not None:
            self._worker.join(timeout_s)

    def __enter__(self) -> PadVision:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _on_error(self, exc: BaseException) -> None:
        with self._done:
            self._done.notify_all()

    # -- the control loop's side -------------------------------------------------------------
    def _pose_now(self) -> Pose:
        snap = self.boards.airframe.snapshot()  # the INS estimate, as the boards fly on it
        n, e, d = snap.pos_ned_m
        pose = Pose(snap.time_s, n, e, d, *snap.rpy_rad)
        self.history.add(pose)
        return pose

    def step(self) -> None:
        """Called by the pilot loop after each tick: hand due observations to the boards and
        fly the pad modes. A vision thread that died anyway (a bug outside its per-frame guard)
        is reported (``stats``, the log) and started again: the pad is not seen meanwhile."""
        worker = self.start()._worker
        assert worker is not None
        if worker.error is not None:
            self.stats.errors += 1
            self.stats.last_error = f"vision thread failed: {worker.error!r}"
            log.error("%s; starting it again", self.stats.last_error)
            self._worker = None
            worker = self.start()._worker
            assert worker is not None
        now = self._pose_now()
        lost = getattr(self.robot.camera, "lost", None)  # a source that knows it has no frames
        if lost and not self.stats.camera_lost:
            log.warning("camera lost (pad not seen; the pad modes hold still until frames "
                        "come again): %s", lost)
            self.stats.camera_lost = lost
            with self.lock:
                self.boards.pad.on_frame(PadObservation(now.time_s, False))
        latest = self.robot.camera.latest
        if latest is not None:
            self._note_arrival(latest.frame, now.time_s)
        if self.pad_source == "truth":
            self._note_truth()
        if not self.lockstep:
            self._kick.set()
        elif latest is not None and now.time_s >= self._busy_until_s - 1e-9:
            self._permitted = latest  # the detector is free: it takes the newest frame
            self._kick.set()
            self._await_detection(latest.frame, worker)
        while True:
            try:
                obs, processing_s = self._observations.get_nowait()
            except queue.Empty:
                break
            self.stats.processing_s = processing_s
            if self.latency_s is None:
                due = obs.frame_time_s + processing_s if self.lockstep else now.time_s
            else:
                due = obs.frame_time_s + self.latency_s
            if self.lockstep:
                self._busy_until_s = max(self._busy_until_s, due)
            self._pending.append((due, obs))
        self._pending.sort(key=lambda item: item[0])
        while self._pending and self._pending[0][0] <= now.time_s + 1e-9:
            _, obs = self._pending.pop(0)
            with self.lock:
                self.boards.pad.on_frame(obs)
                self._apply(obs, now)
        if self.predict:
            with self.lock:
                self._navigate_tick(now)

    def _await_detection(self, frame: int, worker: Worker) -> None:
        """Lockstep: wait until the worker is done with ``frame`` (or has died, or the vision
        is closed). How long it takes never changes the flight: the simulator is paused, and
        the step goes on only with the frame's result in the queue. Until 2026-11-28 the wait
        ended after 5 s and the step flew on without it, applying it a period or more later:
        on a loaded machine (load 17 on 2 cores) the first frame of a webcam episode took more
        than that, and PadLanding-v0's seed 100 landed 4.3 cm from the pad instead of 5.4.

        Raises:
            VisionStalled: still not done after ``lockstep_wait_s`` (a hung detector).
        """
        with self._done:
            done = self._done.wait_for(
                lambda: self._attempted >= frame or not worker.alive or self._stop.is_set(),
                self.lockstep_wait_s,
            )
        if not done:
            raise VisionStalled(
                f"vision: the detector has not finished frame {frame} after "
                f"{self.lockstep_wait_s:g} s of wall time (lockstep waits for each frame's "
                f"detection rather than fly on without it); is it hung?")

    def _apply(self, obs: PadObservation, now: Pose) -> None:
        """One observation reaches the pad hold, ``now.time_s - obs.frame_time_s`` late."""
        stats = self.stats
        stats.applied += 1
        age = max(0.0, now.time_s - obs.frame_time_s)
        stats.latency_s = age
        stats.max_latency_s = max(stats.max_latency_s, age)
        then = self.history.at(obs.frame_time_s) if obs.found else None
        late = age > self.max_latency_s or (obs.found and then is None)
        if late:
            stats.too_slow_count += 1
        change = self._late.update(late, now.time_s)
        if change is True:
            stats.too_slow = (f"vision too slow to hold: a detection arrived {age:.2f} s "
                              f"after its frame (limit {self.max_latency_s:.2f} s)")
            text = self._warnings.say(f"{stats.too_slow}; pad navigation holds still until "
                                      f"detections are in time for {self._late.recovery_s:g} s")
            if text is not None:
                log.warning("%s", text)
            self.boards.pad.vision_too_slow(True)
        elif change is False:
            log.info("vision in time again (%.2f s) for %g s: pad navigation resumes", age,
                     self._late.recovery_s)
            stats.too_slow = ""
            self.boards.pad.vision_too_slow(False)
        if self._late.on:
            return
        self._newest_capture_s = max(self._newest_capture_s, obs.frame_time_s)
        if obs.found and then is not None:
            self._fix = locate_pad(obs.dx_m, obs.dy_m, obs.height_m, then)
            self._missed_since_s = None
        elif self._missed_since_s is None:
            self._missed_since_s = obs.frame_time_s
        if not self.predict:
            self._navigate(obs.found, obs.dx_m, obs.dy_m, obs.height_m, now)

    def _navigate_tick(self, now: Pose) -> None:
        """Predicting: fly on the pad offset predicted to now, once per control period."""
        if now.time_s - self._last_nav_s < CONTROL_PERIOD_S - 1e-6:
            return
        self._last_nav_s = now.time_s
        if self._newest_capture_s == -math.inf:
            return  # nothing seen yet (the first detection is still on its way)
        fix = self._fix
        seen = fix is not None and (
            self._missed_since_s is None
            or self._newest_capture_s - fix.capture_s < self.law.p.lost_after_s
        )
        if fix is None or not seen:
            self._navigate(False, 0.0, 0.0, 0.0, now)
            return
        forward, right, height = offset_now(fix, now)
        self._navigate(True, forward, right, height, now)

    # -- the worker's side -------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            self._kick.wait(0.05)
            self._kick.clear()
            # In lockstep the worker takes the frame the loop let it take, as the loop saw it
            # (the loop waits for it), never one it sees itself: a source's newest can move
            # between the two looks, and a worker waiting for the loop's frame while the loop
            # waits for the worker's was a deadlock (until 2026-11-28, with a sim:// camera).
            latest = self._permitted if self.lockstep else self.robot.camera.latest
            if latest is None or self._stop.is_set():
                continue
            if latest.frame > self._last_frame:
                t0 = time.perf_counter()
                try:
                    obs = self._process(latest.frame, latest.time_s)
                except Exception as exc:  # one frame's failure, whatever the value: not seen
                    obs = self._failed(latest.frame, latest.time_s, exc)
                if obs is not None:
                    self._put((obs, time.perf_counter() - t0))
            elif not self.lockstep or latest.frame <= self._attempted:
                continue  # (the loop is not waiting for it: nothing to say)
            # (lockstep: a frame no newer than the last fetched is dealt with as well)
            with self._done:
                self._attempted = max(self._attempted, latest.frame)
                self._done.notify_all()

    def _note_truth(self) -> None:
        """Keep the simulator's ground truth (``--pad-source truth`` only): the last 2 s."""
        gt = self.robot.ground_truth.latest
        if gt is None or (self._truth and self._truth[-1][0] >= gt.time_s):
            return
        n, e, d = gt.position_ned_m
        with self._arrivals_lock:
            self._truth.append((gt.time_s, n, e, d, gt.rpy_rad[2]))
            while self._truth and self._truth[0][0] < gt.time_s - 2.0:
                self._truth.pop(0)

    def _truth_observation(self, frame_s: float, capture_s: float) -> PadObservation:
        """The pad's offset and height from ground truth at the frame's capture, ``capture_s``
        (interpolated between the rows around it; the pad at the world origin, as in the pad
        and indoor worlds), stamped ``frame_s`` as a detection is: a perfect detector, for
        comparison. (Until 2026-11-28 it took the last row kept at or before ``frame_s``: by
        default the frame's arrival, a later moment than the image's, and at any frame time
        a row up to the pilot's loop interval old; E1, which flies with the capture as the
        frame time, read a 0.47 cm, 1.27 % height error for it, 0.05 cm, 0.14 % now.)"""
        with self._arrivals_lock:
            rows = list(self._truth)
        if not rows:
            return PadObservation(frame_s, False)
        later = next((k for k, row in enumerate(rows) if row[0] > capture_s), len(rows))
        if later == 0 or later == len(rows):  # outside the rows kept: the nearest
            _, n, e, d, yaw = rows[min(later, len(rows) - 1)]
        else:
            (t0, *a), (t1, *b) = rows[later - 1], rows[later]
            w = (capture_s - t0) / (t1 - t0)
            n, e, d = (a[k] + w * (b[k] - a[k]) for k in range(3))
            yaw = a[3] + w * math.remainder(b[3] - a[3], math.tau)
        c, s = math.cos(yaw), math.sin(yaw)
        forward, right = c * -n + s * -e, -s * -n + c * -e
        height = -d - CAMERA_BELOW_CENTRE_M - PAD_SURFACE_M
        return PadObservation(frame_s, True, 0b1111, forward, right, height, 1.0)

    def _note_arrival(self, frame: int, now_s: float) -> None:
        """The sim time the pilot first saw ``frame`` announced, plus the host's jitter."""
        with self._arrivals_lock:
            if frame in self._arrivals:
                return
            jitter = self._jitter_rng.uniform(0.0, self.frame_jitter_s) if self.frame_jitter_s \
                else 0.0
            self._arrivals[frame] = now_s + jitter
            while len(self._arrivals) > ARRIVALS_KEPT:
                del self._arrivals[min(self._arrivals)]

    def frame_time_s(self, frame: int, capture_s: float) -> float:
        """The time the pilot gives a frame: its arrival (default) or its capture time."""
        if self.frame_time == "capture":
            return capture_s
        with self._arrivals_lock:
            arrived = self._arrivals.get(frame)
            if arrived is None:  # fetched before its announcement was seen: newer than all
                arrived = max(self._arrivals.values(), default=capture_s)
        return max(arrived, capture_s)

    def _failed(self, frame: int, time_s: float, exc: Exception) -> PadObservation:
        """A frame the worker could not handle: counted and said (once per kind of failure:
        one line for skeye's own errors, which name their cause, such as a calibration for
        another image size; with the traceback for any other exception), and the pad is not
        seen in it."""
        stats = self.stats
        stats.errors += 1
        first = not stats.last_error.startswith(type(exc).__name__)
        stats.last_error = f"{type(exc).__name__}: {exc}"
        if first:  # skeye's own error names its cause; another exception is a bug: traced
            log.warning("vision: frame %d failed (pad not seen; said once per kind of "
                        "failure): %s", frame, stats.last_error,
                        exc_info=None if isinstance(exc, SkeyeError) else exc)
        self._last_frame = max(self._last_frame, frame)
        return PadObservation(time_s, False)

    def _put(self, item: tuple[PadObservation, float]) -> None:
        while True:
            try:
                self._observations.put_nowait(item)
                return
            except queue.Full:
                try:
                    self._observations.get_nowait()  # the loop is behind: drop the oldest
                except queue.Empty:
                    pass

    def _process(self, announced: int, announced_time_s: float) -> PadObservation | None:
        """Fetch and detect the newest frame; a failure is "pad not seen", never an exception."""
        camera = self.robot.camera
        try:
            image = camera.image()
        except SkeyeError as exc:
            if self._stop.is_set():  # close() closed the camera under the request
                return None
            self.stats.errors += 1
            self.stats.last_error = str(exc)
            if not self.stats.camera_lost:
                log.warning("camera lost (pad not seen; the pad modes hold still until frames "
                            "come again): %s", exc)
            self.stats.camera_lost = str(exc)
            self._last_frame = announced
            self._stop.wait(0.1)  # do not hammer a server that is down
            return PadObservation(self.frame_time_s(announced, announced_time_s), False)
        if self.stats.camera_lost:
            log.warning("camera frames again: pad navigation resumes")
            self.stats.camera_lost = ""
        if image.frame <= self._last_frame:
            return None
        self._last_frame = image.frame
        frame_s = self.frame_time_s(image.frame, image.time_s)
        # The attitude at the frame's time (the estimator's history), else the newest.
        then = self.history.at(frame_s)
        ins = self.robot.ins.latest
        if then is not None:
            roll, pitch = then.roll_rad, then.pitch_rad
        else:
            roll, pitch = (ins.rpy_rad[0], ins.rpy_rad[1]) if ins is not None else (0.0, 0.0)
        known = then is not None or ins is not None
        t0 = time.perf_counter()
        if looks_at_ground(roll, pitch):
            grey = cv2.cvtColor(image.bgr, cv2.COLOR_BGR2GRAY)
            est = detect(grey, self.fov_h_rad, self.pad, roll_rad=roll, pitch_rad=pitch,
                         calibration=self.calibration)
        else:  # a tumbling vehicle: its camera is not looking down at any pad
            self.stats.bad_attitude += 1
            if self.stats.bad_attitude == 1:
                log.warning("vision: roll %.3f / pitch %.3f rad points the camera away from the "
                            "ground: pad not seen", roll, pitch)
            est = NOT_FOUND
            known = False
        detect_ms = (time.perf_counter() - t0) * 1e3
        self.stats.frames += 1
        video = self._video
        if video is not None:
            attitude = (float(roll), float(pitch)) if known else (None, None)
            try:
                video(CameraFrame(image.frame, frame_s, image.bgr,
                                  wire_detection(est, *attitude), detect_ms))
            except SkeyeError as exc:  # a value the video protocol cannot carry: not served
                self.stats.video_errors += 1
                log.warning("frame %d not served on the video port: %s", image.frame, exc)
        if self.pad_source == "truth":
            return self._truth_observation(frame_s, image.time_s)
        if est.found and est.offset_body_m is not None and est.height_m is not None:
            self.stats.detections += 1
            bits = 0
            for ring in est.rings:
                bits |= 1 << (ring - 1)
            return PadObservation(frame_s, True, bits, est.offset_body_m[0],
                                  est.offset_body_m[1], est.height_m, est.quality)
        return PadObservation(frame_s, False)

    def _gains(self) -> PadHoldParams:
        """The pad-hold gains for this loop's delay (:func:`design_delay`), unless given."""
        if self._explicit_gains:
            return self.base_params
        latency = self.latency_s if self.latency_s is not None else self.stats.latency_s
        kp, ki = loop_gains(design_delay(latency, self.predict))
        return replace(self.base_params, kp=kp, ki=ki)

    def _navigate(self, found: bool, forward_m: float, right_m: float, height_m: float,
                  now: Pose) -> None:
        boards = self.boards
        settings = boards.pad.settings
        mode = settings.mode
        if mode != self._mode:
            self._mode = mode
            base = self._gains()
            self.law = PadHoldLaw(
                replace(
                    base,
                    deadband_m=settings.deadband_m or base.deadband_m,
                    max_speed_m_s=settings.max_speed_m_s or base.max_speed_m_s,
                )
            )
            if mode == PadAction.OFF and boards.state is NavState.HOLDING:
                boards.airframe.hover()
        if mode == PadAction.OFF or boards.state is not NavState.HOLDING:
            return  # landed, taking off, flying a ground command, landing, failsafe: hands off
        if self.stats.too_slow or self.stats.camera_lost:
            boards.airframe.set_velocity(0.0, 0.0, 0.0, 0.0, None)
            return
        sp = self.law.update(now.time_s, found, forward_m, right_m, height_m,
                             landing=mode == PadAction.LAND,
                             altitude_m=boards.home_ned_m[2] - now.down_m)
        if sp.searching:
            log.info("pad not seen: holding, climbing to widen the view up to the search ceiling")
        if sp.touchdown:
            boards.land()  # the final descent is the vehicle's own landing, straight down
            return
        boards.fly_velocity(sp.forward_m_s, sp.right_m_s, sp.up_m_s)  # inside the envelope
