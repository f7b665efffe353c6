"""AscTec conformance (issue 19, points 6-8): a ground station written from the SDK's structures.

The client (tests/compat/asctec_client.py) packs ``WO_CTRL_INPUT`` and unpacks LL_STATUS,
RC_DATA and IMU_CALCDATA with ``struct`` from ``sdk.h``'s C layouts and checks the CRC itself;
it talks to a real pilot on a loopback port that flies a real simulator (lockstep, paced by the
pilot). Waits are on the vehicle's own answers and on sim time, never on wall-clock guesses.

- RC_DATA: ``channel[0]`` pitch, ``[1]`` roll, ``[2]`` thrust, ``[3]`` yaw, ``[4]`` serial
  interface enable (> 2048 enabled), ``[5]`` mode switch (sdk.h, ``RO_RC_DATA``).
- IMU_CALCDATA: angles 1000 = 1 deg, angular rates 64.8 counts = 1 deg/s (sdk.h:
  "in 0.0154 deg/s (=> 64.8 = 1 deg/s)"), ``angle_yaw`` 0..360000. The SDK states no signs;
  skeye uses the aerospace body frame (x forward, y right, z down): roll right, nose up and
  clockwise yaw are positive. A manoeuvre flown with the sticks (roll right, pitch forward,
  yaw clockwise) is read back with those signs and scales.
- Start-up: a pilot answers a poll sent the moment it serves.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from skeye.control.connection import connect
from skeye.pilot.server import PilotServer
from skeye.pilot.sim_airframe import SimAirframe
from skeye.processes import start_skeye, stop_process
from tests.compat.asctec_client import AscTecClient
from tests.sim.conftest import running_sim

ATTITUDE_MODE = 0x0F  # pitch, roll, yaw and thrust from the serial input
STICK_DEG = 0.025  # CTRL_INPUT: +-2047 = 51.2 deg (sdk.h, WO_CTRL_INPUT)
YAW_STICK_DEG_S = 0.120  # skeye's yaw-rate stick scale (docs/protocols/packets.md)
THRUST = 1850  # of 4095: a little above the Hummingbird's hover thrust


@pytest.fixture
def vehicle() -> Iterator[tuple[AscTecClient, object]]:
    with ExitStack() as stack:
        server = stack.enter_context(running_sim(mode="lockstep", seed=11))
        sim = stack.enter_context(connect(f"127.0.0.1:{server.port}", timeout_s=10.0))
        robot = sim.spawn("hummingbird", start="Pad1")
        pilot = stack.enter_context(PilotServer(
            SimAirframe(sim, robot), port=0, lockstep=True, lockstep_rate=2.0, tick_s=0.05))
        client = AscTecClient(int(pilot.address.rsplit(":", 1)[1]))
        stack.callback(client.close)
        yield client, robot


def _motors_on(client: AscTecClient) -> None:
    """Thrust 0 and full yaw held (the real vehicle's gesture) until LL_STATUS says motors on."""
    for _ in range(10_000):
        client.ctrl_input(0, 0, -2047, 0, ATTITUDE_MODE)
        if client.ll_status()[7]:  # motors_on
            return
    raise AssertionError("the stick gesture never started the motors")


def _fly(client: AscTecClient, robot, seconds: float, pitch: int, roll: int, yaw: int) -> None:
    """Send the sticks as a ground station does for ``seconds`` of sim time."""
    start = robot.ground_truth.latest.time_s
    while robot.ground_truth.latest.time_s - start < seconds:
        client.ctrl_input(pitch, roll, yaw, THRUST, ATTITUDE_MODE)


def test_rc_data_carries_the_sticks_in_asctec_channel_order(vehicle) -> None:
    client, _robot = vehicle
    client.ctrl_input(100, -200, 300, 40, ATTITUDE_MODE)  # motors off: only shown
    channels = client.rc_data()[:8]
    assert channels[0] == 2048 + 100  # pitch
    assert channels[1] == 2048 - 200  # roll
    assert channels[2] == 40  # thrust
    assert channels[3] == 2048 + 300  # yaw
    assert channels[4] > 2048  # serial interface enabled
    assert channels[5] in (0, 2048, 4095)  # mode switch: manual / height / GPS
    assert all(0 <= c <= 4095 for c in channels)


def test_imu_calcdata_signs_and_scales_in_a_stick_manoeuvre(vehicle) -> None:
    client, robot = vehicle
    _motors_on(client)
    # Roll right: 600 counts = 15 deg.
    _fly(client, robot, 1.5, 0, 600, 0)
    imu = client.imu_calcdata()
    gt = robot.ground_truth.latest
    assert imu[1] / 1000 == pytest.approx(600 * STICK_DEG, abs=2.0)  # angle_roll, deg
    assert abs(imu[0]) / 1000 < 2.0  # angle_nick
    assert gt.rpy_rad[0] > 0.2 and gt.velocity_ned_m_s[1] > 0.2  # leaning right, going east
    # Pitch forward (stick forward = nose down = negative pitch count): moves north.
    _fly(client, robot, 1.5, -600, 0, 0)
    imu = client.imu_calcdata()
    gt = robot.ground_truth.latest
    assert imu[0] / 1000 == pytest.approx(-600 * STICK_DEG, abs=2.0)  # angle_nick, deg
    assert abs(imu[1]) / 1000 < 2.0
    assert gt.rpy_rad[1] < -0.2 and gt.velocity_ned_m_s[0] > 0.2  # nose down, going north
    # Yaw clockwise (seen from above): positive yaw stick, 500 counts = 60 deg/s.
    yaw_before = client.imu_calcdata()[2]
    _fly(client, robot, 1.0, 0, 0, 500)
    imu = client.imu_calcdata()
    rate_deg_s = imu[5] / 64.8  # angvel_yaw
    assert rate_deg_s == pytest.approx(500 * YAW_STICK_DEG_S, rel=0.15)
    assert robot.ground_truth.latest.angular_velocity_frd_rad_s[2] > 0.5  # body z down: clockwise
    turned = (imu[2] - yaw_before) % 360_000  # angle_yaw grows clockwise, 0..360000
    assert 20_000 < turned < 120_000, (yaw_before, imu[2])


def test_a_pilot_answers_a_poll_sent_the_moment_it_serves() -> None:
    sim, found = start_skeye(["sim", "--mode", "lockstep", "--port", "0", "--seed", "2"],
                             [r"control protocol on [\d.]+:(\d+)"], "skeye sim")
    try:
        pilot, pfound = start_skeye(
            ["pilot", "--sim", f"127.0.0.1:{found[0].group(1)}", "--port", "0"],
            [r"ground control on tcp://[\d.]+:(\d+)"], "skeye pilot")
        try:
            client = AscTecClient(int(pfound[0].group(1)), timeout_s=30.0)
            try:
                status = client.ll_status()  # at once, before any other command
                assert status[0] > 9000  # battery_voltage_1 in mV: a real reading
                assert status[3] > 0  # cpu_load: the LL board's cycles per second
                assert status[7] == 0  # motors off on the ground
            finally:
                client.close()
        finally:
            stop_process(pilot)
    finally:
        stop_process(sim)
