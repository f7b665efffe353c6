"""World descriptions: loading, validation, the MJCF they become, where the pad lands on screen."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skeye.errors import ConfigError
from skeye.sim.world import (
    BUILTIN_WORLDS,
    PAD_SURFACE_HEIGHT_M,
    build_mjcf,
    load_world,
    parse_world,
    start_pose_list,
)
from skeye.vision.pad import SKEYE_4

ROBOT_BOX_HALF_M = (0.15, 0.15, 0.05)


def robot_xml(pos_mj: tuple[float, float, float]) -> str:
    """An example robot: a free body with one box geom, as the engine would insert one."""
    hx, hy, hz = ROBOT_BOX_HALF_M
    return (
        f'<body name="robot" pos="{pos_mj[0]} {pos_mj[1]} {pos_mj[2]}"><freejoint/>'
        f'<geom name="robot_box" type="box" size="{hx} {hy} {hz}" mass="1.2" '
        'material="robot_paint"/></body>'
    )


ROBOT_ASSETS = '<material name="robot_paint" rgba="0.9 0.2 0.1 1"/>'

BASE_TOML = """
name = "test_world"
sea_level_pressure_pa = 100000.0

[geo_origin]
latitude_deg = 50.0
longitude_deg = 12.0
altitude_m = 250.0

[magnetic_field]
ned_ut = [19.0, 1.0, 45.0]

[ground]
size_m = 20.0
texture = "checker"

[[pads]]
pad = "skeye-4"
position_ned_m = [1.0, 2.0, 0.0]
yaw_rad = 0.3

[[boxes]]
name = "house"
center_ned_m = [6.0, 2.0, -1.0]
size_m = [4.0, 2.0, 2.0]
yaw_rad = 0.5
rgb = [0.5, 0.4, 0.3]

[[lights]]
direction_ned = [0.0, 0.0, 1.0]
diffuse = [0.5, 0.5, 0.5]

[[start_poses]]
name = "Pad1"
position_ned_m = [1.0, 2.0, -0.001]
rpy_rad = [0.0, 0.0, 0.3]

[[start_poses]]
name = "Field1"
position_ned_m = [-3.0, 0.0, 0.0]
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "world.toml"
    path.write_text(text)
    return path


def compile_world(world: Any, robots: str = "", assets: str = "") -> mujoco.MjModel:
    xml, files = build_mjcf(world, robots_xml=robots, robot_assets_xml=assets)
    return mujoco.MjModel.from_xml_string(xml, files)


# ----------------------------------------------------------------------------------------------
# Built-in worlds


@pytest.mark.parametrize("name", BUILTIN_WORLDS)
def test_builtin_world_compiles_and_a_robot_rests_on_its_first_start_pose(name: str) -> None:
    world = load_world(name)
    assert world.name == name
    assert world.start_poses, "every built-in world offers start poses"
    pose_name, pos_ned, _ = start_pose_list(world)[0]
    # Drop the robot from 5 cm above the start point; it must come to rest standing on it.
    drop_m = 0.05
    center = (pos_ned[0], -pos_ned[1], -pos_ned[2] + ROBOT_BOX_HALF_M[2] + drop_m)
    model = compile_world(world, robot_xml(center), ROBOT_ASSETS)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.opt.timestep == pytest.approx(0.001)
    np.testing.assert_allclose(model.opt.gravity, (0.0, 0.0, -9.81))
    assert model.opt.density == 0.0 and model.opt.viscosity == 0.0
    data = mujoco.MjData(model)
    for _ in range(800):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    bottom_up_m = data.qpos[2] - ROBOT_BOX_HALF_M[2]
    # Resting on the given point, allowing MuJoCo's soft-contact penetration of a few mm.
    assert bottom_up_m == pytest.approx(-pos_ned[2], abs=0.004), pose_name
    assert np.linalg.norm(data.qvel) < 0.05


def test_builtin_names_and_unknown_world_lists_them() -> None:
    assert set(BUILTIN_WORLDS) == {"pad", "yard", "indoor", "checkerboard"}
    with pytest.raises(ConfigError) as err:
        load_world("moon")
    for name in BUILTIN_WORLDS:
        assert name in str(err.value)


def test_pad_world_facts() -> None:
    world = load_world("pad")
    assert world.geo_origin is not None
    assert world.geo_origin.latitude_deg == pytest.approx(50.8123)
    assert world.ground.texture == "grass" and world.ground.size_m >= 40.0
    (pad,) = world.pads
    assert pad.pad is SKEYE_4 and pad.position_ned_m == (0.0, 0.0, 0.0)
    assert pad.surface_down_m == pytest.approx(-PAD_SURFACE_HEIGHT_M)
    poses = start_pose_list(world)
    assert poses[0][0] == "Pad1"
    assert poses[0][1] == pytest.approx((0.0, 0.0, pad.surface_down_m))
    assert len(poses) >= 3 and all(p[0].startswith("Field") for p in poses[1:])
    for _, pos, _ in poses[1:]:
        assert 2.0 <= math.hypot(pos[0], pos[1]) <= 10.0


def test_indoor_has_no_gps_and_a_ceiling() -> None:
    world = load_world("indoor")
    assert world.geo_origin is None
    ceiling = max(world.boxes, key=lambda b: -b.center_ned_m[2])
    assert ceiling.center_ned_m[2] + ceiling.size_m[2] / 2 == pytest.approx(-3.0)


def test_yard_has_buildings_and_rotated_debris() -> None:
    world = load_world("yard")
    tall = [b for b in world.boxes if b.size_m[2] >= 3.0]
    small_rotated = [b for b in world.boxes if b.size_m[2] < 1.0 and b.yaw_rad != 0.0]
    assert len(tall) >= 3 and len(small_rotated) >= 3
    (pad,) = world.pads
    for box in world.boxes:  # the pad lies in an open spot
        assert math.dist(box.center_ned_m[:2], pad.position_ned_m[:2]) > 3.0


# ----------------------------------------------------------------------------------------------
# Files and MJCF


def test_file_world_defaults_and_values(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, BASE_TOML))
    assert world.source == str(tmp_path / "world.toml")
    assert world.sea_level_pressure_pa == 100000.0
    assert world.magnetic_field_ned_ut == (19.0, 1.0, 45.0)
    assert world.geo_origin is not None and world.geo_origin.altitude_m == 250.0
    assert world.pads[0].name == "pad1"
    assert list(world.start_poses) == ["Pad1", "Field1"]
    assert world.start_poses["Field1"].rpy_rad == (0.0, 0.0, 0.0)
    minimal = load_world(write(tmp_path, 'name = "bare"\n'))
    assert minimal.magnetic_field_ned_ut == pytest.approx((20.0, 1.5, 44.0))
    assert minimal.sea_level_pressure_pa == 101325.0
    assert minimal.geo_origin is None and minimal.pads == () and minimal.start_poses == {}
    compile_world(minimal)


def test_gps_false_means_no_geo_origin(tmp_path: Path) -> None:
    text = BASE_TOML.replace("[geo_origin]\n", "[geo_origin]\ngps = false\n")
    assert load_world(write(tmp_path, text)).geo_origin is None


def test_box_pose_converts_from_ned_to_mujoco(tmp_path: Path) -> None:
    model = compile_world(load_world(write(tmp_path, BASE_TOML)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "box:house")
    # NED (6, 2, -1) is 6 m north, 2 m east, 1 m up: MuJoCo NWU (6, -2, 1).
    np.testing.assert_allclose(data.geom_xpos[gid], (6.0, -2.0, 1.0), atol=1e-12)
    np.testing.assert_allclose(model.geom_size[gid], (2.0, 1.0, 1.0))
    # Yaw 0.5 rad about down turns the box's long (north) axis towards east, i.e. towards -y.
    axis = data.geom_xmat[gid].reshape(3, 3)[:, 0]
    np.testing.assert_allclose(axis, (math.cos(0.5), -math.sin(0.5), 0.0), atol=1e-9)


def test_pad_surface_and_collider_share_one_plane(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, BASE_TOML))
    model = compile_world(world)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    visual = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "pad:pad1")
    collider = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "pad:pad1:collider")
    surface_up_m = -world.pads[0].surface_down_m
    assert data.geom_xpos[visual][2] == pytest.approx(surface_up_m)
    np.testing.assert_allclose(data.geom_xpos[visual][:2], (1.0, -2.0))
    assert data.geom_xpos[collider][2] + model.geom_size[collider][2] == pytest.approx(surface_up_m)
    np.testing.assert_allclose(model.geom_size[visual][:2], (0.3, 0.3))
    assert model.geom_contype[visual] == 0 and model.geom_conaffinity[visual] == 0
    assert model.geom_group[collider] == 3  # hidden from cameras by default


def test_robot_xml_is_inserted_and_options_follow_arguments(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, BASE_TOML))
    xml, assets = build_mjcf(
        world, robot_xml((0.0, 0.0, 1.0)), ROBOT_ASSETS, timestep_s=0.002,
        offscreen_size=(1024, 768),
    )
    assert robot_xml((0.0, 0.0, 1.0)) in xml and ROBOT_ASSETS in xml
    model = mujoco.MjModel.from_xml_string(xml, assets)
    assert model.opt.timestep == pytest.approx(0.002)
    assert (model.vis.global_.offwidth, model.vis.global_.offheight) == (1024, 768)
    assert model.light_castshadow.sum() == 0 and model.mat_reflectance.max() == 0.0
    # Deterministic: the same world gives the same text and the same texture bytes.
    assert build_mjcf(world, robot_xml((0.0, 0.0, 1.0)), ROBOT_ASSETS, 0.002, (1024, 768)) == (
        xml,
        assets,
    )
    with pytest.raises(ConfigError, match="timestep_s"):
        build_mjcf(world, timestep_s=0.0)


# ----------------------------------------------------------------------------------------------
# Validation: every error names the file and the key


@pytest.mark.parametrize(
    ("old", "new", "key", "problem"),
    [
        ('name = "test_world"', 'name = "test_world"\ncolour = "red"', "colour", "unknown key"),
        ('rgb = [0.5, 0.4, 0.3]', 'rgb = [0.5, 0.4, 0.3]\nheight = 3', "height", "unknown key"),
        ('size_m = 20.0', 'size_m = "big"', "size_m", "finite number"),
        ('yaw_rad = 0.5', 'yaw_rad = true', "yaw_rad", "finite number"),
        ('size_m = [4.0, 2.0, 2.0]', 'size_m = [4.0, -2.0, 2.0]', "size_m", "positive"),
        ('size_m = [4.0, 2.0, 2.0]', 'size_m = [4.0, 2.0]', "size_m", "3 finite numbers"),
        ('pad = "skeye-4"', 'pad = "skeye-9"', "pad", "skeye-4"),
        ('name = "Field1"', 'name = "Pad1"', "name", "duplicate start pose name 'Pad1'"),
        ('name = "Field1"', 'name = "Field 1"', "name", "letters, digits"),
        # "$" matched before a final newline: a world named "test_world\n" loaded, and its
        # NFO {Level ...} line raised in the server's accept thread, which then took no client.
        ('name = "test_world"', 'name = "test_world\\n"', "name", "letters, digits"),
        ('name = "Field1"', 'name = "Field1\\n"', "name", "letters, digits"),
        # INIT's {Start name} ignores case: {Start Pad1} stood the vehicle on PAD1.
        ('name = "Field1"', 'name = "PAD1"', "name",
         "duplicate start pose name 'PAD1' (as 'Pad1'"),
        # Under the house (its bottom on the ground), and in its walls: the vehicle was spawned
        # inside the box, and MuJoCo threw it out at up to 20 m/s.
        ('position_ned_m = [-3.0, 0.0, 0.0]', 'position_ned_m = [6.0, 2.0, 0.0]',
         "position_ned_m", "start pose 'Field1' lies inside box 'house'"),
        ('position_ned_m = [-3.0, 0.0, 0.0]', 'position_ned_m = [7.5, 2.5, -1.0]',
         "position_ned_m", "start pose 'Field1' lies inside box 'house'"),
        # Loaded: the pad lay under the house (its bottom on the ground), hidden from every
        # camera, its collider inside the box.
        ('position_ned_m = [1.0, 2.0, 0.0]', 'position_ned_m = [6.0, 2.0, 0.0]',
         "position_ned_m", "pad 'pad1' lies inside box 'house': no camera sees it there"),
        ('texture = "checker"', 'texture = "lava"', "texture", "grass"),
        # Both passed the check and stopped skeye sim with MuJoCo's XML error (znear 0.01/1e300
        # underflowed to 0; texrepeat 2 * 20 / 1e-300 overflowed).
        ('size_m = 20.0', 'size_m = 1e300', "size_m", "in (0, 10000] m"),
        ('texture = "checker"', 'texture = "checker"\ntexture_cell_m = 1e-300', "texture_cell_m",
         "at least 0.001 m"),
        ('latitude_deg = 50.0', 'latitude_deg = 95.0', "latitude_deg", "(-90, 90)"),
        ('altitude_m = 250.0', 'altitude_m = 50000', "altitude_m", "[-430, 11000]"),
        ('altitude_m = 250.0', 'altitude_m = 1e300', "altitude_m", "[-430, 11000]"),
        ('altitude_m = 250.0', 'altitude_m = -500.0', "altitude_m", "[-430, 11000]"),
        ('diffuse = [0.5, 0.5, 0.5]', 'diffuse = [0.5, 1.5, 0.5]', "diffuse", "between 0 and 1"),
        ('position_ned_m = [-3.0, 0.0, 0.0]', 'position_ned_m = [-30.0, 0.0, 0.0]',
         "position_ned_m", "outside the ground"),
        ('name = "house"\n', "", "name", "missing required key"),
        ('position_ned_m = [-3.0, 0.0, 0.0]', 'position_ned_m = [-3.0, 0.0, 5.0]',
         "position_ned_m", "start pose 'Field1' is 5 m below the ground"),
        # 50 km up: the barometer's pressure went complex and the engine died formatting it,
        # taking every client down (INIT's own Location stops at 10 km).
        ('position_ned_m = [-3.0, 0.0, 0.0]', 'position_ned_m = [-3.0, 0.0, -50000.0]',
         "position_ned_m", "start pose 'Field1' lies more than 10000 m from the origin"),
        ('position_ned_m = [1.0, 2.0, 0.0]', 'position_ned_m = [1.0, 2.0, 0.5]',
         "position_ned_m", "the pad is 0.5 m below the ground"),
    ],
)
def test_validation_errors_name_file_and_key(
    tmp_path: Path, old: str, new: str, key: str, problem: str
) -> None:
    assert old in BASE_TOML
    path = write(tmp_path, BASE_TOML.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_world(path)
    message = str(err.value)
    assert str(path) in message and key in message and problem in message, message


def test_start_poses_on_beside_and_under_boxes_are_accepted(tmp_path: Path) -> None:
    along = (6.0 + 2.05 * math.cos(0.5), 2.0 + 2.05 * math.sin(0.5))  # past the house's end
    text = BASE_TOML + f"""
[[boxes]]
name = "roof"
center_ned_m = [-3.0, 0.0, -3.0]
size_m = [2.0, 2.0, 0.2]

[[start_poses]]
name = "HouseTop"
position_ned_m = [6.0, 2.0, -2.0]

[[start_poses]]
name = "HouseEnd"
position_ned_m = [{along[0]!r}, {along[1]!r}, 0.0]
"""
    world = load_world(write(tmp_path, text))  # Field1 stands under the roof
    assert list(world.start_poses) == ["Pad1", "Field1", "HouseTop", "HouseEnd"]


def test_checkerboard_world_holds_the_calibration_board() -> None:
    world = load_world("checkerboard")
    (board,) = world.checkerboards
    assert board.inner_corners == (9, 6) and board.square_m == pytest.approx(0.025)
    assert board.sheet_m == pytest.approx((0.3, 0.225))  # 12 x 9 squares with the margins
    xml, assets = build_mjcf(world)
    assert 'name="checkerboard:board1"' in xml and "skeye_checkerboard_9x6.png" in assets


@pytest.mark.parametrize(
    ("board", "problem"),
    [
        ("inner_corners = [9]\nsquare_m = 0.025", "[cols, rows]"),
        ("inner_corners = [9, 1]\nsquare_m = 0.025", "[cols, rows]"),
        ("inner_corners = [9, 6]\nsquare_m = 0", "square_m"),
        ("inner_corners = [9, 6]", "missing required key"),
        ("inner_corners = [9, 6]\nsquare_m = 0.025\nsquares = 3", "unknown key"),
        ("inner_corners = [9, 6]\nsquare_m = 0.025\nposition_ned_m = [0.0, 0.0, 2.0]",
         "the board is 2 m below the ground"),
        ("inner_corners = [9, 6]\nsquare_m = 0.025\nposition_ned_m = [6.0, 2.0, 0.0]",
         "checkerboard 'board1' lies inside box 'house'"),
    ],
)
def test_checkerboard_errors_name_the_key(tmp_path: Path, board: str, problem: str) -> None:
    if "position_ned_m" not in board:
        board += "\nposition_ned_m = [0.0, 0.0, 0.0]"
    text = BASE_TOML + f"\n[[checkerboards]]\n{board}\n"
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_world(path)
    assert "[[checkerboards]] #1" in str(err.value) and problem in str(err.value), err.value


def test_missing_file_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "nowhere" / "world.toml"
    with pytest.raises(ConfigError, match="not found") as err:
        load_world(path)
    assert str(path) in str(err.value)


def test_toml_syntax_error_names_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, BASE_TOML.replace("size_m = 20.0", "size_m = = 20.0"))
    with pytest.raises(ConfigError, match="TOML syntax error") as err:
        load_world(path)
    assert str(path) in str(err.value) and "line" in str(err.value)


def test_light_direction_of_huge_components_is_normalised(tmp_path: Path) -> None:
    # Its norm overflowed to inf: the light's dir came out "0 0 0" and MuJoCo refused the
    # model ("zero direction in light"), a traceback from skeye sim.
    text = BASE_TOML.replace("direction_ned = [0.0, 0.0, 1.0]", "direction_ned = [1e300, 0, 1e300]")
    model = compile_world(load_world(write(tmp_path, text)))
    # NED (1, 0, 1) is MuJoCo (1, 0, -1): north and down.
    assert model.light_dir[0] == pytest.approx([math.sqrt(0.5), 0.0, -math.sqrt(0.5)])


def test_duplicate_box_names_are_rejected(tmp_path: Path) -> None:
    text = BASE_TOML + (
        '\n[[boxes]]\nname = "house"\ncenter_ned_m = [0, 0, -1]\nsize_m = [1, 1, 2]\n'
    )
    with pytest.raises(ConfigError, match=r"\[\[boxes\]\].name: duplicate name 'house'"):
        load_world(write(tmp_path, text))


_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**6), 10**6)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=8,
)


def _paths(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = []
    if isinstance(doc, dict):
        items: Any = doc.items()
    else:
        items = enumerate(doc) if isinstance(doc, list) else []
    for k, v in items:
        out.append((*prefix, k))
        out.extend(_paths(v, (*prefix, k)))
    return out


BASE_DOC = tomllib.loads(BASE_TOML)
BASE_PATHS = _paths(BASE_DOC)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(BASE_PATHS), _values)
def test_fuzzed_documents_give_a_world_or_a_config_error(path: tuple[Any, ...], value: Any) -> None:
    doc = tomllib.loads(BASE_TOML)
    target = doc
    for step in path[:-1]:
        target = target[step]
    target[path[-1]] = value
    try:
        world = parse_world(doc, "fuzz.toml")
    except ConfigError as exc:
        assert str(exc).startswith("fuzz.toml: ")
    else:
        assert world.name


# ----------------------------------------------------------------------------------------------
# Rendering: the pad texture lands where the pad data says


_RENDER_CHILD = """
import os, sys
os.environ["MUJOCO_GL"] = sys.argv[1]
import mujoco, numpy as np
from skeye.sim.world import build_mjcf, load_world
world_name, camera_xml, height, width, out = sys.argv[2:]
xml, assets = build_mjcf(load_world(world_name), robots_xml=camera_xml)
model = mujoco.MjModel.from_xml_string(xml, assets)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
with mujoco.Renderer(model, int(height), int(width)) as renderer:
    renderer.update_scene(data, camera="down")
    np.save(out, renderer.render())
"""


def _render(
    world_name: str, camera_xml: str, height: int, width: int, tmp_path: Path
) -> np.ndarray:
    """Render from the camera named "down"; RGB uint8, row 0 at the top.

    MuJoCo picks its OpenGL backend when first imported; if something imported it before this
    module could set MUJOCO_GL (a conftest, say) and that backend has no context here, render in
    a fresh interpreter with MUJOCO_GL=egl instead.
    """
    xml, assets = build_mjcf(load_world(world_name), robots_xml=camera_xml)
    model = mujoco.MjModel.from_xml_string(xml, assets)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as exc:  # no OpenGL context with the backend chosen at import
        first_error = repr(exc)
    else:
        with renderer:
            renderer.update_scene(data, camera="down")
            return renderer.render()
    out = tmp_path / "frame.npy"
    env = {**os.environ, "MUJOCO_GL": "egl"}
    args = [sys.executable, "-c", _RENDER_CHILD, "egl", world_name, camera_xml, str(height),
            str(width), str(out)]
    child = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    if child.returncode != 0:
        pytest.skip(
            "no OpenGL rendering here: in-process "
            f"({first_error}); with MUJOCO_GL=egl: {child.stderr.strip().splitlines()[-1:]}"
        )
    return np.load(out)


def _crossings(profile: np.ndarray, threshold: float) -> np.ndarray:
    """Sub-pixel positions (pixel centres at i + 0.5) where the profile crosses the threshold."""
    above = profile > threshold
    idx = np.nonzero(above[:-1] != above[1:])[0]
    a, b = profile[idx], profile[idx + 1]
    return idx + 0.5 + (threshold - a) / (b - a)


@pytest.mark.filterwarnings("ignore:.*(DISPLAY|GLFW)")
def test_pad_rings_render_at_their_pinhole_radii(tmp_path: Path) -> None:
    world = load_world("pad")
    pad = world.pads[0]
    width, height, fovy_deg, camera_height_m = 800, 600, 60.0, 1.0
    cam_up_m = -pad.surface_down_m + camera_height_m
    camera = f'<camera name="down" pos="0 0 {cam_up_m!r}" fovy="{fovy_deg!r}"/>'
    grey = _render("pad", camera, height, width, tmp_path).astype(float).mean(axis=2)
    f_px = (height / 2) / math.tan(math.radians(fovy_deg) / 2)
    cx, cy = width / 2, height / 2  # the optical axis, in continuous pixel coordinates

    # Lighting for a downward camera: the rings clearly white, the square clearly black.
    r4_px = f_px * pad.pad.rings[3].outer_m / camera_height_m
    ring4 = grey[int(cy) - 2 : int(cy) + 2, int(cx + 0.7 * r4_px) - 2 : int(cx + 0.7 * r4_px) + 2]
    black = grey[int(cy) - 2 : int(cy) + 2, int(cx + 0.29 / camera_height_m * f_px) - 1]
    assert ring4.min() > 200 and black.max() < 40, (ring4.min(), black.max())
    # The square ends at its side: beyond it lies grass (not dark).
    grass = grey[int(cy), int(cx + 0.32 / camera_height_m * f_px)]
    assert grass > 60

    white, dark = np.percentile(grey, 99.5), np.percentile(grey, 0.5)
    threshold = (white + dark) / 2
    expected_m = sorted(r for ring in pad.pad.rings for r in (ring.outer_m, ring.inner_m))
    reach_px = 0.29 / camera_height_m * f_px  # inside the black border of the square
    profiles = {
        "row": (grey[int(cy) - 1 : int(cy) + 1, :].mean(axis=0), cx),
        "column": (grey[:, int(cx) - 1 : int(cx) + 1].mean(axis=1), cy),
    }
    for label, (profile, centre) in profiles.items():
        x = _crossings(profile, threshold)
        x = x[np.abs(x - centre) < reach_px]
        plus, minus = np.sort(x[x > centre]), np.sort(x[x < centre])[::-1]
        assert len(plus) == len(minus) == len(expected_m), (label, plus - centre, centre - minus)
        radii_px = (plus - minus) / 2
        predicted_px = f_px * np.array(expected_m) / camera_height_m
        np.testing.assert_allclose(radii_px, predicted_px, atol=1.5, err_msg=label)
        np.testing.assert_allclose((plus + minus) / 2, centre, atol=0.75, err_msg=label)
        # The two named in the spec: ring 4's and ring 1's outer borders.
        assert abs(radii_px[1] - f_px * pad.pad.rings[3].outer_m) < 1.5
        assert abs(radii_px[-1] - f_px * pad.pad.rings[0].outer_m) < 1.5
