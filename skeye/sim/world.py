"""Worlds: a small declarative description (TOML) and the builder that turns it into MuJoCo MJCF.

How this works: a world file names a ground, landing pads, boxes (buildings, debris, walls,
ceilings), lights, USARSim start poses and the world's geodetic and magnetic facts, all in the
protocol's NED frame (x north, y east, z down, metres; yaw in rad about down). :func:`load_world`
validates every key (unknown keys included) and raises ConfigError naming the file, the table and
the problem; nothing is half-loaded. :func:`build_mjcf` writes the MuJoCo model, which is NWU
(x north, y west, z up): every position and orientation crosses over through
:mod:`skeye.sim.frames` and nowhere else. Textures (the pad, procedural ground) are generated
deterministically (:mod:`skeye.sim.world_textures`) and handed back as an assets dict for
``MjModel.from_xml_string``. The description's types live in :mod:`skeye.sim.world_model`, the
TOML validator in :mod:`skeye.sim.world_file`; this module re-exports their public names, so
``skeye.sim.world`` stays the one entry point.

Invariants: a pad's visible surface lies ``PAD_SURFACE_HEIGHT_M`` above the point the file gives
(so it never z-fights the ground) and a hidden collider's top face lies in the same plane, so a
vehicle standing on the pad and a camera measuring height above it agree; the pad texture covers
the pad's square exactly once.
"""

from __future__ import annotations

import math
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from skeye.errors import ConfigError
from skeye.sim.frames import euler_to_quat, ned_to_mj, quat_ned_to_mj
from skeye.sim.world_file import load_world, parse_world, start_pose_list
from skeye.sim.world_model import (
    BUILTIN_WORLDS,
    DEFAULT_MAGNETIC_FIELD_NED_UT,
    DEFAULT_SEA_LEVEL_PRESSURE_PA,
    GRAVITY_M_S2,
    GROUND_TEXTURES,
    NEAR_CLIP_M,
    PAD_SURFACE_HEIGHT_M,
    PAD_TEXTURE_PX,
    Box,
    CheckerboardPlacement,
    Ground,
    Light,
    PadPlacement,
    StartPose,
    Vec3,
    Visual,
    WorldDescription,
)
from skeye.sim.world_textures import (
    checkerboard_texture_png,
    ground_texture_png,
    pad_texture_png,
)

__all__ = [
    "BUILTIN_WORLDS",
    "DEFAULT_MAGNETIC_FIELD_NED_UT",
    "DEFAULT_SEA_LEVEL_PRESSURE_PA",
    "GRAVITY_M_S2",
    "GROUND_TEXTURES",
    "NEAR_CLIP_M",
    "PAD_SURFACE_HEIGHT_M",
    "PAD_TEXTURE_PX",
    "Box",
    "CheckerboardPlacement",
    "Ground",
    "Light",
    "PadPlacement",
    "StartPose",
    "Vec3",
    "Visual",
    "WorldDescription",
    "build_mjcf",
    "ground_texture_png",
    "load_world",
    "pad_texture_png",
    "parse_world",
    "start_pose_list",
]


# ----------------------------------------------------------------------------------------------
# MJCF


def _f(*values: float) -> str:
    return " ".join(format(float(v) + 0.0, ".10g") for v in values)  # + 0.0: no "-0"


def _el(tag: str, **attrs: Any) -> str:
    parts = [tag] + [f"{k}={quoteattr(str(v))}" for k, v in attrs.items() if v is not None]
    return "<" + " ".join(parts) + "/>"


def _pose_attrs(center_ned_m: Vec3, yaw_rad: float) -> dict[str, str]:
    return {
        "pos": _f(*ned_to_mj(center_ned_m)),
        "quat": _f(*quat_ned_to_mj(tuple(euler_to_quat(0.0, 0.0, yaw_rad)))),
    }


def build_mjcf(
    world: WorldDescription,
    robots_xml: str = "",
    robot_assets_xml: str = "",
    timestep_s: float = 0.001,
    offscreen_size: tuple[int, int] = (800, 600),
) -> tuple[str, dict[str, bytes]]:
    """The complete MJCF text and its assets (file name -> bytes).

    ``robots_xml`` goes verbatim into <worldbody>, ``robot_assets_xml`` into <asset>. The
    integrator is MuJoCo's semi-implicit ``Euler``: one dynamics evaluation per step (RK4 costs
    four, and would hold the engine's applied rotor forces fixed across its sub-steps anyway).
    ``implicitfast`` would differ from it only in velocity-dependent joint damping and actuator
    forces, which these models do not have (contacts go through the constraint solver either
    way; drag is an applied force), and costs about 20 % more per step. At 1 kHz the
    first-order error is far below the vehicle model's own uncertainty. MuJoCo's air density
    and viscosity are zero: the engine applies drag itself.
    """
    if not (math.isfinite(timestep_s) and 0.0 < timestep_s <= 0.05):
        raise ConfigError(f"build_mjcf: timestep_s must be in (0, 0.05] s, got {timestep_s!r}")
    width, height = offscreen_size
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise ConfigError(
            f"build_mjcf: offscreen_size must be two positive ints, got {offscreen_size!r}"
        )
    assets: dict[str, bytes] = {}
    asset_xml: list[str] = []
    body_xml: list[str] = []
    vis = world.visual
    ground = world.ground
    extent_m = max(ground.size_m, 1.0)
    far_m = max(4.0 * extent_m, 200.0)

    # Ground: a plane at down = 0; its texture tiles every texture_cell_m.
    ground_attrs: dict[str, Any] = {
        "name": "ground", "type": "plane", "pos": _f(0.0, 0.0, 0.0),
        "size": _f(ground.size_m, ground.size_m, 0.5), "group": "0", "condim": "3",
    }
    repeat = 2.0 * ground.size_m / ground.texture_cell_m
    if ground.texture == "none":
        ground_attrs["rgba"] = _f(*ground.rgb, 1.0)
    else:
        if ground.texture == "checker":
            # MuJoCo's builtin checker holds 2x2 squares per tile.
            asset_xml.append(_el(
                "texture", name="ground", type="2d", builtin="checker", width="512",
                height="512", rgb1=_f(*ground.rgb), rgb2=_f(*ground.rgb2),
            ))
            repeat /= 2.0
        else:
            file_name = f"skeye_ground_{ground.texture}.png"
            assets[file_name] = ground_texture_png(ground.texture, ground.rgb, ground.rgb2)
            asset_xml.append(_el("texture", name="ground", type="2d", file=file_name))
        asset_xml.append(_el(
            "material", name="ground", texture="ground", texrepeat=_f(repeat, repeat),
            texuniform="false", specular="0", shininess="0", reflectance=_f(vis.reflectance),
        ))
        ground_attrs["material"] = "ground"
    if vis.skybox:
        asset_xml.append(_el(
            "texture", name="sky", type="skybox", builtin="gradient", width="128",
            height="768", rgb1=_f(*vis.sky_rgb), rgb2=_f(*vis.horizon_rgb),
        ))
    body_xml.append(_el("geom", **ground_attrs))

    # Pads: a textured plane (visual only) exactly PAD_SURFACE_HEIGHT_M above the given point,
    # and a hidden collider box (group 3) whose top face is that same plane. With
    # texrepeat 1 1 on a plane of half-size side/2 the texture covers the square exactly once.
    for pad_def in sorted({p.pad for p in world.pads}, key=lambda p: p.name):
        file_name = f"skeye_pad_{pad_def.name}.png"
        assets[file_name] = pad_texture_png(pad_def)
        asset_xml.append(_el("texture", name=f"pad:{pad_def.name}", type="2d", file=file_name))
        asset_xml.append(_el(
            "material", name=f"pad:{pad_def.name}", texture=f"pad:{pad_def.name}",
            texrepeat="1 1", texuniform="false", specular="0", shininess="0", reflectance="0",
            emission="0",
        ))
    for pad in world.pads:
        half = pad.pad.side_m / 2.0
        n, e, _ = pad.position_ned_m
        surface = (n, e, pad.surface_down_m)
        body_xml.append(_el(
            "geom", name=f"pad:{pad.name}", type="plane", size=_f(half, half, half / 6.0),
            material=f"pad:{pad.pad.name}", contype="0", conaffinity="0", group="1",
            **_pose_attrs(surface, pad.yaw_rad),
        ))
        collider_half_m = 0.01
        body_xml.append(_el(
            "geom", name=f"pad:{pad.name}:collider", type="box",
            size=_f(half, half, collider_half_m), group="3", rgba="0.1 0.1 0.1 1",
            **_pose_attrs((n, e, surface[2] + collider_half_m), pad.yaw_rad),
        ))

    # Calibration boards: a textured plane (visual only) PAD_SURFACE_HEIGHT_M above the ground;
    # texrepeat 1 1 stretches the texture over the sheet once, in both directions.
    for layout in sorted({b.inner_corners for b in world.checkerboards}):
        tex = f"checkerboard:{layout[0]}x{layout[1]}"
        file_name = f"skeye_checkerboard_{layout[0]}x{layout[1]}.png"
        assets[file_name] = checkerboard_texture_png(*layout)
        asset_xml.append(_el("texture", name=tex, type="2d", file=file_name))
        asset_xml.append(_el(
            "material", name=tex, texture=tex, texrepeat="1 1", texuniform="false",
            specular="0", shininess="0", reflectance="0", emission="0",
        ))
    for board in world.checkerboards:
        along, across = board.sheet_m
        n, e, d = board.position_ned_m
        body_xml.append(_el(
            "geom", name=f"checkerboard:{board.name}", type="plane",
            size=_f(along / 2.0, across / 2.0, 0.01),
            material=f"checkerboard:{board.inner_corners[0]}x{board.inner_corners[1]}",
            contype="0", conaffinity="0", group="1",
            **_pose_attrs((n, e, d - PAD_SURFACE_HEIGHT_M), board.yaw_rad),
        ))

    for box in world.boxes:
        body_xml.append(_el(
            "geom", name=f"box:{box.name}", type="box", size=_f(*(s / 2.0 for s in box.size_m)),
            rgba=_f(*box.rgb, 1.0), group="0", **_pose_attrs(box.center_ned_m, box.yaw_rad),
        ))

    light_xml: list[str] = []
    for light in world.lights:
        direction = ned_to_mj(light.direction_ned)
        # Scaled to a largest component of 1 before the norm: the norm of [1e300, 1e300, 0]
        # overflowed to inf and MuJoCo refused the zero direction left by dividing by it.
        direction = direction / np.max(np.abs(direction))
        common: dict[str, Any] = {
            "name": f"light:{light.name}", "dir": _f(*(direction / np.linalg.norm(direction))),
            "diffuse": _f(*light.diffuse), "ambient": _f(*light.ambient),
            "specular": _f(*light.specular), "castshadow": str(vis.shadows).lower(),
        }
        if light.position_ned_m is None:
            light_xml.append(_el("light", type="directional", pos=_f(0.0, 0.0, 10.0), **common))
        else:
            light_xml.append(_el(
                "light", type="spot", pos=_f(*ned_to_mj(light.position_ned_m)),
                cutoff=_f(math.degrees(light.cutoff_rad)), exponent="1", **common,
            ))

    visual_xml = "\n".join([
        "  <visual>",
        "    " + _el("global", offwidth=str(width), offheight=str(height)),
        "    " + _el("quality", shadowsize="4096" if vis.shadows else "0"),
        "    " + _el(
            "headlight", active="1", ambient=_f(*vis.headlight_ambient),
            diffuse=_f(*vis.headlight_diffuse), specular="0 0 0",
        ),
        # znear/zfar are fractions of the model extent; haze off.
        "    " + _el(
            "map", znear=_f(NEAR_CLIP_M / extent_m), zfar=_f(far_m / extent_m), haze="0",
        ),
        "    " + _el("rgba", haze="0 0 0 0"),
        "  </visual>",
    ])
    xml = "\n".join([
        f"<mujoco model={quoteattr('skeye-' + world.name)}>",
        "  " + _el("compiler", angle="radian", autolimits="true"),
        "  " + _el(
            "option", timestep=_f(timestep_s), gravity=_f(*ned_to_mj((0.0, 0.0, GRAVITY_M_S2))),
            integrator="Euler", density="0", viscosity="0", wind="0 0 0",
        ),
        "  " + _el("statistic", extent=_f(extent_m), center="0 0 0"),
        visual_xml,
        "  <asset>",
        *("    " + line for line in asset_xml),
        robot_assets_xml,
        "  </asset>",
        "  <worldbody>",
        *("    " + line for line in light_xml + body_xml),
        robots_xml,
        "  </worldbody>",
        "</mujoco>",
        "",
    ])
    return xml, assets
