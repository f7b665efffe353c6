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
