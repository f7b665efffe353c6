"""A serial-port AscTec client that reads the line the way the ROS AscTec drivers do.

The open-source drivers of the AscTec AutoPilot (CCNY Robotics Lab's ``asctec_drivers``,
``asctec_autopilot/src/serial_interface.cpp``, GPL; this file is written from its description,
not copied) are strict about the line:

- the port is opened ``O_RDWR | O_NOCTTY | O_NDELAY`` and set raw with ``termios`` (8N1, no
  flow control, no echo, VMIN = VTIME = 0), then flushed;
- a poll flushes the line, writes ``>*>p`` + the uint16 mask, and then reads exactly one frame
  per requested bit, back to back: 3 bytes that must be ``>*>``, uint16 length, uint8
  descriptor, the payload, uint16 CRC, 3 bytes that must be ``<#<``; anything else between
  frames fails the poll;
- a CTRL_INPUT flushes, writes ``>*>di`` + the 12-byte structure and reads exactly 5 bytes
  that must be ``>a`` PD ``a<``;
- each read waits a bounded time for its bytes (the driver spins about 650 times on
  ``FIONREAD`` with ``usleep(1)``; here 0.5 s), and a short read is an error.

So a board that interleaves anything unasked, answers a command with a frame where an ack is
expected, or delays a frame's bytes fails here, as it would fail those drivers.
"""

from __future__ import annotations

import os
import select
import struct
import termios
import time

from tests.compat.asctec_client import crc16

POLL_BITS = (0x0001, 0x0002, 0x0004, 0x0008, 0x0010, 0x0080, 0x0100, 0x0200)


class DriverError(AssertionError):
    """The line broke one of the driver's expectations."""


class SerialDriverClient:
    def __init__(self, device: str, wait_s: float = 0.5) -> None:
        self.fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NDELAY)
        cflag, cc = termios.tcgetattr(self.fd)[2], termios.tcgetattr(self.fd)[6]
        iflag = termios.IGNBRK
        oflag = 0
        cflag = (cflag & ~termios.CSIZE) | termios.CS8
        cflag &= ~(termios.PARENB | termios.CRTSCTS | termios.CSTOPB)
        lflag = termios.NOFLSH
        cc[termios.VMIN] = 0
        cc[termios.VTIME] = 0
        speed = termios.B57600
        termios.tcsetattr(self.fd, termios.TCSADRAIN,
                          [iflag, oflag, cflag, lflag, speed, speed, cc])
        termios.tcflush(self.fd, termios.TCIOFLUSH)
        self.wait_s = wait_s

    def close(self) -> None:
        os.close(self.fd)

    def _read_exactly(self, n: int) -> bytes:
        out = b""
        deadline = time.monotonic() + self.wait_s
        while len(out) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DriverError(f"timeout: {len(out)} bytes available, {n} requested")
            ready, _, _ = select.select([self.fd], [], [], left)
            if ready:
                try:
                    out += os.read(self.fd, n - len(out))
                except BlockingIOError:
                    pass
        return out

    def get_packets(self, mask: int) -> dict[int, bytes]:
        """One poll: descriptor -> payload for every requested structure."""
        termios.tcflush(self.fd, termios.TCIOFLUSH)
        os.write(self.fd, b">*>p" + struct.pack("<H", mask))
        packets = {}
        for _ in range(bin(mask).count("1")):
            if self._read_exactly(3) != b">*>":
                raise DriverError("error reading packet header")
            size, pd = struct.unpack("<HB", self._read_exactly(3))
            payload = self._read_exactly(size)
            (crc,) = struct.unpack("<H", self._read_exactly(2))
            if self._read_exactly(3) != b"<#<":
                raise DriverError("packet footer corrupt")
            if crc != crc16(payload):
                raise DriverError(f"bad CRC on descriptor 0x{pd:02x}")
            packets[pd] = payload
        return packets

    def send_control(self, pitch: int, roll: int, yaw: int, thrust: int, ctrl: int) -> int:
        """One CTRL_INPUT; the descriptor the ack names."""
        termios.tcflush(self.fd, termios.TCIOFLUSH)
        chksum = (pitch + roll + yaw + thrust + ctrl + 0xAAAA) & 0xFFFF
        os.write(self.fd, b">*>di" + struct.pack("<5hH", pitch, roll, yaw, thrust, ctrl, chksum))
        data = self._read_exactly(5)
        if data[:2] != b">a" or data[3:] != b"a<":
            raise DriverError(f"corrupt control response {data!r}")
        return data[2]
