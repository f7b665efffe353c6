"""Which options and render modes each environment takes (skeye.gym.options): an option the
environment would ignore, or a render mode it does not offer, is a ConfigError naming it."""

from __future__ import annotations

import re
import threading
from pathlib import Path

import gymnasium
import numpy as np
import pytest

import skeye.gym  # noqa: F401  (registers the environments)
from skeye.errors import ConfigError
from skeye.gym import HoverEnv, PadLandingEnv

NO_CAMERA = (r"skeye/Hover-v0 has no camera, so it offers no render mode \(with "
             r"camera='ideal' or 'webcam' it offers 'rgb_array'\); got render_mode=")


def test_a_render_mode_not_offered_is_refused_naming_the_offered_ones_and_the_given_one(
        ) -> None:
    """The message was "render_mode 'rgb_array': only 'rgb_array', with a camera" for a
    'human' given to gymnasium.make (which asks for 'rgb_array' in its place)."""
    given_note = r"'rgb_array' \(gymnasium\.make asks for 'rgb_array' when given 'human' or " \
                 r"'rgb_array_list'\)$"
    with pytest.raises(ConfigError, match=NO_CAMERA + given_note), \
            pytest.warns(UserWarning, match="HumanRendering wrapper is being applied"):
        gymnasium.make("skeye/Hover-v0", render_mode="human")
    # (the note said 'human' only, to someone who had given 'rgb_array_list')
    with pytest.raises(ConfigError, match=NO_CAMERA + given_note):
        gymnasium.make("skeye/Hover-v0", render_mode="rgb_array_list")
    with pytest.raises(ConfigError, match=NO_CAMERA + "'human'$"):
        HoverEnv(render_mode="human")
    with pytest.raises(ConfigError, match=NO_CAMERA + "3$"):
        HoverEnv(render_mode=3)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"^skeye/PadLanding-v0 offers render_mode 'rgb_array' "
                                          r"\(its downward camera's newest frame\); got "
                                          r"render_mode=3$"):
        PadLandingEnv(render_mode=3, camera="ideal")  # type: ignore[arg-type]


@pytest.mark.parametrize("render_mode", [3, "rgb_array", "human"])
def test_the_batched_environment_offers_no_render_mode(render_mode: object) -> None:
    """It refused render_mode as an "unknown option", as if Gymnasium had no such keyword."""
    with pytest.raises(ConfigError, match=r"^the batched skeye/Hover-v0 offers no render mode; "
                                          rf"got render_mode={render_mode!r}$"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2, render_mode=render_mode,
                           vectorization_mode="vector_entry_point")


def test_gymnasium_make_fails_on_a_render_mode_that_is_not_a_string_before_the_env_is_built(
        ) -> None:
    """Gymnasium's own make calls render_mode.endswith() before it builds the environment
    (Gymnasium 1.4), so the environment's ConfigError cannot be reached that way. docs/gym.md
    quotes this error: should a Gymnasium release change it, update the docs (the environment
    itself then answers with the ConfigError above)."""
    with pytest.raises(AttributeError, match=r"^'int' object has no attribute 'endswith'$"):
        gymnasium.make("skeye/Hover-v0", render_mode=3)


def test_a_camera_renders_hover_with_rgb_array() -> None:
    env = gymnasium.make("skeye/Hover-v0", camera="ideal", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        env.step(np.zeros(4, np.float32))
        frame = env.render()
        assert isinstance(frame, np.ndarray) and frame.ndim == 3 and frame.dtype == np.uint8
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["skeye/Hover-v0", "skeye/GoTo-v0"])
def test_a_camera_only_rendered_runs_no_pad_detector(env_id: str) -> None:
    """Hover and GoTo given a camera to render started the pilot's pad detector on it (a
    'pilot-vision' thread detecting, so rendering, every frame of every step), whose
    detections they never observe: a step took about 35 times as long, and a hung detector
    could stop it. Now the frames are rendered only when render() asks for one."""
    def detectors() -> int:
        return sum(1 for t in threading.enumerate() if t.name == "pilot-vision")

    before = detectors()
    env = gymnasium.make(env_id, camera="ideal", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        first = env.render()
        for _ in range(10):
            env.step(np.array((1.0, 0.0, 0.5, 0.0), np.float32))
        assert detectors() == before
        frame = env.render()
        assert isinstance(frame, np.ndarray) and frame.shape == first.shape  # type: ignore[union-attr]
        assert not np.array_equal(frame, first)  # the view moved with the vehicle
    finally:
        env.close()


IGNORED = "would do nothing in "
DETECTOR = ": it tunes the pilot's pad detector, whose detections only PadLanding observes$"
RENDER_ONLY = ": it has a camera only to render it, with render_mode='rgb_array'$"


@pytest.mark.parametrize("env_id,kwargs,message", [
    ("skeye/Hover-v0", {"calibration": "lens.toml"},
     "calibration 'lens.toml' " + IGNORED + "skeye/Hover-v0" + DETECTOR),
    ("skeye/GoTo-v0", {"calibration": "model"},
     "calibration 'model' " + IGNORED + "skeye/GoTo-v0" + DETECTOR),
    ("skeye/GoTo-v0", {"vision_latency_s": 0.05},
     "vision_latency_s 0.05 " + IGNORED + "skeye/GoTo-v0" + DETECTOR),
    ("skeye/Hover-v0", {"vision_latency_s": 0.05, "camera": "ideal", "render_mode": "rgb_array"},
     "vision_latency_s 0.05 " + IGNORED + "skeye/Hover-v0" + DETECTOR),
    ("skeye/Hover-v0", {"camera": "webcam"},
     "camera 'webcam' " + IGNORED + "skeye/Hover-v0" + RENDER_ONLY),
    ("skeye/GoTo-v0", {"camera_name": "Front"},
     "camera_name 'Front' " + IGNORED + "skeye/GoTo-v0" + RENDER_ONLY),
])
def test_a_camera_or_vision_option_the_environment_ignores_is_refused_naming_it(
        env_id: str, kwargs: dict, message: str) -> None:
    """Hover and GoTo observe no pad detection and have a camera only to render it: these
    options were taken and did nothing."""
    with pytest.raises(ConfigError, match="^" + message):
        gymnasium.make(env_id, **kwargs)


@pytest.mark.parametrize("kwargs,message", [
    ({"camera": "webcam"}, "camera 'webcam' "),
    ({"calibration": "model"}, "calibration 'model' "),
])
def test_the_batched_environment_refuses_the_camera_options_it_ignores(
        kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match="^" + message + IGNORED + "the batched skeye/Hover-v0"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                           vectorization_mode="vector_entry_point", **kwargs)


def test_the_defaults_of_the_ignored_options_may_be_given() -> None:
    """Generic code may pass every option at its default to every environment."""
    env = gymnasium.make("skeye/GoTo-v0", camera=None, camera_name="Down", vision_latency_s=0,
                         calibration=None)
    env.close()
    env = gymnasium.make("skeye/Hover-v0", camera_name="down")  # the mount's name, any case
    env.close()
    env = gymnasium.make("skeye/PadLanding-v0", camera="ideal", vision_latency_s=0.05,
                         calibration="model", camera_name="Down")
    env.close()


def test_a_robot_dir_that_is_not_a_folder_is_refused_naming_it(tmp_path: Path) -> None:
    """robot_dir="/nonexistent" was taken, and the robot came from the built-ins."""
    missing = tmp_path / "nonexistent"
    with pytest.raises(ConfigError, match=rf"^robot_dir '{re.escape(str(missing))}': no such "
                                          r"folder$"):
        gymnasium.make("skeye/Hover-v0", robot_dir=str(missing))
    a_file = tmp_path / "robot.toml"
    a_file.write_text("")
    with pytest.raises(ConfigError, match=rf"^robot_dir '{re.escape(str(a_file))}': not a "
                                          r"folder$"):
        gymnasium.make("skeye/Hover-v0", robot_dir=[tmp_path, a_file])
    gymnasium.make("skeye/Hover-v0", robot_dir=tmp_path).close()


def test_the_options_table_gives_every_keyword_the_environments_take() -> None:
    """docs/gym.md's options table is the reference of gymnasium.make's keywords; timestep_s,
    which every environment takes (the physics step, as skeye sim --timestep), was missing."""
    from dataclasses import fields

    from skeye.gym.envs import ENV_KEYWORDS
    from skeye.gym.flight import FlightSettings
    from skeye.gym.tasks import PadLanding

    text = (Path(__file__).resolve().parents[2] / "docs" / "gym.md").read_text()
    table = text.split("### Options", 1)[1].split("\n\n", 2)[1]  # the table after its heading
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    documented = {name for row in rows for name in re.findall(r"`(\w+)`", row.split("|")[1])}
    taken = {f.name for f in fields(FlightSettings)} | set(ENV_KEYWORDS) | set(
        PadLanding.keywords) | {"max_episode_steps"}
    assert taken <= documented, sorted(taken - documented)
