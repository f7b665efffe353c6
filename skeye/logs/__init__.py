"""Real flight logs: readers (EuRoC CSV, PX4 ULog, ROS bags) and IMU figures (Allan deviation,
spectrum). ``skeye logs`` (:mod:`skeye.sim.log_replay`) puts them beside the simulated IMU."""
