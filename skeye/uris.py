"""The URIs skeye's seams are chosen by (``tcp://``, ``sim://``, ``asctec-ll://``, ``mavlink://``,
``udp://``, ``rtp://``...): splitting one into its parts, with a clear error for what
:func:`urllib.parse.urlsplit` cannot split.

Why: ``urlsplit`` raises a bare ``ValueError`` for an IPv6 address whose bracket is left open
(``tcp://[::1:7000``), and ``SplitResult.port`` for a port that is no number or over 65535;
each parser of a URI gives the user its own message naming the URI and the form it expects.
"""

from __future__ import annotations

from urllib.parse import SplitResult, urlsplit

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
