"""An independent AscTec-style ground station for the conformance tests (plain sockets).

Written from the AscTec SDK (``sdk.h``, the HL processor's ``LL_HL_comm.h`` structures) and the
AutoPilot manual, not from skeye's codec, so that it fails where a real AscTec client would:

- commands: ``>*>p`` + uint16 poll mask; ``>*>di`` + ``WO_CTRL_INPUT`` (int16 pitch, roll,
  yaw, thrust, ctrl; then the 16-bit checksum pitch + roll + yaw + thrust + ctrl + 0xAAAA);
- answers: ``>*>`` uint16 length, uint8 descriptor, payload, uint16 CRC16 of the payload,
  ``<#<``; an accepted command is acknowledged with ``>a`` PD ``a<``;
- structures unpacked with ``struct`` from their C layouts (packed, little endian).
"""

from __future__ import annotations

import socket
import struct
import time

PD_LL_STATUS = 0x02
PD_IMU_CALCDATA = 0x03
PD_CONTROLLER_OUTPUT = 0x11
PD_RC_DATA = 0x15
POLL_LL_STATUS = 0x0001
POLL_IMU_CALCDATA = 0x0004
POLL_RC_DATA = 0x0008
POLL_CONTROLLER_OUTPUT = 0x0010

# LL_STATUS: short battery_voltage_1, battery_voltage_2, status, cpu_load; char compass_enabled,
# chksum_error, flying, motors_on; short flightMode, up_time.
LL_STATUS = struct.Struct("<4h4b2h")
# IMU_CALCDATA: int angle_nick, angle_roll, angle_yaw (1000 = 1 deg); int angvel_nick, _roll,
# _yaw; short acc_x/y/z_calib; short acc_x/y/z; int acc_angle_nick, acc_angle_roll;
# int acc_absolute_value; int Hx, Hy, Hz; int mag_heading; int speed_x, speed_y, speed_z;
# int height; int dheight; int dheight_reference; int height_reference.
IMU_CALCDATA = struct.Struct("<3i3i3h3h2ii3ii3iiiii")
# RC_DATA: unsigned short channels_in[8], channels_out[8]; unsigned char lock.
RC_DATA = struct.Struct("<8H8HB")
# CONTROLLER_OUTPUT: int nick, roll, yaw ("attitude controller outputs; 0..200 = -100..+100 %");
# int thrust ("current thrust (height controller output); 0..200 = 0..100 %").
CONTROLLER_OUTPUT = struct.Struct("<4i")


def crc16(data: bytes) -> int:
    """The SDK's ``crc_update`` over the payload, starting at 0xFF."""
    crc = 0x00FF
    for byte in data:
        d = byte ^ (crc & 0xFF)
        d ^= (d << 4) & 0xFF
        crc = (((d << 8) | (crc >> 8)) ^ (d >> 4) ^ (d << 3)) & 0xFFFF
    return crc


class AscTecClient:
    def __init__(self, port: int, timeout_s: float = 10.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.timeout_s = timeout_s
        self.buf = b""

    def close(self) -> None:
        self.sock.close()

    def ctrl_input(self, pitch: int, roll: int, yaw: int, thrust: int, ctrl: int) -> None:
        """Send WO_CTRL_INPUT and wait for its ack (``>a`` 0x17 ``a<``)."""
        chksum = (pitch + roll + yaw + thrust + ctrl + 0xAAAA) & 0xFFFF
        self.sock.sendall(b">*>di" + struct.pack("<5hH", pitch, roll, yaw, thrust, ctrl, chksum))
        self._read_until(b">a\x17a<")

    def poll(self, mask: int, pd: int) -> bytes:
        """Poll one structure; its payload."""
        self.sock.sendall(b">*>p" + struct.pack("<H", mask))
        deadline = time.monotonic() + self.timeout_s
        while True:
            got_pd, payload = self._frame(deadline)
            if got_pd == pd:
                return payload

    def ll_status(self) -> tuple[int, ...]:
        return LL_STATUS.unpack(self.poll(POLL_LL_STATUS, PD_LL_STATUS))

    def imu_calcdata(self) -> tuple[int, ...]:
        return IMU_CALCDATA.unpack(self.poll(POLL_IMU_CALCDATA, PD_IMU_CALCDATA))

    def rc_data(self) -> tuple[int, ...]:
        return RC_DATA.unpack(self.poll(POLL_RC_DATA, PD_RC_DATA))

    def controller_output(self) -> tuple[int, ...]:
        return CONTROLLER_OUTPUT.unpack(self.poll(POLL_CONTROLLER_OUTPUT, PD_CONTROLLER_OUTPUT))

    # -- reading -----------------------------------------------------------------------------
    def _recv(self, deadline: float) -> None:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("no answer from the vehicle")
        self.sock.settimeout(left)
        chunk = self.sock.recv(65536)
        if not chunk:
            raise ConnectionError("the vehicle closed the link")
        self.buf += chunk

    def _read_until(self, marker: bytes) -> None:
        deadline = time.monotonic() + self.timeout_s
        while marker not in self.buf:
            self._recv(deadline)
        self.buf = self.buf[self.buf.index(marker) + len(marker) :]

    def _frame(self, deadline: float) -> tuple[int, bytes]:
        while True:
            start = self.buf.find(b">*>")
            if start >= 0 and len(self.buf) >= start + 6:
                length, pd = struct.unpack_from("<HB", self.buf, start + 3)
                end = start + 6 + length + 5
                if len(self.buf) >= end:
                    payload = self.buf[start + 6 : start + 6 + length]
                    (crc,) = struct.unpack_from("<H", self.buf, start + 6 + length)
                    assert self.buf[end - 3 : end] == b"<#<", "bad stop string"
                    assert crc == crc16(payload), "bad CRC"
                    self.buf = self.buf[end:]
                    return pd, payload
            self._recv(deadline)
