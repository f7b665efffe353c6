"""The URIs skeye's seams are chosen by (``tcp://``, ``sim://``, ``asctec-ll://``, ``mavlink://``,
``udp://``, ``rtp://``...): splitting one into its parts, with a clear error for what
:func:`urllib.parse.urlsplit` cannot split.

Why: ``urlsplit`` raises a bare ``ValueError`` for an IPv6 address whose bracket is left open
(``tcp://[::1:7000``), and ``SplitResult.port`` for a port that is no number or over 65535;
each parser of a URI gives the user its own message naming the URI and the form it expects.
Its options (the query) are read by :func:`query_of`, which refuses what ``parse_qs`` would pass
over in silence: an option given twice (``?baud=57600&baud=9600``: it took the last) and a part
with no ``=`` (``?loop``: read as blank, so as no loop).
"""

from __future__ import annotations

from urllib.parse import SplitResult, parse_qsl, urlsplit

from skeye.errors import LocalProtocolError, SkeyeError


def split_uri(uri: str, what: str, expected: str,
              error: type[SkeyeError] = LocalProtocolError) -> SplitResult:
    """``urlsplit(uri)``; a URI it cannot split raises ``error`` naming ``what`` it was for
    (``"camera"``), the URI and the ``expected`` form."""
    try:
        return urlsplit(uri)
    except ValueError as exc:
        raise error(f"{what} {uri!r}: {exc}; expected {expected}") from None


def url_host(host: str) -> str:
    """``host`` as it goes in a URL: an IPv6 address in brackets."""
    return f"[{host}]" if ":" in host else host


def port_of(parts: SplitResult) -> int | None:
    """The URI's port; None when it has none, or one that is no number or over 65535."""
    try:
        return parts.port
    except ValueError:
        return None


def query_of(uri: str, parts: SplitResult, what: str,
             error: type[SkeyeError] = LocalProtocolError) -> dict[str, list[str]]:
    """The URI's options, ``{key: [value]}`` as ``parse_qs`` gives them with blank values kept
    (``baud=`` is ``[""]``, for its parser to refuse); raises ``error`` naming ``what`` it was
    for and the URI for an option given twice or a part that is not ``key=value`` (an empty
    part, a stray ``&``, is passed over)."""
    given = [part for part in parts.query.split("&") if part]  # a stray & is no option
    try:
        pairs = parse_qsl("&".join(given), keep_blank_values=True, strict_parsing=True)
    except ValueError:
        bad = [part for part in given if "=" not in part]
        raise error(f"{what} {uri!r}: option {bad[0]!r} is not KEY=VALUE") from None
    query: dict[str, list[str]] = {}
    for key, value in pairs:
        if key in query:
            raise error(f"{what} {uri!r}: option {key!r} is given twice "
                        f"({key}={query[key][0]}, {key}={value}): give it once")
        query[key] = [value]
    return query
