"""The camera sensor: frame numbers from the control stream, pixels from the image server.

How this works: the simulator announces every rendered frame on the control stream
(``SEN {Type Camera} {Name Down} {Frame n}``); that line updates :class:`CameraSensor` like any
other sensor. The pixels live on the image server (docs/protocols/images.md);
:meth:`CameraSensor.image` asks it for the newest frame of ``<robot>/<camera>`` over one lazily
opened :class:`~skeye.control.image_client.ImageClient` (RAW + META, so the frame number and sim
time come with the pixels). The image client is not thread-safe: one lock serialises its use. A
request that fails in any way (timeout, reset, refused, a server that restarted) drops the
connection, so the next call reconnects and a late frame can never answer a later request;
socket errors are raised as :class:`~skeye.errors.SkeyeError`. A connection the server closed
for idling is replaced once, transparently.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from skeye.control.image_client import ImageClient
from skeye.errors import (
    LinkClosed,
    LinkTimeout,
    LocalProtocolError,
    RemoteProtocolError,
    SkeyeError,
)
from skeye.pixels import frame_image
from skeye.wire.sim_messages import SenCamera

from .sensors import CameraReading, Sensor


@dataclass(frozen=True)
class CameraImage:
    """One camera image: BGR uint8 pixels (H, W, 3), its frame number and sim time."""

    frame: int
    time_s: float
    bgr: np.ndarray


class CameraSensor(Sensor[CameraReading]):
    """A mounted camera. ``latest.frame`` counts rendered frames; :meth:`image` fetches pixels.

    Args:
        name: camera name on the robot (``Down``).
        images: a factory for the image client (None when the connection has no image server).
        robot_name: the robot's name, for the image server's ``robot/camera`` address.
    """

    type_name = "Camera"
    message_class = SenCamera

    def __init__(
        self,
        name: str,
        *,
        images: Callable[[], ImageClient] | None = None,
        robot_name: str = "",
        **kwargs: Any,
    ) -> None:
        super().__init__(name, **kwargs)
        self._images = images
        self._robot_name = robot_name
        self._client: ImageClient | None = None
        self._client_lock = threading.Lock()
        self._closed = False
        self.prerender = True  # frames rendered ahead of this camera's requests (set_prerender)

    def convert(self, message: Any) -> CameraReading:
        s: SenCamera = message
        return CameraReading(s.time_s, s.frame)

    def wait_next(self, timeout_s: float = 5.0) -> CameraReading:
        """:meth:`Sensor.wait_next`; a timeout before any frame names the likely cause."""
        try:
            return super().wait_next(timeout_s)
        except LinkTimeout as exc:
            if self.latest is not None:
                raise
            raise LinkTimeout(f"{exc}, and none before: the simulator announces frames only "
                              "when it serves images (`skeye sim --image-port 5003`)") from None

    def image(self) -> CameraImage:
        """The newest frame of this camera from the image server.

        In lockstep, call it after :meth:`wait_next` (the frame of a step exists once the step
        has returned and its ``SEN`` line arrived).

        Raises:
            LocalProtocolError: the connection was opened without ``images=``.
            RemoteProtocolError / LinkTimeout: the image server refused or did not answer.
        """
        if self._images is None:
            raise LocalProtocolError(
                f"camera {self.name!r}: connect with images='host:port' to fetch pixels"
            )
        with self._client_lock:
            reused = self._client is not None
            try:
                frame = self._fetch()
            except (RemoteProtocolError, LinkClosed) as exc:
                self._drop()
                closed = isinstance(exc, LinkClosed) or "closed" in str(exc)
                if not (reused and closed) or self._closed:  # close() ended it: no retry
                    raise _as_skeye(self.name, exc) from exc
                # The server closed a connection that sat idle (its --idle-timeout): once more,
                # on a fresh one.
                try:
                    frame = self._fetch()
                except SkeyeError as exc2:
                    self._drop()
                    raise _as_skeye(self.name, exc2) from exc2
            except SkeyeError:
                self._drop()  # e.g. a timeout: a late frame must not answer the next request
                raise
        bgr = frame_image(frame)
        if frame.meta is None:
            latest = self.latest
            number, time_s = (latest.frame, latest.time_s) if latest else (0, 0.0)
        else:
            number, time_s = frame.meta.frame_number, frame.meta.sim_time_s
        return CameraImage(number, time_s, bgr)

    def _fetch(self) -> Any:
        """The newest frame over the current connection, opening one if needed (lock held)."""
        assert self._images is not None
        if self._closed:
            raise LinkClosed(f"camera {self.name!r}: closed")
        if self._client is None:
            client = self._images()
            try:
                client.select_camera(f"{self._robot_name}/{self.name}")
                client.set_format("raw")
                client.set_meta(True)
                if not self.prerender:
                    client.set_prerender(False)
            except BaseException:
                client.close()
                raise
            self._client = client
        return self._client.get_frame()

    def set_prerender(self, on: bool) -> None:
        """Whether the simulator renders this camera's frames ahead of :meth:`image` (on, the
        default) or only the frame each call asks for (off: the call waits for that render).
        Off suits a lockstep client that takes some of the frames, as the pilot's vision does:
        the others cost no render. In lockstep the pixels of a frame are the same either way,
        but an auto-exposing camera meters only the frames rendered (docs/camera.md,
        "Auto-exposure"), so the frames after a skipped one may be exposed a little
        differently. It takes effect from the next request (on a fresh connection)."""
        with self._client_lock:
            if self.prerender != bool(on):
                self.prerender = bool(on)
                self._drop()

    def _drop(self) -> None:
        """Close the connection: its state is unknown (a frame may still be on its way)."""
        if self._client is not None:
            self._client.close()
            self._client = None

    def close(self) -> None:
        """Close the image-server connection (idempotent). A request blocked on it (on another
        thread) is woken at once: it fails, instead of holding the lock until its timeout, and
        is not retried on a new connection (before 2026-11-27 it was, and a frozen image server
        held ``close()`` for the whole timeout). :meth:`image` fails from now on."""
        self._closed = True
        client = self._client
        if client is not None:
            client.close()
        with self._client_lock:
            if self._client is not None:
                self._client.close()
                self._client = None


def _as_skeye(camera: str, exc: BaseException) -> SkeyeError:
    if isinstance(exc, SkeyeError):
        return exc
    return SkeyeError(f"camera {camera!r}: image server: {exc}")
