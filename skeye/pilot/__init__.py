"""skeye.pilot (see docs/pilot.md)."""
