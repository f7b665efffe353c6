"""``mavlink://`` airframe URIs: every option is used or refused, never dropped.

The companion's ``udpout`` link sends from 127.0.0.1 unless its URI says ``?bind=ADDR``
(docs/protocols/mavlink.md), so a flight controller on another machine (a Pixhawk's Ethernet
port) is reachable only with it; the option was dropped, as was any option but a serial line's
baud, and a typo (``speed=`` for ``baud=``) ended as "no flight controller" after the whole
``--timeout``. The controller here is a pymavlink script on loopback.
"""

from __future__ import annotations

import threading
import time

import pytest
from pymavlink import mavutil

from skeye.errors import ConfigError
from skeye.pilot.mavlink_airframe import open_mavlink_airframe
from tests.mavlink.conftest import free_udp_port
from tests.mavlink.test_airframe_ready import send_telemetry


def test_udpout_sends_from_the_address_its_bind_option_names():
    """127.0.0.2 is loopback too (127.0.0.0/8), so the controller can tell which address the
    companion's link was bound to: the one the URI names, not the default 127.0.0.1."""
    port = free_udp_port()
    controller = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1,
                                            source_component=1)
    senders: set[str] = set()
    stop = threading.Event()

    def serve() -> None:
        boot_ms = 0
        while not stop.is_set():
            controller.recv_match(blocking=True, timeout=0.05)
            senders.update(address[0] for address in controller.clients)
            if not senders:
                continue  # udpin sends to those it heard from: none yet
            boot_ms += 50
            send_telemetry(controller.mav, boot_ms, 11_800)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        airframe = open_mavlink_airframe(f"mavlink://udpout/127.0.0.1:{port}?bind=127.0.0.2",
                                         wait_s=10.0)
        airframe.close()
    finally:
        stop.set()
        thread.join(5.0)
        controller.close()
    assert senders == {"127.0.0.2"}, senders


@pytest.mark.parametrize(("uri", "named"), [
    ("mavlink://serial/dev/ttyACM0?speed=921600", "speed"),
    ("mavlink://udp/127.0.0.1:{port}?baud=921600", "baud"),
    ("mavlink://udp/127.0.0.1:{port}?bind=127.0.0.2", "bind"),
    ("mavlink://tcp/127.0.0.1:{port}?bind=127.0.0.2", "bind"),
    ("mavlink://udpout/127.0.0.1:{port}?baud=57600", "baud"),
    ("mavlink://udp/127.0.0.1:{port}/extra", "/extra"),
    ("mavlink://tcp/127.0.0.1:{port}/extra", "/extra"),
])
def test_an_option_or_part_the_link_does_not_take_is_refused_before_it_opens(uri, named):
    """Refused at once, naming it (a listening udp link with nothing on it would otherwise
    wait out ``wait_s`` and say no controller answered)."""
    uri = uri.format(port=free_udp_port())
    started = time.monotonic()
    with pytest.raises(ConfigError) as info:
        open_mavlink_airframe(uri, wait_s=5.0)
    assert uri in str(info.value) and named in str(info.value), info.value
    assert time.monotonic() - started < 1.0, "refused only after waiting for a controller"
