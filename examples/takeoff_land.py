"""Take off to 1 m and land again (the simulator's address comes from $SKEYE_SIM)."""

import os

import skeye

with skeye.connect(os.environ.get("SKEYE_SIM", "127.0.0.1:3000")) as sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    copter.take_off(1.0)
    copter.land()
