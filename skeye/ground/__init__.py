"""skeye.ground (see ARCHITECTURE.md)."""
