"""Small flight logs built from published figures, in each format ``skeye logs`` reads.

No licensed real log ships with skeye, so the tests make their own: an IMU of the EuRoC MAV
dataset's kind (ADIS16448 at 200 Hz, the noise densities of the dataset's own sensor file,
gyro 1.6968e-4 rad/s/sqrt(Hz) and accelerometer 2.0e-3 m/s^2/sqrt(Hz), Kalibr's continuous-time
densities: density x sqrt(200 Hz) per sample), at rest for two
seconds and then hovering with a rotor line (75 Hz) and broadband vibration whose level is
issue 33's measured hover figure (1.1 m/s^2, 0.065 rad/s per axis above 10 Hz), while the
attitude sways (roll 8 deg at 0.2 Hz, pitch 5 deg at 0.13 Hz). Ground truth is the attitude and
position the samples were made from.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

RATE_HZ = 200.0
GYRO_DENSITY = 1.6968e-4
ACCEL_DENSITY = 2.0e-3
VIB_ACCEL = 1.1
VIB_GYRO = 0.065
LINE_HZ = 75.0
REST_S = 2.0
G = 9.81


@dataclass
class Synthetic:
    t_s: np.ndarray
    gyro: np.ndarray  # body FRD, rad/s
    accel: np.ndarray  # body FRD, m/s^2
    quat_ned: np.ndarray  # body -> NED, w x y z
    pos_ned: np.ndarray


def _quat(roll: float, pitch: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    return (cr * cp, sr * cp, cr * sp, -sr * sp)


def synthetic(seconds: float = 40.0, seed: int = 1, vibration: bool = True) -> Synthetic:
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    fly = t >= REST_S
    tau = np.where(fly, t - REST_S, 0.0)
    roll = np.radians(8.0) * np.sin(2 * np.pi * 0.2 * tau)
    pitch = np.radians(5.0) * np.sin(2 * np.pi * 0.13 * tau)
    droll = np.radians(8.0) * 2 * np.pi * 0.2 * np.cos(2 * np.pi * 0.2 * tau) * fly
    dpitch = np.radians(5.0) * 2 * np.pi * 0.13 * np.cos(2 * np.pi * 0.13 * tau) * fly
    # body rates of a roll-pitch (ZYX, yaw 0) attitude
    p = droll - np.sin(pitch) * 0.0
    q = np.cos(roll) * dpitch
    r = -np.sin(roll) * dpitch
    gyro = np.column_stack([p, q, r])
    # specific force in hover (no acceleration): -g along the body's "up" in NED
    accel = np.column_stack([G * np.sin(pitch), -G * np.sin(roll) * np.cos(pitch),
                             -G * np.cos(roll) * np.cos(pitch)])
    # The densities are Kalibr's continuous-time (two-sided) ones, as EuRoC's sensor.yaml
    # gives them: a sample carries density * sqrt(rate) (Kalibr wiki, "IMU Noise Model").
    white = math.sqrt(RATE_HZ)
    gyro += GYRO_DENSITY * white * rng.standard_normal((n, 3))
    accel += ACCEL_DENSITY * white * rng.standard_normal((n, 3))
    if vibration:
        # half the variance in the line, half broadband (white up to Nyquist: 95 % above 10 Hz)
        for data, level in ((accel, VIB_ACCEL), (gyro, VIB_GYRO)):
            amp = level * math.sqrt(0.5) * math.sqrt(2.0)
            phase = rng.uniform(0, 2 * np.pi, 3)
            line = amp * np.sin(2 * np.pi * LINE_HZ * t[:, None] + phase)
            broad = level * math.sqrt(0.5 / 0.95) * rng.standard_normal((n, 3))
            data += (line + broad) * fly[:, None]
    quat = np.array([_quat(a, b) for a, b in zip(roll, pitch, strict=True)])
    pos = np.column_stack([np.zeros(n), np.zeros(n), -1.0 * fly])
    return Synthetic(t, gyro, accel, quat, pos)


def write_euroc(folder: Path, s: Synthetic, t0_ns: int = 1403636579758555392) -> Path:
    """EuRoC layout (mav0/imu0, mav0/state_groundtruth_estimate0). The IMU's axes are the
    body's, its world z is up: the NED quaternion is turned into an ENU one (x north -> east)."""
    imu = folder / "mav0" / "imu0"
    gt = folder / "mav0" / "state_groundtruth_estimate0"
    imu.mkdir(parents=True)
    gt.mkdir(parents=True)
    stamps = t0_ns + np.round(s.t_s * 1e9).astype(np.int64)
    with open(imu / "data.csv", "w") as f:
        f.write("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n")
        for k in range(len(stamps)):
            f.write(f"{stamps[k]},{','.join(f'{v:.9g}' for v in s.gyro[k])},"
                    f"{','.join(f'{v:.9g}' for v in s.accel[k])}\n")
    # ENU world from NED: R_enu = C R_ned with C = [[0,1,0],[1,0,0],[0,0,-1]]
    c = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    with open(gt / "data.csv", "w") as f:
        f.write("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], "
                "q_RS_y [], q_RS_z []\n")
        for k in range(0, len(stamps), 2):
            m = c @ _rows(s.quat_ned[k])
            q = _from_rows(m)
            p = c @ s.pos_ned[k]
            f.write(f"{stamps[k]},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},"
                    f"{q[0]:.9f},{q[1]:.9f},{q[2]:.9f},{q[3]:.9f}\n")
    return folder


def _rows(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _from_rows(m: np.ndarray) -> np.ndarray:
    """A proper rotation matrix's quaternion (w x y z); m here may be improper (an axis swap
    with a flip is a rotation: C has det +1)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return np.array([0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
                         (m[1, 0] - m[0, 1]) / s])
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
    q = np.zeros(4)
    q[0] = (m[k, j] - m[j, k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (m[j, i] + m[i, j]) / s
    q[1 + k] = (m[k, i] + m[i, k]) / s
    return q


def write_ulog(path: Path, s: Synthetic,
               imu_fields: str = "uint64_t timestamp;float[3] gyro_rad;"
                                 "float[3] accelerometer_m_s2", attitude_delay_us: int = 0) -> Path:
    """A minimal ULog (the format PX4 documents: file header, format and subscription
    messages, data): sensor_combined and the ground-truth topics of a PX4 simulation.
    ``imu_fields`` renames sensor_combined's fields (the data keep their layout);
    ``attitude_delay_us`` stamps the attitude that much after the position it was taken with
    (two topics, published apart)."""
    def msg(kind: bytes, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), kind[0]) + payload

    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
    out += msg(b"B", bytes(40))
    formats = {
        "sensor_combined": imu_fields,
        "vehicle_local_position_groundtruth": "uint64_t timestamp;float x;float y;float z",
        "vehicle_attitude_groundtruth": "uint64_t timestamp;float[4] q",
    }
    for name, fields in formats.items():
        out += msg(b"F", f"{name}:{fields};".encode())
    for msg_id, name in enumerate(formats):
        out += msg(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
    for k in range(len(s.t_s)):
        stamp = round(float(s.t_s[k]) * 1e6) + 1_000_000
        out += msg(b"D", struct.pack("<HQ6f", 0, stamp, *s.gyro[k], *s.accel[k]))
        if k % 4 == 0:
            out += msg(b"D", struct.pack("<HQ3f", 1, stamp, *s.pos_ned[k]))
            out += msg(b"D", struct.pack("<HQ4f", 2, stamp + attitude_delay_us,
                                         *s.quat_ned[k]))
    path.write_bytes(bytes(out))
    return path


def write_rosbag(path: Path, s: Synthetic, t0_sec: int = 1000) -> Path:
    """A ROS 1 bag (rosbags' writer): /imu0 (sensor_msgs/Imu) and /vicon (TransformStamped),
    world z up, stamped from ``t0_sec`` seconds (exactly, in whole nanoseconds)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    Imu = ts.types["sensor_msgs/msg/Imu"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    Quaternion = ts.types["geometry_msgs/msg/Quaternion"]
    Transform = ts.types["geometry_msgs/msg/Transform"]
    TransformStamped = ts.types["geometry_msgs/msg/TransformStamped"]
    c = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    zero9 = np.zeros(9)
    with Writer(path) as writer:
        imu_conn = writer.add_connection("/imu0", Imu.__msgtype__, typestore=ts)
        gt_conn = writer.add_connection("/vicon", TransformStamped.__msgtype__, typestore=ts)
        for k in range(len(s.t_s)):
            rel_ns = round(float(s.t_s[k]) * 1e9)
            stamp = Time(sec=t0_sec + rel_ns // 1_000_000_000, nanosec=rel_ns % 1_000_000_000)
            header = Header(seq=k, stamp=stamp, frame_id="imu4")
            g, a = s.gyro[k], s.accel[k]
            msg = Imu(header=header, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                      orientation_covariance=zero9,
                      angular_velocity=Vector3(x=g[0], y=g[1], z=g[2]),
                      angular_velocity_covariance=zero9,
                      linear_acceleration=Vector3(x=a[0], y=a[1], z=a[2]),
                      linear_acceleration_covariance=zero9)
            ns = t0_sec * 1_000_000_000 + rel_ns
            writer.write(imu_conn, ns, ts.serialize_ros1(msg, Imu.__msgtype__))
            if k % 4 == 0:
                q = _from_rows(c @ _rows(s.quat_ned[k]))
                p = c @ s.pos_ned[k]
                tf = TransformStamped(
                    header=header, child_frame_id="body",
                    transform=Transform(translation=Vector3(x=p[0], y=p[1], z=p[2]),
                                        rotation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0])))
                writer.write(gt_conn, ns, ts.serialize_ros1(tf, TransformStamped.__msgtype__))
    return path
