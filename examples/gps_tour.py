"""A GPS waypoint tour: fly to latitude/longitude points around the pad, then land."""

import os

import skeye

try:  # no simulator there, or a bad address: said in one line, not a traceback
    sim = skeye.connect(os.environ.get("SKEYE_SIM", "127.0.0.1:3000"))
except skeye.SkeyeError as exc:
    raise SystemExit(f"gps_tour: {exc}") from None
with sim:
    copter = sim.spawn("hummingbird", start="Pad1")
    copter.take_off(2.0)
    fix = copter.gps.wait_next()
    if fix.latitude_deg is None or fix.longitude_deg is None:  # a world without GPS (indoor)
        copter.land()
        raise SystemExit(f"gps_tour: no GPS fix ({fix.satellites} satellites): this world has "
                         "no GPS (indoor?); fly it over the pad or the yard")
    print(f"start {fix.latitude_deg:.7f}, {fix.longitude_deg:.7f} ({fix.satellites} satellites)")
    # Waypoints a few metres from the start (1e-5 deg of latitude is about 1.1 m).
    for dlat, dlon in [(+3e-5, 0.0), (+3e-5, +4e-5), (0.0, +4e-5), (0.0, 0.0)]:
        copter.fly_to_gps(fix.latitude_deg + dlat, fix.longitude_deg + dlon, altitude_m=2.0)
        here = copter.gps.wait_next()
        print(f"t={sim.time_s:6.2f} s  GPS {here.latitude_deg:.7f}, {here.longitude_deg:.7f}")
    copter.land()
