"""``sim://HOST:PORT/ROBOT/CAMERA``: a camera of the simulator, from its image server alone.

How this works: the source needs no control connection, so it serves a robot the pilot did
not spawn (the robot ``skeye sim --ll-board`` flies as the hardware in the loop). Two image
clients (docs/protocols/images.md): ``latest`` asks one for the newest frame's META header
alone (``SKEYE INFO``: its number and sim time, 29 bytes on the wire, the frame not rendered
for it), at most every ``probe_interval_s`` of wall time unless the vehicle's clock moved (in
lockstep: every step); ``image()`` fetches the newest whole frame (RAW + META) on the other,
so the vision's worker and the control loop never share a connection. An image server from
before ``SKEYE INFO`` (2026-11-28) answers it with an error frame (``unknown SKEYE command``):
that connection is then probed with a 1x1 sub-rectangle and its META header instead (37 bytes;
it renders the newest frame). A failed request drops its connection (a late frame never
answers a later one) and raises :class:`CameraError`.
:meth:`SimCamera.set_prerender` (off: the pilot's lockstep vision, which takes some of the
frames) makes both connections say ``SKEYE PRERENDER off``, so the simulator renders only
the frames ``image()`` asks for.

Times: frames carry the simulator's time. When the vehicle's clock is the simulator's
(``sim://`` airframe, lockstep ``asctec-ll://``) they pass through; otherwise (a realtime
``asctec-ll://`` flight: the onboard computer's monotonic clock) each is mapped by the offset
``clock - sim time`` seen when the newest frame arrived, the smallest of the last
``OFFSET_WINDOW`` (the smallest is the one least delayed by the line).

A new camera under the URI's name (its robot spawned again, a simulator started again behind
the port) numbers its frames from 1 again: a connection whose frame number goes back, or whose
camera id changes, has met it (each connection's answers come in order, so a late answer on
one never counts). Its frames are announced at once, numbered on after the old camera's (the
vision takes a frame only if its number is above the last), and their times mapped afresh.

Field of view: ``fov_rad=`` / ``fov_deg=`` in the URI (``skeye sim --ll-board`` prints it),
else the pilot's (asked of the simulator on a ``sim://`` airframe), else a calibration file.
"""

from __future__ import annotations

import threading
import time
from collections import deque

from skeye.control.image_client import ImageClient
from skeye.errors import LocalProtocolError, RemoteProtocolError, SkeyeError
from skeye.pilot.camera import (
    CameraError,
    CameraImage,
    CameraOptions,
    FrameInfo,
    check_size,
    fov_option,
)
from skeye.pixels import frame_image
from skeye.uris import port_of, query_of, split_uri
from skeye.wire.images import MetaHeader

OFFSET_WINDOW = 50
_NO_INFO = "unknown SKEYE command"  # an image server's answer to INFO from before it

_Meta = tuple[int, int, float]  # a frame's camera id, number and sim time


def _behind(frame: _Meta, last: _Meta | None) -> bool:
    """True if ``frame`` cannot follow ``last`` from one camera: another camera id, or a
    number or a sim time that went back (a camera's frames count up in both)."""
    return last is not None and (frame[0] != last[0] or frame[1] < last[1]
                                 or frame[2] < last[2])


def parse_sim_camera(uri: str, robot: str = "R1") -> tuple[str, int, str, float | None]:
    """(host, port, ``robot/camera``, fov or None) of a ``sim://`` camera URI.

    Raises:
        LocalProtocolError: naming what is wrong.
    """
    parts = split_uri(uri, "camera", "sim://HOST:PORT/ROBOT/CAMERA")
    port = port_of(parts)
    if parts.scheme.lower() != "sim" or not parts.hostname or port is None:
        raise LocalProtocolError(f"camera {uri!r}: expected sim://HOST:PORT/ROBOT/CAMERA "
                                 "(the image server's address, PORT 0..65535)")
    name = parts.path.strip("/")
    if not name or name.count("/") > 1:
        raise LocalProtocolError(f"camera {uri!r}: expected sim://HOST:PORT/ROBOT/CAMERA or "
                                 "sim://HOST:PORT/CAMERA")
    if "/" not in name:
        name = f"{robot}/{name}"
    query = query_of(uri, parts, "camera")
    unknown = sorted(set(query) - {"fov_deg", "fov_rad"})
    if unknown:
        raise LocalProtocolError(f"camera {uri!r}: unknown option(s) {unknown} (fov_deg, "
                                 "fov_rad)")
    return parts.hostname, port, name, fov_option(uri, query)


class SimCamera:
    """The simulator's camera through its image server (see the module docstring)."""

    def __init__(self, uri: str, host: str, port: int, name: str, options: CameraOptions,
                 fov_h_rad: float | None = None, probe_interval_s: float = 0.005) -> None:
        self.uri = uri
        self.host, self.port, self.name = host, port, name
        self.options = options
        self.fov_h_rad = fov_h_rad if fov_h_rad is not None else options.fov_h_rad
        self.probe_interval_s = probe_interval_s
        self.errors = 0
        self._clients: dict[str, ImageClient | None] = {"probe": None, "image": None}
        self._locks = {"probe": threading.Lock(), "image": threading.Lock()}
        self._latest: FrameInfo | None = None
        self._probed_at = -1e9
        self._probed_vehicle_s = -1e9
        self._offsets: deque[float] = deque(maxlen=OFFSET_WINDOW)
        self._lost: str | None = None
        self._checked = False
        self._prerender = True  # frames rendered ahead of our requests (set_prerender)
        self._no_info: ImageClient | None = None  # a probe connection refused SKEYE INFO
        # Numbering across the cameras met under the name (see the module docstring): the
        # frames of camera run k are announced as base + their own number.
        self._runs_lock = threading.Lock()
        self._run = 0
        self._bases = {0: 0}  # run -> base
        self._newest: _Meta | None = None  # the newest frame of the current run
        self._seen: dict[str, tuple[int, _Meta]] = {}  # which -> (run, its newest frame)

    # -- connections -----------------------------------------------------------------------
    def _client(self, which: str) -> ImageClient:
        client = self._clients[which]
        if client is None:
            client = ImageClient(self.host, self.port, timeout_s=self.options.timeout_s)
            try:
                client.select_camera(self.name)
                client.set_format("raw")
                client.set_meta(True)
                if not self._prerender:
                    client.set_prerender(False)
            except BaseException:
                client.close()
                raise
            self._clients[which] = client
        return client

    def set_prerender(self, on: bool) -> None:
        """Whether the simulator renders this camera's frames ahead of :meth:`image` (on, the
        default) or only the frame each call asks for (off; see the module docstring). The
        connections are made again with the new setting at their next request."""
        on = bool(on)
        if on == self._prerender:
            return
        self._prerender = on
        for which in ("probe", "image"):
            with self._locks[which]:
                self._drop(which)

    def _drop(self, which: str) -> None:
        client = self._clients[which]
        if client is not None:
            client.close()
            self._clients[which] = None

    def _vehicle_time(self, sim_time_s: float, received_s: float | None = None) -> float:
        if self.options.clock_is_sim:
            return sim_time_s
        now = self.options.clock() if received_s is None else received_s
        self._offsets.append(now - sim_time_s)
        return sim_time_s + min(self._offsets)

    def _frame_info(self, which: str, meta: MetaHeader) -> FrameInfo:
        """The frame ``meta`` describes as this source announces it (and the newest known),
        received on connection ``which``; a new camera's first frame starts a new run."""
        frame = (meta.camera_id, meta.frame_number, meta.sim_time_s)
        with self._runs_lock:
            own = self._seen.get(which)
            if own is None:  # this connection's first frame: after the newest either has
                new_camera = _behind(frame, self._newest)
            elif own[0] == self._run:
                new_camera = _behind(frame, own[1])
            elif self._newest is not None and meta.camera_id == own[1][0] != self._newest[0]:
                # the old camera's, answered after the other connection met the new one
                return FrameInfo(self._bases[own[0]] + meta.frame_number,
                                 self._vehicle_time(meta.sim_time_s))
            else:
                new_camera = False  # the other connection met this camera first
            if new_camera:
                self._run += 1
                self._bases[self._run] = self._latest.frame if self._latest is not None else 0
                self._offsets.clear()  # its sim time started again
                self._checked = False
            self._seen[which] = (self._run, frame)
            if new_camera or self._newest is None or meta.frame_number > self._newest[1]:
                self._newest = frame
            number = self._bases[self._run] + meta.frame_number
            known = self._latest
            if known is not None and known.frame == number:
                return known  # the time it was announced with
            info = FrameInfo(number, self._vehicle_time(meta.sim_time_s))
            if known is None or number > known.frame:
                self._latest = info
            return info

    def _failed(self, which: str, exc: BaseException) -> CameraError:
        self._drop(which)
        self.errors += 1
        self._lost = f"camera {self.uri}: {exc}"
        return CameraError(self._lost)

    # -- the source ------------------------------------------------------------------------
    @property
    def latest(self) -> FrameInfo | None:
        now = time.monotonic()
        vehicle_now = self.options.clock()
        with self._locks["probe"]:
            # Asked again at the moment of the last probe (lockstep: the same step): its
            # answer. Looked at under the lock, and the moment noted once the answer is in:
            # until 2026-11-28 the moment was noted as a probe began, and a caller in between
            # (the pilot's loop while its vision's worker probed) got the answer before it,
            # a frame older than the worker's, and the two waited for each other.
            if (now - self._probed_at < self.probe_interval_s
                    and vehicle_now == self._probed_vehicle_s):
                return self._latest
            try:
                meta = self._probe(self._client("probe"))
            except SkeyeError as exc:
                self._failed("probe", exc)
            else:
                self._frame_info("probe", meta)
            self._probed_at, self._probed_vehicle_s = now, vehicle_now
        return self._latest

    def _probe(self, client: ImageClient) -> MetaHeader:
        """The newest frame's META header: ``SKEYE INFO``, or on a server from before it a 1x1
        sub-rectangle's (see the module docstring)."""
        if client is not self._no_info:
            try:
                return client.frame_info()
            except RemoteProtocolError as exc:
                if _NO_INFO not in str(exc):
                    raise
                self._no_info = client  # the error frame was its answer: the connection holds
        meta = client.get_subrect(0, 0, 1, 1).meta
        if meta is None:
            raise CameraError("the image server sent no META header")
        return meta

    def image(self) -> CameraImage:
        with self._locks["image"]:
            try:
                frame = self._client("image").get_frame()
                bgr = frame_image(frame)
            except SkeyeError as exc:
                raise self._failed("image", exc) from exc
        if frame.meta is None:
            raise self._failed("image", CameraError("the image server sent no META header"))
        info = self._frame_info("image", frame.meta)
        if not self._checked:
            try:
                check_size(self.uri, self.options.size_px, bgr.shape[1], bgr.shape[0])
            except CameraError as exc:
                self._lost = str(exc)
                raise
            self._checked = True
        self._lost = None
        return CameraImage(info.frame, info.time_s, bgr)

    @property
    def lost(self) -> str | None:
        return self._lost

    def close(self) -> None:
        for which in ("probe", "image"):
            client = self._clients[which]
            if client is not None:
                client.close()  # wakes a request blocked on it
            with self._locks[which]:
                self._drop(which)


def open_sim_camera(uri: str, options: CameraOptions) -> SimCamera:
    """The ``sim://`` camera source (nothing is connected until the first frame is asked)."""
    host, port, name, fov = parse_sim_camera(uri, options.robot)
    return SimCamera(uri, host, port, name, options, fov)
