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


def test_a_controllers_serial_port_held_or_missing_stops_the_pilot_as_unreachable(tmp_path,
                                                                                  capsys):
    """``skeye pilot --airframe mavlink://serial/...`` whose port another program holds (a
    second pilot beside the vehicle's own) or that is not there (the flight controller not
    plugged in, or not enumerated yet at boot): the vehicle cannot be reached, exit status 4,
    as on ``asctec-ll://serial/...`` and as docs/onboard.md says. Until 2026-11-27 it was
    status 2, a bad option, which a supervisor restarting the pilot until the vehicle answers
    takes as a mistake in the command not worth retrying."""
    import os

    from skeye.cli import main
    from skeye.link.transport import open_link

    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)
    first = open_link(f"serial://{path}")  # another program's: an advisory flock
    try:
        for device, said in ((path, "in use by another program"),
                             (str(tmp_path / "ttyACM0"), "No such file")):
            status = main(["pilot", "--airframe", f"mavlink://serial{device}?baud=57600",
                           "--port", "0", "--timeout", "2"])
            err = capsys.readouterr().err
            assert status == 4, err
            assert device in err and said in err, err
    finally:
        first.close()
        os.close(master)


@pytest.mark.parametrize("baud", ["0", "-1", "57600.5", "4000001", "99999999999"])
def test_a_baud_that_is_no_serial_rate_is_a_bad_option(baud, tmp_path, capsys):
    """``mavlink://serial/DEVICE?baud=...`` (and ``--mavlink serial://``) out of 1..4000000
    or not a whole number is a bad option, exit status 2, named before the device is looked
    at, as ``asctec-ll://serial/...?baud=`` is. Until 2026-11-28 0, -1 and 99999999999 were
    handed to the serial port (exit status 4, the vehicle unreachable, "cannot open serial
    /dev/ttyACM0 at 0 baud: ... No such file"), and 57600.5 was "not a number"."""
    from skeye.cli import main

    device = tmp_path / "ttyACM0"  # not there: a baud let through would say so, status 4
    for args in (["--airframe", f"mavlink://serial{device}?baud={baud}"],
                 ["--airframe", "asctec-ll://tcp/127.0.0.1:1",
                  "--mavlink", f"serial://{device}?baud={baud}"]):
        status = main(["pilot", "--port", "0", "--timeout", "2", *args])
        err = capsys.readouterr().err
        assert status == 2, err
        assert f"baud={baud} is not a whole number 1..4000000" in err, err
        assert "No such file" not in err and "Traceback" not in err, err
