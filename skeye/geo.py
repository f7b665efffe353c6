"""Geodetic positions from a world's origin with a local tangent-plane model.

How this works: latitude and longitude follow from north/east offsets with the WGS-84 meridian
and prime-vertical radii of curvature at the origin (the equirectangular approximation PX4 and
AirSim use for local frames); altitude is the origin's altitude minus the NED down coordinate.
Good to a few millimetres over the few hundred metres a small UAV flies, away from the poles.

At a pole longitude is degenerate (every longitude is the same point) and the east radius is
zero, so an origin exactly at a pole uses the polar azimuthal equidistant form instead: the
distance from the pole along the meridian, in the direction of the longitude, with north along
the origin's meridian (the tangent plane's own north there, as from the ECEF rotation at
latitude +-90). A point at a pole is the same point at any longitude: it takes the origin's. A
position past a pole (latitude beyond +-90) continues on the far side (the longitude + 180).
Within some kilometres of a pole, short of it, the equirectangular form does not hold: its east
scale errs by the tangent of the latitude times the north offset (27 % over 300 m at
89.99 deg), and within a few hundred metres of the pole an east offset spans more than 180 deg
of longitude, which wraps (at 89.9999 deg, 40 m east comes back from latitude and longitude as
about 30 m west). Positions there are wrong by up to hundreds of metres; world files refuse an
origin at the poles, and no flight of a small UAV in this model should start near one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from skeye.errors import InvalidArgument

WGS84_A_M = 6378137.0
WGS84_E2 = 6.69437999014e-3
LOWEST_LAND_AMSL_M = -430.0
"""The lowest dry land on Earth, the Dead Sea shore, about 430 m below sea level: no world's
origin and no flight target lies below it."""
MAX_POSITION_M: Final = 1.0e5
"""The farthest a position coordinate (north, east or down) lies from a world's origin: 100 km.
The simulator stops a robot beyond it as diverged (:func:`skeye.sim.robot.check_state`), so
no recording of it holds one; no small UAV's flight comes near it."""


@dataclass(frozen=True)
class GeoOrigin:
    """The geodetic position of a world's NED origin."""

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0

    def __post_init__(self) -> None:
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise InvalidArgument(f"latitude {self.latitude_deg} deg is outside [-90, 90]")
        if not -180.0 <= self.longitude_deg <= 180.0:
            raise InvalidArgument(f"longitude {self.longitude_deg} deg is outside [-180, 180]")

    @property
    def pole(self) -> int:
        """+1 at the north pole, -1 at the south pole, 0 elsewhere."""
        return 1 if self.latitude_deg == 90.0 else -1 if self.latitude_deg == -90.0 else 0

    def _radii_m(self) -> tuple[float, float]:
        lat = math.radians(self.latitude_deg)
        s2 = math.sin(lat) ** 2
        meridian = WGS84_A_M * (1 - WGS84_E2) / (1 - WGS84_E2 * s2) ** 1.5
        normal = WGS84_A_M / math.sqrt(1 - WGS84_E2 * s2)
        return meridian, normal * math.cos(lat)

    def to_geodetic(
        self, north_m: float, east_m: float, down_m: float
    ) -> tuple[float, float, float]:
        """NED offset (m) -> (latitude deg, longitude deg, altitude m)."""
        r_north, r_east = self._radii_m()
        if self.pole:
            # Polar: the distance from the pole, and the bearing from the origin's meridian.
            distance_m = math.hypot(north_m, east_m)
            lat = self.pole * (90.0 - math.degrees(distance_m / r_north))
            bearing = math.atan2(east_m, -self.pole * north_m) if distance_m else 0.0
            lon = self.longitude_deg + math.degrees(bearing)
        else:
            lat = self.latitude_deg + math.degrees(north_m / r_north)
            lon = self.longitude_deg + math.degrees(east_m / r_east)
        if abs(lat) > 90.0:  # past a pole: on the far side of it
            lat = math.copysign(180.0, lat) - lat
            lon += 180.0
        if not -180.0 <= lon <= 180.0:
            lon = math.remainder(lon, 360.0)
        return lat, lon, self.altitude_m - down_m

    def to_ned(
        self, latitude_deg: float, longitude_deg: float, altitude_m: float
    ) -> tuple[float, float, float]:
        """(latitude deg, longitude deg, altitude m) -> NED offset (m)."""
        r_north, r_east = self._radii_m()
        if abs(latitude_deg) == 90.0:  # a pole is one point: its longitude is the origin's
            longitude_deg = self.longitude_deg
        if self.pole:
            distance_m = math.radians(90.0 - self.pole * latitude_deg) * r_north
            bearing = math.radians(longitude_deg - self.longitude_deg)
            north = -self.pole * distance_m * math.cos(bearing)
            east = distance_m * math.sin(bearing)
        else:
            north = math.radians(latitude_deg - self.latitude_deg) * r_north
            # The shorter way round: across the antimeridian (179.9999 to -179.9999 deg) the
            # plain difference is almost a whole turn. Exact for differences within 180 deg.
            east = math.radians(math.remainder(longitude_deg - self.longitude_deg, 360.0)) * r_east
        return north, east, self.altitude_m - altitude_m


def to_degrees_minutes(value_deg: float, positive: str, negative: str) -> str:
    """USARSim's GPS text: ``39,8.0341,N`` (whole degrees, decimal minutes, hemisphere)."""
    hemi = positive if value_deg >= 0 else negative
    a = abs(value_deg)
    deg = int(a)
    minutes = (a - deg) * 60.0
    return f"{deg},{minutes:.4f},{hemi}"


def from_degrees_minutes(text: str) -> float:
    """Inverse of :func:`to_degrees_minutes`."""
    deg_s, min_s, hemi = text.split(",")
    value = int(deg_s) + float(min_s) / 60.0
    if hemi.strip().upper() in ("S", "W"):
        value = -value
    elif hemi.strip().upper() not in ("N", "E"):
        raise InvalidArgument(f"unknown hemisphere {hemi!r} in {text!r}")
    return value
