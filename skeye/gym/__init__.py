"""Gymnasium environments on skeye's simulator, with the pilot's sensors, camera and vision.

Importing this package registers (docs/gym.md)::

    skeye/Hover-v0        hold a point; observation: what the board knows
    skeye/GoTo-v0         fly to a target; the same observation
    skeye/PadLanding-v0   land on the pad through the downward camera (webcam profile) and the
                          pilot's own pad detector, under the paper's random force

    import gymnasium
    import skeye.gym  # noqa: F401  (registers the environments)

    env = gymnasium.make("skeye/PadLanding-v0", camera="ideal")
    vec = gymnasium.make_vec("skeye/Hover-v0", num_envs=16,
                             vectorization_mode="vector_entry_point")  # one world, 16 vehicles

``gymnasium.make("skeye.gym:skeye/Hover-v0")`` imports it on the way. Needs the ``gym`` extra
(``pip install skeye[gym]``).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from skeye.gym.envs import EnvironmentClosed, GoToEnv, HoverEnv, PadLandingEnv, SkeyeEnv
from skeye.gym.vector import SkeyeVectorEnv

__all__ = ["ENV_IDS", "EnvironmentClosed", "GoToEnv", "HoverEnv", "PadLandingEnv", "SkeyeEnv",
           "SkeyeVectorEnv"]

ENV_IDS = ("skeye/Hover-v0", "skeye/GoTo-v0", "skeye/PadLanding-v0")

for _id, _name in zip(ENV_IDS, ("HoverEnv", "GoToEnv", "PadLandingEnv"), strict=True):
    if _id not in registry:
        register(
            id=_id,
            entry_point=f"skeye.gym.envs:{_name}",
            vector_entry_point=f"skeye.gym.vector:{_name.replace('Env', 'VectorEnv')}",
            disable_env_checker=False,
        )
