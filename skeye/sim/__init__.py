"""The simulator process: MuJoCo world, quadrotor physics, sensors, control and image servers.

Only the simulator lives here (and ``skeye.cli``, which starts it, imports it): clients are in
:mod:`skeye.control`, codecs in :mod:`skeye.wire`, recordings in :mod:`skeye.recording`, robot
class files in :mod:`skeye.robots`. Importing this package has no side effect; the modules that
load MuJoCo import :mod:`skeye.sim.gl` first, which picks the OpenGL backend.
"""
