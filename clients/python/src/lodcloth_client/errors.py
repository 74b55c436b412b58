"""The exceptions of the client. Every one derives from :class:`LodclothError`
and its message names the problem (the key, the daemon's refusal code, the
timeout)."""

from __future__ import annotations

from typing import Optional

__all__ = [
    "LodclothError",
    "ConnectError",
    "ZenohError",
    "NoReplyError",
    "RefusedError",
    "DecodeError",
    "NoDataError",
]


class LodclothError(Exception):
    """Base class of every error this package raises on purpose."""


class ConnectError(LodclothError):
    """The connect options are inconsistent, or the zenoh session could not be
    opened (e.g. client mode and no router or daemon at the endpoint)."""


class ZenohError(LodclothError):
    """zenoh itself failed (an invalid key expression, a closed session...)."""


class NoReplyError(LodclothError):
    """Nobody answered a query within its timeout.

    Either no daemon is reachable, the instance does not exist on any
    daemon that could answer (a daemon answers an unknown instance with a
    refusal, so this usually means no daemon), the request needs more time
    (an unprepared level is estimated before a switch replies), or, on a
    secured daemon, this client is not one of its operators.
    """

    def __init__(self, key: str, seconds: float, detail: str = ""):
        self.key = key
        self.seconds = seconds
        self.detail = detail
        text = f"no reply to {key} within {seconds:g} s"
        if detail:
            text += f" (zenoh: {detail})"
        text += (
            "; is a daemon running and reachable (and, for switch, control or input on a secured"
            " daemon, are you one of its operators)? An unprepared level may need a longer timeout."
        )
        super().__init__(text)


class RefusedError(LodclothError):
    """The daemon refused the request with a ``lodcloth.v1.Error``.

    ``code`` is the numeric ``Error.Code``, ``code_name`` its name (e.g.
    ``"CODE_UNKNOWN_INSTANCE"``), ``message`` the daemon's explanation and
    ``error`` the decoded message itself.
    """

    def __init__(self, key: str, code: int, code_name: str, message: str, error: Optional[object] = None):
        self.key = key
        self.code = code
        self.code_name = code_name
        self.message = message
        self.error = error
        super().__init__(f"{key} refused: {code_name}: {message}")


class DecodeError(LodclothError):
    """A payload is not the message its key carries (a daemon speaking
    another version of the contract, or a foreign publisher on the key)."""

    def __init__(self, key: str, detail: str):
        self.key = key
        self.detail = detail
        super().__init__(f"undecodable message on {key}: {detail}")


class NoDataError(LodclothError, TimeoutError):
    """Nothing was published on the watched keys within the timeout."""

    def __init__(self, keys: "list[str]", seconds: float, detail: str = ""):
        self.keys = keys
        self.seconds = seconds
        text = f"nothing on {' or '.join(keys)} for {seconds:g} s"
        if detail:
            text += f" ({detail})"
        text += "; is the instance running? (list shows the instances)"
        super().__init__(text)
