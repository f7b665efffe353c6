"""The paper's two experiments (docs/experiments.md), run through the real processes.

How this works: each run starts ``skeye sim`` (lockstep, seeded, camera images served, every
line recorded with ``--record``) and ``skeye pilot`` (landing-pad vision on frames from the
image server, driving the lockstep clock) as child processes, then flies a scripted ground
client (:class:`skeye.link.Vehicle`) over the vehicle packet protocol, exactly as ground control
would. The estimates come from the PAD packets the pilot streams; the truth comes afterwards
from the simulator's recording (the GroundTruth lines it sent), matched by sim time. Nothing
reads the simulator's state behind the pilot's back.

- E1: hover 0.30 m above the pad, climb at 0.1 m/s to 1.0 m, hold 10 s, climb to 2.0 m, hold
  10 s; for every processed frame: time, estimated height, true camera height.
- E2: hover 0.70 m above the pad under the paper's random force (F_max 0.3 N redrawn every
  1/30 s), position hold on the pad (PAD_MODE 1: deadband 0.05 m, 0.3 m/s) for 5 minutes;
  the horizontal distance of the vehicle from the pad centre. Beside it, on the same seed and
  disturbance, two baselines without vision: the board's velocity hold on its own estimate
  (HOLD; with the onboard estimator that estimate comes from the optical flow and sonar, and
  GPS where the world has a sky: the pad world does, the indoor world does not, so there it is
  the flow-only hold of the paper's extension board) and attitude + height hold (AscTec
  height mode, CTRL_INPUT with centred sticks: no horizontal feedback at all).

The camera (``camera``: a ``skeye sim --camera-profile``), the board's estimator
(``estimator``: ``skeye sim --estimator``) and the world (``world``: ``pad``, outdoors with
GPS, or ``indoor``, no GPS; both have the pad at the origin) are settings of every run; with a
``calibration`` file the pilot's pad detector undistorts with it, and E1 is also flown without
it (the bias a missing calibration causes).

``quick`` runs the same code for a fraction of the time (CI).
"""

from __future__ import annotations

import math
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from skeye.errors import ConfigError, LocalProtocolError, SkeyeError
from skeye.link.vehicle import Vehicle
from skeye.processes import scaled_s, start_skeye, stop_process
from skeye.recording.records import RecordingReader
from skeye.values import is_finite_number, is_number, number, text
from skeye.vision.pad import PAD_SURFACE_HEIGHT_M
from skeye.wire.packet_units import PadModeSi, nav_status_to_si, pad_mode_from_si, pad_report_to_si
from skeye.wire.packets import NavState, PadAction, PadReport, SkeyeMask
from skeye.wire.sim import decode_line
from skeye.wire.sim_messages import SenGroundTruth
from skeye.wire.wind import PARAM_RANGES, WIND_MODES, make_settings, parse_params

CAMERAS = ("ideal", "webcam")  # RunSettings.camera: skeye sim --camera-profile
ESTIMATORS = ("onboard", "truth")  # RunSettings.estimator: skeye sim --estimator
WORLDS = ("pad", "indoor")  # RunSettings.world: built-in worlds with the pad at the origin
PAD_SOURCES = ("vision", "truth")  # RunSettings.pad_source: skeye pilot --pad-source
CAMERA_BELOW_CENTRE_M = 0.035  # the Hummingbird's downward camera mount (robot file)
F_MAX_N = 0.3


@dataclass(frozen=True)
class RunSettings:
    """One trial's settings; every field may be swept (``skeye sweep``)."""

    seed: int
    quick: bool = False
    f_max_n: float = F_MAX_N
    e2_duration_s: float = 300.0
    # E2's disturbance, a ``skeye sim --wind`` mode: MIL-F-8785C low-altitude Dryden gusts with
    # a mean wind (docs/physics.md, Wind); ``random_force`` is the paper's own disturbance.
    wind: str = "dryden"
    wind_params: str = ""  # extra ``--wind-params`` (k=v,...); f_max_n is added for random_force
    # When a pad detection is used (``skeye pilot --vision-latency-ms``): ``measured``, the
    # detector's own processing time, as on a real computer; a number of ms fixes it.
    vision_latency: str = "measured"
    # The vision run's pad observations: "vision" (the detector) or "truth" (ground truth in
    # place of each detection, same frames and timing: the comparison case).
    pad_source: str = "vision"
    deadband_m: float = 0.05  # E2's PAD_MODE 1 deadband
    max_speed_m_s: float = 0.3  # E2's PAD_MODE 1 speed limit
    camera: str = "ideal"  # the camera profile (skeye sim --camera-profile)
    estimator: str = "onboard"  # the boards' estimator (skeye sim --estimator)
    world: str = "pad"  # the built-in world (skeye sim --world): pad (GPS) or indoor (none)
    calibration: str = ""  # a `skeye calibrate` file for the pilot's detector ("" = none)

    def __post_init__(self) -> None:
        """Every setting checked as the trial's processes check it (:func:`check_setting`),
        then the disturbance as a whole (``wind`` with ``wind_params`` and ``f_max_n``, as
        ``skeye sim`` gets them); a bad one is a ConfigError naming it."""
        for name in SETTING_NAMES:
            check_setting(name, getattr(self, name))
        check_disturbance(self.wind, self.wind_params, self.f_max_n)

    @property
    def e2_seconds(self) -> float:
        """E2's hold: ``e2_duration_s``, at most 20 s in a quick run."""
        return min(20.0, self.e2_duration_s) if self.quick else self.e2_duration_s

    def wind_args(self) -> list[str]:
        return _wind_args(self.wind, self.wind_params, self.f_max_n)

    def describe_wind(self) -> str:
        """E2's disturbance in words, with the parameters given (else the simulator's)."""
        if self.wind == "none":
            return "still air"
        args = self.wind_args()
        what = {"dryden": "MIL-F-8785C low-altitude Dryden gusts with their mean wind",
                "random_force": "the paper's random force on the centre of mass",
                "turbulence": "skeye's first-order turbulence",
                "constant": "a steady wind"}.get(self.wind, self.wind)
        given = args[3] if len(args) > 3 else "the simulator's defaults, docs/physics.md"
        return f"{what} (skeye sim --wind {self.wind}: {given})"


SETTING_NAMES = tuple(f.name for f in fields(RunSettings) if f.name not in ("seed", "quick"))
"""The fields of :class:`RunSettings` a trial takes as parameters (all but seed and quick)."""


SETTING_CHOICES: dict[str, tuple[str, ...]] = {
    "camera": CAMERAS, "estimator": ESTIMATORS, "world": WORLDS, "pad_source": PAD_SOURCES,
    "wind": WIND_MODES}
"""The settings that take one of a list of names, and those names."""


def _wind_args(wind: str, wind_params: str, f_max_n: float) -> list[str]:
    """``skeye sim``'s wind arguments for these settings (none in still air)."""
    if wind == "none":
        return []
    params = [p for p in wind_params.split(",") if p]
    if wind == "random_force" and not any(p.startswith("f_max_n=") for p in params):
        params.append(f"f_max_n={f_max_n}")
    return ["--wind", wind] + (["--wind-params", ",".join(params)] if params else [])


def check_disturbance(wind: str, wind_params: str, f_max_n: float) -> None:
    """The disturbance as a whole (``wind`` with ``wind_params`` and ``f_max_n``, as ``skeye
    sim`` gets them), each already checked alone by :func:`check_setting`.

    Raises:
        ConfigError: naming the three and what ``skeye sim`` would refuse.
    """
    args = _wind_args(wind, wind_params, f_max_n)
    if args:
        try:
            make_settings(args[1], parse_params(args[3]) if len(args) > 3 else {})
        except ConfigError as exc:
            raise ConfigError(f"wind {wind!r} with wind_params {wind_params!r} "
                              f"and f_max_n {f_max_n!r}: {exc}") from None


def _number(name: str, value: object) -> float:
    if not is_number(value):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    if not is_finite_number(value):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return number(name, value)


def check_setting(name: str, value: object) -> None:
    """One setting of a run alone, by the rule of the process it goes to (``skeye sim``'s wind
    ranges, ``skeye pilot``'s vision latency and calibration file, PAD_MODE's field ranges).
    ``skeye sweep`` calls it for every value of a spec before any trial starts, and every
    :class:`RunSettings` for each of its fields, so the two cannot disagree.

    Raises:
        ConfigError: naming the setting, the value and what is wrong with it.
    """
    choices = SETTING_CHOICES.get(name)
    if choices is not None:
        if value not in choices:
            raise ConfigError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
    elif name == "f_max_n":
        low, high = PARAM_RANGES["f_max_n"]
        if not low <= _number(name, value) <= high:
            raise ConfigError(f"f_max_n must be in [{low:g}, {high:g}] N (skeye sim's random "
                              f"force), got {value!r}")
    elif name == "e2_duration_s":
        if not _number(name, value) >= STEP_S:
            raise ConfigError(f"e2_duration_s must be at least one pilot tick ({STEP_S:g} s), "
                              f"got {value!r}")
    elif name == "wind_params":
        try:
            parse_params(text(name, value))
        except ConfigError as exc:
            raise ConfigError(f"wind_params {value!r}: {exc}") from None
    elif name == "vision_latency":
        from skeye.pilot.cli import vision_latency_s

        try:
            vision_latency_s(text(name, value))
        except ConfigError:
            raise ConfigError(f"vision_latency must be 'measured' or a number of ms 0..10000 "
                              f"(skeye pilot --vision-latency-ms), got {value!r}") from None
    elif name in ("deadband_m", "max_speed_m_s"):
        pad = {"deadband_m": 0.0, "max_speed_m_s": 0.0, name: _number(name, value)}
        try:
            pad_mode_from_si(PadModeSi(PadAction.HOLD, **pad))
        except LocalProtocolError as exc:
            raise ConfigError(f"{name} {value!r} does not fit PAD_MODE: {exc}") from None
    elif name == "calibration":
        if text(name, value):
            from skeye.vision.calibration import load_calibration

            try:
                load_calibration(str(value))
            except ConfigError as exc:
                raise ConfigError(f"calibration: {exc}") from None  # exc names the file
    else:
        raise ConfigError(f"no run setting {name!r}; settings: {', '.join(SETTING_NAMES)}")


@dataclass
class E1Series:
    time_s: list[float] = field(default_factory=list)
    estimated_m: list[float | None] = field(default_factory=list)
    true_m: list[float] = field(default_factory=list)


@dataclass
class E2Series:
    time_s: list[float] = field(default_factory=list)
    distance_m: list[float] = field(default_factory=list)


# -- processes --------------------------------------------------------------------------------
@contextmanager
def flight_stack(settings: RunSettings, record: Path, *, vision: bool, wind: bool,
                 frame_time: str = "arrival") -> Iterator[Vehicle]:
    """Simulator + pilot as processes, and a ground client connected to the pilot.
    ``frame_time``: the pilot's ``--frame-time`` (E1 measures the detector against the truth
    at each frame's capture, so it flies with "capture"; E2 with the host's "arrival")."""
    sim_args = ["sim", "--mode", "lockstep", "--port", "0", "--seed", str(settings.seed),
                "--record", str(record), "--estimator", settings.estimator,
                "--world", settings.world]
    if vision:
        sim_args += ["--image-port", "0", "--camera-profile", settings.camera]
    if wind:
        sim_args += settings.wind_args()
    patterns = [r"control protocol on [\d.]+:(\d+)"]
    if vision:
        patterns.append(r"image server on [\d.]+:(\d+)")
    with ExitStack() as stack:
        sim, found = start_skeye(sim_args, patterns, "skeye sim", timeout_s=scaled_s(180.0))
        stack.callback(stop_process, sim)
        pilot_args = ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}", "--port", "0",
                      "--lockstep-rate", "0", "--ground-clock", "--link-timeout",
                      f"{scaled_s(30.0):.0f}", "--land-timeout", f"{scaled_s(60.0):.0f}"]
        if vision:
            pilot_args += ["--images", f"127.0.0.1:{found[1].group(1)}",
                           "--vision-latency-ms", settings.vision_latency,
                           "--pad-source", settings.pad_source, "--frame-time", frame_time]
            if settings.calibration:
                pilot_args += ["--calibration", settings.calibration]
        pilot, pfound = start_skeye(pilot_args, [r"ground control on (tcp://[\d.]+:\d+)"],
                                    "skeye pilot", timeout_s=scaled_s(180.0))
        stack.callback(stop_process, pilot)
        vehicle = stack.enter_context(Vehicle.open(pfound[0].group(1), timeout_s=scaled_s(30.0)))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.005)
        yield vehicle


def _sim_time(vehicle: Vehicle) -> float:
    from skeye.wire.packets import PD

    msg = vehicle.wait_for(PD.NAV_STATUS, timeout_s=scaled_s(30.0))
    return nav_status_to_si(msg).time_s  # type: ignore[arg-type]


# The pilot runs with --ground-clock: sim time passes only as far as this script grants it, so
# every command is given at an exact sim time and a seeded run repeats bit for bit.
STEP_S = 0.05  # one pilot tick (the Hummingbird's 20 Hz control period)


def _wait_sim(vehicle: Vehicle, seconds: float, timeout_s: float, *, step_s: float | None = None
              ) -> float:
    """Let ``seconds`` of sim time pass (in steps of ``step_s``, or at once); the sim time."""
    now = _sim_time(vehicle)
    end = now + seconds
    while now < end - 1e-6:
        until = end if step_s is None else min(end, now + step_s)
        now = nav_status_to_si(vehicle.run_until(until, timeout_s=scaled_s(timeout_s))).time_s
    return now


def _until_state(vehicle: Vehicle, state: NavState, limit_s: float = 600.0) -> float:
    """Step sim time one tick at a time until the pilot reports ``state``; the sim time."""
    now = _sim_time(vehicle)
    end = now + limit_s
    while True:
        nav = vehicle.run_until(now + STEP_S, timeout_s=scaled_s(60.0))
        now = nav_status_to_si(nav).time_s
        if nav.state is state:
            return now
        if now > end:
            raise SkeyeError(f"the vehicle was not {state.name} within {limit_s} s of sim time "
                             f"(state {nav.state.name})")


def _ground_truth(record: Path) -> list[tuple[float, float, float, float, float]]:
    """(sim time, north, east, down, cos(roll)cos(pitch)) of every GroundTruth line sent."""
    out = []
    for rec in RecordingReader(record).records():
        if rec.direction != ">" or not rec.line.startswith("SEN") or "GroundTruth" not in rec.line:
            continue
        msg = decode_line(rec.line)
        if not isinstance(msg, SenGroundTruth):
            continue
        n, e, d = msg.location_ned_m
        roll, pitch, _ = msg.orientation_rpy_rad
        out.append((msg.time_s, n, e, d, math.cos(roll) * math.cos(pitch)))
    if not out:
        raise SkeyeError(f"{record}: no ground truth recorded")
    return out


def _interpolate(truth: Sequence[tuple[float, ...]], t: float) -> tuple[float, ...]:
    lo, hi = 0, len(truth) - 1
    if t <= truth[0][0]:
        return truth[0]
    if t >= truth[hi][0]:
        return truth[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if truth[mid][0] <= t:
            lo = mid
        else:
            hi = mid
    a, b = truth[lo], truth[hi]
    w = (t - a[0]) / (b[0] - a[0]) if b[0] > a[0] else 0.0
    return tuple(x + w * (y - x) for x, y in zip(a, b, strict=True))


# -- E1 ---------------------------------------------------------------------------------------
def run_e1(settings: RunSettings, workdir: Path, name: str = "e1") -> E1Series:
    record = workdir / f"{name}_seed{settings.seed}.rec"
    pads: dict[float, PadReport] = {}
    lock = threading.Lock()
    plateaus = [(1.0, 10.0), (2.0, 10.0)] if not settings.quick else [(0.6, 2.0)]
    with flight_stack(settings, record, vision=True, wind=False, frame_time="capture") as vehicle:

        def on_packet(msg: object) -> None:
            if isinstance(msg, PadReport):
                with lock:
                    pads.setdefault(msg.frame_time, msg)

        vehicle.take_off(0.30 - 0.045)  # camera 0.30 m above the pad (0.045: gear - camera)
        start = _until_state(vehicle, NavState.HOLDING)
        vehicle.add_callback(on_packet)
        height = 0.30
        for target, hold_s in plateaus:
            vehicle.move_by(up_m=target - height, speed_m_s=0.1)
            _until_state(vehicle, NavState.HOLDING)
            height = target
            # one tick at a time: the PAD report of every processed frame reaches us
            _wait_sim(vehicle, hold_s, timeout_s=60, step_s=STEP_S)
    truth = _ground_truth(record)
    series = E1Series()
    for frame_ms in sorted(pads):
        t = frame_ms / 1000.0
        if t < start:
            continue
        report = pad_report_to_si(pads[frame_ms])
        _, _, _, down, tilt = _interpolate(truth, t)
        series.time_s.append(t)
        series.estimated_m.append(report.height_m if report.found else None)
        series.true_m.append(-down - CAMERA_BELOW_CENTRE_M * tilt - PAD_SURFACE_HEIGHT_M)
    return series


E2_WINDS = ("dryden", "random_force", "none")
"""E2's disturbances (``skeye validate --wind``): the default gust model, the paper's force."""


# -- E2 ---------------------------------------------------------------------------------------
E2_RUNS = ("vision", "velocity", "attitude")  # pad hold; HOLD; height mode, centred sticks
HEIGHT_MODE_STICKS = 0x1F  # CTRL_INPUT: roll, pitch, yaw, thrust from the sticks, height mode


def run_e2(settings: RunSettings, workdir: Path, *, run: str) -> E2Series:
    """One E2 run: ``vision`` (PAD_MODE 1), ``velocity`` (HOLD on the board's estimate) or
    ``attitude`` (attitude + height hold: centred sticks in the AscTec height mode)."""
    if run not in E2_RUNS:
        raise SkeyeError(f"unknown E2 run {run!r}: {', '.join(E2_RUNS)}")
    vision = run == "vision"
    record = workdir / f"e2_{run}_seed{settings.seed}.rec"
    with flight_stack(settings, record, vision=vision, wind=True) as vehicle:
        vehicle.take_off(0.70 - 0.081)  # vehicle centre 0.70 m above the pad (0.081: on gear)
        start = _until_state(vehicle, NavState.HOLDING)
        if vision:
            vehicle.pad_mode(1, deadband_m=settings.deadband_m,
                             max_speed_m_s=settings.max_speed_m_s)
        elif run == "velocity":
            vehicle.hold()
        else:
            vehicle.ctrl_input(0.0, 0.0, 0.0, 0.5, ctrl=HEIGHT_MODE_STICKS)
        end = _wait_sim(vehicle, settings.e2_seconds, timeout_s=settings.e2_seconds * 10 + 600)
    series = E2Series()
    for t, n, e, _d, _tilt in _ground_truth(record):
        if start <= t <= end:
            series.time_s.append(t - start)
            series.distance_m.append(math.hypot(n, e))
    return series


def e1_runs(settings: RunSettings, workdir: Path) -> dict[str, E1Series]:
    """E1, and with a calibration E1 again without it (``E1_uncalibrated``)."""
    out = {"E1": run_e1(settings, workdir)}
    if settings.calibration:
        out["E1_uncalibrated"] = run_e1(replace(settings, calibration=""), workdir,
                                        "e1_uncalibrated")
    return out


def e2_key(run: str) -> str:
    """The series key of an E2 run: ``E2`` (vision), ``E2_velocity``, ``E2_attitude``."""
    return "E2" if run == "vision" else f"E2_{run}"


def e2_runs(settings: RunSettings, workdir: Path) -> dict[str, E2Series]:
    """E2's three runs, by :func:`e2_key`."""
    return {e2_key(run): run_e2(settings, workdir, run=run) for run in E2_RUNS}


def run_all(settings: RunSettings, experiments: tuple[str, ...], workdir: str | None = None
            ) -> dict[str, object]:
    """Run the chosen experiments for one seed (a worker process's job)."""
    with tempfile.TemporaryDirectory() as tmp:
        wd = Path(workdir or tmp)
        wd.mkdir(parents=True, exist_ok=True)
        out: dict[str, object] = {}
        if "E1" in experiments:
            out.update(e1_runs(settings, wd))
        if "E2" in experiments:
            out.update(e2_runs(settings, wd))
        return out


# The pieces a flight script for ``skeye sweep`` builds on (docs/sweeps.md).
until_state = _until_state
wait_sim = _wait_sim
ground_truth = _ground_truth
