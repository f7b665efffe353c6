"""Robot classes as data: the TOML files of the built-in robots and their loader.

The simulator (physics, sensors), the pilot (flight envelope), ground control (limits, camera)
and vision (camera field of view) all read a robot class file, so the files and their
validation live here, outside :mod:`skeye.sim`: :mod:`skeye.robots.config` loads a class by name
or path, :mod:`skeye.robots.params` holds the parameter dataclasses it fills.
"""
