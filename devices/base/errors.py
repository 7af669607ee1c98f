"""Typed errors of the mobile base. Each carries the spec's error code when the base sent one.

``devices`` never imports ``fieldapp``, so these do not derive from ``FieldappError``; the
``fieldapp base`` command catches :class:`BaseError` itself.
"""

from __future__ import annotations


class BaseError(Exception):
    """Base of every mobile base error; ``code`` is the spec's error code when the base sent one."""

    def __init__(self, message: str, code: str | None = None) -> None:
        super().__init__(message)
        self.code = code


class BaseOffline(BaseError):
    """No reply within the retry budget: the base, its bridge or the link is down."""


class LinkClosed(BaseError):
    """This client's link was closed (by the application): a request still waiting for its
    reply ends with this, and no later one is sent."""


class BaseAuthRejected(BaseError):
    """The base refused this client's CURVE key (or the security handshake failed)."""


class BaseStopped(BaseError):
    """The stop latch is set (``stop`` or a lost link); ``reset`` then a new ``goto`` is needed."""


class NavigationFailed(BaseError):
    """Navigation gave up on the goal, or refused it."""


class BaseRequestRejected(BaseError):
    """The base answered with an error code (``bad_request``, ``out_of_bounds``, ``busy``...)."""


class InsecureEndpoint(BaseError):
    """A non-loopback address was asked for without CURVE keys."""


class KeyFileError(BaseError):
    """A CURVE key file or folder is missing or malformed."""
