"""skeye.ground (see docs/ground.md)."""
