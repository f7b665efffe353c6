"""Gymnasium environment benchmark: environment steps per second, state and camera observations.

Measures, in one run (docs/gym.md, "Speed"):

- ``skeye/Hover-v0`` (state observation: what the board knows): 1 environment; 16 as the
  native batched vector environment (16 vehicles in one MuJoCo world); 16 in Gymnasium's
  ``SyncVectorEnv`` and ``AsyncVectorEnv``;
- ``skeye/PadLanding-v0`` (camera: the webcam profile rendered every frame at 30 Hz, the
  pilot's pad detector on the newest each step): 1 environment; 16 native; 16 in
  ``SyncVectorEnv``;
- beside them, gym-pybullet-drones' ``HoverAviary`` (its defaults: 240 Hz physics, 30 Hz
  control, kinematic observation), 1 environment and 16 in ``SyncVectorEnv``, run by
  ``--gpd-python``: a Python that has ``gym_pybullet_drones`` installed (it is not on PyPI:
  install its source in a separate virtual environment), in a child process while this one
  waits. Without it, that row says "not measured".

An environment step is one control period: 50 ms of sim time in skeye (its pilot's 20 Hz),
33 ms in HoverAviary (30 Hz), so each row also gives sim seconds per wall second. Each figure
is the best of ``--repeats`` runs (on a shared machine the slower runs measure the
neighbours); the machine's load average is printed before and after, and ratios are taken
inside this run.

Usage: python benchmarks/bench_gym.py [--steps 400] [--camera-steps 40] [--envs 16]
       [--repeats 3] [--gpd-python /path/to/venv/bin/python] [--no-camera]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from skeye.cliargs import positive_int

MAX_ENVS = 256  # skeye.gym.vector.MAX_NUM_ENVS (not imported here: it loads MuJoCo)

GPD_SCRIPT = r"""
import json, sys, time, warnings
warnings.filterwarnings("ignore")
import numpy as np, gymnasium
from gym_pybullet_drones.envs.HoverAviary import HoverAviary
steps, envs, repeats = (int(a) for a in sys.argv[1:4])

def run(env, n, batch):
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    best = 0.0
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(n):
            _, _, term, trunc, _ = env.step(action)
            if batch == 1 and (term or trunc):
                env.reset()
        best = max(best, n * batch / (time.perf_counter() - t))
    return best

one = HoverAviary()
out = {"ctrl_hz": one.CTRL_FREQ, "physics_hz": one.PYB_FREQ, "one": run(one, steps, 1)}
one.close()
vec = gymnasium.vector.SyncVectorEnv([HoverAviary for _ in range(envs)])
out["sync"] = run(vec, max(1, steps // envs), envs)
vec.close()
print(json.dumps(out))
"""


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores"


def reference_loop_ms() -> float:
    """A fixed pure-Python workload (best of 5): a slow moment of the machine shows here."""
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        x = 0.0
        for i in range(300_000):
            x += (i * 0.5) ** 0.5
        best = min(best, time.perf_counter() - start)
    return best * 1000.0


def steps_per_s(make: Callable[[], Any], steps: int, batch: int, repeats: int) -> float:
    """Best env steps per second over ``repeats`` runs of ``steps`` step calls (``batch``
    environment steps each), zero actions, resets where episodes end."""
    env = make()
    try:
        env.reset(seed=0)
        shape = env.action_space.shape
        action = np.zeros(shape, dtype=np.float32)
        best = 0.0
        for _ in range(repeats):
            started = time.perf_counter()
            for _ in range(steps):
                _, _, terminated, truncated, _ = env.step(action)
                if batch == 1 and (terminated or truncated):
                    env.reset()
            best = max(best, steps * batch / (time.perf_counter() - started))
        return best
    finally:
        env.close()


def gpd(python: str | None, steps: int, envs: int, repeats: int) -> dict[str, float] | None:
    if python is None:
        return None
    done = subprocess.run([python, "-c", GPD_SCRIPT, str(steps), str(envs), str(repeats)],
                          capture_output=True, text=True, timeout=3600)
    if done.returncode != 0:
        print(f"gym-pybullet-drones did not run: {done.stderr.strip().splitlines()[-1:]}")
        return None
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def envs_count(text: str) -> int:
    """``--envs``: 1..MAX_ENVS (the native vector environment's most vehicles)."""
    value = positive_int(text)
    if value > MAX_ENVS:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_ENVS} (the native vector "
                                         f"environment's most vehicles), got {text!r}")
    return value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=400,
                        help="step calls per state run")
    parser.add_argument("--camera-steps", type=positive_int, default=40,
                        help="step calls per camera run (one environment)")
    parser.add_argument("--envs", type=envs_count, default=16,
                        help=f"environments per vector run, 1..{MAX_ENVS}")
    parser.add_argument("--repeats", type=positive_int, default=3)
    parser.add_argument("--gpd-python", default=None,
                        help="a Python with gym_pybullet_drones installed (HoverAviary)")
    parser.add_argument("--no-camera", action="store_true", help="skip the camera rows")
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    import gymnasium

    import skeye.gym  # noqa: F401
    from skeye import native

    n = args.envs
    print(f"bench_gym: {load()}; {native.status().describe()}")
    print(f"CPU reference loop before: {reference_loop_ms():.1f} ms (lower = faster machine)")
    rows: list[tuple[str, str, float, float]] = []  # (what, how, steps/s, control period s)

    def add(what: str, how: str, rate: float, period_s: float) -> None:
        rows.append((what, how, rate, period_s))
        print(f"  {what:<34} {how:<34} {rate:9.1f} steps/s  {rate * period_s:7.1f} sim s/s",
              flush=True)

    hover_ref = gpd(args.gpd_python, args.steps, n, args.repeats)
    if hover_ref is not None:
        period = 1.0 / hover_ref["ctrl_hz"]
        add("gym-pybullet-drones HoverAviary", "1 env", hover_ref["one"], period)
        add("gym-pybullet-drones HoverAviary", f"{n} envs, Gymnasium SyncVectorEnv",
            hover_ref["sync"], period)
    else:
        print("  gym-pybullet-drones HoverAviary: not measured (no --gpd-python)")

    def hover() -> Any:
        return gymnasium.make("skeye/Hover-v0")

    vec_steps = max(1, args.steps // n)
    add("skeye Hover-v0 (state)", "1 env", steps_per_s(hover, args.steps, 1, args.repeats), 0.05)
    add("skeye Hover-v0 (state)", f"{n} vehicles, native (one world)",
        steps_per_s(lambda: gymnasium.make_vec("skeye/Hover-v0", num_envs=n,
                                               vectorization_mode="vector_entry_point"),
                    vec_steps, n, args.repeats), 0.05)
    add("skeye Hover-v0 (state)", f"{n} envs, Gymnasium SyncVectorEnv",
        steps_per_s(lambda: gymnasium.vector.SyncVectorEnv([hover] * n), vec_steps, n,
                    args.repeats), 0.05)
    add("skeye Hover-v0 (state)", f"{n} envs, Gymnasium AsyncVectorEnv",
        steps_per_s(lambda: gymnasium.vector.AsyncVectorEnv([hover] * n), vec_steps, n,
                    args.repeats), 0.05)
    if not args.no_camera:
        def landing() -> Any:
            return gymnasium.make("skeye/PadLanding-v0")

        cam_vec = max(1, args.camera_steps // n * 4)
        add("skeye PadLanding-v0 (webcam)", "1 env",
            steps_per_s(landing, args.camera_steps, 1, 1), 0.05)
        add("skeye PadLanding-v0 (webcam)", f"{n} vehicles, native (one world)",
            steps_per_s(lambda: gymnasium.make_vec("skeye/PadLanding-v0", num_envs=n,
                                                   vectorization_mode="vector_entry_point"),
                        cam_vec, n, 1), 0.05)
        add("skeye PadLanding-v0 (webcam)", f"{n} envs, Gymnasium SyncVectorEnv",
            steps_per_s(lambda: gymnasium.vector.SyncVectorEnv([landing] * n), cam_vec, n, 1),
            0.05)
    print(f"CPU reference loop after: {reference_loop_ms():.1f} ms; {load()}")
    if hover_ref is not None:
        ref = hover_ref["one"]
        for what, how, rate, period in rows:
            if what.startswith("skeye Hover"):
                print(f"ratio to HoverAviary (1 env): {how}: {rate / ref:.2f}x steps/s, "
                      f"{rate * period / (ref / hover_ref['ctrl_hz']):.2f}x sim time")


if __name__ == "__main__":
    main()
