"""The camera model (docs/camera.md): profiles from the robot file, the lens maps against
OpenCV's projection, seeded noise, motion blur, rolling shutter, shadows and capture latency."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.errors import ConfigError
from skeye.robots.camera_model import WEBCAM_FOCAL_PX_AT_800, build_camera_model
from skeye.robots.config import SensorMount, camera_model
from skeye.sim.cameras import CameraSpec, CameraSystem
from skeye.sim.engine import Simulation
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


def first_frame(sim: Simulation, buffer: FrameBuffer, name: str, body_ned, rate=None):
    sim.spawn("hummingbird", name=name, sink=lambda events: None, location_ned_m=body_ned)
    for _ in range(300):  # past the capture latency
        sim.step(1)
        frame = buffer.latest(f"{name}/Down")
        if frame is not None:
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
                   system_gain_dn_per_e=0.0, jpeg_quality=0)
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
                   system_gain_dn_per_e=0.0, jpeg_quality=0)
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


def test_shadows_on_darken_the_ground_under_the_vehicle(tmp_path: Path):
    """Same view, the webcam profile with and without shadows: the vehicle shades the ground."""
    text = (ROBOTS / "hummingbird.toml").read_text()
    text = text.replace('name = "hummingbird"', 'name = "noshadow"', 1)
    text = text.replace('profile = "webcam"', 'profile = "webcam"\nshadows = false')
    (tmp_path / "noshadow.toml").write_text(text)
    frames = {}
    for cls in ("hummingbird", "noshadow"):
        sim = Simulation(load_world("pad"), seed=3, robot_dirs=(tmp_path,))
        buffer = FrameBuffer()
        with CameraSystem(sim, buffer, synchronous=True, profile="webcam"):
            sim.spawn(cls, name="S1", sink=lambda events: None, location_ned_m=(3.0, 2.0, -0.4))
            for _ in range(300):
                sim.step(1)
                if buffer.latest("S1/Down") is not None:
                    break
            frame = buffer.latest("S1/Down")
            assert frame is not None
            frames[cls] = cv2.cvtColor(np.array(frame.rgb), cv2.COLOR_RGB2GRAY).astype(float)
    # MuJoCo's shadow pass brightens the lit ground (sun + headlight) and leaves the shaded
    # ground at about the shadowless frame's (headlight only): both parts are in view.
    ratio = (frames["hummingbird"] + 1.0) / (frames["noshadow"] + 1.0)
    lit, shaded = np.mean(ratio > 1.2), np.mean(ratio < 1.05)
    assert lit > 0.05 and shaded > 0.05, (lit, shaded)


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
