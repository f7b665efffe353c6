"""A scripted Airframe for testing the boards and the server without a simulator."""

from __future__ import annotations

from dataclasses import replace

from skeye.pilot.airframe import GpsFix, Snapshot


class FakeAirframe:
    """Records every command; motions finish when a test calls ``finish()``."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[float, ...]]] = []
        self.busy = False
        self.gps_mode = False  # the last set_velocity's
        self.snap = Snapshot(
            time_s=0.0,
            pos_ned_m=(0.0, 0.0, 0.0),
            rpy_rad=(0.0, 0.0, 0.0),
            vel_ned_m_s=(0.0, 0.0, 0.0),
            rates_frd_rad_s=(0.0, 0.0, 0.0),
            specific_force_frd_m_s2=(0.0, 0.0, -9.80665),
            mag_field_frd_ut=(20.0, 0.0, 40.0),
            mag_heading_rad=0.0,
            baro_pressure_pa=101325.0,
            baro_altitude_m=0.0,
            baro_climb_m_s=0.0,
            gps=GpsFix(True, 9, 49.0, 8.0, 100.0, (0.0, 0.0, 0.0)),
            battery_v=12.4,
            armed=False,
            landed=True,
            thrust_fraction=0.0,
        )

    def snapshot(self) -> Snapshot:
        return self.snap

    def describe(self) -> str:
        return "a scripted airframe (tests/pilot/fake_airframe.py)"

    def _cmd(self, name: str, *args: float | None, busy: bool = True) -> None:
        self.calls.append((name, tuple(a for a in args if a is not None)))
        self.busy = busy

    def take_off(self, altitude_m: float) -> None:
        self._cmd("take_off", altitude_m)
        self.snap = replace(self.snap, armed=True)

    def fly_to(self, north_m: float, east_m: float, altitude_m: float, speed_m_s: float) -> None:
        self._cmd("fly_to", north_m, east_m, altitude_m, speed_m_s)

    def fly_to_gps(self, lat: float, lon: float, altitude_m: float, speed_m_s: float) -> None:
        self._cmd("fly_to_gps", lat, lon, altitude_m, speed_m_s)

    def turn_by(self, yaw_rad: float) -> None:
        self._cmd("turn_by", yaw_rad)

    def set_velocity(
        self, fwd: float, right: float, up: float, yaw_rate: float, duration_s: float | None,
        *, gps_mode: bool = False,
    ) -> None:
        self.gps_mode = gps_mode
        self._cmd("set_velocity", fwd, right, up, yaw_rate, duration_s, busy=False)

    def hover(self) -> None:
        self._cmd("hover", busy=False)

    def land(self) -> None:
        self._cmd("land")

    def attitude(self, roll: float, pitch: float, yaw_rate: float, thrust: float,
                 height_mode: bool = False) -> None:
        self._cmd("attitude", roll, pitch, yaw_rate, thrust, busy=False)
        self.height_mode = height_mode
        if thrust > 0:
            self.snap = replace(self.snap, armed=True)

    def advance(self, seconds: float) -> None:
        pass

    def reset(self) -> str:
        self._cmd("reset", busy=False)
        self.snap = replace(self.snap, crashed="", armed=False, landed=True,
                            pos_ned_m=(0.0, 0.0, 0.0), vel_ned_m_s=(0.0, 0.0, 0.0))
        return "reset at home"

    def finish(self, **changes: object) -> None:
        """The current motion is done; the snapshot takes ``changes``."""
        self.busy = False
        self.snap = replace(self.snap, **changes)  # type: ignore[arg-type]

    def names(self) -> list[str]:
        return [c[0] for c in self.calls]
