"""Robot configuration files: which vehicle model, its parameters, and which sensors sit where.

How this works: a robot class is a TOML file (built-ins in ``skeye/robots/``). Its tables
``[airframe]``, ``[battery]`` and ``[controller]`` fill the parameter dataclasses of
:mod:`skeye.robots.params`; each ``[[sensors]]`` entry mounts a sensor USARSim-style: ``type``,
``name`` (no whitespace, braces, ``/``, ``,``, ``:`` or control characters: protocol lines carry
it), ``position_m`` (body FRD), ``direction_rad`` (roll, pitch, yaw of the sensor frame in the
body frame) and the sensor class's own parameters. An
optional ``[envelope]`` table (``ceiling_m``, ``max_radius_m``) is the flight envelope the pilot
enforces for this class (``skeye.pilot.envelope``; the simulator itself does not use it). Every
mistake raises ConfigError naming the file and the key; nothing is half-loaded.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from skeye.errors import ConfigError
from skeye.pilot.envelope import FlightEnvelope
from skeye.robots.camera_model import CameraModel, build_camera_model
from skeye.robots.params import (
    AirframeParams,
    BatteryParams,
    ControllerParams,
    EstimatorParams,
    dataclass_from_mapping,
)
from skeye.wire.sim_lines import CONTROL_CHARACTERS

BUILTIN_ROBOTS = ("hummingbird", "airrobot")
CAMERA_TYPE = "camera"
MOTORS_TYPE = "motors"


@dataclass(frozen=True)
class SensorMount:
    """One mounted sensor as the configuration file gives it."""

    type_name: str
    name: str
    position_m: tuple[float, float, float]
    direction_rad: tuple[float, float, float]
    params: tuple[tuple[str, Any], ...]


@dataclass(frozen=True)
class RobotConfig:
    """A validated robot class."""

    class_name: str
    description: str
    board_rate_hz: float
    status_rate_hz: float
    airframe: AirframeParams
    battery: BatteryParams
    controller: ControllerParams
    sensors: tuple[SensorMount, ...]
    source: str
    envelope: FlightEnvelope = field(default_factory=FlightEnvelope)
    estimator: EstimatorParams = field(default_factory=EstimatorParams)


_TOP_KEYS = {
    "name",
    "description",
    "board_rate_hz",
    "status_rate_hz",
    "airframe",
    "battery",
    "controller",
    "sensors",
    "envelope",
    "estimator",
}


_NAME_FORBIDDEN = "{}/,:"
"""What a sensor's name may not hold, besides whitespace and control characters: the braces and
blanks that delimit a protocol line's fields, ``/`` (a camera's key is ``robot/camera``), and the
``,`` and ``:`` of the robot's ``CONF {Sensors Type:Name,...}``. A control character (BEL, ESC,
...) went out in every SEN line to the client's terminal, and the encoder refused CONF over it."""


def _vector(owner: str, key: str, value: Any) -> tuple[float, float, float]:
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        or not all(math.isfinite(v) for v in value)
    ):
        raise ConfigError(f"{owner}: {key} must be a list of 3 finite numbers, got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def parse_robot_config(data: dict[str, Any], source: str) -> RobotConfig:
    """Validate a parsed TOML document; ``source`` names the file in error messages."""
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {unknown}; known: {sorted(_TOP_KEYS)}")
    name = data.get("name")
    # CONF {Class <name>} carries it: one word of printable text (a blank, a brace or a control
    # character made GETCONF {Type Robot} answer ERR for every robot of the class).
    if (not isinstance(name, str) or not name or any(c in "{}" or c.isspace() for c in name)
            or CONTROL_CHARACTERS.search(name)):
        raise ConfigError(f"{source}: 'name' must be a non-empty string without whitespace, "
                          f"braces or control characters (CONF {{Class ...}} carries it), "
                          f"got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"{source}: 'description' must be a string, got {description!r}")
    rates = {}
    for key, default in (("board_rate_hz", 1000.0), ("status_rate_hz", 10.0)):
        value = data.get(key, default)
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not (math.isfinite(value) and value > 0)
        ):
            raise ConfigError(f"{source}: {key} must be a positive finite number, got {value!r}")
        rates[key] = float(value)
    tables = {}
    for key in ("airframe", "battery", "controller", "envelope", "estimator"):
        table = data.get(key, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: [{key}] must be a table")
        tables[key] = table
    airframe = dataclass_from_mapping(AirframeParams, tables["airframe"], f"{source} [airframe]")
    battery = dataclass_from_mapping(BatteryParams, tables["battery"], f"{source} [battery]")
    controller = dataclass_from_mapping(
        ControllerParams, tables["controller"], f"{source} [controller]"
    )
    envelope = dataclass_from_mapping(FlightEnvelope, tables["envelope"], f"{source} [envelope]")
    estimator = dataclass_from_mapping(
        EstimatorParams, tables["estimator"], f"{source} [estimator]"
    )
    sensors_data = data.get("sensors", [])
    if not isinstance(sensors_data, list):
        raise ConfigError(f"{source}: 'sensors' must be an array of tables ([[sensors]])")
    mounts: list[SensorMount] = []
    seen: set[tuple[str, str]] = set()
    for i, entry in enumerate(sensors_data):
        owner = f"{source} sensors[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(f"{owner}: must be a table")
        type_name = entry.get("type")
        sensor_name = entry.get("name")
        if not isinstance(type_name, str) or not type_name:
            raise ConfigError(f"{owner}: 'type' must be a non-empty string")
        if (not isinstance(sensor_name, str) or not sensor_name
                or any(c in _NAME_FORBIDDEN or c.isspace() for c in sensor_name)
                or CONTROL_CHARACTERS.search(sensor_name)):
            raise ConfigError(
                f"{owner}: 'name' must be a non-empty string without whitespace, braces, '/', "
                f"',', ':' or control characters (protocol lines carry it), got {sensor_name!r}"
            )
        ident = (type_name.lower(), sensor_name.lower())
        if ident in seen:
            raise ConfigError(f"{owner}: duplicate sensor {type_name} {sensor_name!r}")
        seen.add(ident)
        position = _vector(owner, "position_m", entry.get("position_m", [0, 0, 0]))
        direction = _vector(owner, "direction_rad", entry.get("direction_rad", [0, 0, 0]))
        params = tuple(
            (k, v)
            for k, v in entry.items()
            if k not in ("type", "name", "position_m", "direction_rad")
        )
        mounts.append(SensorMount(type_name, sensor_name, position, direction, params))
    return RobotConfig(
        class_name=name.lower(),
        description=description,
        board_rate_hz=rates["board_rate_hz"],
        status_rate_hz=rates["status_rate_hz"],
        airframe=airframe,
        battery=battery,
        controller=controller,
        sensors=tuple(mounts),
        source=source,
        envelope=envelope,
        estimator=estimator,
    )


def load_robot_config(
    name_or_path: str | Path, search_dirs: tuple[Path, ...] = (), *, allow_paths: bool = True
) -> RobotConfig:
    """A robot class by name or a TOML path.

    Names resolve to the built-ins (``USARBot.`` prefix and case ignored), then to
    ``<dir>/<name>.toml`` in ``search_dirs`` (``skeye sim --robot-dir``; case ignored too, as
    USARSim's class names: ``MyQuad.toml`` is ``myquad``). A path is accepted only with
    ``allow_paths`` (the command line, not the network: a client may not read files).
    """
    candidate = str(name_or_path)
    short = candidate.split(".", 1)[1] if candidate.lower().startswith("usarbot.") else candidate
    path: Path | None = None
    if short.lower() in BUILTIN_ROBOTS:
        source = f"robots/{short.lower()}.toml"
        builtin = resources.files("skeye.robots").joinpath(f"{short.lower()}.toml")
        text = builtin.read_text(encoding="utf-8")
    else:
        if short.replace("_", "").replace("-", "").isalnum():
            for folder in search_dirs:
                path = _class_file(Path(folder), short)
                if path is not None:
                    break
        if path is None and allow_paths and candidate.endswith(".toml"):
            path = Path(candidate)
            if not path.is_file():
                raise ConfigError(f"robot configuration file not found: {path}")
        if path is None:
            known = list(BUILTIN_ROBOTS) + sorted(
                p.stem for folder in search_dirs for p in Path(folder).glob("*.toml")
            )
            raise ConfigError(
                f"unknown robot class {candidate!r}; known classes: {', '.join(known)}"
            )
        source = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{source}: not valid TOML (not UTF-8 text): {exc}") from None
        except OSError as exc:
            raise ConfigError(f"{source}: cannot read robot file: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: invalid TOML: {exc}") from None
    return parse_robot_config(data, source)


def _class_file(folder: Path, name: str) -> Path | None:
    """``<folder>/<name>.toml``, the name's case ignored (an exact match first).

    Raises:
        ConfigError: two files whose names differ only in case and neither matches exactly.
    """
    exact = folder / f"{name}.toml"
    if exact.is_file():
        return exact
    found = sorted(p for p in folder.glob("*.toml")
                   if p.stem.casefold() == name.casefold() and p.is_file())
    if len(found) > 1:
        raise ConfigError(f"robot class {name!r} is ambiguous in {folder}: "
                          f"{', '.join(p.name for p in found)} (class names ignore case)")
    return found[0] if found else None


def robot_folders(search_dirs: tuple[str | Path, ...]) -> tuple[Path, ...]:
    """``--robot-dir`` values as folders.

    Raises:
        ConfigError: one is missing or not a folder (named with the option).
    """
    folders = tuple(Path(d) for d in search_dirs)
    for folder in folders:
        if not folder.is_dir():
            raise ConfigError(f"--robot-dir {folder}: not a folder")
    return folders


def validate_robot_dirs(
    search_dirs: tuple[Path, ...], check: Callable[[RobotConfig], None] | None = None,
    profile: str | None = None,
) -> list[RobotConfig]:
    """Load every ``*.toml`` in each ``--robot-dir`` folder, so a typo stops ``skeye sim`` at
    start-up with the message an ``INIT`` would have got, not at the first ``INIT``.

    ``check`` runs on each loaded class the checks building its robot runs (``skeye sim``
    passes :func:`skeye.sim.robot.check_robot_config` at its physics step, which builds the
    robot as INIT does: the sensors' parameters and rates, the cameras, the board rate, the
    board's estimator; this package may not import the simulator). Without it only the file
    and its camera models are checked. ``profile`` is ``skeye sim --camera-profile``: the
    camera models are checked under it, as the cameras will render them.

    Raises:
        ConfigError: a folder that is missing or not a folder, or a robot file that does not
            load (the message names the file and the problem).
    """
    configs = []
    classes: dict[str, Path] = {}  # class name -> the file INIT takes for it
    seen_folders: set[Path] = set()
    for folder in robot_folders(search_dirs):
        if folder.resolve() in seen_folders:
            continue  # the same folder named twice: its files are the same classes
        seen_folders.add(folder.resolve())
        paths = sorted(folder.glob("*.toml"))
        stems = [p.stem.casefold() for p in paths]
        for path in paths:
            # A file INIT never loads: its edits were silently ignored (hummingbird.toml with
            # another mass_kg flew the built-in's) or its class could not be asked for.
            if path.stem.casefold() in BUILTIN_ROBOTS:
                raise ConfigError(f"--robot-dir {folder}: {path.name} is never used: INIT "
                                  f"{{ClassName {path.stem}}} takes the built-in class "
                                  f"{path.stem.lower()}; give the file (and its 'name') another "
                                  "name")
            if not path.stem.replace("_", "").replace("-", "").isalnum():
                raise ConfigError(f"--robot-dir {folder}: {path.name} is never used: a class "
                                  "name (the file's name) holds only letters, digits, '-' and "
                                  "'_'")
            if stems.count(path.stem.casefold()) > 1:
                raise ConfigError(f"--robot-dir {folder}: {path.name} and another file name "
                                  "the same robot class (class names ignore case)")
            # INIT takes the first folder's file: a later one's edits were silently ignored.
            earlier = classes.setdefault(path.stem.casefold(), path)
            if earlier != path:
                raise ConfigError(f"--robot-dir {folder}: {path.name} is never used: INIT "
                                  f"{{ClassName {path.stem}}} takes {earlier} (an earlier "
                                  "--robot-dir; class names ignore case)")
            config = load_robot_config(folder / path.name)
            for mount in config.sensors:  # a bad camera model stops us here too
                if mount.type_name.lower() == CAMERA_TYPE:
                    mount_camera_model(config, mount, profile)
            if check is not None:
                check(config)
            configs.append(config)
    return configs


def camera_model(
    robot: str | Path, camera: str | None = None, profile: str | None = None
) -> CameraModel:
    """The :class:`~skeye.robots.camera_model.CameraModel` of a robot class's camera (its
    first, or the one named), under the robot file's profile or ``profile`` if given: the
    intrinsics (``camera_matrix``, ``dist_coeffs``) frames are rendered through.

    Raises:
        ConfigError: unknown robot class or camera, or a bad camera key.
    """
    config = load_robot_config(robot)
    for mount in config.sensors:
        if mount.type_name.lower() != CAMERA_TYPE:
            continue
        if camera is not None and mount.name.lower() != camera.lower():
            continue
        return mount_camera_model(config, mount, profile)
    names = [m.name for m in config.sensors if m.type_name.lower() == CAMERA_TYPE]
    if camera and names:
        raise ConfigError(f"robot class {config.class_name!r} has no camera named {camera!r} "
                          f"(its cameras: {', '.join(names)})")
    raise ConfigError(f"robot class {config.class_name!r} has no camera")


def mount_camera_model(
    config: RobotConfig, mount: SensorMount, profile: str | None = None
) -> CameraModel:
    """The camera model of one camera entry of a loaded robot class.

    Raises:
        ConfigError: a bad size, field of view or camera-model key (named with the file).
    """
    params = dict(mount.params)
    where = f"{config.source} camera {mount.name!r}"
    size = []
    for key, default in (("width", 800), ("height", 600)):
        value = params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not 8 <= value <= 8192:
            raise ConfigError(f"{where}: {key} must be an integer 8..8192, got {value!r}")
        size.append(value)
    fov = params.get("fov_h_rad", 1.309)
    if isinstance(fov, bool) or not isinstance(fov, int | float) or not (
        math.isfinite(fov) and 0.01 < fov < math.pi - 0.01
    ):
        raise ConfigError(f"{where}: fov_h_rad must be in (0.01, pi - 0.01), got {fov!r}")
    return build_camera_model(params, size[0], size[1], float(fov), where, profile)
