"""Every URI skeye is given goes through :mod:`skeye.uris`: one that ``urlsplit`` cannot split
(an IPv6 address whose bracket is left open) or whose port is no number is refused with the
parser's own error naming the URI, never urllib's bare ValueError (a traceback from the
command line: ``skeye ground --vehicle``, ``skeye pilot --airframe/--camera``, ``--rtp-video``,
``--mavlink``, ``skeye link``)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from skeye.errors import ConfigError, LocalProtocolError, SkeyeError
from skeye.ground.video import parse_video_uri
from skeye.link.transport import parse_uri as parse_link_uri
from skeye.mavlink.transport import parse_uri as parse_mavlink_uri
from skeye.pilot.asctec_ll import parse_asctec_ll
from skeye.pilot.camera_file import parse_file_camera
from skeye.pilot.camera_sim import parse_sim_camera
from skeye.pilot.camera_v4l2 import parse_v4l2_uri
from skeye.pilot.mavlink_airframe import open_mavlink_airframe
from skeye.pilot.rtp_video import parse_rtp_uri

PARSERS: list[tuple[str, Callable[[str], object], str, type[SkeyeError]]] = [
    ("link", parse_link_uri, "tcp://{}", LocalProtocolError),
    ("ground video", parse_video_uri, "tcp://{}", LocalProtocolError),
    ("MAVLink link", parse_mavlink_uri, "udpin://{}", ConfigError),
    ("LL airframe", parse_asctec_ll, "asctec-ll://{}", LocalProtocolError),
    ("MAVLink airframe", open_mavlink_airframe, "mavlink://{}", ConfigError),
    ("RTP video", parse_rtp_uri, "rtp://{}", ConfigError),
    ("sim camera", parse_sim_camera, "sim://{}/R1/Down", LocalProtocolError),
    ("v4l2 camera", parse_v4l2_uri, "v4l2://{}/dev/video0", LocalProtocolError),
    ("file camera", parse_file_camera, "file://{}/x.mp4", LocalProtocolError),
]


@pytest.mark.parametrize(("name", "parse", "form", "error"), PARSERS,
                         ids=[p[0] for p in PARSERS])
def test_an_unclosed_ipv6_bracket_is_named(name, parse, form, error) -> None:
    uri = form.format("[::1:5000")
    with pytest.raises(error) as info:
        parse(uri)
    assert uri in str(info.value) and "Invalid IPv6 URL" in str(info.value), info.value


@pytest.mark.parametrize(("name", "parse", "form", "error"),
                         [p for p in PARSERS if p[0] in ("link", "ground video", "MAVLink link",
                                                         "RTP video", "sim camera")],
                         ids=lambda p: p if isinstance(p, str) else "")
def test_a_port_that_is_no_number_is_named(name, parse, form, error) -> None:
    for port in ("abc", "99999"):
        uri = form.format(f"127.0.0.1:{port}")
        with pytest.raises(error) as info:
            parse(uri)
        assert uri in str(info.value), info.value


OPTIONED: list[tuple[str, Callable[[str], object], str, str, type[SkeyeError]]] = [
    ("link", parse_link_uri, "serial:///dev/ttyUSB0?{}", "baud", LocalProtocolError),
    ("MAVLink link", parse_mavlink_uri, "serial:///dev/ttyACM0?{}", "baud", ConfigError),
    ("LL airframe", parse_asctec_ll, "asctec-ll://serial/dev/ttyUSB0?{}", "baud",
     LocalProtocolError),
    ("MAVLink airframe", open_mavlink_airframe, "mavlink://serial/dev/ttyACM0?{}", "baud",
     ConfigError),
    ("sim camera", parse_sim_camera, "sim://127.0.0.1:5003/R1/Down?{}", "fov_deg",
     LocalProtocolError),
    ("v4l2 camera", parse_v4l2_uri, "v4l2:///dev/video0?{}", "fov_deg", LocalProtocolError),
    ("file camera", parse_file_camera, "file:///x.mp4?{}", "fps", LocalProtocolError),
]
VALUES = {"baud": ("57600", "9600"), "fov_deg": ("60", "90"), "fps": ("10", "30")}


@pytest.mark.parametrize(("name", "parse", "form", "key", "error"), OPTIONED,
                         ids=[p[0] for p in OPTIONED])
def test_an_option_given_twice_is_refused_not_the_last_taken(name, parse, form, key,
                                                             error) -> None:
    """``parse_qs`` keeps every value and each parser took the last: a pasted
    ``?baud=57600&baud=9600`` ran at 9600 without a word."""
    first, second = VALUES[key]
    uri = form.format(f"{key}={first}&{key}={second}")
    with pytest.raises(error) as info:
        parse(uri)
    text = str(info.value)
    assert uri in text and "given twice" in text and f"{key}={second}" in text, text


@pytest.mark.parametrize(("name", "parse", "form", "key", "error"), OPTIONED,
                         ids=[p[0] for p in OPTIONED])
def test_an_option_without_a_value_sign_is_refused(name, parse, form, key, error) -> None:
    """``?loop`` (a file camera's ``loop=1`` typed as a flag) was read as blank, so as no
    loop, or dropped unread by the parsers that kept no blank values."""
    uri = form.format(f"{key}={VALUES[key][0]}&loop")
    with pytest.raises(error) as info:
        parse(uri)
    text = str(info.value)
    assert uri in text and "'loop' is not KEY=VALUE" in text, text


def test_a_stray_ampersand_is_passed_over() -> None:
    """``?baud=57600&`` (a pasted URL's trailing &) was taken before options were read
    strictly, and must still be: an empty part is no option."""
    assert parse_link_uri("serial:///dev/ttyUSB0?baud=57600&") == ("serial", "/dev/ttyUSB0",
                                                                   57600)
    assert parse_link_uri("serial:///dev/ttyUSB0?&baud=9600&&")[2] == 9600
