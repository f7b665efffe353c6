"""The same observation on both sides: the environments' snapshot against the pilot's
SimAirframe, the scripted lander in the environment, and the same lander flying the real pilot
(``skeye pilot --policy``) on the simulator."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from skeye.control.connection import connect
from skeye.gym.board import BoardView
from skeye.gym.tasks import PAD_TOLERANCE_M
from skeye.link.vehicle import Vehicle
from skeye.pilot.cli import pad_vision_factory
from skeye.pilot.policy import (
    ActionLimits,
    DetectOnlyVision,
    PolicyPilot,
    load_policy,
    policy_factory,
    state_vector,
)
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.robots.config import load_robot_config
from skeye.sim.engine import Simulation
from skeye.wire.packets import NavState, SkeyeMask
from tests.control.conftest import sim_running
from tests.sim.test_cameras import sim_with_images

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "gym"


def test_the_in_process_snapshot_is_the_pilots_to_the_wires_rounding() -> None:
    """One flight on a real control server: the pilot's SimAirframe reads the robot's text
    stream, and the environments' BoardView takes the same typed readings from the engine (a
    second sink beside the server's); their snapshots agree to the wire's rounding."""
    view = BoardView(load_robot_config("hummingbird"))

    def tee(sim: Simulation) -> None:
        robot = sim.robots["R1"]
        server_sink = robot.sink

        def both(events: list) -> None:
            server_sink(events)
            view.sink(events)

        robot.sink = both

    with sim_running(seed=4) as handle, connect(handle.address) as sim:
        robot = sim.spawn("hummingbird", location_ned_m=(0.5, -0.2, -1.2), name="R1")
        handle.runner.call(tee)
        airframe = SimAirframe(sim, robot)
        robot.set_velocity(0.4, -0.2, 0.1, 0.3)
        sim.run_for(1.5)
        pilot = airframe.snapshot()
        ours = view.snapshot(sim.time_s)
    assert ours.time_s == pytest.approx(pilot.time_s, abs=1e-9)
    home = (0.0, 0.0, 0.0)
    ours_v, pilot_v = state_vector(ours, home), state_vector(pilot, home)
    assert np.allclose(ours_v, pilot_v, atol=1e-3), ours_v - pilot_v
    assert ours_v[3] != 0.0 and ours_v[11] != 0.0  # it moved and turned: not a trivial match
    assert ours.armed == pilot.armed and ours.landed == pilot.landed
    assert ours.baro_altitude_m == pytest.approx(pilot.baro_altitude_m, abs=1e-3)
    assert ours.mag_heading_rad == pytest.approx(pilot.mag_heading_rad, abs=1e-3)
    assert ours.thrust_fraction == pytest.approx(pilot.thrust_fraction, abs=1e-3)
    assert ours.battery_v == pytest.approx(pilot.battery_v, abs=1e-3)


def test_the_scripted_controller_lands_on_the_pad_through_the_webcam() -> None:
    """The example at a small count (docs/gym.md has the 20-episode figure)."""
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "pad_landing_scripted.py"), "--episodes", "2",
         "--seed", "100"],
        capture_output=True, text=True, timeout=600, cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    assert "landed on the pad in 2 of 2 episodes" in done.stdout, done.stdout


def test_load_policy_names_what_is_wrong(monkeypatch: pytest.MonkeyPatch) -> None:
    from skeye.errors import ConfigError

    monkeypatch.syspath_prepend(str(EXAMPLES))
    lander = load_policy("pad_landing_scripted:ScriptedLander")
    assert callable(lander)
    for spec, message in (("nocolon", "module:callable"), ("no_such_mod:x", "cannot import"),
                          ("pad_landing_scripted:Nope", "has no"),
                          ("pad_landing_scripted:LAND_SPEED_M_S", "not callable")):
        with pytest.raises(ConfigError, match=message):
            load_policy(spec)


def test_a_policy_module_that_exits_on_import_is_a_config_error(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A script with argparse at its top level parsed the pilot's own arguments and ended
    `skeye pilot` with its usage and exit 2; sys.exit(3) ended it with 3 and no word."""
    from skeye.errors import ConfigError

    (tmp_path / "exits_on_import.py").write_text("import sys\nsys.exit(3)\n")
    (tmp_path / "exits_when_made.py").write_text(
        "import sys\nclass P:\n    def __init__(self):\n        sys.exit(4)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError, match=r"importing exits_on_import called sys.exit\(3\)"):
        load_policy("exits_on_import:f")
    with pytest.raises(ConfigError, match=r"P\(\) failed: SystemExit: 4"):
        load_policy("exits_when_made:P")


def test_skeye_pilot_refuses_a_policy_without_images_or_that_does_not_load() -> None:
    from skeye.cli import main

    assert main(["pilot", "--policy", "pad_landing_scripted:ScriptedLander"]) == 2
    assert main(["pilot", "--images", "127.0.0.1:1", "--policy", "no_such_module:f"]) == 2


def _policy_pilot(sim: Any, robot: Any, policy: object, lockstep_rate: float) -> PilotServer:
    """A real pilot (``skeye pilot --policy``'s PolicyPilot on the pad detector) flying
    ``robot`` of ``sim`` in lockstep, at the robot file's speed limits."""
    cfg = robot.motion_config
    vision = policy_factory(
        pad_vision_factory(sim, robot, vision_class=DetectOnlyVision), policy,
        observation="pad",
        limits=ActionLimits(cfg.max_speed_m_s, cfg.max_climb_m_s, cfg.max_yaw_rate_rad_s),
        period_s=0.05)
    return PilotServer(SimAirframe(sim, robot), port=0, lockstep=True,
                       lockstep_rate=lockstep_rate, tick_s=0.05, vision=vision)


@pytest.fixture
def policy_flight(monkeypatch: pytest.MonkeyPatch
                  ) -> Iterator[tuple[Vehicle, object, PilotServer]]:
    monkeypatch.syspath_prepend(str(EXAMPLES))
    with ExitStack() as stack:
        control, images, _ = stack.enter_context(sim_with_images(mode="lockstep"))
        sim = stack.enter_context(
            connect(f"127.0.0.1:{control.port}", images=f"127.0.0.1:{images.port}"))
        robot = sim.spawn("hummingbird", start="Pad1")
        pilot = stack.enter_context(_policy_pilot(
            sim, robot, load_policy("pad_landing_scripted:ScriptedLander"), lockstep_rate=5.0))
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        yield vehicle, control, pilot


def test_the_pilot_flies_the_policy_that_solves_the_environment(policy_flight) -> None:
    vehicle, control, pilot = policy_flight
    assert isinstance(pilot.vision, PolicyPilot)
    vehicle.stream(0, int(SkeyeMask.NAV_STATUS | SkeyeMask.PAD), 0.05)
    vehicle.take_off(1.5)
    vehicle.wait_state(NavState.HOLDING, timeout_s=60)
    vehicle.move_by(forward_m=0.3, right_m=-0.2)
    vehicle.wait_state(NavState.FLYING, timeout_s=60)
    vehicle.wait_state(NavState.HOLDING, timeout_s=60)
    assert pilot.vision.calls == 0  # PAD_MODE 0: the policy does not fly
    vehicle.pad_mode(2, deadband_m=0.05, max_speed_m_s=0.3)
    vehicle.wait_state(NavState.LANDED, timeout_s=300)
    north, east, _ = control.runner.call(lambda sim: tuple(sim.body_state("R1").pos_ned_m))
    # landed on the pad as the environment counts a success (its vision runs beside the
    # lockstep clock, so where within the pad it touches down varies from run to run: 2.6 cm
    # median over 20 episodes, docs/gym.md; one run here touched down at 12.6 cm)
    assert math.hypot(north, east) <= PAD_TOLERANCE_M, (north, east)
    assert pilot.vision.calls > 20 and pilot.vision.vision.stats.detections > 20


class _Airframe:
    """Records what a PolicyPilot commands; its clock is set by the test."""

    def __init__(self) -> None:
        self.commands: list[tuple] = []
        self.time_s = 0.0

    def snapshot(self) -> SimpleNamespace:
        return SimpleNamespace(
            time_s=self.time_s, pos_ned_m=(0.0, 0.0, -1.0), rpy_rad=(0.0, 0.0, 0.0),
            vel_ned_m_s=(0.0, 0.0, 0.0), rates_frd_rad_s=(0.0, 0.0, 0.0),
            specific_force_frd_m_s2=(0.0, 0.0, -9.8), landed=False)

    def set_velocity(self, *args: object) -> None:
        self.commands.append(("velocity", *args))

    def hover(self) -> None:
        self.commands.append(("hover",))


class _Vision:
    lock = threading.Lock()

    def attach_video(self, sink: object) -> None:
        pass

    def step(self) -> None:
        pass


def _holding_pilot(policy: object) -> tuple[PolicyPilot, _Airframe]:
    """A PolicyPilot engaged (PAD_MODE HOLD, HOLDING) on a recording airframe, 20 Hz."""
    from skeye.pilot.pad import PadModeSi
    from skeye.pilot.policy import ObservedPad
    from skeye.wire.packets import PadAction

    pad = ObservedPad()
    pad._settings = PadModeSi(PadAction.HOLD, 0.05, 0.3)
    airframe = _Airframe()
    boards = SimpleNamespace(pad=pad, state=NavState.HOLDING, airframe=airframe,
                             home_ned_m=(0.0, 0.0, 0.0), pad_commands=0, motion_changes=0)
    # OnboardBoards.fly_velocity, far inside the flight envelope (nothing to limit)
    boards.fly_velocity = lambda fwd, right, up, yaw_rate=0.0: airframe.set_velocity(
        fwd, right, up, yaw_rate, None)
    pilot = PolicyPilot(boards, _Vision(), policy, observation="pad",  # type: ignore[arg-type]
                        limits=ActionLimits(1.0, 1.0, 1.0), period_s=0.05)
    return pilot, airframe


def test_a_policy_that_fails_leaves_the_vehicle_holding_still_and_says_so() -> None:
    """A policy that raised, or returned NaN, the wrong shape or text, left the vehicle flying
    its last set-point (1 m/s forward here) for as long as it failed; the loop's fault said
    only an InvalidArgument or RuntimeError from the vision's step."""
    from skeye.errors import InvalidArgument, LocalProtocolError

    def boom(obs: object) -> object:
        raise RuntimeError("boom")

    answers = iter([np.array([1.0, 0, 0, 0]), np.full(4, np.nan), np.zeros(3), "abcd", boom,
                    np.zeros(4)])

    def policy(obs: object) -> object:
        answer = next(answers)
        return answer(obs) if callable(answer) else answer

    pilot, airframe = _holding_pilot(policy)
    pilot.step()
    assert airframe.commands == [("velocity", 1.0, 0.0, 0.0, 0.0, None)]
    for error, message in ((InvalidArgument, "the policy's action: an action must be finite"),
                           (InvalidArgument, "the policy's action: an action has 4 numbers"),
                           (InvalidArgument, "the policy's action: an action is 4 real"),
                           (LocalProtocolError, "the policy raised RuntimeError: boom")):
        airframe.time_s += 0.05
        with pytest.raises(error, match=message):
            pilot.step()
        assert airframe.commands[-1] == ("hover",)  # not the last set-point flown on
    assert airframe.commands.count(("hover",)) == 1 and pilot.failures == 4
    airframe.time_s += 0.05
    pilot.step()  # flies again
    assert airframe.commands[-1] == ("velocity", 0.0, 0.0, 0.0, 0.0, None)
    assert pilot.failures_in_a_row == 0 and pilot.calls == 6


def test_a_policy_slower_than_its_period_is_counted_and_said(
        caplog: pytest.LogCaptureFixture) -> None:
    """The policy runs on the pilot's loop: a call longer than its period (here 0.2 s of wall
    time against 0.05 s) held up the boards' tick with no word. It is counted and said (the
    first; a loaded machine may make the fast ones after it slow too)."""
    delays = iter([0.2, 0.0, 0.0])

    def policy(obs: object) -> object:
        time.sleep(next(delays))
        return np.zeros(4)

    pilot, airframe = _holding_pilot(policy)
    with caplog.at_level("WARNING", logger="skeye.pilot.policy"):
        for _ in range(3):
            pilot.step()
            airframe.time_s += 0.05
    assert pilot.calls == 3 and pilot.slow_calls >= 1
    assert "the policy took 0.2" in caplog.text and "over its 0.050 s period" in caplog.text
    assert airframe.commands[-1] == ("velocity", 0.0, 0.0, 0.0, 0.0, None)  # still flies


def test_a_policy_whose_reset_fails_holds_the_vehicle_until_a_reset_succeeds(
        caplog: pytest.LogCaptureFixture) -> None:
    """A policy's reset() that raised on taking over escaped as a bare error to the pilot's
    loop, uncounted and unsaid as the policy's, and the policy was then flown without its
    reset (on the state of its last engagement). It is now a failure as a call's is: the vehicle
    holds still, it is counted and said, and the reset is tried again each period until it
    succeeds; only then is the policy flown."""
    from skeye.errors import LocalProtocolError

    class Policy:
        def __init__(self) -> None:
            self.resets_to_fail = 2
            self.resets = 0

        def reset(self) -> None:
            if self.resets_to_fail:
                self.resets_to_fail -= 1
                raise RuntimeError("no model loaded")
            self.resets += 1

        def __call__(self, obs: object) -> object:
            assert self.resets == 1, "flown before its reset succeeded"
            return np.array([1.0, 0, 0, 0])

    policy = Policy()
    pilot, airframe = _holding_pilot(policy)
    with caplog.at_level("WARNING", logger="skeye.pilot.policy"):
        for _ in range(2):
            with pytest.raises(LocalProtocolError,
                               match="the policy's reset raised RuntimeError: no model loaded"):
                pilot.step()
            airframe.time_s += 0.05
    assert airframe.commands == [("hover",)] and pilot.failures == 2
    assert caplog.text.count("no model loaded") == 1  # said at the first of the run
    pilot.step()
    assert policy.resets == 1 and airframe.commands[-1] == ("velocity", 1.0, 0.0, 0.0, 0.0, None)
    assert pilot.failures_in_a_row == 0



@contextmanager
def _policy_engaged(tmp_path: Path, policy: object) -> Iterator[tuple[Vehicle, PilotServer]]:
    """A real pilot (``skeye pilot --policy``'s PolicyPilot) on the simulator over loopback,
    its vehicle taken off to 0.5 m and holding, then PAD_MODE HOLD: the policy flies."""
    from tests.sim.test_cameras import small_camera_robot

    robots = small_camera_robot(tmp_path, 160, 120)  # the vision's frames, cheaply
    with ExitStack() as stack:
        control, images, _ = stack.enter_context(
            sim_with_images(mode="lockstep", robot_dirs=(robots,)))
        sim = stack.enter_context(
            connect(f"127.0.0.1:{control.port}", images=f"127.0.0.1:{images.port}"))
        robot = sim.spawn("smallcam", start="Pad1")
        pilot = stack.enter_context(_policy_pilot(sim, robot, policy, lockstep_rate=0.0))
        vehicle = stack.enter_context(Vehicle.open(pilot.address, timeout_s=10.0))
        vehicle.stream(0, int(SkeyeMask.NAV_STATUS), 0.05)
        vehicle.take_off(0.5)
        vehicle.wait_state(NavState.HOLDING, timeout_s=60)
        vehicle.pad_mode(1, deadband_m=0.05, max_speed_m_s=0.3)  # HOLD: the policy flies
        yield vehicle, pilot
        vehicle.wait_state(NavState.HOLDING, timeout_s=10)  # still holding, still reported


def test_a_policy_that_calls_sys_exit_is_a_failed_call_not_the_end_of_the_pilot(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A policy call that raised SystemExit (``sys.exit()``, ``exit()`` in a policy script)
    escaped ``except Exception`` and ended the pilot's whole loop ("pilot loop failed"): no
    more ticks, no link-loss watch, the vehicle flying its last set-point. It is now a failed
    call as any other (``load_policy`` already took it so on import and construction): the
    vehicle holds still, it is counted and said, and the pilot flies the next call."""
    calls: list[object] = []
    flown = threading.Event()

    def policy(obs: object) -> object:
        calls.append(obs)
        if len(calls) == 1:
            sys.exit("the policy gave up")
        if len(calls) == 3:
            flown.set()
        return np.zeros(4)

    with caplog.at_level("WARNING", logger="skeye.pilot.policy"), \
            _policy_engaged(tmp_path, policy) as (_, pilot):
        assert flown.wait(30), f"the pilot's loop stopped: {pilot.loop_error!r}"
        assert pilot.loop_error is None and pilot.vision.failures == 1
        assert pilot.loop_faults >= 1
    assert "the policy raised SystemExit: the policy gave up; the vehicle holds" in caplog.text


def test_an_action_numpy_cannot_convert_holds_the_vehicle_and_is_counted(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An action whose conversion raised anything but TypeError or ValueError (a Python int
    beyond a float's range: OverflowError; a PyTorch tensor that requires grad: RuntimeError)
    went past the action's check as that bare error: the pilot's loop reported it as a fault
    of the vision's step, and the vehicle flew on its last set-point, the failure neither
    counted nor said as the policy's. It is now the policy's failed action, as a NaN is."""
    calls: list[object] = []
    flown = threading.Event()

    def policy(obs: object) -> object:
        calls.append(obs)
        if len(calls) == 3:
            flown.set()
        return [10**400, 0, 0, 0] if len(calls) == 1 else np.zeros(4)

    with caplog.at_level("WARNING", logger="skeye.pilot.policy"), \
            _policy_engaged(tmp_path, policy) as (_, pilot):
        assert flown.wait(30), f"the pilot's loop stopped: {pilot.loop_error!r}"
        assert pilot.vision.failures == 1 and pilot.vision.failures_in_a_row == 0
    assert "the policy's action: an action is 4 real numbers" in caplog.text
    assert "OverflowError" in caplog.text


def test_ground_control_takes_the_vehicle_back_while_the_policy_thinks(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The policy was called holding the boards' lock, which every ground-control command
    takes too: while a call ran (a slow model, a hung one), ground control could not take the
    vehicle back (PAD_MODE 0), land it or get any answer, and when the call returned, its
    action was flown before the command was even read. The call now runs outside that lock:
    the command is answered at once, while the policy still thinks, and the late action is
    not flown over it (the vehicle is handed back with a hover)."""
    from skeye.link.vehicle import pad_mode_command
    from skeye.wire.packets import PadAction

    thinking, released = threading.Event(), threading.Event()
    calls: list[object] = []

    def policy(obs: object) -> object:
        calls.append(obs)
        if len(calls) == 2:
            thinking.set()
            released.wait(30)  # until the test lets it answer
            return np.array([1.0, 0.0, 0.0, 0.0])
        return np.zeros(4)

    with caplog.at_level("INFO", logger="skeye.pilot.policy"), \
            _policy_engaged(tmp_path, policy) as (vehicle, pilot):
        try:
            assert thinking.wait(30)
            vehicle.command(pad_mode_command(PadAction.OFF), timeout_s=5.0)
            assert not released.is_set()  # answered while the policy still thought
        finally:
            released.set()
        vehicle.wait_state(NavState.HOLDING, timeout_s=10)
    assert len(calls) == 2 and pilot.vision.failures == 0
    assert not pilot.vision.engaged
    assert "the policy's action came after ground control changed PAD_MODE HOLD" in caplog.text


def test_ground_control_engaging_it_anew_during_a_call_makes_the_call_stale(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """PAD_MODE 0 and then HOLD again while one policy call runs: the vehicle ends up in the
    mode the call was made in, HOLDING, so a check of mode and state alone flew the stale
    action, and the new engagement got no ``reset()``. The boards now count PAD_MODE
    commands (and changes of motion): the late action is not flown, and the policy is reset
    for the new engagement before its next call."""
    from skeye.link.vehicle import pad_mode_command
    from skeye.wire.packets import PadAction

    thinking, released, again = threading.Event(), threading.Event(), threading.Event()

    class Policy:
        def __init__(self) -> None:
            self.calls = 0
            self.resets = 0
            self.resets_at_call: list[int] = []

        def reset(self) -> None:
            self.resets += 1

        def __call__(self, obs: object) -> object:
            self.calls += 1
            self.resets_at_call.append(self.resets)
            if self.calls == 2:
                thinking.set()
                released.wait(30)  # until the test lets it answer
                return np.array([1.0, 0.0, 0.0, 0.0])
            if self.calls == 3:
                again.set()
            return np.zeros(4)

    policy = Policy()
    with caplog.at_level("INFO", logger="skeye.pilot.policy"), \
            _policy_engaged(tmp_path, policy) as (vehicle, pilot):
        try:
            assert thinking.wait(30)
            vehicle.command(pad_mode_command(PadAction.OFF), timeout_s=5.0)
            vehicle.command(pad_mode_command(PadAction.HOLD), timeout_s=5.0)
        finally:
            released.set()
        assert again.wait(30), "no call after the new engagement"
    assert "the policy's action came after ground control changed PAD_MODE HOLD" in caplog.text
    assert policy.resets_at_call[:3] == [1, 1, 2], policy.resets_at_call
    assert pilot.vision.failures == 0
