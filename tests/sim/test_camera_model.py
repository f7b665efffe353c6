"""The camera model (docs/camera.md): profiles from the robot file, the lens maps against
OpenCV's projection, seeded noise, motion blur, rolling shutter, shadows and capture latency."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.robots.camera_model import WEBCAM_FOCAL_PX_AT_800, build_camera_model
from skeye.robots.config import SensorMount, camera_model
from skeye.sim.cameras import CameraSpec, CameraSystem
from skeye.sim.engine import Simulation
from skeye.sim.exposure import AutoExposure
from skeye.sim.image_server import FrameBuffer
from skeye.sim.lens import Lens, Motion
from skeye.sim.world import PAD_SURFACE_HEIGHT_M, load_world
from skeye.vision.pad import SKEYE_4
from tests.sim.test_cameras import ring_edges_along

ROBOTS = Path(__file__).parents[2] / "skeye/robots"


def test_the_hummingbird_webcam_profile():
    assert camera_model("hummingbird").profile == "webcam"  # its default
    model = camera_model("hummingbird", profile="webcam")
    assert model.profile == "webcam"
    assert (model.width, model.height) == (800, 600)
    assert model.dist_coeffs == (0.112507, -0.272067, 0.0, 0.0, 0.15775)
    assert model.shadows and model.jpeg_quality == 85 and model.latency_s > 0
    # the published C920 calibration's focal length at 800x600
    assert model.fx_px == WEBCAM_FOCAL_PX_AT_800 == model.fy_px == 775.79
    assert model.camera_matrix[0][2] == 399.5 and model.camera_matrix[1][2] == 299.5
    ideal = camera_model("hummingbird", profile="ideal")
    assert ideal.dist_coeffs == (0.0,) * 5 and not ideal.noisy and not ideal.shadows
    assert ideal.fov_h_rad == pytest.approx(1.309, abs=1e-12)


def spec(**params):
    mount = SensorMount("Camera", "Down", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                        tuple(params.items()))
    return CameraSpec.from_mount(mount, "robots/test.toml")


def test_robot_file_overrides_and_bad_values_are_named():
    cam = spec(profile="webcam", k1=0.05, k2=0.0, exposure_s=0.004, noise_seed=7)
    assert cam.model is not None and cam.model.k1 == 0.05 and cam.model.exposure_s == 0.004
    assert cam.model.noise_seed == 7 and cam.lens is not None
    assert spec().lens is None  # the ideal pinhole renders as before
    cases = [
        ({"profile": "fisheye-deluxe"}, "unknown camera profile 'fisheye-deluxe'"),
        ({"k1": "0.1"}, "k1 must be a finite number"),
        ({"exposure_s": -0.01}, "exposure_s must be >= 0"),
        ({"fx_px": 0}, "fx_px must be positive"),
        ({"shadows": 1}, "shadows must be true or false"),
        ({"jpeg_quality": 101}, "jpeg_quality must be 0 (raw) .. 100"),
        ({"msaa_samples": 32}, "msaa_samples must be 0 (point-sampled) .. 16"),
        ({"msaa_samples": 2.5}, "msaa_samples must be a non-negative integer"),
        ({"latency_s": 0.01, "latency_jitter_s": 0.02}, "latency_jitter_s (0.02) must not exceed"),
        ({"profile": "webcam", "k2": -1.0}, "folds over"),
        ({"cy_px": 600.0}, "cy_px must lie on the image, 0..599 px"),
        ({"fy_px": 1e300}, "fy_px 1e+300 px gives a vertical field of view of 6e-298 rad"),
        # Both hung for hours (skeye sim --robot-dir never started): the fold-over check walked
        # in steps of 0.002 out to the image corner, at normalised radius 4e8 and 1e297.
        ({"fx_px": 1e-6}, "fx_px 1e-06 px gives a horizontal field of view of 3.142 rad"),
        ({"cx_px": 1e300}, "cx_px must lie on the image, 0..799 px"),
        ({"lens_colour": 3}, "unknown key(s) ['lens_colour']"),
    ]
    for params, message in cases:
        with pytest.raises(ConfigError) as err:
            spec(**params)
        assert message in str(err.value), (params, str(err.value))
        assert "robots/test.toml camera 'Down'" in str(err.value)


def test_distortion_maps_invert_opencv_projection():
    """Each output pixel's ray, projected by cv2.projectPoints, lands on that pixel."""
    model = camera_model("hummingbird", profile="webcam")
    lens = Lens(model)
    rays = np.stack([lens.ray_x.ravel(), lens.ray_y.ravel(), np.ones(lens.ray_x.size)], 1)
    uv, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), np.array(model.camera_matrix),
                              np.array(model.dist_coeffs))
    u, v = np.meshgrid(np.arange(model.width), np.arange(model.height))
    uv = uv.reshape(model.height, model.width, 2)
    assert np.max(np.abs(uv[..., 0] - u)) < 1e-3 and np.max(np.abs(uv[..., 1] - v)) < 1e-3
    # ...and into the wide render with its square-pixel pinhole.
    assert np.allclose(lens.map_x, lens.ray_x * lens.focal_px + lens.render_cx, atol=1e-3)
    assert lens.map_x.min() > 0 and lens.map_x.max() < lens.render_width - 1
    assert lens.map_y.min() > 0 and lens.map_y.max() < lens.render_height - 1


def first_frame(sim: Simulation, buffer: FrameBuffer, name: str, body_ned, cls="hummingbird"):
    sim.spawn(cls, name=name, sink=lambda events: None, location_ned_m=body_ned)
    for _ in range(300):  # past the capture latency
        sim.step(1)
        frame = buffer.latest(f"{name}/Down")
        if frame is not None:
            assert frame.rgb.shape[2] == 3  # its pixels, while the cameras run (on request)
            return frame, sim.time_s
    raise AssertionError("no frame")


def test_rendered_pad_rings_sit_where_opencv_projects_them():
    """A webcam frame straight above the pad: each ring edge along the centre row is where
    cv2.projectPoints puts that radius (the distortion moves the outer ones by pixels)."""
    cam_height = 0.70  # the outer ring inside the 54.6 deg horizontal view
    sim = Simulation(load_world("pad"), seed=3)
    buffer = FrameBuffer()
    with CameraSystem(sim, buffer, synchronous=True, profile="webcam") as cams:
        body = (0.0, 0.0, -(cam_height + 0.035 + PAD_SURFACE_HEIGHT_M))
        frame, _ = first_frame(sim, buffer, "W1", body)
        model = sim.robots["W1"].cameras[0].model
        assert cams.error is None
    assert model is not None and model.profile == "webcam"
    grey = frame.rgb.mean(axis=2)
    row = grey[round(model.cy_px)]
    right = ring_edges_along(row, round(model.cx_px), +1)
    left = ring_edges_along(row, round(model.cx_px), -1)
    radii = sorted(r for ring in SKEYE_4.rings for r in (ring.inner_m, ring.outer_m))
    points = np.array([[r, 0.0, cam_height] for r in radii])
    uv, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), np.array(model.camera_matrix),
                              np.array(model.dist_coeffs))
    expected = uv[:, 0, 0] - model.cx_px
    pinhole = model.fx_px * np.array(radii) / cam_height
    assert np.max(np.abs(expected - pinhole)) > 3.0  # the distortion is visible
    for i, want in enumerate(expected):
        measured = (right[i] - left[i]) / 2
        assert abs(measured - want) < 1.0, (i, measured, want)


def test_noise_is_seeded_and_follows_the_photon_transfer_model():
    model = camera_model("hummingbird", profile="webcam")
    lens = Lens(model)
    grey = np.full((model.height, model.width, 3), 128, np.uint8)
    a, b, c = lens.add_noise(grey, 5), lens.add_noise(grey, 5), lens.add_noise(grey, 6)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    other = Lens(replace(model, noise_seed=1)).add_noise(grey, 5)
    assert not np.array_equal(a, other)
    k = model.system_gain_dn_per_e * model.gain
    sigma = math.sqrt(k * 128 + (k * model.read_noise_e) ** 2)
    assert np.std(a.astype(float)) == pytest.approx(sigma, rel=0.05)
    assert abs(np.mean(a.astype(float)) - 128) < 0.1


def edge_render(lens: Lens) -> np.ndarray:
    """A wide render: dark left half, bright right half (a vertical edge through the centre)."""
    img = np.full((lens.render_height, lens.render_width, 3), 40, np.uint8)
    img[:, lens.render_width // 2:] = 220
    return img


def edge_columns(image: np.ndarray, row: int) -> tuple[float, int]:
    """(sub-pixel column of mid-grey, number of pixels in the 10-90 % transition) on a row."""
    line = image[row, :, 0].astype(float)
    lo, hi = 40 + 0.1 * 180, 40 + 0.9 * 180
    width = int(np.sum((line > lo) & (line < hi)))
    i = int(np.argmax(line > 130))
    a, b = line[i - 1], line[i]
    return i - 1 + (130 - a) / (b - a), width


def test_blur_grows_with_angular_rate():
    base = replace(camera_model("hummingbird", profile="webcam"), k1=0.0, k2=0.0, line_time_s=0.0,
                   system_gain_dn_per_e=0.0, jpeg_quality=0, vignetting_exponent=0.0)
    lens = Lens(base)
    render = edge_render(lens)
    widths = []
    for rate in (0.0, 1.0, 3.0):
        image = lens.apply(render, Motion(omega_rad_s=(0.0, rate, 0.0)), 1)
        widths.append(edge_columns(image, base.height // 2)[1])
    assert widths[0] <= 2 < widths[1] < widths[2], widths
    # 3 rad/s over 10 ms: an edge smeared over f * 0.03 px (10-90 %: 80 % of it)
    assert widths[2] == pytest.approx(0.8 * base.fx_px * 3.0 * base.exposure_s, rel=0.25)


def test_rolling_shutter_skews_a_rotating_view():
    base = replace(camera_model("hummingbird", profile="webcam"), k1=0.0, k2=0.0, exposure_s=0.0,
                   system_gain_dn_per_e=0.0, jpeg_quality=0, vignetting_exponent=0.0)
    lens = Lens(base)
    render = edge_render(lens)
    rate = 2.0  # the vehicle rolling: about the camera's image-down axis
    image = lens.apply(render, Motion(omega_rad_s=(0.0, rate, 0.0)), 1)
    top, _ = edge_columns(image, 10)
    bottom, _ = edge_columns(image, base.height - 11)
    # turning right (+y): later rows see the world further left
    expected = -base.fx_px * rate * (base.height - 21) * base.line_time_s
    assert bottom - top == pytest.approx(expected, rel=0.1)
    still = lens.apply(render, Motion(), 1)
    assert edge_columns(still, 10)[0] == pytest.approx(edge_columns(still, 589)[0], abs=0.05)


def webcam_variant(tmp_path: Path, name: str, extra: str) -> str:
    """A copy of the Hummingbird whose webcam entry has ``extra`` lines; its class name."""
    text = (ROBOTS / "hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', f'name = "{name}"', 1)
    (tmp_path / f"{name}.toml").write_text(
        text.replace('profile = "webcam"', f'profile = "webcam"\n{extra}'))
    return name


def still_frame(tmp_path: Path, cls: str, body_ned, frames_s: float = 0.0) -> np.ndarray:
    """The grey level of cls's camera frame at ``body_ned`` (hovering), ``frames_s`` of sim
    time after the first."""
    sim = Simulation(load_world("pad"), seed=3, robot_dirs=(tmp_path,))
    buffer = FrameBuffer()
    with CameraSystem(sim, buffer, synchronous=True):
        frame, _ = first_frame(sim, buffer, "S1", body_ned, cls=cls)
        if frames_s:
            sim.step(round(frames_s / sim.dt))
            frame = buffer.latest("S1/Down")
        return cv2.cvtColor(np.array(frame.rgb), cv2.COLOR_RGB2GRAY).astype(float)


# Noise, MJPEG and auto-exposure off: two frames of one view differ only by what is tested.
_PLAIN = "system_gain_dn_per_e = 0.0\njpeg_quality = 0\nauto_exposure = false"


def test_soft_shadows_darken_the_ground_and_leave_lit_ground_alone(tmp_path: Path):
    """The webcam's shadows: the vehicle shades the grass below it by the share of light the
    sun gives (the lit ground keeps its brightness: MuJoCo's own shadow pass made it 13-32 %
    brighter), and the shadow's edge is a penumbra of several pixels, not a texel staircase."""
    shadow = webcam_variant(tmp_path, "withshadow", _PLAIN)
    plain = webcam_variant(tmp_path, "noshadow", _PLAIN + "\nshadows = false")
    body = (3.0, 2.0, -0.4)
    ratio = (still_frame(tmp_path, shadow, body) + 1.0) / (still_frame(tmp_path, plain, body) + 1.0)
    lit = np.abs(ratio - 1.0) < 0.03
    # In the pad world the sun gives 0.45 of the light's diffuse 0.45 + headlight 0.35 + 0.55
    # on level ground, about a third: the shade keeps about two thirds.
    shaded = ratio < 0.8
    assert lit.mean() > 0.3 and shaded.mean() > 0.05, (lit.mean(), shaded.mean())
    depth = float(np.median(ratio[ratio < 0.75]))
    assert 0.55 < depth < 0.8, depth
    # The edge: pixels between 20 % and 80 % of the way from the shade to the light, per pixel
    # of edge length (a hard edge has about one, blurred by the lens's interpolation).
    low, high = depth + 0.2 * (1.0 - depth), depth + 0.8 * (1.0 - depth)
    band = int(((ratio > low) & (ratio < high)).sum())
    mask = (ratio < (depth + 1.0) / 2).astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    length = sum(cv2.arcLength(c, True) for c in contours)
    assert band / length > 3.0, (band, length)


def test_no_shadow_lattice_on_the_lit_pad(tmp_path: Path):
    """MuJoCo's shadow pass left a lattice of grey dots on lit surfaces (2.0 % of the white
    pad's pixels more than 15 DN darker than their neighbours; 0.02 % without shadows): gone."""
    shadow = webcam_variant(tmp_path, "withshadow", _PLAIN)
    plain = webcam_variant(tmp_path, "noshadow", _PLAIN + "\nshadows = false")

    def dots(grey: np.ndarray) -> float:
        median = cv2.medianBlur(grey.astype(np.uint8), 5).astype(float)
        white = median > 180
        assert white.sum() > 50_000  # the pad fills much of the view
        return float(((median - grey > 15) & white).sum() / white.sum())

    body = (0.05, 0.0, -1.0)
    with_shadows, without = dots(still_frame(tmp_path, shadow, body)), dots(
        still_frame(tmp_path, plain, body))
    assert with_shadows < 0.001 and with_shadows < without + 0.0005, (with_shadows, without)


def test_vignetting_follows_the_cos4_law():
    model = replace(camera_model("hummingbird", profile="webcam"), system_gain_dn_per_e=0.0,
                    jpeg_quality=0, auto_exposure=False)
    assert model.vignetting_exponent == 4.0
    lens = Lens(model)
    flat = np.full((lens.render_height, lens.render_width, 3), 200, np.uint8)
    image = lens.apply(flat, Motion(), 1)[:, :, 1].astype(float)
    h, w = image.shape
    assert image[h // 2, w // 2] == pytest.approx(200, abs=1)
    for v, u in ((0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (h // 2, 0)):
        x, y = lens.ray_x[v, u], lens.ray_y[v, u]
        cos_theta = 1.0 / math.sqrt(1.0 + x * x + y * y)
        assert image[v, u] == pytest.approx(200 * cos_theta ** 4, abs=1.0), (v, u)
    assert image[0, 0] < 0.6 * 200  # the C920 at 4:3: the corner is 33 deg off the axis
    off = Lens(replace(model, vignetting_exponent=0.0)).apply(flat, Motion(), 1)
    assert int(off.min()) == int(off.max()) == 200


def run_auto_exposure(model, scene_dn, seconds, ae=None, start_s=0.0):
    """Frames at 30 fps of a scene whose mean is ``scene_dn(t)`` at the nominal settings;
    returns the AutoExposure and [(t, exposure, mean DN)]."""
    ae = ae or AutoExposure(model)
    out = []
    for k in range(round(seconds * 30)):
        t = start_s + k / 30
        exposure = ae.exposure_at(t)
        mean = min(255.0, scene_dn(t) * exposure.brightness)
        ae.metered(t, exposure, mean)
        out.append((t, exposure, mean))
    return ae, out


def test_auto_exposure_steers_to_its_target_with_its_lag():
    model = camera_model("hummingbird", profile="webcam")
    assert model.auto_exposure and model.ae_target_dn == 118.0
    tau = model.ae_time_constant_s
    # A dark scene (40 DN at 10 ms, gain 4): the exposure time carries the change, gain stays.
    _, frames = run_auto_exposure(model, lambda t: 40.0, 3.0)
    assert frames[0][2] == 40.0 and frames[0][1].exposure_s == model.exposure_s
    _, exposure, mean = frames[-1]
    assert mean == pytest.approx(model.ae_target_dn, rel=0.01)
    assert exposure.gain == model.gain and exposure.exposure_s == pytest.approx(0.0295, rel=0.01)
    # The lag: one time constant after the first metered frame (t = 0), 63 % of the log error
    # is gone.
    goal = math.log(model.ae_target_dn / 40.0)
    done = [math.log(e.brightness) / goal for t, e, _ in frames if abs(t - tau) < 1e-6]
    assert done == [pytest.approx(1 - math.exp(-1), abs=0.01)]
    # Darker still: the exposure time reaches the frame period, then the gain rises to its
    # limit; the frame stays darker than the target.
    _, frames = run_auto_exposure(model, lambda t: 20.0, 3.0)
    exposure, mean = frames[-1][1], frames[-1][2]
    assert exposure.exposure_s == model.exposure_max_s
    assert exposure.gain == pytest.approx(model.gain_max, rel=1e-3)
    assert mean == pytest.approx(20.0 * (1 / 30) * 5.0 / (0.010 * 4.0), rel=0.01)
    assert mean < 118
    # A bright scene: shorter exposures (less motion blur).
    _, frames = run_auto_exposure(model, lambda t: 240.0, 3.0)
    assert frames[-1][1].exposure_s == pytest.approx(0.010 * 118 / 240, rel=0.02)
    # A change of scene: the next frame is still exposed for the scene before.
    _, frames = run_auto_exposure(model, lambda t: 40.0 if t < 2.0 else 120.0, 3.0)
    before = [e for t, e, _ in frames if t < 2.0][-1]
    after = [m for t, _, m in frames if t >= 2.0]
    assert after[0] == 255.0 and 120.0 * before.brightness > 255.0  # over-exposed, clipped
    assert after[-1] == pytest.approx(118.0, rel=0.06)  # clipped frames meter low: slower
    # Off: the nominal settings, whatever the scene.
    fixed = replace(model, auto_exposure=False)
    _, frames = run_auto_exposure(fixed, lambda t: 40.0, 1.0)
    assert {(e.exposure_s, e.gain) for _, e, _ in frames} == {(0.010, 4.0)}


def test_webcam_frames_settle_at_the_auto_exposure_target(tmp_path: Path):
    """The simulator's webcam meters each rendered frame's mean luma: over the grass, whose
    render at the nominal settings is darker, a frame 1.5 s (5 time constants) after the
    first is at the target; only the two frames are rendered, the lag runs in sim time."""
    cls = webcam_variant(tmp_path, "aecam", "")
    first = still_frame(tmp_path, cls, (3.0, 2.0, -1.5))
    settled = still_frame(tmp_path, cls, (3.0, 2.0, -1.5), frames_s=1.5)
    target = camera_model("hummingbird", profile="webcam").ae_target_dn
    assert abs(float(first.mean()) - target) > 10
    assert float(settled.mean()) == pytest.approx(target, abs=4)


def test_auto_exposure_time_sets_the_blur_and_its_gain_the_noise():
    model = replace(camera_model("hummingbird", profile="webcam"), jpeg_quality=0,
                    vignetting_exponent=0.0)
    lens = Lens(model)
    turning = Motion(omega_rad_s=(0.0, 1.0, 0.0))
    assert lens.blur_length_px(turning, 0.02) == pytest.approx(
        2 * lens.blur_length_px(turning, 0.01), rel=1e-3)  # first order in the exposure
    grey = np.full((model.height, model.width, 3), 100, np.uint8)
    low, high = (np.std(lens.add_noise(grey, 3, gain).astype(float)) for gain in (1.0, 4.0))
    k = model.system_gain_dn_per_e
    assert low == pytest.approx(math.sqrt(k * 100 + (k * 3) ** 2), rel=0.05)
    assert high == pytest.approx(math.sqrt(4 * k * 100 + (4 * k * 3) ** 2), rel=0.05)


def test_point_sampled_render_has_no_antialiased_geometry_edges(tmp_path: Path):
    """``msaa_samples = 0`` (the webcam profile's) renders each pixel at one point: the pad's
    outline against the ground (a geometry edge) loses the in-between greys of the 4x
    multisampled render. The rings inside are texture: filtered alike in both."""
    text = (ROBOTS / "hummingbird.toml").read_text()
    for cls, samples in (("multisampled", 4), ("pointsampled", 0)):
        (tmp_path / f"{cls}.toml").write_text(
            text.replace('name = "hummingbird"', f'name = "{cls}"', 1)
            .replace('profile = "webcam"', f'profile = "ideal"\nmsaa_samples = {samples}'))
    grey, mixed = {}, {}
    for cls in ("multisampled", "pointsampled"):
        sim = Simulation(load_world("pad"), seed=3, robot_dirs=(tmp_path,))
        buffer = FrameBuffer()
        with CameraSystem(sim, buffer, synchronous=True):
            sim.spawn(cls, name="S1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, -2.5), rotation_rpy_rad=(0.0, 0.0, 0.3))
            sim.step(1)
            frame = buffer.latest("S1/Down")
            assert frame is not None
            grey[cls] = cv2.cvtColor(np.array(frame.rgb), cv2.COLOR_RGB2GRAY).astype(float)
        ground = float(np.median(grey[cls]))  # the pad covers a small part of the view
        pad = grey[cls][200:400, 300:500]  # the pad and the ground around it
        mixed[cls] = int(((pad > 0.2 * ground) & (pad < 0.8 * ground)).sum())
    changed = np.abs(grey["multisampled"] - grey["pointsampled"]) > 20
    assert 100 < changed.sum() < 2000, changed.sum()  # the outline's pixels, nothing else
    assert mixed["pointsampled"] < mixed["multisampled"] - 150, mixed


def test_frames_arrive_capture_latency_after_capture():
    sim = Simulation(load_world("pad"), seed=3)
    buffer = FrameBuffer()
    with CameraSystem(sim, buffer, synchronous=True, profile="webcam"):
        frame, arrived_s = first_frame(sim, buffer, "L1", (0.0, 0.0, -1.0))
        model = sim.robots["L1"].cameras[0].model
    assert model is not None
    delay = arrived_s - frame.sim_time_s
    assert model.latency_s - model.latency_jitter_s - 0.002 <= delay
    assert delay <= model.latency_s + model.latency_jitter_s + 0.002
    ideal_sim = Simulation(load_world("pad"), seed=3)
    ideal_buffer = FrameBuffer()
    with CameraSystem(ideal_sim, ideal_buffer, synchronous=True, profile="ideal"):
        frame, arrived_s = first_frame(ideal_sim, ideal_buffer, "L1", (0.0, 0.0, -1.0))
    assert arrived_s - frame.sim_time_s < 0.0015


def test_an_unknown_profile_is_refused():
    sim = Simulation(load_world("pad"), seed=3)
    with pytest.raises(ConfigError, match="unknown camera profile 'fancy'"):
        CameraSystem(sim, FrameBuffer(), synchronous=True, profile="fancy")
    assert build_camera_model({}, 64, 48, 1.0, "x").profile == "ideal"


def test_skeye_sim_checks_camera_models_and_the_profile_option(tmp_path: Path):
    import subprocess
    import sys

    text = (ROBOTS / "hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', 'name = "badcam"', 1)
    assert 'profile = "webcam"' in text
    (tmp_path / "badcam.toml").write_text(text.replace('profile = "webcam"',
                                                       'profile = "webcam"\nk1 = "strong"'))
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--port", "0",
                           "--robot-dir", str(tmp_path)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2, done
    assert "badcam.toml camera 'Down': k1 must be a finite number" in done.stderr
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--port", "0",
                           "--camera-profile", "fisheye"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "--camera-profile" in done.stderr


def test_a_camera_the_camera_profile_cannot_model_is_refused_naming_the_file(
        tmp_path: Path) -> None:
    """The start-up check ignored ``--camera-profile``: a file whose camera sets latency_s 5 ms
    under its own ideal profile passed ``skeye sim --check`` and the start-up check, and with
    ``--camera-profile webcam`` (latency_jitter_s 10 ms) INIT was then refused with "camera
    'Down': latency_jitter_s (0.01) must not exceed latency_s (0.005)", naming no file."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    path = tmp_path / "mine.toml"
    path.write_text(text.replace('name = "hummingbird"', 'name = "mine"')
                    .replace('profile = "webcam"', 'profile = "ideal"\nlatency_s = 0.005'))
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--check", "--robot-dir",
                           str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done  # its own profile models it
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--check", "--robot-dir",
                           str(tmp_path), "--camera-profile", "webcam"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done
    assert f"{path} camera 'Down': latency_jitter_s (0.01) must not exceed" in done.stderr, done
    sim = Simulation(load_world("pad"), seed=3, robot_dirs=(tmp_path,))
    with CameraSystem(sim, FrameBuffer(), synchronous=True, profile="webcam"):
        with pytest.raises(ConfigError) as info:
            sim.spawn("mine", sink=lambda events: None, name="M",
                      location_ned_m=(0.0, 0.0, -1.0))
    assert f"{path} camera 'Down': latency_jitter_s" in str(info.value)


@pytest.mark.parametrize("profile", ["ideal", "webcam"])
def test_an_exposure_over_a_second_is_refused_naming_the_file(tmp_path: Path,
                                                             profile: str) -> None:
    """exposure_s = 1e308 times the gain is inf: the auto-exposure's brightness range became 0
    and math.log raised ValueError, a traceback out of ``skeye sim --check``."""
    text = resources.files("skeye.robots").joinpath("hummingbird.toml").read_text("utf-8")
    path = tmp_path / "mine.toml"
    path.write_text(text.replace('name = "hummingbird"', 'name = "mine"')
                    .replace('profile = "webcam"', f'profile = "{profile}"\nexposure_s = 1e308'))
    done = subprocess.run([sys.executable, "-m", "skeye.cli", "sim", "--check", "--robot-dir",
                           str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done
    assert done.stderr == (f"skeye sim: error: {path} camera 'Down': exposure_s must be <= 1 s, "
                           "got 1e+308 s\n"), done.stderr
