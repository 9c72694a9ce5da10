"""Typed errors, one per way a request can fail in docs/protocol.md.

They mirror scp-estimatorctl's exit codes: DaemonUnreachable and ProtocolError are its 2,
RequestError and CommandRefused its 1.
"""


class ScpError(Exception):
    """Base of every error raised by scp_estimator."""


class DaemonUnreachable(ScpError, ConnectionError):
    """No daemon on the socket, no permission to connect, a timeout, or a closed connection."""


class ProtocolError(ScpError):
    """The peer is not scp-estimatord, speaks another protocol major version, or sent garbage."""


class RequestError(ScpError):
    """The daemon answered {"class":"ERROR"}: the request was malformed or not allowed."""

    def __init__(self, message, request=None):
        super().__init__(message)
        self.message = message
        self.request = request


class PermissionDenied(RequestError):
    """A mutating request (reset, excitation, clear-fault) from a peer without the privilege:
    root, the daemon's user, or a member of socket.group."""


class CommandRefused(ScpError):
    """The loop answered an ACK with ok false (e.g. clear-fault while the cause persists)."""

    def __init__(self, reply):
        super().__init__("%s refused: %s" % (reply.get("request", "?"), reply.get("message", "")))
        self.reply = reply
        self.message = reply.get("message", "")
