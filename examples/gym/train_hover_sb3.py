"""Learn skeye/Hover-v0 with Stable-Baselines3's PPO (on the CPU), then evaluate the policy.

Stable-Baselines3 is a well-kept PyTorch library of the standard algorithms that takes
Gymnasium environments as they are. It is not a skeye dependency (PyTorch is large): install
PyTorch's CPU-only build first (a plain ``pip install torch`` may fetch a CUDA build of several
GB), then ``pip install 'stable-baselines3>=2.4'`` (docs/gym.md, "Learning a policy").

Run: ``python examples/gym/train_hover_sb3.py [--steps 200000] [--envs 4] [--out hover_ppo]``.
It trains on ``--envs`` environments in worker processes, saves the model, and prints the mean
episode return of the learned policy against holding still (zero velocity) on the same seeds.
:func:`load` gives the saved model back as an ``obs -> action`` function for the environment.
It does not fly ``skeye pilot --policy``: the pilot builds PadLanding-v0's observations (the
pad vector or the camera image), not Hover-v0's (docs/gym.md).
"""

from __future__ import annotations

import argparse
import time

import gymnasium
import numpy as np

import skeye.gym  # noqa: F401  (registers the environments)
from skeye.cliargs import positive_int


def make_hover() -> gymnasium.Env:  # type: ignore[type-arg]
    """One Hover-v0 (a function, so SB3's worker processes can make their own)."""

    return gymnasium.make("skeye/Hover-v0")


def evaluate(act, episodes: int, seed: int) -> float:  # type: ignore[no-untyped-def]
    """Mean return of ``act(obs) -> action`` over seeded Hover-v0 episodes."""
    env = gymnasium.make("skeye/Hover-v0")
    total = 0.0
    try:
        for k in range(episodes):
            obs, _ = env.reset(seed=seed + k)
            done = False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(act(obs))
                total += float(reward)
                done = terminated or truncated
    finally:
        env.close()
    return total / episodes


def load(path: str):  # type: ignore[no-untyped-def]
    """The saved model as an observation -> action function."""
    from stable_baselines3 import PPO

    model = PPO.load(path, device="cpu")
    return lambda obs: model.predict(obs, deterministic=True)[0]



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=200_000)
    parser.add_argument("--envs", type=positive_int, default=4)
    parser.add_argument("--out", default="hover_ppo")
    parser.add_argument("--episodes", type=positive_int, default=5, help="evaluation episodes")
    args = parser.parse_args()  # --help works without Stable-Baselines3
    try:
        from stable_baselines3 import PPO
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        raise SystemExit("train_hover_sb3.py needs Stable-Baselines3, not a skeye dependency: "
                         "install PyTorch's CPU-only build, then "
                         "pip install 'stable-baselines3>=2.4' (docs/gym.md)") from None
    envs = make_vec_env(make_hover, n_envs=args.envs, seed=0,
                        vec_env_cls=SubprocVecEnv if args.envs > 1 else None)
    model = PPO("MlpPolicy", envs, n_steps=512, batch_size=256, device="cpu", seed=0,
                verbose=0)
    started = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    wall = time.perf_counter() - started
    envs.close()
    model.save(args.out)
    learned = evaluate(load(args.out), args.episodes, 1000)
    still = evaluate(lambda obs: np.zeros(4, dtype=np.float32), args.episodes, 1000)
    print(f"PPO, {args.steps} steps on {args.envs} envs in {wall:.0f} s "
          f"({args.steps / wall:.0f} steps/s); mean return over {args.episodes} episodes: "
          f"learned {learned:.1f}, holding still {still:.1f} (best possible 200); "
          f"saved {args.out}.zip")


if __name__ == "__main__":
    main()
