"""Wire units of the vehicle packet protocol: how an integer field maps to an SI value.

How this works: a ``Scale`` says ``si = counts * num / den`` (converted from degrees to radians
first when ``degrees``), and the reverse rounds ``value * den / num`` to the nearest count.
Writing a unit as the two numbers the AscTec manual gives (``num`` per ``den`` counts) keeps
every conversion to one multiplication and one division, in that order, so both directions are
the exact float operations the protocol's units name. Each field of ``packet_defs.LAYOUTS``
that carries a physical quantity names its ``Scale``; ``packet_units`` derives the SI views of
whole messages from that table.

Invariants: ``to_wire`` refuses NaN, infinity and non-numbers with ``LocalProtocolError``; it
clamps only where the unit itself has a protocol range (``clamp``: sticks, thrust, quality),
because full stick is a legitimate request; a heading (``wrap``) goes on the wire as
0..359999 thousandths of a degree and comes back in [-pi, pi).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from skeye.errors import LocalProtocolError

G_M_S2 = 9.80665  # standard gravity; AscTec's 10000 counts
ACC_COUNTS_PER_G = 10_000
# AscTec SDK sdk.h (RO_ALL_DATA, IMU_CALCDATA): angular velocities "in 0.0154 deg/s
# (=> 64.8 = 1 deg/s)".
ANGVEL_COUNTS_PER_DEG_S = 64.8
STICK_DEG_PER_COUNT = 0.025
STICK_YAW_DEG_S_PER_COUNT = 0.120
STICK_MAX = 2047
THRUST_MAX = 4095
CONTROLLER_THRUST_MAX = 200
QUALITY_MAX = 1000
YAW_FULL_MDEG = 360_000


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def clamp(value: int, lo: int, hi: int) -> int:
    """``value`` limited to ``lo..hi``."""
    return lo if value < lo else hi if value > hi else value


@dataclass(frozen=True)
class Scale:
    """One wire unit: ``num`` SI units (degrees when ``degrees``) per ``den`` counts.

    ``unit`` is the SI unit and ``suffix`` the ending an SI name in that unit carries
    (``_rad``, ``_m_s``...), so a view's names can be checked against the table.
    """

    unit: str
    suffix: str
    num: float = 1
    den: float = 1
    degrees: bool = False  # the wire counts (fractions of) degrees; SI is radians
    clamp: tuple[int, int] | None = None  # the protocol's range: to_wire saturates at it
    wrap: bool = False  # a heading: 0..359999 on the wire, [-pi, pi) in SI
    modulus: int | None = None  # a counter that wraps on the wire (a clock: 2**32 ms)

    def to_si(self, counts: int) -> float:
        """Wire counts -> SI value."""
        value = counts * self.num / self.den
        if self.degrees:
            value = math.radians(value)
        return wrap_pi(value) if self.wrap else value

    def to_wire(self, value: float, what: str = "value") -> int:
        """SI value -> the nearest count (clamped or wrapped as the unit says).

        Raises:
            LocalProtocolError: ``value`` is not a finite real number.
        """
        if not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise LocalProtocolError(f"{what} must be a finite number, got {value!r}")
        if self.degrees:
            value = math.degrees(value)
        counts = round(value * self.den / self.num)
        if self.wrap:
            counts %= YAW_FULL_MDEG
        if self.modulus is not None:
            counts %= self.modulus
        return counts if self.clamp is None else clamp(counts, *self.clamp)


# The protocol's units (docs/protocols/packets.md, "Conventions" and each structure's table).
MDEG = Scale("rad", "_rad", 1, 1000, degrees=True)  # 1/1000 degree
HEADING_MDEG = Scale("rad", "_rad", 1, 1000, degrees=True, wrap=True)  # 0..360000, clockwise
ANGVEL = Scale("rad/s", "_rad_s", 1, ANGVEL_COUNTS_PER_DEG_S, degrees=True)  # 64.8 = 1 deg/s
MRAD_S = Scale("rad/s", "_rad_s", 1, 1000)
ACC = Scale("m/s^2", "_m_s2", G_M_S2, ACC_COUNTS_PER_G)  # 10000 = 1 g
MM = Scale("m", "_m", 1, 1000)
DM = Scale("m", "_m", 1, 10)
MM_S = Scale("m/s", "_m_s", 1, 1000)
DEG_E7 = Scale("deg", "_deg", 1, 10_000_000)  # latitude, longitude
MS = Scale("s", "_s", 1, 1000)
CLOCK_MS = Scale("s", "_s", 1, 1000, modulus=2**32)
"""A time stamp in ms in a uint32 that wraps, as MAVLink's ``time_boot_ms`` (every 49.7 days):
on a real airframe the vehicle's clock is the host's monotonic clock, its uptime, which a
machine left running passes."""
CS = Scale("s", "_s", 1, 100)
MV = Scale("V", "_v", 1, 1000)
QUALITY = Scale("1", "", 1, QUALITY_MAX, clamp=(0, QUALITY_MAX))  # 0..1
CONTROLLER_THRUST = Scale(
    "1", "_fraction", 1, CONTROLLER_THRUST_MAX, clamp=(0, CONTROLLER_THRUST_MAX)
)
STICK_ANGLE = Scale("rad", "_rad", STICK_DEG_PER_COUNT, degrees=True, clamp=(-STICK_MAX, STICK_MAX))
STICK_YAW_RATE = Scale(
    "rad/s", "_rad_s", STICK_YAW_DEG_S_PER_COUNT, degrees=True, clamp=(-STICK_MAX, STICK_MAX)
)
THRUST = Scale("1", "_fraction", 1, THRUST_MAX, clamp=(0, THRUST_MAX))
