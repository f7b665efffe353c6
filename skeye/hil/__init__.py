"""The simulator as the hardware in the loop: a simulated robot presented as the vehicle's own
boards on a serial line (``skeye sim --ll-board``), so onboard software talks to the simulator
over the very bytes it exchanges with the real vehicle (docs/onboard.md)."""
