"""The render thread's work: one camera shot (a snapshot of the world) to the camera's pixels.

How this works (docs/camera.md): :class:`ShotRenderer` owns the OpenGL contexts (MuJoCo's
offscreen renderers; a context belongs to the thread that made it) and is used from the render
thread only. For one shot it sets its own ``MjData`` to the snapshot (``qpos``, ``qvel``),
renders the camera's view and, for a camera model with a lens, hands the render to the lens and
sensor model (:mod:`skeye.sim.lens`) with the frame's exposure (:mod:`skeye.sim.exposure`).

Lights and shadows. MuJoCo's own shadow pass leaves a lattice of grey dots on every lit
surface (shadow acne: its depth offset is a fixed number of depth-buffer units, so it shrinks
with the clip range) and a hard shadow whose edge steps along the shadow map's texels. A camera
model with ``shadows`` is therefore rendered in two parts:

* the image: the scene without MuJoCo's shadow pass, every light dimmed by ``HEADROOM`` (and
  emission with it) so that nothing saturates in the 8-bit render; the lens multiplies the
  headroom back in, with the frame's exposure, before the sensor clips (a sunlit white pad
  keeps its shading in the shadow);
* the shadow term: the same view rendered at a quarter of the size in a grey world (every
  surface grey, untextured), with and without MuJoCo's shadow pass; their ratio is the light
  each surface keeps in the shadow, whatever its colour. The shadow map is centred on the view
  and sized to it (the light's frustum follows the camera, so shadows fall anywhere in the
  world), its depth range is ``SHADOW_DEPTH_RANGE_M`` (MuJoCo's depth offset scales with it:
  at the camera's 300 m the lattice covered 8 % of the white pad, at 10 km 0.01 %), and the
  ratio is blurred by the penumbra: the sun's 0.53 deg disc (a spot light: its bulb seen from
  the camera) times the distance from the vehicle to the ground, which seen from the vehicle
  is that angle times the focal length in pixels, at least two shadow-map texels. The image
  is multiplied by the blurred term.

A camera without a lens (the ideal pinhole) is rendered as it is, MuJoCo's shadow pass off.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from skeye.errors import LocalProtocolError, SkeyeError
from skeye.sim.gl import GL_BACKEND  # noqa: F401  (before mujoco: picks MUJOCO_GL)
from skeye.sim.lens import Motion

log = logging.getLogger(__name__)

HEADROOM = 2.0  # lights dimmed by this in a lens camera's render; the lens multiplies it back
SHADOW_DOWNSCALE = 4  # the shadow term is rendered at 1 / this of the image's size
SHADOW_MAP_PX = 512  # the shadow map's size (pixels a side): it covers the view only
SHADOW_DEPTH_RANGE_M = 10_000.0  # the shadow pass's depth range: sets MuJoCo's depth offset
SHADOW_MIN_HALF_SIZE_M = 0.5  # the shadow map covers at least +-this around the view's centre
SHADOW_MAX_HALF_SIZE_M = 60.0
_DIRECTIONAL = 1  # mjtLightType.mjLIGHT_DIRECTIONAL
ROTOR_GEOM_MARK = ":rotor"  # skeye.sim.engine names each robot's rotor discs robot:<name>:rotor<i>
# The time-averaged shadow of a spinning two-bladed propeller: its solidity N c / (pi R), the
# share of the disc its blades cover (about 0.1 for a chord of 0.15 R; assumption).
ROTOR_SOLIDITY = 0.1
SUN_DIAMETER_RAD = 0.0093  # the sun's angular diameter (0.53 deg): a directional light's disc
_GREY_LEVEL = 0.9  # the grey world's brightest lit surface (fraction of full scale)
RENDER_TIMEOUT_S = 60.0  # a frame's pixels must be made within this
_MODELS_KEPT = 2


@dataclass(frozen=True)
class WorldState:
    """One snapshot of the world for the cameras due at one step."""

    model: Any
    qpos: np.ndarray
    qvel: np.ndarray
    time_s: float


def camera_motion(mujoco: Any, model: Any, data: Any, cam_id: int) -> Motion:
    """The camera's motion at the state in ``data`` (after mj_kinematics/comPos/comVel), in
    OpenCV camera axes (MuJoCo's camera: x right, y up, looking along -z)."""
    vel = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_CAMERA, cam_id, vel, 1)
    xmat = data.cam_xmat[cam_id].reshape(3, 3)
    down = -xmat[2, :]  # world -z in the camera's axes
    return Motion(
        omega_rad_s=(float(vel[0]), float(-vel[1]), float(-vel[2])),
        velocity_m_s=(float(vel[3]), float(-vel[4]), float(-vel[5])),
        down=(float(down[0]), float(-down[1]), float(-down[2])),
        height_m=float(data.cam_xpos[cam_id][2]),
    )


def camera_index(model: Any, name: str) -> int:
    import mujoco

    idx = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name)
    if idx < 0:
        raise LocalProtocolError(f"no camera {name} in the model")
    return int(idx)


class ShotRenderer:
    """Renders shots on the thread that made it (see the module comment)."""

    def __init__(self) -> None:
        import mujoco

        self._mujoco = mujoco
        self._model: Any = None
        self._data: Any = None
        self._loaded: WorldState | None = None
        self._renderers: dict[tuple[int, int, int, int], Any] = {}
        # The last models' data and renderers (a frame taken before a robot came or went may
        # be asked for after: switching back costs no new OpenGL contexts).
        self._models: list[tuple[Any, Any, dict[tuple[int, int, int, int], Any]]] = []
        self._buffers: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
        self._rotors: dict[int, frozenset[int]] = {}  # rotor-disc geom ids, by model

    def close(self) -> None:
        for _, _, renderers in self._models:
            for r in renderers.values():
                r.close()
        self._models = []
        self._model = self._data = None
        self._renderers = {}
        self._loaded = None

    def describe(self) -> str:
        """The OpenGL renderer this thread's contexts run on (GL_RENDERER, GL_VENDOR,
        GL_VERSION), from a 1x1 context of an empty model."""
        mujoco = self._mujoco
        model = mujoco.MjModel.from_xml_string("<mujoco/>")
        renderer = _make_renderer(mujoco, model, 1, 1, 0)
        try:
            from OpenGL import GL

            def text(name: int) -> str:
                value = GL.glGetString(name)
                return value.decode(errors="replace") if isinstance(value, bytes) else "?"

            return (f"{text(GL.GL_RENDERER)} ({text(GL.GL_VENDOR)}, OpenGL "
                    f"{text(GL.GL_VERSION)}; MUJOCO_GL={os.environ.get('MUJOCO_GL', '?')})")
        finally:
            renderer.close()

    def render(self, state: WorldState, camera: str, cam: Any, number: int
               ) -> tuple[np.ndarray, bytes | None, float]:
        """One camera's pixels at ``state``: (RGB, the camera's JPEG bytes or None, the
        metered mean level or -1 without a lens). ``cam`` is its CameraSpec."""
        mujoco = self._mujoco
        self._load(state)
        model, data = self._model, self._data
        shadows = cam.model is not None and cam.model.shadows
        lens = cam.lens
        height, width = cam.render_size
        renderer = self._renderer(height, width, cam.render_samples)
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        renderer.update_scene(data, camera=camera)
        if lens is not None:
            _dim_lights(renderer.scene, 1.0 / HEADROOM)
        rgb = renderer.render()
        cam_id = camera_index(model, camera)
        motion = camera_motion(mujoco, model, data, cam_id)
        if shadows:
            focal = lens.focal_px if lens is not None else cam.focal_length_px
            term = self._shadow_term(camera, cam_id, height, width, focal, motion.height_m)
            rgb = cv2.multiply(rgb, term, scale=1.0 / 255.0, dtype=cv2.CV_8U)
        if lens is None:
            return rgb, None, -1.0
        ae = cam.auto_exposure
        exposure = ae.exposure_at(state.time_s) if ae is not None else None
        out = lens.process(rgb, motion, number, exposure, HEADROOM, cam.noise_stream)
        if ae is not None and exposure is not None:
            ae.metered(state.time_s, exposure, out.mean_dn)
        return out.rgb, out.jpeg, out.mean_dn

    def _load(self, state: WorldState) -> None:
        mujoco = self._mujoco
        if state.model is not self._model:
            entry = next((e for e in self._models if e[0] is state.model), None)
            if entry is None:
                entry = (state.model, mujoco.MjData(state.model), {})
                if len(self._models) >= _MODELS_KEPT:
                    for r in self._models.pop(0)[2].values():
                        r.close()
            else:
                self._models.remove(entry)
            self._models.append(entry)
            self._model, self._data, self._renderers = entry
            self._loaded = None
        if state is self._loaded:
            return
        data = self._data
        data.qpos[:] = state.qpos
        data.qvel[:] = state.qvel
        mujoco.mj_kinematics(self._model, data)
        mujoco.mj_comPos(self._model, data)
        mujoco.mj_comVel(self._model, data)
        mujoco.mj_camlight(self._model, data)
        self._loaded = state

    def _renderer(self, height: int, width: int, samples: int, shadow_px: int = 0) -> Any:
        key = (height, width, samples, shadow_px)
        renderer = self._renderers.get(key)
        if renderer is None:
            renderer = _make_renderer(self._mujoco, self._model, height, width, samples,
                                      shadow_px)
            self._renderers[key] = renderer
        return renderer

    def _shadow_term(self, camera: str, cam_id: int, height: int, width: int, focal_px: float,
                     cam_height_m: float) -> np.ndarray:
        """The light each pixel keeps in the shadows (255 = all), (height, width, 3) uint8."""
        mujoco = self._mujoco
        lh, lw = max(8, height // SHADOW_DOWNSCALE), max(8, width // SHADOW_DOWNSCALE)
        renderer = self._renderer(lh, lw, 0, SHADOW_MAP_PX)
        scene = renderer.scene
        renderer.update_scene(self._data, camera=camera)
        _grey_world(scene)
        for cam in scene.camera:  # the depth range of the shadow pass (its offset scales)
            cam.frustum_far = max(float(cam.frustum_far), SHADOW_DEPTH_RANGE_M)
        half = self._fit_shadow_map(scene, cam_id, width / focal_px, height / focal_px)
        renderer._mjr_context.shadowClip = half
        key = (lh, lw)
        buffers = self._buffers.get(key)
        if buffers is None:
            buffers = tuple(np.empty((lh, lw, 3), np.uint8) for _ in range(3))
            self._buffers[key] = buffers
        lit, shaded, rotors = buffers
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        renderer.render(out=lit)
        scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 1
        # The rotor discs stand for spinning propellers: a blade shades a point of the disc's
        # shadow only ROTOR_SOLIDITY of the time. The shadow of everything else, then of the
        # rotors alone, each as a ratio to the lit render.
        discs = self._rotor_geoms(scene)
        for i in discs:
            scene.geoms[i].castshadow = 0
        renderer.render(out=shaded)
        ratio = _ratio(shaded, lit)
        if discs:
            for i in range(scene.ngeom):
                scene.geoms[i].castshadow = 0
            for i in discs:
                scene.geoms[i].castshadow = 1
            renderer.render(out=rotors)
            # light kept: the others' ratio times 1 - solidity * (what the discs alone take)
            rotor_ratio = _ratio(rotors, lit)
            rotor_ratio *= ROTOR_SOLIDITY
            rotor_ratio += 255.0 * (1.0 - ROTOR_SOLIDITY)
            ratio = cv2.multiply(ratio, rotor_ratio, scale=1.0 / 255.0)
        # Penumbra: the light's angular size seen from the vehicle, in image pixels; at least
        # two shadow-map texels (the map's own resolution), and a little for the small render.
        texel_px = 2.0 * half / SHADOW_MAP_PX * focal_px / max(cam_height_m, 0.05)
        width_px = max(_penumbra_rad(scene) * focal_px, 2.0 * texel_px)
        # the penumbra as a Gaussian of that full width at half maximum, in the small render;
        # at least one of its pixels (the small render samples each pixel at one point)
        sigma = max(1.0, width_px / 2.355 / SHADOW_DOWNSCALE)
        ratio = cv2.GaussianBlur(ratio, (0, 0), sigma)
        term = cv2.resize(ratio, (width, height), interpolation=cv2.INTER_LINEAR)
        return cv2.convertScaleAbs(term)

    def _rotor_geoms(self, scene: Any) -> list[int]:
        """The scene's geoms that are rotor discs (skeye's robot bodies name them)."""
        model = self._model
        ids = self._rotors.get(id(model))
        if ids is None:
            mujoco = self._mujoco
            ids = frozenset(
                g for g in range(model.ngeom)
                if ROTOR_GEOM_MARK in (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""))
            self._rotors = {id(model): ids}
        geom_type = int(self._mujoco.mjtObj.mjOBJ_GEOM)
        return [i for i in range(scene.ngeom)
                if scene.geoms[i].objtype == geom_type and scene.geoms[i].objid in ids]

    def _fit_shadow_map(self, scene: Any, cam_id: int, tan_w: float, tan_h: float) -> float:
        """Centre the directional lights' shadow frustum on the ground the camera sees and
        size it to that view; returns its half-size (m)."""
        data = self._data
        pos = np.array(data.cam_xpos[cam_id], dtype=float)
        xmat = np.array(data.cam_xmat[cam_id], dtype=float).reshape(3, 3)
        look = -xmat[:, 2]  # MuJoCo cameras look along their -z
        height = max(float(pos[2]), 0.05)
        reach = height * math.hypot(tan_w, tan_h) / 2.0  # the view's half-diagonal at nadir
        if look[2] < -0.2:  # the boresight meets the ground ahead
            centre = pos + look * (height / -look[2])
            reach /= -look[2]
        else:
            centre = pos + np.array([look[0], look[1], 0.0]) * height
            reach = SHADOW_MAX_HALF_SIZE_M
        half = min(max(1.3 * reach + 0.5, SHADOW_MIN_HALF_SIZE_M), SHADOW_MAX_HALF_SIZE_M)
        centre[2] = 0.0
        for i in range(scene.nlight):
            light = scene.lights[i]
            if light.headlight:
                continue
            light.castshadow = 1  # every world light casts (a spot light from where it is)
            if int(light.type) != _DIRECTIONAL:
                continue
            direction = np.array(light.dir, dtype=float)
            norm = float(np.linalg.norm(direction)) or 1.0
            light.pos[:] = centre - direction / norm * (height + 20.0)
        return half


def _ratio(shaded: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """255 * shaded / lit (float32), at most 255; 255 where nothing is lit."""
    ratio = cv2.divide(shaded, lit, scale=255.0, dtype=cv2.CV_32F)
    np.minimum(ratio, 255.0, out=ratio)
    ratio[lit == 0] = 255.0
    return ratio


def _penumbra_rad(scene: Any) -> float:
    """The widest angular size of the scene's shadow-casting lights: the sun's disc for a
    directional light, a spot light's bulb seen from the camera."""
    widest = 0.0
    head = np.array(scene.camera[0].pos, dtype=float)
    for i in range(scene.nlight):
        light = scene.lights[i]
        if light.headlight or not light.castshadow:
            continue
        if int(light.type) == _DIRECTIONAL:
            widest = max(widest, SUN_DIAMETER_RAD)
        else:
            distance = float(np.linalg.norm(np.array(light.pos, dtype=float) - head))
            widest = max(widest, 2.0 * float(light.bulbradius) / max(distance, 0.1))
    return widest


def _dim_lights(scene: Any, factor: float) -> None:
    """Scale every light (and emissive surface) of a scene by ``factor``."""
    for i in range(scene.nlight):
        light = scene.lights[i]
        light.ambient[:] = np.asarray(light.ambient) * factor
        light.diffuse[:] = np.asarray(light.diffuse) * factor
        light.specular[:] = np.asarray(light.specular) * factor
    for i in range(scene.ngeom):
        geom = scene.geoms[i]
        if geom.emission:
            geom.emission = geom.emission * factor


def _grey_world(scene: Any) -> None:
    """Every surface one untextured grey, bright enough to resolve the shadows' ratio and
    dark enough that the most brightly lit one stays below saturation."""
    total = np.zeros(3)
    for i in range(scene.nlight):
        light = scene.lights[i]
        total += np.asarray(light.ambient) + np.asarray(light.diffuse)
    grey = _GREY_LEVEL / max(float(np.max(total)), 1e-6)
    grey = min(grey, 1.0)
    for i in range(scene.ngeom):
        geom = scene.geoms[i]
        geom.matid = -1
        geom.texid = -1
        geom.rgba[:3] = grey
        geom.emission = 0.0
        geom.specular = 0.0
        geom.reflectance = 0.0


_CONTEXT_FAILURES: dict[str, SkeyeError] = {}
"""The backends (``MUJOCO_GL``) this process could not make an OpenGL context with, and the
error: a second ``mujoco.Renderer`` after a failed one can abort the whole process (GLFW
without a display: libc++abi's "recursive initialization" in MuJoCo's GL loader), so a later
renderer is refused with the first error instead of trying again. Only GLFW's failures are
kept: EGL's and OSMesa's are tried again (one may be transient: memory)."""


def _make_renderer(mujoco: Any, model: Any, height: int, width: int, samples: int,
                   shadow_px: int = 0) -> Any:
    """A renderer of this size with ``samples``-fold multisampling and a ``shadow_px`` shadow
    map (MuJoCo reads the model's ``offsamples`` and ``shadowsize`` when it makes the GL
    context; the model's own values are put back)."""
    backend = os.environ.get("MUJOCO_GL", "?")
    failed = _CONTEXT_FAILURES.get(backend)
    if failed is not None:  # a second try can abort the process (below): the same error
        raise SkeyeError(str(failed))
    quality = model.vis.quality
    before = (int(quality.offsamples), int(quality.shadowsize))
    quality.offsamples = samples
    quality.shadowsize = shadow_px
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:
        error = SkeyeError(
            f"cannot render camera images with MUJOCO_GL={backend}: {exc}. Install an OpenGL "
            "backend: Mesa's EGL (apt-get install libegl1 libgl1-mesa-dri) for MUJOCO_GL=egl, "
            "or OSMesa (apt-get install libosmesa6) for MUJOCO_GL=osmesa, or run with a display "
            "(MUJOCO_GL=glfw)"
        )
        if backend == "glfw":  # only there is a retry known to abort (EGL's may be transient)
            _CONTEXT_FAILURES[backend] = error
        raise error from exc
    finally:
        quality.offsamples, quality.shadowsize = before
    flags = renderer.scene.flags
    flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
    flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
    flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
    return renderer

