"""The camera model of a robot file's camera, in OpenCV's calibration terms.

How this works: a ``[[sensors]]`` entry with ``type = "Camera"`` may name a ``profile``
(``ideal`` or ``webcam``) and override any of its figures with keys of the same names as the
fields of :class:`CameraModel` below. :func:`camera_model` resolves the entry (width, height and
``fov_h_rad`` give the pinhole when ``fx_px`` etc. are not given) into one frozen
:class:`CameraModel`, the public description of the lens and sensor that the simulator renders
through (``skeye.sim.lens``) and that a calibration (``skeye calibrate``) should recover:
``camera_matrix`` and ``dist_coeffs`` are exactly what ``cv2.calibrateCamera`` returns.

Profiles (sources in docs/camera.md):

* ``ideal``: a perfect pinhole with the mount's float field of view, no distortion, noise,
  blur, rolling shutter or latency, shadows off (algorithm debugging).
* ``webcam``: a Logitech HD Pro Webcam C920 at 4:3: the focal length and radial distortion of
  a published OpenCV-model calibration of it at 800x600 (f 775.79 px, k1 0.112507,
  k2 -0.272067, k3 0.15775; the focal length scaled with the image width), fixed exposure
  10 ms, photon-transfer noise (EMVA 1288 model) with a small-pixel CMOS's read noise and full
  well, a rolling shutter reading the rows out over the
  frame time, the lens's cos^4 fall-off (vignetting), auto-exposure with its lag, 8-bit MJPEG
  output, capture latency with jitter, soft shadows on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from skeye.errors import ConfigError

PROFILES = ("ideal", "webcam")
DEFAULT_PROFILE = "ideal"
FOV_MIN_RAD = 0.01
FOV_MAX_RAD = math.pi - 0.01
"""The range of a camera's field of view on each axis, ``fov_h_rad`` or the one its focal
lengths give (open at both ends)."""
DISTORTION_LIMIT = 10.0
"""The largest magnitude of a distortion coefficient (k1, k2, p1, p2, k3) a camera may have,
here and in a calibration file (skeye.vision.calibration): OpenCV fits of real lenses, wide
ones included, stay within a few units."""


@dataclass(frozen=True)
class CameraModel:
    """One camera's lens, sensor and output, OpenCV conventions (pixel centres at integers).

    Pinhole: ``u = fx_px * x_d + cx_px``, ``v = fy_px * y_d + cy_px`` with the distorted
    normalised coordinates ``x_d, y_d`` of OpenCV's Brown-Conrady model (``k1 k2 p1 p2 k3``).
    """

    profile: str
    width: int
    height: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    exposure_s: float = 0.0  # integration time of each row (motion blur)
    line_time_s: float = 0.0  # rolling shutter: row i starts i * line_time_s after row 0
    gain: float = 1.0  # analog gain: multiplies the system gain below
    system_gain_dn_per_e: float = 0.0  # EMVA 1288 K at gain 1 (DN per electron); 0: no noise
    read_noise_e: float = 0.0  # EMVA 1288 dark noise sigma_d (electrons)
    jpeg_quality: int = 0  # MJPEG output: each frame JPEG-coded at this quality; 0: raw
    latency_s: float = 0.0  # capture latency: frame delivered this long after its capture
    latency_jitter_s: float = 0.0  # +- uniform jitter on the latency
    shadows: bool = False
    msaa_samples: int = 4  # renderer multisampling: 4 area-averages edge pixels, 0 point-samples
    noise_seed: int = 0
    # Relative illumination cos^n of a pixel's field angle (vignetting); 0: none, 4: the cos^4 law.
    vignetting_exponent: float = 0.0
    # Auto-exposure: each frame's exposure time and gain follow the mean of the frames before
    # (skeye.sim.exposure); off: every frame at exposure_s and gain.
    auto_exposure: bool = False
    ae_target_dn: float = 118.0  # the mean luma (DN) auto-exposure steers to
    ae_time_constant_s: float = 0.3  # its lag: first-order, this time constant
    exposure_min_s: float = 0.0003  # the exposure time's range under auto-exposure
    exposure_max_s: float = 1.0 / 30.0
    gain_max: float = 5.0  # the analog gain's upper limit under auto-exposure (lower: 1)

    @property
    def camera_matrix(self) -> tuple[tuple[float, float, float], ...]:
        """OpenCV's 3x3 K."""
        return ((self.fx_px, 0.0, self.cx_px), (0.0, self.fy_px, self.cy_px), (0.0, 0.0, 1.0))

    @property
    def dist_coeffs(self) -> tuple[float, float, float, float, float]:
        """OpenCV's ``(k1, k2, p1, p2, k3)``."""
        return (self.k1, self.k2, self.p1, self.p2, self.k3)

    @property
    def distorted(self) -> bool:
        return any(c != 0.0 for c in self.dist_coeffs)

    @property
    def fov_h_rad(self) -> float:
        """The pinhole's horizontal field of view (edges of the outer pixels)."""
        return 2.0 * math.atan((self.width / 2.0) / self.fx_px)

    @property
    def noisy(self) -> bool:
        return self.system_gain_dn_per_e > 0.0


# The webcam profile's figures (sources: docs/camera.md, "Parameters").
_WEBCAM: dict[str, Any] = {
    # Radial distortion of a Logitech HD Pro Webcam C920 at 800x600: the published calibration
    # by R. Atkinson (2018-05-30, 3DF Zephyr, OpenCV's model) in FIRST-Tech-Challenge's
    # FtcRobotController, TeamCode/src/main/res/xml/teamwebcamcalibrations.xml.
    "k1": 0.112507,
    "k2": -0.272067,
    "k3": 0.15775,
    # 10 ms: an indoor auto-exposure setting (C920 exposure_absolute 100 x 100 us units, UVC).
    "exposure_s": 0.010,
    # Rolling shutter reading the rows over a whole 30 fps frame period (worst case for a
    # webcam sensor in 30 fps modes): line time = 1 / (30 * rows), set per size below.
    "gain": 4.0,  # indoor light: the webcam's auto gain at a few times base gain
    # Small-pixel (about 3 um) consumer CMOS: full well about 6000 e-, read noise about 3 e-
    # (EMVA 1288 data sheets of such sensors); 8-bit output -> K = 255 / 6000 DN/e-.
    "system_gain_dn_per_e": 255.0 / 6000.0,
    "read_noise_e": 3.0,
    # The C920 streams 800x600 at 30 fps as MJPEG over UVC; quality of its encoder about 85.
    "jpeg_quality": 85,
    # USB webcam capture latency (capture to delivery) 60 ms +- 10 ms: assumptions, no C920
    # measurement found; Pupil Labs measured start of exposure to frame available for two of
    # their own 30 fps UVC cameras, 35.6 and 127.7 ms (docs/camera.md, "Parameters").
    "latency_s": 0.060,
    "latency_jitter_s": 0.010,
    "shadows": True,
    # Point-sampled render (no multisampling): software GL's 4x MSAA doubles the render time
    # (docs/camera.md, "Cost"); the lens remap's bilinear interpolation smooths edges.
    "msaa_samples": 0,
    # The cos^4 law of natural vignetting (assumption: the C920's relative illumination and its
    # image processor's lens-shading correction are not published).
    "vignetting_exponent": 4.0,
    # Auto-exposure on, as the C920 ships (V4L2 exposure_auto 3, aperture priority): exposure
    # 0.3 ms .. 1/30 s (exposure_absolute 3..333 at 30 fps), gain 1..5 (gain 100..500).
    "auto_exposure": True,
}

# The same calibration's focal length at 800x600 (its 640x480 one, 622.0 px, is the same per
# pixel of width to 0.2 %): scaled with the image width for other 4:3 sizes.
WEBCAM_FOCAL_PX_AT_800 = 775.79

_FIELDS = {f.name for f in fields(CameraModel)} - {"profile", "width", "height"}
_INT_FIELDS = {"jpeg_quality", "noise_seed", "msaa_samples"}
_BOOL_FIELDS = {"shadows", "auto_exposure"}
_SIGNED_FIELDS = {"k1", "k2", "p1", "p2", "k3"}
_POSITIVE_FIELDS = {"fx_px", "fy_px", "gain", "ae_target_dn", "ae_time_constant_s",
                    "exposure_min_s", "exposure_max_s", "gain_max"}
CAMERA_MODEL_KEYS = frozenset(_FIELDS | {"profile"})


def pinhole(width: int, height: int, fov_h_rad: float) -> dict[str, float]:
    """fx = fy from the horizontal field of view, principal point at the image centre."""
    f = (width / 2.0) / math.tan(fov_h_rad / 2.0)
    return {"fx_px": f, "fy_px": f, "cx_px": (width - 1) / 2.0, "cy_px": (height - 1) / 2.0}


def build_camera_model(
    params: dict[str, Any],
    width: int,
    height: int,
    fov_h_rad: float,
    where: str,
    profile: str | None = None,
) -> CameraModel:
    """The model of one camera entry: ``profile`` (argument, else the entry's, else ``ideal``),
    then the entry's own keys over it.

    Raises:
        ConfigError: unknown profile, or a key with a bad value (the message names it).
    """
    chosen = profile if profile is not None else params.get("profile", DEFAULT_PROFILE)
    if not isinstance(chosen, str) or chosen.lower() not in PROFILES:
        raise ConfigError(f"{where}: unknown camera profile {chosen!r}; known: {list(PROFILES)}")
    chosen = chosen.lower()
    values: dict[str, Any] = dict(pinhole(width, height, fov_h_rad))
    if chosen == "webcam":
        values.update(_WEBCAM)
        values["line_time_s"] = 1.0 / (30.0 * height)
        # The published C920 calibration's focal length, per pixel of image width (the mount's
        # fov_h_rad is not used).
        values["fx_px"] = values["fy_px"] = WEBCAM_FOCAL_PX_AT_800 * width / 800.0
    for key, value in params.items():
        if key == "profile" or key not in _FIELDS:
            continue
        values[key] = _check(key, value, where)
    model = CameraModel(profile=chosen, width=width, height=height, **values)
    if model.msaa_samples > 16:
        raise ConfigError(f"{where}: msaa_samples must be 0 (point-sampled) .. 16, got "
                          f"{model.msaa_samples}")
    if not (0 <= model.jpeg_quality <= 100):
        raise ConfigError(f"{where}: jpeg_quality must be 0 (raw) .. 100, got {model.jpeg_quality}")
    if model.latency_jitter_s > model.latency_s:
        raise ConfigError(f"{where}: latency_jitter_s ({model.latency_jitter_s}) must not exceed "
                          f"latency_s ({model.latency_s})")
    if model.ae_target_dn > 255.0:
        raise ConfigError(f"{where}: ae_target_dn must be within 0..255, got {model.ae_target_dn}")
    if model.exposure_min_s > model.exposure_max_s:
        raise ConfigError(f"{where}: exposure_min_s ({model.exposure_min_s:g}) must not exceed "
                          f"exposure_max_s ({model.exposure_max_s:g})")
    if model.gain_max < 1.0:
        raise ConfigError(f"{where}: gain_max must be >= 1 (the sensor's base gain), got "
                          f"{model.gain_max}")
    if model.vignetting_exponent > 16.0:
        raise ConfigError(f"{where}: vignetting_exponent must be within 0..16, got "
                          f"{model.vignetting_exponent}")
    # 1e308 (times the gain, inf) made the auto-exposure's brightness range 0 and its log
    # raised ValueError: a traceback out of skeye sim --check and the start-up check.
    if model.exposure_s > 1.0:
        raise ConfigError(f"{where}: exposure_s must be <= 1 s, got {model.exposure_s:g} s")
    if model.line_time_s * height > 1.0:
        raise ConfigError(f"{where}: line_time_s * height must be <= 1 s, got "
                          f"{model.line_time_s * height:g} s")
    _check_intrinsics(model, where)
    _check_monotonic(model, where)
    return model


def _check_intrinsics(model: CameraModel, where: str) -> None:
    """Each axis's field of view within the range of a mount's ``fov_h_rad`` (0.01, pi - 0.01),
    and the principal point on the image. A focal length of 1e-6 px (an image corner at a
    normalised radius of 1e8) held :func:`_check_monotonic`'s walk out to the corner for hours,
    so ``skeye sim --robot-dir`` never started; a principal point far off the image did too."""
    for key, centre, size in (("cx_px", model.cx_px, model.width),
                              ("cy_px", model.cy_px, model.height)):
        if not 0.0 <= centre <= size - 1:
            raise ConfigError(f"{where}: {key} must lie on the image, 0..{size - 1} px (pixel "
                              f"centres), got {centre!r}")
    for key, focal, size, axis in (("fx_px", model.fx_px, model.width, "horizontal"),
                                   ("fy_px", model.fy_px, model.height, "vertical")):
        fov = 2.0 * math.atan((size / 2.0) / focal)
        if not FOV_MIN_RAD < fov < FOV_MAX_RAD:
            raise ConfigError(
                f"{where}: {key} {focal:g} px gives a {axis} field of view of {fov:.4g} rad "
                f"over {size} px; it must be in (0.01, pi - 0.01) rad, as fov_h_rad")


def _check_monotonic(model: CameraModel, where: str) -> None:
    """The radial distortion must not fold over inside the image: r (1 + k1 r^2 + k2 r^4 +
    k3 r^6) must keep growing until it reaches the image corner's distorted radius."""
    corner = max(
        math.hypot((u - model.cx_px) / model.fx_px, (v - model.cy_px) / model.fy_px)
        for u in (-0.5, model.width - 0.5) for v in (-0.5, model.height - 0.5)
    )
    r = 0.0
    while True:
        r2 = r * r
        slope = 1 + 3 * model.k1 * r2 + 5 * model.k2 * r2 * r2 + 7 * model.k3 * r2 ** 3
        if slope <= 0.05:
            raise ConfigError(
                f"{where}: distortion k1={model.k1:g} k2={model.k2:g} k3={model.k3:g} folds over "
                f"at normalised radius {r:.3f}, inside the image (its corner is at distorted "
                f"radius {corner:.3f}): use a longer focal length or smaller coefficients")
        if r * (1 + model.k1 * r2 + model.k2 * r2 * r2 + model.k3 * r2 ** 3) > corner * 1.02:
            return
        r += 0.002


def _check(key: str, value: Any, where: str) -> Any:
    if key in _BOOL_FIELDS:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: {key} must be true or false, got {value!r}")
        return value
    if key in _INT_FIELDS:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ConfigError(f"{where}: {key} must be a non-negative integer, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{where}: {key} must be a finite number, got {value!r}")
    if key in _POSITIVE_FIELDS and not value > 0:
        raise ConfigError(f"{where}: {key} must be positive, got {value!r}")
    if key not in _SIGNED_FIELDS and key not in _POSITIVE_FIELDS and value < 0:
        raise ConfigError(f"{where}: {key} must be >= 0, got {value!r}")
    if key in _SIGNED_FIELDS and abs(value) > DISTORTION_LIMIT:
        raise ConfigError(f"{where}: {key} must be within -{DISTORTION_LIMIT:g}.."
                          f"{DISTORTION_LIMIT:g}, got {value!r}")
    return float(value)


__all__ = [
    "CAMERA_MODEL_KEYS",
    "DEFAULT_PROFILE",
    "PROFILES",
    "CameraModel",
    "build_camera_model",
    "pinhole",
]
