"""Fly a 2 m square at 1.5 m and come back to the start; print how close it got.

The vehicle flies on its own estimate (GPS-aided, as a real one), so it closes the square in
its own belief; the simulator's truth shows how far that belief drifted meanwhile.
"""

import math
import os

import skeye

try:  # no simulator there, or a bad address: said in one line, not a traceback
    sim = skeye.connect(os.environ.get("SKEYE_SIM", "127.0.0.1:3000"))
except skeye.SkeyeError as exc:
    raise SystemExit(f"square: {exc}") from None
with sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    start, start_believed = copter.position(), copter.estimated_position()
    with copter.flight(take_off_m=1.5):  # lands on any exit, errors included
        for north_m, east_m in ((2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)):
            copter.fly_to(north_m=north_m, east_m=east_m, altitude_m=1.5)
            print(f"t={sim.time_s:6.2f} s  at {copter.position()}")
    believed = math.dist(start_believed[:2], copter.estimated_position()[:2])
    true = math.dist(start[:2], copter.position()[:2])
    print(f"landed {believed * 100:.1f} cm from the start by the vehicle's own estimate, "
          f"{true * 100:.1f} cm by the simulator's truth (the difference is the estimate's "
          "drift)")
