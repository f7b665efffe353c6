"""Onboard estimator benchmark: the board's estimate against ground truth.

Flies a Hummingbird for ``--sim-seconds`` (default 60) in four runs, stepped in this process:
hovering and in motion (a 2 m square of 0.5 m/s legs, 4 s each, well inside the indoor room;
USARSim velocity DRIVE), indoors (no GPS: optical flow + sonar) and outdoors (the pad world:
GPS as well). Every 0.1 s it
compares the board's estimate (what the INS stream reports and the controller flies on) with
ground truth, and prints per run: RMS roll/pitch error and RMS yaw error (deg), RMS height
error (m), RMS horizontal velocity error (m/s), the horizontal position error at the end
expressed per minute (estimate drift, m/min), and how far the vehicle itself wandered from
where it was told to hover (true drift, m/min; hover runs only).

Published figures the numbers should resemble (printed with them):

- optical-flow hover drift of a PX4 vehicle (EKF2 with flow and a rangefinder): "roughly
  1 meter per minute", https://discuss.px4.io/t/uav-drifts-away-when-hovering-based-on-optical-flow/28601
- GPS position hold: u-blox NEO-M8N horizontal accuracy 2.5 m CEP (u-blox NEO-M8 data sheet,
  UBX-15031086), so metres of wander, not centimetres;
- attitude: MEMS AHRS static roll/pitch accuracy 0.5 deg, heading 2 deg (VectorNav VN-100
  data sheet);
- height: SRF10 sonar resolution 1 cm (Devantech SRF10 technical specification).

The estimator also states its own accuracy (the 1-sigma of its covariance, SEN INS
``PositionSigma``, shown on the ground page as the estimate's "±"). The last two columns test
that statement: the horizontal error divided by the stated horizontal 1-sigma (DRMS,
sqrt(var_n + var_e)), median and 95th percentile. For an honest (consistent) estimator
whose error is a circular Gaussian these are 0.83 and 1.73; larger means the estimator
believes itself better than it is. A last run stands landed and disarmed (the at-rest updates).
Outdoors the pilot states more than the filter's figure (NAV_STATUS, the page's "±"): the GPS
receiver's own accuracy (2.5 m CEP, 3.0 m DRMS) is added to it, since the filter takes the
receiver's wandering error for white noise; the "stated" columns divide by that.

Usage: python benchmarks/bench_estimator.py [--sim-seconds 60] [--seed 1]
"""

from __future__ import annotations

import argparse
import math
import time

from skeye import native
from skeye.cliargs import float_at_least, seed
from skeye.pilot.telemetry import GPS_DRMS_M
from skeye.sim.engine import Simulation
from skeye.sim.world import load_world

PUBLISHED = {
    "indoor": "PX4 optical-flow hover drift ~1 m/min (discuss.px4.io t/28601)",
    "pad": "GPS hold: NEO-M8N 2.5 m CEP; metres of wander",
}
LEGS = ((0.5, 0.0), (0.0, 0.5), (-0.5, 0.0), (0.0, -0.5))  # forward, right m/s; 4 s each


def _angle(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


# err / DRMS of a circular 2-D Gaussian: P(r <= k DRMS) = 1 - exp(-k^2), so the median is
# sqrt(ln 2) and the 95th percentile sqrt(ln 20).
CONSISTENT = (math.sqrt(math.log(2.0)), math.sqrt(math.log(20.0)))


SAMPLE_S = 0.1  # sim seconds between two comparisons with the truth


# --sim-seconds: at least one comparison (a shorter run compared nothing)
sim_seconds = float_at_least(SAMPLE_S, "one comparison with the truth")


def run(world: str, moving: bool, sim_seconds: float, seed: int,
        landed: bool = False) -> dict[str, float]:
    sim = Simulation(load_world(world), seed=seed, estimator="onboard")
    robot = sim.spawn("hummingbird", name="R1", sink=lambda events: None,
                      location_ned_m=(0.0, 0.0, 0.0 if landed else -1.5))
    assert robot.estimator is not None
    sim.step(2000)  # settle after the spawn
    ratios: list[float] = []
    stated: list[float] = []  # by what the pilot states (with the receiver's accuracy)
    has_gps = load_world(world).geo_origin is not None
    start = sim.body_state("R1").pos_ned_m
    sums = {"rp": 0.0, "yaw": 0.0, "h": 0.0, "v": 0.0}
    n = 0
    steps = round(sim_seconds * 10)
    for k in range(steps):
        if moving and k % 40 == 0:
            fwd, right = LEGS[(k // 40) % 4]
            robot.drive(forward_m_s=fwd, right_m_s=right)
        sim.step(100)
        s = sim.body_state("R1")
        e = robot.estimator.estimate()
        sums["rp"] += (_angle(e.rpy_rad[0] - s.rpy_rad[0]) ** 2
                       + _angle(e.rpy_rad[1] - s.rpy_rad[1]) ** 2) / 2
        sums["yaw"] += _angle(e.rpy_rad[2] - s.rpy_rad[2]) ** 2
        sums["h"] += (e.pos_ned_m[2] - s.pos_ned_m[2]) ** 2
        sums["v"] += ((e.vel_ned_m_s[0] - s.vel_ned_m_s[0]) ** 2
                      + (e.vel_ned_m_s[1] - s.vel_ned_m_s[1]) ** 2)
        if e.pos_sigma_ned_m is not None:
            drms = math.hypot(e.pos_sigma_ned_m[0], e.pos_sigma_ned_m[1])
            err = math.hypot(e.pos_ned_m[0] - s.pos_ned_m[0], e.pos_ned_m[1] - s.pos_ned_m[1])
            ratios.append(err / drms)
            said = math.hypot(drms, GPS_DRMS_M) if has_gps else drms
            stated.append(err / said)
        n += 1
    s = sim.body_state("R1")
    e = robot.estimator.estimate()
    minutes = sim_seconds / 60.0
    return {
        "rp_deg": math.degrees(math.sqrt(sums["rp"] / n)),
        "yaw_deg": math.degrees(math.sqrt(sums["yaw"] / n)),
        "h_m": math.sqrt(sums["h"] / n),
        "v_m_s": math.sqrt(sums["v"] / n),
        "pos_m_min": math.hypot(e.pos_ned_m[0] - s.pos_ned_m[0],
                                e.pos_ned_m[1] - s.pos_ned_m[1]) / minutes,
        "true_m_min": math.hypot(s.pos_ned_m[0] - start[0], s.pos_ned_m[1] - start[1]) / minutes,
        "ratio_p50": _quantile(ratios, 0.5),
        "ratio_p95": _quantile(ratios, 0.95),
        "stated_p50": _quantile(stated, 0.5),
        "stated_p95": _quantile(stated, 0.95),
    }


def _quantile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sim-seconds", type=sim_seconds, default=60.0)
    parser.add_argument("--seed", type=seed, default=1)
    args = parser.parse_args()
    print(f"bench_estimator: {native.status().describe()}; {args.sim_seconds:g} s per run, "
          f"seed {args.seed}")
    print(f"{'run':<18}{'roll/pitch':>11}{'yaw':>7}{'height':>8}{'vel':>7}{'est drift':>11}"
          f"{'true drift':>12}{'err/sigma':>11}{'':>6}{'err/stated':>11}{'':>6}  wall")
    print(f"{'':<18}{'deg RMS':>11}{'deg':>7}{'m RMS':>8}{'m/s':>7}{'m/min':>11}{'m/min':>12}"
          f"{'p50':>11}{'p95':>6}{'p50':>11}{'p95':>6}")
    for world in ("indoor", "pad"):
        for moving, landed in ((False, False), (True, False), (False, True)):
            t0 = time.perf_counter()
            r = run(world, moving, args.sim_seconds, args.seed, landed=landed)
            wall = time.perf_counter() - t0
            name = f"{world} {'moving' if moving else 'landed' if landed else 'hover'}"
            true = f"{r['true_m_min']:12.2f}" if not moving else f"{'-':>12}"
            print(f"{name:<18}{r['rp_deg']:11.2f}{r['yaw_deg']:7.2f}{r['h_m']:8.3f}"
                  f"{r['v_m_s']:7.3f}{r['pos_m_min']:11.2f}{true}{r['ratio_p50']:11.2f}"
                  f"{r['ratio_p95']:6.2f}{r['stated_p50']:11.2f}{r['stated_p95']:6.2f}"
                  f"  {wall:.1f} s")
        print(f"  published: {PUBLISHED[world]}")
    print(f"  err/sigma of an honest estimator: p50 {CONSISTENT[0]:.2f}, p95 {CONSISTENT[1]:.2f}")
    print("  published: MEMS AHRS 0.5 deg roll/pitch, 2 deg heading (VN-100); "
          "SRF10 sonar 1 cm resolution")


if __name__ == "__main__":
    main()
