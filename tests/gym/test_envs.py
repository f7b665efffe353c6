"""The Gymnasium environments: Gymnasium's own checker, seeding, vector environments, options."""

from __future__ import annotations

import copy
import gc
import pickle
import re
import socket
import threading
import warnings
import weakref
from typing import Any

import cloudpickle
import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import skeye.gym
from skeye.errors import ConfigError
from skeye.pilot.policy import PAD_FIELDS, STATE_FIELDS

CLOSE_TIMEOUT_S = 5.0  # how long a flight's close() waits for each of its threads


@pytest.mark.parametrize("env_id", skeye.gym.ENV_IDS)
def test_gymnasiums_checker_passes_every_registered_environment(env_id: str) -> None:
    env = gymnasium.make(env_id)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # Gymnasium's warnings are failures here
            check_env(env.unwrapped)
    finally:
        env.close()


def test_the_checker_passes_the_image_observation() -> None:
    env = gymnasium.make("skeye/PadLanding-v0", observation="image", camera="ideal",
                         image_size=(64, 48))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
        obs, _ = env.reset(seed=2)
        assert obs["image"].shape == (48, 64, 1) and obs["image"].dtype == np.uint8
        for _ in range(3):
            obs, *_ = env.step(np.zeros(4, dtype=np.float32))
        assert obs["image"].std() > 5  # a real frame (the pad on grass), not a blank one
    finally:
        env.close()


def _episode(env: gymnasium.Env, seed: int, steps: int) -> tuple[list, list]:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(99)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(
            rng.uniform(-0.3, 0.3, size=4).astype(np.float32))
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return observations, rewards


def _same(a: list, b: list) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if isinstance(x, dict):
            if not all(np.array_equal(x[k], y[k]) for k in x):
                return False
        elif not np.array_equal(x, y):
            return False
    return True


@pytest.mark.parametrize("env_id,kwargs,steps", [
    ("skeye/Hover-v0", {"wind": "turbulence"}, 60),
    ("skeye/PadLanding-v0", {"camera": "webcam", "observation": "image"}, 12),
])
def test_reset_with_a_seed_repeats_an_episode_bit_for_bit(env_id, kwargs, steps) -> None:
    env = gymnasium.make(env_id, **kwargs)
    try:
        first = _episode(env, 7, steps)
        again = _episode(env, 7, steps)
        other = _episode(env, 8, steps)
    finally:
        env.close()
    assert _same(first[0], again[0]) and first[1] == again[1]
    assert not _same(first[0], other[0])


def test_the_state_is_what_the_board_knows_and_the_pad_is_the_pilots_detection(
        monkeypatch: pytest.MonkeyPatch) -> None:
    def no_sockets(*args: object, **kwargs: object) -> None:
        raise AssertionError("an environment opened a socket")

    monkeypatch.setattr(socket, "socket", no_sockets)
    env = gymnasium.make("skeye/PadLanding-v0", camera="ideal", wind="none")
    try:
        obs, _ = env.reset(seed=1, options={"start_ned_m": (0.3, 0.0, -1.5), "yaw_rad": 0.0})
        assert obs.shape == (len(STATE_FIELDS) + len(PAD_FIELDS),)
        for _ in range(4):
            obs, _reward, terminated, truncated, _info = env.step(np.zeros(4, np.float32))
        state = dict(zip(STATE_FIELDS + PAD_FIELDS, obs.tolist(), strict=True))
        truth = env.unwrapped.vehicle.truth()
    finally:
        env.close()
    # Home is the ground below the spawn point: the height is the estimate's, about 1.5 m
    # less the landing gear, and the accelerometer feels gravity.
    assert -state["down_m"] == pytest.approx(1.5 - 0.08, abs=0.1)
    assert state["accel_z_m_s2"] == pytest.approx(-9.8, abs=0.5) and state["landed"] == 0
    # The pad 0.3 m behind, seen from 1.5 m: the detector's level-frame offset and height.
    assert state["pad_found"] == 1 and state["pad_forward_m"] == pytest.approx(-0.3, abs=0.05)
    assert state["pad_height_m"] == pytest.approx(-truth.pos_ned_m[2] - 0.035, abs=0.05)
    assert 0 <= state["pad_age_s"] < 0.1 and not terminated and not truncated


def test_pad_landing_ends_at_touchdown_and_judges_it_on_the_truth() -> None:
    env = gymnasium.make("skeye/PadLanding-v0", camera="ideal", wind="none",
                         start_height_m=(0.6, 0.6))
    try:
        env.reset(seed=3, options={"start_ned_m": (0.5, 0.0, -0.6)})
        for _ in range(200):  # straight down, 0.5 m off the centre: off the pad
            _, reward, terminated, _, info = env.step(np.array((0, 0, -0.2, 0), np.float32))
            if terminated:
                break
    finally:
        env.close()
    assert terminated and reward == -10.0 and info["success"] is False
    assert info["touchdown_error_m"] == pytest.approx(0.5, abs=0.1)


@pytest.mark.parametrize("limit", [{"episode_s": 0.2}, {"max_episode_steps": 4}])
def test_a_truncated_pad_landing_episode_reads_no_success(limit: dict) -> None:
    """Truncated by its length or by Gymnasium's TimeLimit, the episode's info had no
    ``success`` key at all (only a touchdown or a crash set it)."""
    env = gymnasium.make("skeye/PadLanding-v0", camera="ideal", wind="none", **limit)
    try:
        _, info = env.reset(seed=0)
        assert info["success"] is False
        for _ in range(10):
            _, _, terminated, truncated, info = env.step(np.zeros(4, np.float32))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert truncated and not terminated and info["success"] is False


@pytest.mark.parametrize("mode", ["sync", "async", "vector_entry_point"])
def test_vector_environments_step_and_reset_their_vehicles(mode: str) -> None:
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=3, vectorization_mode=mode,
                              episode_s=0.5)
    try:
        obs, _ = envs.reset(seed=5)
        assert obs.shape == (3, 19) and obs.dtype == np.float32
        ended = np.zeros(3, dtype=bool)
        for step in range(11):
            obs, rewards, _terminated, truncated, infos = envs.step(np.zeros((3, 4), np.float32))
            if step == 9:
                ended = truncated  # the 10th step of 0.05 s ends the 0.5 s episodes
            if step == 10:  # next-step autoreset: fresh episodes, no reward
                assert np.all(ended) and np.all(rewards == 0)
                assert np.allclose(infos["sim_time_s"], 0.0)
        assert np.all(np.isfinite(obs))
    finally:
        envs.close()


def test_the_batched_environment_flies_its_vehicles_in_one_world_repeatably() -> None:
    def run() -> np.ndarray:
        envs = gymnasium.make_vec("skeye/PadLanding-v0", num_envs=4, camera="ideal",
                                  vectorization_mode="vector_entry_point")
        try:
            obs, _ = envs.reset(seed=11)
            flight = envs.unwrapped.flight
            assert len(flight.sim.robots) == 4 and len(flight.world.pads) == 4
            for _ in range(4):
                obs, *_ = envs.step(np.zeros((4, 4), np.float32))
            return obs
        finally:
            envs.close()

    first, again = run(), run()
    assert np.array_equal(first, again)
    found = first[:, len(STATE_FIELDS)]
    assert np.all(found == 1)  # each vehicle sees its own pad below it


@pytest.mark.parametrize("kwargs,message", [
    ({"wind": "hurricane"}, "unknown mode"),
    ({"sensor_noise": -1}, "sensor_noise"),
    ({"camera": "fisheye"}, "camera must be one of"),
    ({"control_rate_hz": 333}, "whole number of physics steps"),
    ({"no_such_option": 1}, "unknown option"),
    ({"robot": "zeppelin"}, "unknown robot class"),
])
def test_bad_options_are_refused_with_their_name(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        gymnasium.make("skeye/Hover-v0", **kwargs)


@pytest.mark.parametrize("kwargs,message", [
    ({"estimator": "bogus"}, "estimator must be one of"),
    ({"estimator": 5}, "estimator must be a string"),
    ({"world": 3}, "world must be a string"),
    ({"wind": 3}, "wind must be a string"),
    ({"wind_params": {"f_max_n": "x"}}, "wind_params must map"),
    ({"wind_params": 5}, "wind_params must map"),
    ({"robot_dir": 5}, "robot_dir must be"),
    ({"camera_name": 3}, "camera_name must be a string"),
    ({"calibration": 3}, "calibration must be a string"),
    # "" (a variable left empty) was read as the folder ".": "cannot read calibration file:
    # Is a directory", naming no option
    ({"calibration": ""}, "calibration must name a calibration file"),
    ({"timestep_s": 0}, "timestep_s must be in"),
    ({"timestep_s": 1.0}, "timestep_s must be in"),
    ({"episode_s": "x"}, "episode_s must be a finite number"),
    ({"image_size": 3}, "image_size must be"),
    ({"image_size": ("a", "b")}, "image_size must be"),
    ({"image_size": (80.5, 60)}, "image_size must be"),
    ({"start_height_m": 3}, "start_height_m must be"),
    ({"start_height_m": ("a", "b")}, "start_height_m must be"),
    ({"start_height_m": (1, 2, 3)}, "start_height_m must be"),
    ({"start_offset_m": "x"}, "start_offset_m must be a finite number"),
    ({"pad_tolerance_m": None}, "pad_tolerance_m must be a finite number"),
])
def test_bad_pad_landing_options_of_any_type_are_config_errors_naming_them(
        kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        gymnasium.make("skeye/PadLanding-v0", **kwargs)


@pytest.mark.parametrize("env_id,options", [
    ("skeye/GoTo-v0", {"start_ned_m": (0.0, 0.0, -1.5), "target_ned_m": (0.5, 0.0, -1.5)}),
    ("skeye/GoTo-v0", {"target_ned_m": (2.0, 0.0, -1.5)}),
    ("skeye/PadLanding-v0", {"start_ned_m": (0.0, 0.0, -4.0)}),
])
def test_the_first_reward_of_a_start_or_target_given_in_the_options_is_their_progress(
        env_id: str, options: dict) -> None:
    """The progress reward was counted from the distance of the start and target the task
    had drawn before the options replaced them: GoTo's first step, hovering 0.5 m from its
    given target, was rewarded 4.3 (seed 0) for a progress of millimetres."""
    env = gymnasium.make(env_id, sensor_noise=0.0, estimator="truth")
    try:
        for seed in (0, 1):
            env.reset(seed=seed, options=options)
            _, reward, terminated, _, info = env.step(np.zeros(4, np.float32))  # hold still
            assert not terminated
            assert abs(float(reward)) < 0.02, (seed, reward, info)
    finally:
        env.close()


@pytest.mark.parametrize("env_id,options,message", [
    ("skeye/PadLanding-v0", {"yaw_rad": "abc"}, "yaw_rad must be a finite number"),
    ("skeye/PadLanding-v0", {"yaw_rad": float("nan")}, "yaw_rad must be a finite number"),
    ("skeye/PadLanding-v0", {"start_ned_m": (0, 0, "x")}, "start_ned_m must be three"),
    ("skeye/PadLanding-v0", {"start_ned_m": 5}, "start_ned_m must be three"),
    ("skeye/PadLanding-v0", {"target_ned_m": (0, 0, -1)}, "unknown reset option"),
    ("skeye/PadLanding-v0", 5, "reset options must be a dict"),
    ("skeye/GoTo-v0", {"target_ned_m": (1, 2, "x")}, "target_ned_m must be three"),
    ("skeye/Hover-v0", {"start_ned_m": (1e6, 0, -1)}, "start_ned_m must be within 100000 m"),
    ("skeye/GoTo-v0", {"target_ned_m": (0, 0, -1e30)}, "target_ned_m must be within"),
])
def test_bad_reset_options_are_config_errors_naming_them(env_id: str, options: object,
                                                          message: str) -> None:
    env = gymnasium.make(env_id)
    try:
        with pytest.raises(ConfigError, match=message):
            env.reset(seed=0, options=options)  # type: ignore[arg-type]
    finally:
        env.close()


@pytest.mark.parametrize("env_id,start", [
    ("skeye/Hover-v0", (0.0, 0.0, 5.0)),  # 5 m underground
    ("skeye/Hover-v0", (0.0, 0.0, 0.0)),  # on the ground
    ("skeye/PadLanding-v0", (0.0, 0.0, -0.05)),  # on the pad, which stands on the ground
])
def test_a_start_that_is_not_in_the_air_is_refused(env_id: str, start: tuple) -> None:
    """A start at or below what is under it stood the vehicle there (the simulator's spawn rule)
    and the episode ended at its first step as a crash, 'touched the ground'."""
    env = gymnasium.make(env_id)
    try:
        env.reset(seed=0)
        with pytest.raises(ConfigError, match=r"is not in the air.*start_ned_m must be above"):
            env.reset(seed=0, options={"start_ned_m": start})
        env.reset(seed=0)
        _, _, terminated, _, _ = env.step(np.zeros(4, np.float32))  # flies on
        assert not terminated
    finally:
        env.close()


@pytest.mark.parametrize("height_m", [2.0, 1500.0, 20000.0])
def test_the_home_is_on_the_ground_below_a_start_of_any_height(height_m: float) -> None:
    """Home is where the vehicle would stand on the ground below its spawn point; the ground
    was looked for within 1000 m only, so above that the home was the spawn point itself and
    the state's down_m read +0.08 m (the gear's height: below the ground) at 1500 m up."""
    env = gymnasium.make("skeye/Hover-v0", sensor_noise=0.0, estimator="truth")
    try:
        obs, _ = env.reset(seed=0, options={"start_ned_m": (0.0, 0.0, -height_m)})
        gear_m = env.unwrapped.setup.config.airframe.gear_height_m  # type: ignore[attr-defined]
        assert obs[STATE_FIELDS.index("down_m")] == pytest.approx(-(height_m - gear_m), abs=0.05)
    finally:
        env.close()


def test_the_batched_environment_refuses_bad_options_as_config_errors() -> None:
    with pytest.raises(ConfigError, match="start_height_m must be"):
        gymnasium.make_vec("skeye/PadLanding-v0", num_envs=2,
                           vectorization_mode="vector_entry_point", start_height_m=3)
    with pytest.raises(ConfigError, match="spacing_m must be a finite number"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                           vectorization_mode="vector_entry_point", spacing_m="x")
    with pytest.raises(ConfigError, match="spacing_m 1e\\+09 puts 2 vehicles"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2,  # raised PhysicsError at reset()
                           vectorization_mode="vector_entry_point", spacing_m=1e9)


def test_the_batched_environment_takes_num_envs_of_any_integer_type() -> None:
    """num_envs=np.int64(2), which Gymnasium's sync and async modes take, was refused by the
    batched environment as 'num_envs must be 1..256, got np.int64(2)'."""
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=np.int64(2),
                              vectorization_mode="vector_entry_point")
    try:
        obs, _ = envs.reset(seed=0)
        assert obs.shape == (2, 19) and type(envs.num_envs) is int
    finally:
        envs.close()
    for bad in (0, 257, 2.0, True, "2"):
        with pytest.raises(ConfigError, match=re.escape(f"num_envs must be a whole number "
                                                        f"1..256, got {bad!r}")):
            gymnasium.make_vec("skeye/Hover-v0", num_envs=bad,
                               vectorization_mode="vector_entry_point")


@pytest.mark.parametrize("env_id,world,num_envs,box", [
    ("skeye/Hover-v0", "yard", 16, "'shed'"),  # vehicle 3 stood in the tower, 15 in the house
    ("skeye/Hover-v0", "indoor", 4, "'wall_south'"),  # the room's walls, at the cells' corners
    ("skeye/PadLanding-v0", "indoor", 4, "'wall_south'"),
])
def test_the_batched_environment_refuses_cells_that_reach_the_worlds_boxes(
        env_id: str, world: str, num_envs: int, box: str) -> None:
    """The cells copy the world's pad, not its obstacles, and were laid out over them: in the
    yard, 16 Hover vehicles of spacing 10 m put vehicle 3 inside the tower and 15 in the house,
    whose every episode ended at once in a crash ('hard impact', 'left the area') whatever
    the policy. Such a cell is now refused, naming the vehicle and the box."""
    with pytest.raises(ConfigError, match=rf"vehicle \d+'s cell, centred at .* m from box "
                                          rf"{box} of world '{world}'.*need 4 m clear"):
        gymnasium.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                           world=world)
    envs = gymnasium.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point",
                              world=world)  # one cell, at the origin: the world's own scene
    try:
        envs.reset(seed=0)
        _, _, terminated, _, _ = envs.step(np.zeros((1, 4), np.float32))
        assert not terminated.any()
    finally:
        envs.close()


@pytest.mark.parametrize(("env_id", "closest_m"), [
    ("skeye/Hover-v0", 8.0), ("skeye/GoTo-v0", 2 * (8 + 4 * 2 ** 0.5) + 2)])
def test_cells_closer_than_the_task_reach_are_refused(env_id: str, closest_m: float) -> None:
    """spacing_m took anything from 2 m: four Hover vehicles 2 m apart flown forward ran into
    the next cell, and a respawn there raised the simulator's 'is taken' refusal from step().
    Cells now leave twice the task's reach and 2 m between them (docs/gym.md)."""
    with pytest.raises(ConfigError, match=f"spacing_m must be >= {closest_m:g} m"):
        gymnasium.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point",
                           spacing_m=closest_m - 0.01)
    env = gymnasium.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    try:
        assert env.unwrapped.spacing_m == max(10.0, closest_m)  # the default: 10 m or more
    finally:
        env.close()


def test_sensor_noise_zero_takes_the_noise_out_of_the_readings() -> None:
    from skeye.gym.flight import scale_noise
    from skeye.robots.config import load_robot_config

    config = scale_noise(load_robot_config("hummingbird"), 0.0)
    gyro = next(m for m in config.sensors if m.type_name == "Gyro")
    params = {k.replace("_", "").lower(): v for k, v in gyro.params}  # as the loader reads them
    for name in ("noisesigma", "biaswalk", "vibrationrotor", "vibrationbladepass",
                 "vibrationbroadband"):
        assert params[name] == 0.0, name
    env = gymnasium.make("skeye/Hover-v0", sensor_noise=0.0, estimator="truth")
    try:
        env.reset(seed=0)
        for _ in range(3):
            obs, *_ = env.step(np.zeros(4, np.float32))
    finally:
        env.close()
    assert abs(obs[STATE_FIELDS.index("roll_rate_rad_s")]) < 0.01


def test_a_step_after_the_episode_ended_needs_a_reset() -> None:
    """Flown into the ground (terminated), the episode is over: stepping on would fly a crashed
    vehicle whose episode is judged afresh (terminated False, reward 0, info still naming the
    crash). Gymnasium's contract is reset() first; so after a truncation."""
    env = gymnasium.make("skeye/Hover-v0")
    try:
        env.reset(seed=2)
        for _ in range(400):
            _, _, terminated, truncated, info = env.step(np.array([0, 0, -1, 0], np.float32))
            if terminated or truncated:
                break
        assert terminated and info["crash"], info
        with pytest.raises(gymnasium.error.ResetNeeded, match=r"episode is over \(terminated\)"):
            env.step(np.zeros(4, np.float32))
        env.reset(seed=3)
        assert env.step(np.zeros(4, np.float32))[2] is False  # flies again after the reset
    finally:
        env.close()
    env = gymnasium.make("skeye/Hover-v0", episode_s=0.2)  # four steps of 50 ms
    try:
        env.reset(seed=4)
        results = [env.step(np.zeros(4, np.float32))[2:4] for _ in range(4)]
        assert results[-1] == (False, True) and (False, True) not in results[:-1]
        with pytest.raises(gymnasium.error.ResetNeeded, match=r"episode is over \(truncated\)"):
            env.step(np.zeros(4, np.float32))
    finally:
        env.close()


@pytest.mark.parametrize("action", [
    ["a", "b", "c", "d"], "abcd", {"a": 1}, np.array(["1", "2", "3", "4"]),
    np.ones(4, dtype=np.complex128) * 1j, [[0, 0], [0]],
])
def test_an_action_that_is_not_four_real_numbers_is_an_invalid_argument(action: object) -> None:
    """Text, a dict, complex or ragged numbers raised ValueError/TypeError from numpy's
    conversion (or, complex, lost their imaginary part with a warning and flew)."""
    from skeye.errors import InvalidArgument

    env = gymnasium.make("skeye/Hover-v0")
    try:
        env.reset(seed=0)
        with pytest.raises(InvalidArgument, match="an action is 4 real numbers"):
            env.unwrapped.step(action)
        env.step(np.zeros(4, np.float32))  # the environment flies on
    finally:
        env.close()


class _TensorThatRequiresGrad:
    """What a PyTorch tensor that requires grad does when numpy converts it."""

    def __array__(self, dtype: object = None, copy: object = None) -> np.ndarray:
        raise RuntimeError("Can't call numpy() on Tensor that requires grad. Use "
                           "tensor.detach().numpy() instead.")


@pytest.mark.parametrize("action,cause", [
    ([10**400, 0, 0, 0], "OverflowError: int too large to convert to float"),
    (_TensorThatRequiresGrad(), "RuntimeError: Can't call numpy"),
])
def test_an_action_whose_conversion_fails_otherwise_is_an_invalid_argument_naming_why(
        action: object, cause: str) -> None:
    """An action numpy could not convert for another reason than TypeError or ValueError
    escaped as that bare error (OverflowError, RuntimeError), not the InvalidArgument the
    environments and the pilot's policy adapter refuse a bad action with."""
    from skeye.errors import InvalidArgument

    env = gymnasium.make("skeye/Hover-v0")
    try:
        env.reset(seed=0)
        with pytest.raises(InvalidArgument, match="an action is 4 real numbers") as refused:
            env.unwrapped.step(action)
        assert cause in str(refused.value)
        env.step(np.zeros(4, np.float32))  # the environment flies on
    finally:
        env.close()


@pytest.mark.parametrize("action", [np.zeros((2, 2)), np.zeros((1, 4)), np.zeros((4, 1))])
def test_an_action_of_four_numbers_in_another_shape_is_refused_not_flattened(
        action: np.ndarray) -> None:
    """A (2, 2), (1, 4) or (4, 1) action was flattened to four numbers and flown: the action
    space is (4,), and a batched array handed to a single environment is a mistake to name."""
    from skeye.errors import InvalidArgument

    env = gymnasium.make("skeye/Hover-v0")
    try:
        env.reset(seed=0)
        with pytest.raises(InvalidArgument,
                           match=re.escape(f"shape (4,), got shape {action.shape}")):
            env.unwrapped.step(action)
        env.step(np.zeros(4, np.float32))  # the environment flies on
    finally:
        env.close()


def test_the_batched_environment_refuses_actions_of_another_shape_touching_no_vehicle(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """(3, 4), (2, 3) or None raised numpy's reshape ValueError; a flat (8,) was silently
    taken as (2, 4); a bad row after a good one left the good one's set-point flown."""
    from skeye.errors import InvalidArgument

    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                              vectorization_mode="vector_entry_point")
    try:
        envs.reset(seed=0)
        for actions in (np.zeros((3, 4)), np.zeros((2, 3)), np.zeros(8), None, [[0] * 4, [0]]):
            with pytest.raises(InvalidArgument, match=r"shape \(2, 4\), got"):
                envs.step(actions)
        flown: list = []
        monkeypatch.setattr("skeye.gym.vector.apply_action", lambda *a: flown.append(a))
        flight = envs.unwrapped.flight
        time_s = flight.time_s
        with pytest.raises(InvalidArgument, match="must be finite"):
            envs.step([[1, 0, 0, 0], [np.nan] * 4])
        assert flight.time_s == time_s and flown == []
        monkeypatch.undo()
        envs.step(np.zeros((2, 4), np.float32))  # flies on
    finally:
        envs.close()


@pytest.mark.parametrize("actions,message", [
    ([[0, 0, 0, 0], [0, 0, 0, 0], [0, np.nan, 0, 0]],
     r"vehicle 2 \(row 2 of the actions\): an action must be finite"),
    ([[0, 0, 0, 0], ["a"] * 4, [0, 0, 0, 0]],
     r"vehicle 1 \(row 1 of the actions\): an action is 4 real numbers"),
])
def test_the_batched_environment_names_the_vehicle_of_a_bad_action_row(
        actions: list, message: str) -> None:
    """A NaN in one row of a (num_envs, 4) batch was refused as 'an action must be finite',
    naming no row: with 16 or 256 vehicles the user could not tell whose action was bad."""
    from skeye.errors import InvalidArgument

    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=3,
                              vectorization_mode="vector_entry_point")
    try:
        envs.reset(seed=0)
        with pytest.raises(InvalidArgument, match=message):
            envs.step(actions)
    finally:
        envs.close()


@pytest.mark.parametrize("env_id,kwargs", [
    ("skeye/Hover-v0", {}),
    ("skeye/PadLanding-v0", {"camera": "ideal"}),
])
def test_a_control_rate_faster_than_the_ins_starts_on_its_first_reading(env_id: str,
                                                                       kwargs: dict) -> None:
    """control_rate_hz 100..1000 (in the documented 0.5..1000) made reset() raise SkeyeError
    'no INS or GroundTruth reading yet': it observed one period (10 ms at 100 Hz) after the
    spawn, before the first reading of the 50 Hz INS. It waits for it, as the pilot's spawn
    does; the episode then runs its steps from there."""
    env = gymnasium.make(env_id, control_rate_hz=200, episode_s=0.1, **kwargs)
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs) and info["sim_time_s"] == 0.0
        ends = [env.step(np.zeros(4, np.float32))[2:4] for _ in range(20)]
        assert ends[-1] == (False, True) and (False, True) not in ends[:-1]
    finally:
        env.close()


def test_the_batched_environment_refuses_a_control_rate_faster_than_the_ins() -> None:
    """It observes a respawned vehicle one control period after its spawn: at 100 Hz that may
    come before the INS's first reading (it raised SkeyeError at reset)."""
    with pytest.raises(ConfigError, match=r"control_rate_hz 100 is faster than robot "
                                          r"hummingbird's INS \(50 Hz\)"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2, control_rate_hz=100,
                           vectorization_mode="vector_entry_point")


@pytest.mark.parametrize("make,own", [
    (lambda **kw: gymnasium.make("skeye/Hover-v0", **kw), ("action", "episode_s", "render_mode")),
    (lambda **kw: gymnasium.make("skeye/PadLanding-v0", **kw),
     ("episode_s", "observation", "image_size", "start_offset_m", "start_height_m",
      "pad_tolerance_m")),
    (lambda **kw: gymnasium.make_vec("skeye/PadLanding-v0", num_envs=2,
                                     vectorization_mode="vector_entry_point", **kw),
     ("episode_s", "image_size", "num_envs", "spacing_m")),
])
def test_an_unknown_option_is_refused_naming_every_option_the_environment_knows(
        make: object, own: tuple[str, ...]) -> None:
    """A misspelt keyword (episodes_s) was answered with a 'known' list of the simulation's
    settings only: episode_s, action, observation, image_size, spacing_m... were missing from
    it, as if they were not options either."""
    with pytest.raises(ConfigError, match=r"unknown option\(s\) \['episodes_s'\] for ") as err:
        make(episodes_s=5)  # type: ignore[operator]
    known = str(err.value).split("known: ")[1].split(", ")
    assert set(own) <= set(known) and {"control_rate_hz", "world"} <= set(known)


@pytest.mark.parametrize("mode", ["sync", "vector_entry_point"])
def test_a_vector_step_before_reset_or_after_close_needs_a_reset(mode: str) -> None:
    """The batched environment raised ConfigError (a bad option's error) where the single one
    and Gymnasium's SyncVectorEnv raise Gymnasium's ResetNeeded."""
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode)
    try:
        with pytest.raises(gymnasium.error.ResetNeeded):
            envs.step(np.zeros((2, 4), np.float32))
        envs.reset(seed=0)
        envs.step(np.zeros((2, 4), np.float32))
    finally:
        envs.close()
    with pytest.raises(gymnasium.error.ResetNeeded):
        envs.step(np.zeros((2, 4), np.float32))


@pytest.mark.parametrize("mode", ["sync", "vector_entry_point"])
def test_max_episode_steps_truncates_each_vehicle_in_every_vectorization_mode(mode: str) -> None:
    """gymnasium.make_vec hands max_episode_steps (its keyword, or the spec's) to a vector entry
    point; the batched environment refused it as an unknown option, where sync and async wrap
    each environment in TimeLimit. It truncates each vehicle's episode as TimeLimit does."""
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode,
                              max_episode_steps=3)
    try:
        envs.reset(seed=0)
        ends = [envs.step(np.zeros((2, 4), np.float32))[3].tolist() for _ in range(8)]
    finally:
        envs.close()
    # the 3rd step truncates, the 4th restarts (next-step autoreset), the 7th truncates again
    assert ends == [[True] * 2 if k in (2, 6) else [False] * 2 for k in range(8)]
    if mode == "vector_entry_point":
        with pytest.raises(ConfigError, match="max_episode_steps must be a whole number"):
            gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode,
                               max_episode_steps=0)
    # -1: gymnasium.make's "no TimeLimit", taken in every mode
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode,
                              max_episode_steps=-1)
    try:
        envs.reset(seed=0)
        assert not any(envs.step(np.zeros((2, 4), np.float32))[3].any() for _ in range(4))
    finally:
        envs.close()


def test_a_robot_without_an_ins_or_ground_truth_is_refused_naming_that(tmp_path) -> None:
    """The observation's pose is the INS's (else GroundTruth's): with neither, reset() raised
    SkeyeError 'no INS or GroundTruth reading yet: step the simulation first'."""
    import re
    from pathlib import Path

    import skeye.robots

    source = (Path(skeye.robots.__file__).parent / "hummingbird.toml").read_text()
    head, *sensors = source.split("[[sensors]]")
    kept = [s for s in sensors if not re.search(r'type = "(INS|GroundTruth)"', s)]
    (tmp_path / "blind.toml").write_text("[[sensors]]".join([head, *kept]))
    options = {"robot": "blind", "robot_dir": tmp_path}
    with pytest.raises(ConfigError, match="mounts no INS nor GroundTruth"):
        gymnasium.make("skeye/Hover-v0", **options)
    with pytest.raises(ConfigError, match="mounts no INS nor GroundTruth"):
        gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode="vector_entry_point",
                           **options)
    # An INS slower than 1 Hz and no GroundTruth: the first reading comes within its period
    # (it was refused as giving none "within 1 s", a review found)
    slow = source.replace('type = "INS"\nname = "INS"\nrate_hz = 50',
                          'type = "INS"\nname = "INS"\nrate_hz = 0.8')
    assert "rate_hz = 0.8" in slow
    head, *sensors = slow.split("[[sensors]]")
    kept = [s for s in sensors if 'type = "GroundTruth"' not in s]
    (tmp_path / "slowins.toml").write_text("[[sensors]]".join([head, *kept]))
    env = gymnasium.make("skeye/Hover-v0", robot="slowins", robot_dir=tmp_path)
    try:
        obs, _ = env.reset(seed=0)
        assert np.all(np.isfinite(obs))
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ["skeye/Hover-v0", "skeye/PadLanding-v0"])
def test_the_info_of_a_crash_out_of_the_area_gives_the_distance_that_ended_it(env_id: str) -> None:
    """Flown out of its 3 m area, the last step's info said ``distance_m`` of the step before
    (inside the area): the crash was judged before the step's distance was recorded."""
    kwargs = {"camera": "ideal", "wind": "none"} if "Pad" in env_id else {}
    env = gymnasium.make(env_id, **kwargs)
    try:
        env.reset(seed=1, options={"start_ned_m": (2.5, 0.0, -1.5), "yaw_rad": 0.0})
        for _ in range(100):  # full speed north, away from the point (or pad) at the origin
            _, _, terminated, truncated, info = env.step(np.array((1, 0, 0, 0), np.float32))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert terminated and info["crash"] == "left the area (3 m)", info
    assert info["distance_m"] > 3.0, info


@pytest.mark.parametrize("mode", ["single", "vector_entry_point"])
def test_a_vehicle_the_simulator_finds_crashed_ends_its_episode(mode: str) -> None:
    """Dropped with its motors at zero thrust, the vehicle hit the ground at about 5 m/s: the
    simulator's crash detector (a hard impact) stopped its motors and refuses its set-points,
    but the task did not see the crash: the episode went on (it bounced, so neither landed nor
    out of its area) and the next step raised the simulator's LocalProtocolError from inside
    step(), the whole batch's in the native vector environment."""
    drop = np.array((0, 0, 0, -1), np.float32)  # attitude: level, no thrust
    if mode == "single":
        env = gymnasium.make("skeye/Hover-v0", action="attitude")
        try:
            env.reset(seed=2)
            for _ in range(60):  # 1.2-1.8 m of free fall takes about 0.6 s: 12 steps
                _, reward, terminated, truncated, info = env.step(drop)
                if terminated or truncated:
                    break
        finally:
            env.close()
        assert terminated and reward == -10.0, info
        assert "hard impact" in info["crash"], info
        return
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, action="attitude",
                              vectorization_mode="vector_entry_point")
    try:
        envs.reset(seed=2)
        hover = np.array((0, 0, 0, 0.0), np.float32)  # about half thrust: stays up a while
        ended = np.zeros(2, dtype=bool)
        for _ in range(30):
            _, rewards, terminated, _, infos = envs.step(np.stack((drop, hover)))
            if terminated[0]:
                ended = terminated
                break
    finally:
        envs.close()
    assert ended[0] and rewards[0] == -10.0 and "hard impact" in infos["crash"][0], infos


def test_the_batched_environment_refuses_reset_options_and_seed_lists_saying_why() -> None:
    """docs/gym.md offered reset options without saying that the native vector environment
    refuses them; a list of seeds (one per environment, as SyncVectorEnv takes) failed in
    Gymnasium's seeding with 'Seed must be a python integer', not saying why."""
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                              vectorization_mode="vector_entry_point")
    try:
        with pytest.raises(ConfigError, match=r"takes no reset options.*own cell.*'sync'"):
            envs.reset(seed=0, options={"yaw_rad": 0.0})
        with pytest.raises(ConfigError, match=r"one world.*got \[1, 2\].*'sync'"):
            envs.reset(seed=[1, 2])
        obs, _ = envs.reset(seed=3)  # one number: fine
        assert obs.shape == (2, 19)
    finally:
        envs.close()


def test_the_batched_environment_says_it_offers_no_partial_reset() -> None:
    """Gymnasium 1.x's vector environments reset only some of their environments given
    options={"reset_mask": ...}; the native one refused that as a reset option that would fix
    the vehicles' starts ('each vehicle starts in its own cell'), which is not what was asked."""
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                              vectorization_mode="vector_entry_point")
    try:
        envs.reset(seed=0)
        with pytest.raises(ConfigError, match=r"no partial reset \(options\['reset_mask'\], got "
                                              r"array.*next step.*'sync'"):
            envs.reset(options={"reset_mask": np.array([True, False])})
    finally:
        envs.close()


def test_the_environments_table_gives_the_starts_and_targets_the_tasks_draw() -> None:
    """docs/gym.md said Hover starts 'within 0.5 m' of its point and GoTo's target is 'up to 4 m
    away horizontally': the tasks draw each of north and east alone within those figures (a
    square), so a Hover start lay up to 0.71 m from the point horizontally and a GoTo target up
    to 5.7 m away. The table now says what is drawn; the draws fill what it says."""
    from pathlib import Path

    from skeye.gym.tasks import GoTo, Hover

    text = (Path(__file__).resolve().parents[2] / "docs" / "gym.md").read_text()
    assert "starting up to 0.5 m north or south and east or west of it and 0.3 m above or " \
           "below it" in text
    assert "to a target up to 4 m north or south and east or west (so up to 5.7 m away " \
           "horizontally), 1-3 m high" in text
    rng = np.random.default_rng(0)
    hover = np.array([Hover().start(rng, (0.0, 0.0, 0.0)).start_ned_m for _ in range(4000)])
    offset = hover - (0.0, 0.0, -1.5)
    assert np.all(np.abs(offset) <= (0.5, 0.5, 0.3))
    assert np.hypot(offset[:, 0], offset[:, 1]).max() > 0.65  # the square's corners
    targets = np.array([GoTo().start(rng, (0.0, 0.0, 0.0)).target_ned_m for _ in range(4000)])
    assert np.all(np.abs(targets[:, :2]) <= 4.0)
    assert np.all((-3.0 <= targets[:, 2]) & (targets[:, 2] <= -1.0))
    assert 5.4 < np.hypot(targets[:, 0], targets[:, 1]).max() <= np.hypot(4.0, 4.0)


def test_sim_time_in_info_is_whole_steps_without_float_noise() -> None:
    """info["sim_time_s"] was the difference of two products steps x dt, and read
    0.15000000000000002 after three 50 ms steps; it is now that many milliseconds exactly,
    as a user comparing it with k * 0.05 written out (0.15) expects."""
    env = gymnasium.make("skeye/Hover-v0", episode_s=1.0)
    try:
        env.reset(seed=0)
        for k in range(1, 9):
            info = env.step(np.zeros(4, np.float32))[4]
            assert info["sim_time_s"] == k * 50 / 1000, (k, info["sim_time_s"])
    finally:
        env.close()


_COPIERS = {
    "pickle": lambda env: pickle.loads(pickle.dumps(env)),
    "cloudpickle": lambda env: cloudpickle.loads(cloudpickle.dumps(env)),  # AsyncVectorEnv's
    "deepcopy": copy.deepcopy,
}


@pytest.mark.parametrize("copier", sorted(_COPIERS))
def test_an_environment_in_flight_copies_as_its_options_as_gymnasiums_mujoco_ones(
        copier: str) -> None:
    """A reset environment (its live simulation: locks, MuJoCo's buffers) could not be
    pickled, cloudpickled or deep-copied (TypeError: cannot pickle memoryview objects, or
    '_thread.lock'). As Gymnasium's own MuJoCo environments (EzPickle), it now copies as its
    constructor's options: a new environment of the same options, not reset (a step needs a
    reset), whose reset(seed=s) flies the original's episode bit for bit; the original flies
    on untouched."""
    env = gymnasium.make("skeye/Hover-v0", episode_s=0.5, sensor_noise=0.5, action="attitude")
    action = np.array([0.1, -0.1, 0.0, 0.0], dtype=np.float32)
    try:
        env.reset(seed=3)
        env.step(action)
        clone = _COPIERS[copier](env)
        try:
            own, twin = env.unwrapped, clone.unwrapped
            assert type(twin) is type(own) and twin is not own and twin.flight is None
            assert twin.settings == own.settings and twin.action_kind == "attitude"
            assert twin.task.episode_s == 0.5
            assert env.step(action)[4]["sim_time_s"] == pytest.approx(0.1)  # flies on
            with pytest.raises(gymnasium.error.ResetNeeded):
                clone.step(action)
            assert _same(_episode(env, 8, 3)[0], _episode(clone, 8, 3)[0])
        finally:
            clone.close()
    finally:
        env.close()


def test_pad_landing_and_the_batched_environment_copy_as_their_options() -> None:
    """PadLanding's own keywords and the batched environment (a reset one: one live world of
    all its vehicles) copy too, each as its constructor's options."""
    pad = skeye.gym.PadLandingEnv(observation="image", image_size=(64, 48), camera="ideal",
                                  start_offset_m=0.2, pad_tolerance_m=0.1, wind="none")
    twin = pickle.loads(pickle.dumps(pad))
    assert twin.observation_space == pad.observation_space
    assert (twin.task.start_offset_m, twin.task.pad_tolerance_m) == (0.2, 0.1)
    assert twin.settings == pad.settings and twin.settings.camera == "ideal"
    envs = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, episode_s=0.5, spacing_m=12.0,
                              vectorization_mode="vector_entry_point")
    try:
        first, _ = envs.reset(seed=4)
        clone = pickle.loads(pickle.dumps(envs))
        try:
            assert clone.flight is None and clone.num_envs == 2 and clone.spacing_m == 12.0
            assert clone.tasks[1].episode_s == 0.5
            with pytest.raises(gymnasium.error.ResetNeeded):
                clone.step(np.zeros((2, 4), np.float32))
            assert np.array_equal(clone.reset(seed=4)[0], first)
        finally:
            clone.close()
    finally:
        envs.close()


def test_a_copy_of_a_made_environment_keeps_its_registration() -> None:
    """A copy was built from the constructor's arguments alone and lost what gymnasium.make
    had set on the environment: its spec (so the copy's spec, its wrappers' and its
    max_episode_steps read None). The copy keeps it."""
    env = gymnasium.make("skeye/Hover-v0", episode_s=2.0, max_episode_steps=7)
    vec = gymnasium.make_vec("skeye/Hover-v0", num_envs=2,
                             vectorization_mode="vector_entry_point")
    try:
        clone = copy.deepcopy(env)
        assert clone.unwrapped.spec == env.unwrapped.spec
        assert clone.spec is not None and clone.spec.id == "skeye/Hover-v0"
        assert clone.spec.max_episode_steps == 7 and clone.spec.kwargs["episode_s"] == 2.0
        assert pickle.loads(pickle.dumps(vec)).spec == vec.spec is not None
    finally:
        env.close()
        vec.close()


def _flight_threads(flight: object) -> list[threading.Thread]:
    """The flight's own threads: its render thread and each vehicle's vision worker."""
    cameras = flight.cameras  # type: ignore[attr-defined]
    workers = [cameras._worker] + [v.vision._worker for v in flight.vehicles.values()  # type: ignore[attr-defined]
                                   if v.vision is not None]
    return [w.thread for w in workers if w is not None]


@pytest.mark.parametrize("mode", ["single", "vector_entry_point"])
def test_an_environment_dropped_without_close_releases_its_flight(mode: str) -> None:
    """An environment dropped without close() (a notebook cell run again, an exception past
    the close) kept its flight for the process's life: its render and vision threads held
    the simulation, MuJoCo's model and the OpenGL contexts (about 165 MB each, pure Python),
    and went on waking. Once the environment is collected its flight is closed: the threads
    end and nothing of the flight is kept."""
    if mode == "single":
        env: Any = gymnasium.make("skeye/PadLanding-v0", camera="ideal")
        env.reset(seed=0)
        env.step(np.zeros(4, np.float32))
    else:
        env = gymnasium.make_vec("skeye/PadLanding-v0", num_envs=1, camera="ideal",
                                 vectorization_mode=mode)
        env.reset(seed=0)
        env.step(np.zeros((1, 4), np.float32))
    flight = env.unwrapped.flight
    threads = _flight_threads(flight)
    assert len(threads) == 2 and all(t.is_alive() for t in threads)
    gone = weakref.ref(flight)
    del env, flight
    gc.collect()
    for thread in threads:
        thread.join(CLOSE_TIMEOUT_S)  # each one's close waits this long at most
    assert not any(t.is_alive() for t in threads)
    gc.collect()
    assert gone() is None


@pytest.mark.parametrize("mode", ["single", "sync", "vector_entry_point"])
def test_reset_after_close_is_refused_naming_it(mode: str) -> None:
    """reset() after close() started a new flight, which the batched environment's next
    close() then left running (Gymnasium's VectorEnv.close does nothing once ``closed``). A
    closed environment now says so at reset() and step(), with Gymnasium's
    ClosedEnvironmentError (as its AsyncVectorEnv does); close() again does nothing."""
    if mode == "single":
        env: Any = gymnasium.make("skeye/Hover-v0")
        action: Any = np.zeros(4, np.float32)
    else:
        env = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode)
        action = np.zeros((2, 4), np.float32)
    env.reset(seed=0)
    env.step(action)
    env.close()
    env.close()  # twice: nothing more
    with pytest.raises(gymnasium.error.ClosedEnvironmentError, match=r"closed \(close\(\)\)"):
        env.reset(seed=0)
    with pytest.raises(gymnasium.error.ClosedEnvironmentError, match=r"closed \(close\(\)\)"):
        env.step(action)
    flights = [env.unwrapped.flight] if mode != "sync" else [e.unwrapped.flight
                                                             for e in env.unwrapped.envs]
    assert flights == [None] * len(flights)


@pytest.mark.parametrize("mode", ["single", "vector_entry_point"])
def test_a_step_cut_short_by_an_exception_needs_a_reset(mode: str) -> None:
    """An exception inside step() (Ctrl-C, a render failure) leaves the period half flown:
    the next step() flew on from there and returned a transition 20 ms longer than a period,
    its reward for the cut period never judged, as if nothing had happened. It now raises
    ResetNeeded naming the cause, and reset() repeats the seeded episode bit for bit."""
    vector = mode != "single"
    if vector:
        env: Any = gymnasium.make_vec("skeye/Hover-v0", num_envs=2, vectorization_mode=mode)
        action: Any = np.zeros((2, 4), np.float32)
    else:
        env = gymnasium.make("skeye/Hover-v0")
        action = np.zeros(4, np.float32)
    try:
        first = [env.reset(seed=3)[0]] + [env.step(action)[0] for _ in range(2)]
        env.reset(seed=3)
        env.step(action)
        sim = env.unwrapped.flight.sim
        period = env.unwrapped.settings.period_steps
        cut_at = sim.steps + period // 2
        fired = threading.Event()

        def interrupt(s: Any) -> None:  # the user's Ctrl-C, half-way through the period
            if s.steps >= cut_at and not fired.is_set():  # (hooks run at the board's ticks)
                fired.set()
                raise KeyboardInterrupt

        sim.step_hooks.append(interrupt)
        with pytest.raises(KeyboardInterrupt):
            env.step(action)
        with pytest.raises(gymnasium.error.ResetNeeded, match="cut short by KeyboardInterrupt"):
            env.step(action)
        again = [env.reset(seed=3)[0]] + [env.step(action)[0] for _ in range(2)]
        assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    finally:
        env.close()


def _record_camera_noise(monkeypatch: pytest.MonkeyPatch) -> dict[tuple[str, int], bytes]:
    """The noise each camera's lens adds to a mid-grey frame in place of each frame it takes,
    by (camera, frame number), with the arguments the renderer gave it (the frames themselves
    are left as they were)."""
    from skeye.sim.lens import Lens
    from skeye.sim.render import ShotRenderer

    add_noise, render = Lens.add_noise, ShotRenderer.render
    noises: dict[tuple[str, int], bytes] = {}
    rendering: list[str] = []  # the camera whose frame the render thread is at

    def recording_render(self: ShotRenderer, state: Any, camera: str, *args: Any) -> Any:
        rendering[:] = [camera]
        return render(self, state, camera, *args)

    def recording_add_noise(self: Lens, image: np.ndarray, frame_number: int, *args: Any,
                            **kwargs: Any) -> np.ndarray:
        grey = np.full_like(image, 128)
        noise = add_noise(self, grey, frame_number, *args, **kwargs).astype(np.int16) - 128
        noises[(rendering[0], frame_number)] = noise.tobytes()
        return add_noise(self, image, frame_number, *args, **kwargs)

    monkeypatch.setattr(ShotRenderer, "render", recording_render)
    monkeypatch.setattr(Lens, "add_noise", recording_add_noise)
    return noises


def test_every_vehicle_and_seed_has_its_own_camera_noise(monkeypatch: pytest.MonkeyPatch) -> None:
    """The webcam's pixel noise was drawn from (noise_seed, frame number) alone: the vehicles of
    the batched environment took the same noise in the same frame, and every reset(seed=s),
    whatever s, the same noise again (so did each environment of a SyncVectorEnv). It now
    follows the flight's seed and the vehicle: a seed still repeats its images bit for bit."""
    noises = _record_camera_noise(monkeypatch)
    envs = gymnasium.make_vec("skeye/PadLanding-v0", num_envs=2,
                              vectorization_mode="vector_entry_point")
    runs = []
    try:
        for seed in (0, 1, 0):
            noises.clear()
            envs.reset(seed=seed)
            for _ in range(4):
                envs.step(np.zeros((2, 4), np.float32))
            runs.append(dict(noises))
    finally:
        envs.close()
    for run in runs:  # no two vehicles share noise
        v0, v1 = "robot:V0:cam:Down", "robot:V1:cam:Down"  # the vehicles' MuJoCo cameras
        both = {n for camera, n in run if camera == v0} & {n for camera, n in run if camera == v1}
        assert both  # frames of the same number, rendered for each vehicle
        for n in both:
            assert run[(v0, n)] != run[(v1, n)]
    assert runs[0] == runs[2]  # the same seed, the same noise
    common = set(runs[0]) & set(runs[1])
    assert common and all(runs[0][k] != runs[1][k] for k in common)  # another seed, other noise
