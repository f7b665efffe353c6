"""A scripted controller that solves skeye/PadLanding-v0: the pilot's own pad-landing law.

The policy (:class:`ScriptedLander`) is what ``skeye pilot`` does in PAD_MODE LAND, written as
an observation -> action function: it places each new pad detection in the onboard estimate's
world frame with the pose at the frame's capture (skeye.pilot.pad_track), predicts the pad's
offset to now, and flies the pilot's pad-hold law (skeye.pilot.pad_hold) on it; once the law
commits to the touchdown it descends straight down holding its position, as the vehicle's own
landing does. The same class flies the real pilot::

    PYTHONPATH=examples/gym skeye pilot --images 127.0.0.1:5003 \\
        --policy pad_landing_scripted:ScriptedLander

Run: ``python examples/gym/pad_landing_scripted.py [--episodes 20] [--seed 0] [--camera
webcam|ideal]``; it prints one line per episode and the success rate (docs/gym.md).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import gymnasium
import numpy as np

import skeye.gym  # noqa: F401  (registers the environments)
from skeye.cliargs import positive_int, seed
from skeye.pilot.pad_hold import PadHoldLaw, PadHoldParams
from skeye.pilot.pad_track import PadFix, Pose, PoseHistory, locate_pad, offset_now

LAND_SPEED_M_S = 0.4  # the control interface's landing (skeye.control.motion.MotionConfig)
HOLD_GAIN = 1.0  # (m/s) per m: holding the position while it lands


class ScriptedLander:
    """Observation ("pad" or "image" kind) -> velocity action in [-1, 1]^4."""

    def __init__(self, period_s: float = 0.05, max_speed_m_s: float = 3.0,
                 max_climb_m_s: float = 1.5) -> None:
        self.period_s = period_s
        self.max_speed_m_s = max_speed_m_s
        self.max_climb_m_s = max_climb_m_s
        self.reset()

    def reset(self) -> None:
        self.law = PadHoldLaw(PadHoldParams())
        self.history = PoseHistory(2.0)
        self.time_s = -self.period_s
        self.fix: PadFix | None = None
        self.newest_capture_s = -math.inf
        self.missed_since_s: float | None = None
        self.hold_at: tuple[float, float] | None = None  # committed: land here

    def __call__(self, obs: object) -> np.ndarray:
        state = obs["state"] if isinstance(obs, dict) else obs
        n, e, d, _, _, _, roll, pitch, yaw = (float(v) for v in state[:9])
        landed = float(state[15]) > 0.5
        found, forward, right, height, _, age = (float(v) for v in state[16:22])
        self.time_s += self.period_s
        now = Pose(self.time_s, n, e, d, roll, pitch, yaw)
        self.history.add(now)
        if age >= 0.0 and self.time_s - age > self.newest_capture_s + 1e-6:
            capture_s = self.time_s - age  # a detection (or a miss) not seen before
            self.newest_capture_s = capture_s
            then = self.history.at(capture_s)
            if found and then is not None:
                self.fix = locate_pad(forward, right, height, then)
                self.missed_since_s = None
            elif not found and self.missed_since_s is None:
                self.missed_since_s = capture_s
        if landed and self.hold_at is not None:
            # On the ground: straight down and nothing else, so the board stops the motors
            # after its second on the ground (a horizontal set-point would arm it again).
            return self._action(0.0, 0.0, -LAND_SPEED_M_S)
        if self.hold_at is not None:
            return self._land(now)
        fix = self.fix
        seen = fix is not None and (self.missed_since_s is None
                                    or self.newest_capture_s - fix.capture_s
                                    < self.law.p.lost_after_s)
        if fix is not None and seen:
            f, r, h = offset_now(fix, now)
            sp = self.law.update(self.time_s, True, f, r, h, landing=True, altitude_m=-d)
        else:
            sp = self.law.update(self.time_s, False, landing=True, altitude_m=-d)
        if sp.touchdown:
            self.hold_at = (n, e)
            return self._land(now)
        return self._action(sp.forward_m_s, sp.right_m_s, sp.up_m_s)

    def _land(self, now: Pose) -> np.ndarray:
        assert self.hold_at is not None
        dn, de = self.hold_at[0] - now.north_m, self.hold_at[1] - now.east_m
        c, s = math.cos(now.yaw_rad), math.sin(now.yaw_rad)
        return self._action(HOLD_GAIN * (c * dn + s * de), HOLD_GAIN * (-s * dn + c * de),
                            -LAND_SPEED_M_S)

    def _action(self, forward: float, right: float, up: float) -> np.ndarray:
        return np.array((forward / self.max_speed_m_s, right / self.max_speed_m_s,
                         up / self.max_climb_m_s, 0.0), dtype=np.float32)


def fly(episodes: int, seed: int, on_result: Callable[[dict[str, object]], None] | None = None,
        **env_kwargs: object) -> list[dict[str, object]]:
    """Fly ``episodes`` seeded episodes; one result per episode, each also given to
    ``on_result`` as soon as its episode ends."""
    env = gymnasium.make("skeye/PadLanding-v0", **env_kwargs)
    lander = ScriptedLander(1.0 / float(env.unwrapped.settings.control_rate_hz))  # type: ignore[attr-defined]
    results = []
    try:
        for k in range(episodes):
            obs, info = env.reset(seed=seed + k)
            lander.reset()
            done, steps = False, 0
            while not done:
                obs, _, terminated, truncated, info = env.step(lander(obs))
                done, steps = terminated or truncated, steps + 1
            results.append({"seed": seed + k, "success": bool(info.get("success", False)),
                            "error_m": info.get("touchdown_error_m"), "crash": info.get("crash"),
                            "time_s": info["sim_time_s"], "truncated": truncated})
            if on_result is not None:
                on_result(results[-1])
    finally:
        env.close()
    return results



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=positive_int, default=20)
    parser.add_argument("--seed", type=seed, default=0)
    parser.add_argument("--camera", default="webcam", choices=("webcam", "ideal"))
    parser.add_argument("--estimator", default="onboard", choices=("onboard", "truth"))
    args = parser.parse_args()
    started = time.perf_counter()
    results: list[dict[str, object]] = []

    def show(r: dict[str, object]) -> None:  # each episode's line as it ends
        results.append(r)
        error = "-" if r["error_m"] is None else f"{100 * float(r['error_m']):.1f} cm"  # type: ignore[arg-type]
        print(f"seed {r['seed']}: {'landed on the pad' if r['success'] else 'FAILED'} "
              f"(touchdown error {error}, {float(r['time_s']):.1f} s sim"  # type: ignore[arg-type]
              f"{', ' + str(r['crash']) if r['crash'] else ''}"
              f"{', out of time' if r['truncated'] else ''})", flush=True)

    interrupted = False
    try:
        fly(args.episodes, args.seed, on_result=show, camera=args.camera,
            estimator=args.estimator)
    except KeyboardInterrupt:  # Ctrl-C: the episodes flown so far are still counted
        if not results:
            raise SystemExit("pad_landing_scripted: interrupted before the first episode "
                             "ended") from None
        interrupted = True
        print(f"interrupted after {len(results)} of {args.episodes} episodes")
    landed = sum(1 for r in results if r["success"])
    print(f"landed on the pad in {landed} of {len(results)} episodes "
          f"({100.0 * landed / len(results):.0f} %); camera {args.camera}, estimator "
          f"{args.estimator}; {time.perf_counter() - started:.0f} s wall")
    if interrupted:
        raise SystemExit(130)  # as a shell reports a Ctrl-C


if __name__ == "__main__":
    main()
