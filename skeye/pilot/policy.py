"""Policies in the pilot: what a policy observes, what its actions mean, and ``--policy``.

How this works: a *policy* is a function from an observation to an action (``policy(obs) ->
action``), written by hand or learned in skeye's Gymnasium environments (:mod:`skeye.gym`,
docs/gym.md). This module is the one definition of both sides of that function, used by the
environments and by the pilot alike, so a policy sees the same numbers in either:

- the *state* (:data:`STATE_FIELDS`, :func:`state_vector`): what the board knows, from the
  pilot's :class:`~skeye.pilot.airframe.Snapshot`: the onboard estimate (position from home,
  velocity, attitude), the gyro's rates, the accelerometer's specific force, and whether the
  vehicle is landed;
- the *pad* (:data:`PAD_FIELDS`, :func:`pad_vector`): the pilot's own pad detection, the
  :class:`~skeye.pilot.pad.PadObservation` its vision hands the boards
  (:class:`~skeye.pilot.vision.PadVision`: the detector on each new camera frame, used
  ``latency_s`` after the frame's capture), and its age;
- the *image* (:func:`grey_image`): the newest camera frame that vision looked at, grey, scaled
  to the policy's size with area averaging.

:func:`policy_observation` assembles them for an observation kind (:data:`OBSERVATIONS`):
``"pad"`` is one float32 vector (state, then pad), ``"image"`` a dict of the state vector and
the image. Actions are float vectors in [-1, 1] (clipped), scaled by the vehicle's own limits
(:class:`ActionLimits`, the robot file's ``[controller]``): :func:`velocity_setpoint` (forward,
right, up, yaw rate: the pilot's ``set_velocity``, the simulator's velocity ``DRIVE``) and
:func:`attitude_setpoint` (roll, pitch, yaw rate, thrust: the AscTec sticks).

In the pilot (``skeye pilot --images ... --policy module:callable``), :class:`PolicyPilot` takes
the place of the pad-hold law: while ground control's PAD_MODE is HOLD or LAND and the vehicle
is HOLDING, it calls the policy once per control period with the observation of that moment
and flies its velocity set-point; PAD_MODE 0 hands the vehicle back with a hover; a touchdown
ends a LAND as it ends the pad-hold law's. The vision keeps detecting and reporting (the PAD
packet, the video port) but no longer flies (:class:`DetectOnlyVision`). :func:`load_policy`
imports the callable.
"""

from __future__ import annotations

import importlib
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, NoReturn

import cv2
import numpy as np

from skeye.errors import ConfigError, InvalidArgument, LocalProtocolError
from skeye.pilot.airframe import Snapshot
from skeye.pilot.boards import OnboardBoards
from skeye.pilot.pad import PadController, PadObservation
from skeye.pilot.pad_track import Pose
from skeye.pilot.video_server import CameraFrame
from skeye.pilot.vision import PadVision
from skeye.wire.packets import NavState, PadAction

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]

STATE_FIELDS: Final = (
    "north_m", "east_m", "down_m",  # onboard estimate, from home (the take-off point)
    "north_m_s", "east_m_s", "down_m_s",  # onboard estimate, NED
    "roll_rad", "pitch_rad", "yaw_rad",  # onboard estimate, (-pi, pi]
    "roll_rate_rad_s", "pitch_rate_rad_s", "yaw_rate_rad_s",  # gyro, body FRD
    "accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2",  # accelerometer, body FRD (about -9.8 z)
    "landed",  # 1 when the vehicle reports itself on the ground, else 0
)
"""The state vector's entries, in order (:func:`state_vector`)."""

_G = 9.80665
STATE_HIGH: Final = np.array(
    (1e5, 1e5, 1e5, 150.0, 150.0, 150.0, math.pi, math.pi, math.pi,
     math.radians(2000.0), math.radians(2000.0), math.radians(2000.0),
     16 * _G, 16 * _G, 16 * _G, 1.0), dtype=np.float32)
"""The state's bounds (low = -high, but ``landed`` 0..1): the simulator's runaway limits for
position and speed, pi for angles, and the MPU-6050's largest ranges for the gyro (2000 deg/s)
and the accelerometer (16 g), where a real IMU saturates: the state is clipped to them."""
STATE_LOW: Final = np.concatenate((-STATE_HIGH[:-1], np.zeros(1, dtype=np.float32)))

PAD_FIELDS: Final = (
    "pad_found",  # 1 when the newest detection found the pad, else 0 (its figures are then 0)
    "pad_forward_m", "pad_right_m",  # the pad centre's offset in the level body frame
    "pad_height_m",  # the camera's height above the pad
    "pad_quality",  # the detector's quality, 0..1
    "pad_age_s",  # now minus the capture time of that detection's frame (-1 before any)
)
"""The pad vector's entries, in order (:func:`pad_vector`)."""

PAD_LOW: Final = np.array((0.0, -1e3, -1e3, 0.0, 0.0, -1.0), dtype=np.float32)
PAD_HIGH: Final = np.array((1.0, 1e3, 1e3, 1e3, 1.0, 1e3), dtype=np.float32)
"""The pad's bounds (clipped to them; an age over 1000 s reads 1000)."""

VELOCITY_ACTION: Final = ("forward", "right", "up", "yaw_rate")
ATTITUDE_ACTION: Final = ("roll", "pitch", "yaw_rate", "thrust")
OBSERVATIONS: Final = ("pad", "image")
DEFAULT_IMAGE_SIZE: Final = (80, 60)
"""(width, height) of the image observation: a tenth of the camera's 800x600."""


def _wrap_pi(angle_rad: float) -> float:
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def state_vector(snap: Snapshot, home_ned_m: Vec3) -> np.ndarray:
    """The state (:data:`STATE_FIELDS`) from the pilot's snapshot, as float32."""
    n, e, d = snap.pos_ned_m
    roll, pitch, yaw = snap.rpy_rad
    state = np.array(
        (n - home_ned_m[0], e - home_ned_m[1], d - home_ned_m[2], *snap.vel_ned_m_s,
         _wrap_pi(roll), _wrap_pi(pitch), _wrap_pi(yaw), *snap.rates_frd_rad_s,
         *snap.specific_force_frd_m_s2, 1.0 if snap.landed else 0.0),
        dtype=np.float32,
    )
    return np.clip(state, STATE_LOW, STATE_HIGH)


def pad_vector(observation: PadObservation | None, now_s: float) -> np.ndarray:
    """The pad (:data:`PAD_FIELDS`) from the newest observation the vision applied."""
    if observation is None:
        return np.array((0.0, 0.0, 0.0, 0.0, 0.0, -1.0), dtype=np.float32)
    age = max(0.0, now_s - observation.frame_time_s)
    if not observation.found:
        pad = np.array((0.0, 0.0, 0.0, 0.0, 0.0, age), dtype=np.float32)
    else:
        pad = np.array((1.0, observation.dx_m, observation.dy_m, observation.height_m,
                        observation.quality, age), dtype=np.float32)
    return np.clip(pad, PAD_LOW, PAD_HIGH)


def grey_image(bgr: np.ndarray | None, size: tuple[int, int]) -> np.ndarray:
    """A camera frame (BGR, as the pilot's camera gives it) as the policy's image: grey,
    ``size`` = (width, height), shape (height, width, 1) uint8; black before the first."""
    width, height = size
    if bgr is None:
        return np.zeros((height, width, 1), dtype=np.uint8)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    if grey.shape != (height, width):
        grey = cv2.resize(grey, (width, height), interpolation=cv2.INTER_AREA)
    return grey.reshape(height, width, 1)


def policy_observation(
    kind: str, snap: Snapshot, home_ned_m: Vec3, pad: PadObservation | None,
    image_bgr: np.ndarray | None = None, image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
) -> np.ndarray | dict[str, np.ndarray]:
    """The observation of kind ``"pad"`` (state + pad, one vector) or ``"image"`` (a dict:
    ``state`` = state + pad, ``image`` = the grey frame)."""
    state = np.concatenate((state_vector(snap, home_ned_m), pad_vector(pad, snap.time_s)))
    if kind == "pad":
        return state
    if kind == "image":
        return {"state": state, "image": grey_image(image_bgr, image_size)}
    raise InvalidArgument(f"observation must be one of {list(OBSERVATIONS)}, got {kind!r}")


@dataclass(frozen=True)
class ActionLimits:
    """What an action of 1 means: the vehicle's own limits (the robot file's [controller])."""

    max_speed_m_s: float
    max_climb_m_s: float
    max_yaw_rate_rad_s: float
    max_tilt_rad: float = 0.44

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (math.isfinite(value) and value > 0):
                raise InvalidArgument(f"action limit {name} must be > 0, got {value!r}")


def action_values(action: Any, count: int = 4) -> list[float]:
    """An action as ``count`` finite floats clipped to [-1, 1]; InvalidArgument naming it if it
    is not ``count`` real numbers. Whatever numpy's conversion raises is that refusal, naming
    its cause (a Python int beyond a float's range: OverflowError; a PyTorch tensor that
    requires grad: RuntimeError), so the environments and the pilot's adapter treat every
    bad action alike."""
    try:
        given = np.asarray(action)
        if given.dtype.kind not in "biufO":  # text, complex: not what an action holds
            raise TypeError(given.dtype)
        values = given.astype(np.float64)  # an object array: each one a number
    except (TypeError, ValueError):
        raise InvalidArgument(f"an action is {count} real numbers, got {action!r:.80}") from None
    except Exception as exc:
        raise InvalidArgument(f"an action is {count} real numbers, got {action!r:.80} "
                              f"({type(exc).__name__}: {exc})") from None
    if values.shape != (count,):  # no silent flattening of a (2, 2) or a (1, 4)
        raise InvalidArgument(f"an action has {count} numbers, shape ({count},), got shape "
                              f"{values.shape}")
    if not np.all(np.isfinite(values)):
        raise InvalidArgument(f"an action must be finite, got {values.tolist()}")
    return [float(v) for v in np.clip(values, -1.0, 1.0)]


def velocity_setpoint(action: Any, limits: ActionLimits) -> tuple[float, float, float, float]:
    """(forward m/s, right m/s, up m/s, yaw rate rad/s) of a velocity action in [-1, 1]^4."""
    f, r, u, y = action_values(action, 4)
    return (f * limits.max_speed_m_s, r * limits.max_speed_m_s, u * limits.max_climb_m_s,
            y * limits.max_yaw_rate_rad_s)


def attitude_setpoint(action: Any, limits: ActionLimits) -> tuple[float, float, float, float]:
    """(roll rad, pitch rad, yaw rate rad/s, thrust 0..1) of an attitude action in [-1, 1]^4
    (thrust -1..1 maps onto 0..1 of the maximum thrust)."""
    r, p, y, t = action_values(action, 4)
    return (r * limits.max_tilt_rad, p * limits.max_tilt_rad, y * limits.max_yaw_rate_rad_s,
            (t + 1.0) / 2.0)


Policy = Callable[[Any], Any]


def load_policy(spec: str) -> Policy:
    """``module:callable`` -> the policy. A class is instantiated without arguments (its
    instances are the policy, e.g. one that keeps state between calls).

    Raises:
        ConfigError: a malformed spec, a module that does not import (or exits on import), a
            missing name, a class that cannot be made, or an object that is not callable (the
            message says which).
    """
    module_name, sep, attr = spec.partition(":")
    if not sep or not module_name or not attr:
        raise ConfigError(f"--policy must be module:callable (e.g. mypkg.policies:lander), "
                          f"got {spec!r}")
    try:
        module = importlib.import_module(module_name)
    except SystemExit as exc:  # a script's top level (argparse on the pilot's own arguments)
        raise ConfigError(f"--policy {spec}: importing {module_name} called sys.exit({exc.code!r})"
                          f" (a script that runs on import?)") from None
    except Exception as exc:
        raise ConfigError(f"--policy {spec}: cannot import {module_name}: "
                          f"{type(exc).__name__}: {exc}") from None
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ConfigError(f"--policy {spec}: {module_name} has no {attr!r}")
        obj = getattr(obj, part)
    if isinstance(obj, type):
        try:
            obj = obj()
        except (Exception, SystemExit) as exc:
            raise ConfigError(f"--policy {spec}: {attr}() failed: {type(exc).__name__}: "
                              f"{exc}") from None
    if not callable(obj):
        raise ConfigError(f"--policy {spec}: {attr} is not callable")
    return obj


def reset_policy(policy: Policy) -> None:
    """Call the policy's ``reset()`` if it has one (a new episode, or a new engagement)."""
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()


class ObservedPad(PadController):
    """The boards' pad controller, keeping the newest observation the vision applied
    (``latest``) for the policy's observation."""

    def __init__(self) -> None:
        super().__init__()
        self.latest: PadObservation | None = None

    def on_frame(self, observation: PadObservation) -> None:
        super().on_frame(observation)
        self.latest = observation


class DetectOnlyVision(PadVision):
    """The pilot's vision, detecting and reporting exactly as :class:`PadVision` does, with
    its flying left to someone else (a policy): the pad modes' set-points are not flown."""

    def _navigate(self, found: bool, forward_m: float, right_m: float, height_m: float,
                  now: Pose) -> None:
        return


class PolicyPilot:
    """The pilot's step hook (``PilotServer(vision=...)``) that flies a policy in the pad modes.

    ``vision`` detects (a :class:`DetectOnlyVision` on the same boards); ``period_s`` is the
    policy's control period in sim time (the environments' ``1 / control_rate_hz``).
    """

    def __init__(self, boards: OnboardBoards, vision: DetectOnlyVision, policy: Policy, *,
                 observation: str, limits: ActionLimits, period_s: float,
                 image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE) -> None:
        if observation not in OBSERVATIONS:
            raise InvalidArgument(f"observation must be one of {list(OBSERVATIONS)}, "
                                  f"got {observation!r}")
        if not (math.isfinite(period_s) and period_s > 0):
            raise InvalidArgument(f"policy period must be > 0 s, got {period_s!r}")
        self.boards = boards
        self.vision = vision
        self.policy = policy
        self.observation = observation
        self.limits = limits
        self.period_s = period_s
        self.image_size = image_size
        self.pad = boards.pad if isinstance(boards.pad, ObservedPad) else None
        if self.pad is None:
            raise InvalidArgument("PolicyPilot needs the boards' pad controller to be an "
                                  "ObservedPad (policy_factory sets it)")
        self.calls = 0  # policy calls made (and reset() tries that raised)
        self.failures = 0  # of them, calls that raised or gave no action (the vehicle held)
        self.failures_in_a_row = 0
        self.slow_calls = 0  # of them, calls that took longer than period_s of wall time
        self.engaged = False
        self._needs_reset = False  # engaged, its reset() not yet done (it raised)
        self._engagement: tuple[PadAction, int, int] | None = None  # the one engaged in
        self._next_s = -math.inf
        self._image: np.ndarray | None = None
        self._video: Callable[[CameraFrame], None] | None = None
        self._image_lock = threading.Lock()
        vision.attach_video(self._on_frame)

    # -- the vision's frames ---------------------------------------------------------------
    def attach_video(self, sink: Callable[[CameraFrame], None] | None) -> None:
        """Hand every frame the vision looked at to ``sink`` too (the pilot's video port)."""
        self._video = sink

    def _on_frame(self, frame: CameraFrame) -> None:
        with self._image_lock:
            self._image = frame.bgr
        video = self._video
        if video is not None:
            video(frame)

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self) -> PolicyPilot:
        self.vision.start()
        return self

    def close(self, timeout_s: float = 5.0) -> None:
        self.vision.close(timeout_s)

    def __enter__(self) -> PolicyPilot:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the control loop's side -------------------------------------------------------------
    def step(self) -> None:
        """Called by the pilot loop after each tick: the vision's step, then the policy's
        set-point once per period while engaged (the server holds no lock here; the boards'
        lock is the vision's). The observation is built, and the set-point flown, holding the
        boards' lock; the policy's own code (its ``reset()`` and its call) runs without it, so
        ground control's commands (PAD_MODE 0, a land) are handled while it thinks, and an
        action that comes back after one took the vehicle elsewhere is not flown."""
        self.vision.step()
        boards = self.boards
        with self.vision.lock:
            mode, state = boards.pad.mode, boards.state
            # what ground control did last: a later command, even one back to this mode, makes
            # a call under way stale
            engagement = (mode, boards.pad_commands, boards.motion_changes)
            engaged = mode is not PadAction.OFF and state is NavState.HOLDING
            if not engaged:
                if self.engaged and state is NavState.HOLDING:
                    boards.airframe.hover()  # PAD_MODE 0: the vehicle is handed back
                self.engaged = False
                return
            snap = boards.airframe.snapshot()
            if self.engaged and engagement != self._engagement:  # ground control engaged it
                self.engaged = False  # anew between two steps (PAD_MODE 0, then HOLD again)
            if not self.engaged:
                self.engaged = True
                self._engagement = engagement
                self._next_s = snap.time_s
                self.failures_in_a_row = 0
                self._needs_reset = True
                log.info("policy engaged (PAD_MODE %s)", mode.name)
            if snap.time_s < self._next_s - 1e-9:
                return
            self._next_s = max(self._next_s + self.period_s, snap.time_s)
            with self._image_lock:
                image = self._image
            assert self.pad is not None
            obs = policy_observation(self.observation, snap, boards.home_ned_m, self.pad.latest,
                                     image, self.image_size)
        if self._needs_reset:  # its reset, tried once a period until it succeeds
            try:
                reset_policy(self.policy)
            except (Exception, SystemExit) as exc:  # a policy's sys.exit(): its failure
                self.calls += 1
                self._failed(engagement, LocalProtocolError(
                    f"the policy's reset raised {type(exc).__name__}: {exc}; the vehicle "
                    f"holds still"), exc)
            self._needs_reset = False
        self.calls += 1
        started = time.monotonic()
        try:
            action = self.policy(obs)
        except (Exception, SystemExit) as exc:  # sys.exit() too: not the pilot's end
            self._timed(time.monotonic() - started)
            self._failed(engagement, LocalProtocolError(
                f"the policy raised {type(exc).__name__}: {exc}; the vehicle holds still"), exc)
        self._timed(time.monotonic() - started)
        try:
            forward, right, up, yaw_rate = velocity_setpoint(action, self.limits)
        except InvalidArgument as exc:
            self._failed(engagement, InvalidArgument(
                f"the policy's action: {exc}; the vehicle holds still"), exc)
        with self.vision.lock:
            if not self._still_engaged(engagement):  # ground control took it meanwhile: its say
                log.info("the policy's action came after ground control changed PAD_MODE "
                         "%s or took the vehicle out of HOLDING: not flown", mode.name)
                return
            if self.failures_in_a_row:
                log.warning("the policy flies again after %d failed call(s)",
                            self.failures_in_a_row)
                self.failures_in_a_row = 0
            boards.fly_velocity(forward, right, up, yaw_rate)  # inside the flight envelope

    def _still_engaged(self, engagement: tuple[PadAction, int, int]) -> bool:
        """Whether the engagement a policy call was made in still holds (call it holding the
        boards' lock): the same PAD_MODE, the vehicle still HOLDING, and no PAD_MODE command
        or change of motion since (PAD_MODE 0 and HOLD again during one call, or a landing and
        a new take-off, are another engagement, whose policy gets its ``reset()``)."""
        mode, pad_commands, motion_changes = engagement
        boards = self.boards
        return (self.engaged and boards.pad.mode is mode and boards.state is NavState.HOLDING
                and boards.pad_commands == pad_commands
                and boards.motion_changes == motion_changes)

    def _timed(self, took_s: float) -> None:
        """A call slower than its period held up the pilot's loop (the boards' tick, their
        link-loss watch): counted, and said at the first and then every 100th."""
        if took_s <= self.period_s:
            return
        self.slow_calls += 1
        if self.slow_calls % 100 == 1:
            log.warning("the policy took %.3f s of wall time, over its %.3f s period: the "
                        "pilot's loop waited for it (%d slow call(s) so far)", took_s,
                        self.period_s, self.slow_calls)

    def _failed(self, engagement: tuple[PadAction, int, int], error: Exception,
                cause: BaseException) -> NoReturn:
        """A policy call that raised (``SystemExit`` included: a policy's ``sys.exit()`` would
        otherwise end the pilot's loop) or gave no action: the vehicle holds still (its last
        set-point is not flown on; unless ground control took it during the call,
        ``engagement`` being the call's), said at the first failure of a run of them, and the
        error goes to the pilot's loop (counted in its ``loop_faults``). Called without the
        boards' lock."""
        self.failures += 1
        self.failures_in_a_row += 1
        if self.failures_in_a_row == 1:
            with self.vision.lock:
                if self._still_engaged(engagement):
                    self.boards.airframe.hover()
            log.warning("%s", error)
        raise error from cause


def policy_factory(
    vision_factory: Callable[[OnboardBoards, Any], Any], policy: Policy, *, observation: str,
    limits: ActionLimits, period_s: float, image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE,
) -> Callable[[OnboardBoards, Any], PolicyPilot]:
    """The ``PilotServer(vision=...)`` factory of a :class:`PolicyPilot`: ``vision_factory``
    makes its :class:`DetectOnlyVision` (``skeye.pilot.cli.pad_vision_factory(...,
    vision_class=DetectOnlyVision)``)."""

    def make(boards: OnboardBoards, lock: Any) -> PolicyPilot:
        boards.pad = ObservedPad()
        vision = vision_factory(boards, lock)
        if not isinstance(vision, DetectOnlyVision):
            raise InvalidArgument("the policy's vision must be a DetectOnlyVision")
        return PolicyPilot(boards, vision, policy, observation=observation, limits=limits,
                           period_s=period_s, image_size=image_size)

    return make
