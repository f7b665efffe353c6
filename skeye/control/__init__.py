"""skeye.control (see ARCHITECTURE.md)."""
