"""Fly a 2 m square at 1.5 m and come back to the start; print how close it got."""

import math
import os

import skeye

with skeye.connect(os.environ.get("SKEYE_SIM", "127.0.0.1:3000")) as sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    start = copter.position()
    with copter.flight(take_off_m=1.5):  # lands on any exit, errors included
        for north_m, east_m in ((2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)):
            copter.fly_to(north_m=north_m, east_m=east_m, altitude_m=1.5)
            print(f"t={sim.time_s:6.2f} s  at {copter.position()}")
    end = copter.position()
    print(f"back on the ground {math.dist(start[:2], end[:2]) * 100:.1f} cm from the start")
