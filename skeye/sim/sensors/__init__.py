"""Simulated sensors: one class per protocol sensor Type, and a factory keyed by Type.

How this works: the engine builds each mounted sensor with :func:`build_sensor` (type name, name,
:class:`Mount`, parameters, a seeded Generator) and calls ``read(state, world)`` at the
sensor's ``rate_hz``: a typed reading, never wire text (the control server writes it as
``SEN {Time t} {Type T} {Name n} ...`` with the layout of :mod:`skeye.wire.sim`'s table). The
classes live in :mod:`.base` (shared machinery), :mod:`.inertial`, :mod:`.navigation` and
:mod:`.ranging`; this module only gathers them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skeye.errors import ConfigError
from skeye.sim.sensors.base import (
    DEFAULT_RATES_HZ,
    BiasedNoise,
    Fields,
    Mount,
    Param,
    Reading,
    Sensor,
    Vec3,
    WorldQuery,
    parse_params,
)
from skeye.sim.sensors.inertial import (
    Accelerometer,
    AccelReading,
    Barometer,
    BaroReading,
    CompassReading,
    Gyro,
    GyroReading,
    MagneticCompass,
    isa_altitude_m,
    isa_pressure_pa,
)
from skeye.sim.sensors.navigation import (
    GPS,
    INS,
    Battery,
    BatteryReading,
    GpsReading,
    GroundTruth,
    GroundTruthReading,
    InsEstimate,
    InsReading,
)
from skeye.sim.sensors.ranging import FlowReading, OpticalFlow, Sonar, SonarReading

SENSOR_CLASSES: dict[str, type[Sensor[Any]]] = {
    cls.type_name.lower(): cls
    for cls in (
        GroundTruth,
        INS,
        Accelerometer,
        Gyro,
        MagneticCompass,
        Barometer,
        GPS,
        Sonar,
        OpticalFlow,
        Battery,
    )
}
"""Every sensor class, keyed by its lower-case protocol Type."""


def build_sensor(
    type_name: str,
    name: str,
    mount: Mount,
    params: Mapping[str, object],
    rng: np.random.Generator,
) -> Sensor[Any]:
    """A sensor of the protocol Type ``type_name`` (case-insensitive); ConfigError if unknown."""
    cls = SENSOR_CLASSES.get(type_name.lower())
    if cls is None:
        known = ", ".join(c.type_name for c in SENSOR_CLASSES.values())
        raise ConfigError(f"sensor {name!r}: unknown sensor type {type_name!r}; known: {known}")
    return cls(name, mount, params, rng)


__all__ = [
    "DEFAULT_RATES_HZ",
    "GPS",
    "INS",
    "SENSOR_CLASSES",
    "AccelReading",
    "Accelerometer",
    "BaroReading",
    "Barometer",
    "Battery",
    "BatteryReading",
    "BiasedNoise",
    "CompassReading",
    "Fields",
    "FlowReading",
    "GpsReading",
    "GroundTruth",
    "GroundTruthReading",
    "Gyro",
    "GyroReading",
    "InsEstimate",
    "InsReading",
    "MagneticCompass",
    "Mount",
    "OpticalFlow",
    "Param",
    "Reading",
    "Sensor",
    "Sonar",
    "SonarReading",
    "Vec3",
    "WorldQuery",
    "build_sensor",
    "isa_altitude_m",
    "isa_pressure_pa",
    "parse_params",
]
