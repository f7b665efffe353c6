"""DRIVE {BoardMode}: the LL board's height and GPS modes selected over the text protocol.

Height mode (attitude form): angles stay angles, Thrust 0.5 holds the height estimate, above
0.5 climbs. A mode with the wrong form, or an unknown one, is refused with ERR naming it, and
the connection keeps working.
"""

from __future__ import annotations

from tests.sim.conftest import running_sim, sensor_series, vec


def _height_m(messages) -> float:
    series = sensor_series(messages, "GroundTruth", "Location")
    return -vec(series[-1][1])[2]


def test_height_mode_holds_then_climbs(client_factory) -> None:
    with running_sim(mode="lockstep", seed=3) as server:
        c = client_factory(server)
        assert c.answer("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-1.5}",
                        "INIT").type == "RES"
        c.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0.5} {BoardMode height}")
        start = _height_m(c.step(100))
        held = _height_m(c.step(2000))  # 2 s at the centre: the height is held
        # on the board's pressure altitude, as the AscTec LL board holds it: within a few
        # of the barometer's 1.5 Pa (0.125 m) noise sigma, the filtered estimate's wander
        assert abs(held - start) < 4 * 0.125, (start, held)
        c.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0.8} {BoardMode height}")
        climbed = _height_m(c.step(2000))  # above the centre: a climb rate
        assert climbed > held + 0.5, (held, climbed)
        # Attitude mode (no BoardMode) at the same stick is collective thrust, not a rate.
        c.send("DRIVE {RollAngle 0} {PitchAngle 0} {Thrust 0.0}")
        fell = _height_m(c.step(500))
        assert fell < climbed - 0.2, (climbed, fell)


def test_board_mode_is_checked(client_factory) -> None:
    with running_sim(mode="lockstep", seed=3) as server:
        c = client_factory(server)
        c.answer("INIT {ClassName hummingbird} {Name R1} {Location 0,0,-1.5}", "INIT")
        err = c.answer("DRIVE {LinearVelocity 0.5} {BoardMode height}", "DRIVE")
        assert err.type == "ERR" and "BoardMode height goes with the attitude" in err.get("Reason")
        err = c.answer("DRIVE {RollAngle 0} {Thrust 0.4} {BoardMode gps}", "DRIVE")
        assert err.type == "ERR" and "velocity form" in err.get("Reason")
        err = c.answer("DRIVE {Thrust 0.4} {BoardMode hover}", "DRIVE")
        assert err.type == "ERR" and "'hover' is not one of height, gps" in err.get("Reason")
        c.send("DRIVE {LinearVelocity 0} {BoardMode gps}")  # accepted: no ERR before PING
        assert c.answer("PING {Id x}", "PING").type == "RES"
