"""skeye.pilot (see ARCHITECTURE.md)."""
