"""The socket client: connect, check the VERSION greeting, exchange JSON lines (docs/protocol.md)."""

import json
import os
import socket
import time
from collections import deque

from .errors import (
    CommandRefused,
    DaemonUnreachable,
    PermissionDenied,
    ProtocolError,
    RequestError,
)

DEFAULT_SOCKET = "/run/scp-estimator/scp-estimator.sock"
PROTO_MAJOR = 1
_MAX_LINE = 1 << 20  # replies are a few kB; a megabyte without a newline is not the daemon


class Client:
    """A connection to scp-estimatord.

    socket_path defaults to $SCP_ESTIMATOR_SOCKET, else /run/scp-estimator/scp-estimator.sock.
    timeout is how long any single answer may take, in seconds (a watch stream waits at least
    three periods). Use it as a context manager, or call close().
    """

    def __init__(self, socket_path=None, timeout=5.0):
        self.path = socket_path or os.environ.get("SCP_ESTIMATOR_SOCKET") or DEFAULT_SOCKET
        self.timeout = timeout
        self._buffer = b""
        self._stream = deque()  # ESTIMATEs of a watch that arrived while waiting for a reply
        self._watching = False
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.settimeout(timeout)
        try:
            self._sock.connect(self.path)
        except OSError as error:
            self._sock.close()
            hint = ""
            if isinstance(error, (FileNotFoundError, ConnectionRefusedError)):
                hint = " - is scp-estimatord running? (systemctl status scp-estimatord)"
            elif isinstance(error, PermissionError):
                hint = " - the socket belongs to the daemon's group; join it (usermod -aG)"
            raise DaemonUnreachable("cannot connect to %s: %s%s" % (self.path, error, hint)) from error
        self.version = self._read_object(timeout)
        if self.version.get("class") != "VERSION":
            self.close()
            raise ProtocolError("%s did not greet with a VERSION object; is it scp-estimatord's "
                                "socket?" % self.path)
        if self.version.get("proto_major") != PROTO_MAJOR:
            self.close()
            raise ProtocolError("the daemon speaks protocol %s.%s; this client speaks %d.x" % (
                self.version.get("proto_major"), self.version.get("proto_minor"), PROTO_MAJOR))

    # -- life cycle
    def close(self):
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- read-only requests
    def status(self):
        """STATUS: state, fault_reason, voltage, sample, loop statistics, driver counters."""
        return self.request({"request": "status"})

    def estimate(self):
        """ESTIMATE: theta_hat, sigma, eps, converged, ... (docs/protocol.md)."""
        return self.request({"request": "estimate"})

    def watch(self, rate_hz=10.0, count=None):
        """Yields ESTIMATE objects at rate_hz (0.1..1000) until `count` were yielded (None: for
        ever). Closing the generator (break, or leaving a for loop) stops the stream, and the
        connection stays usable."""
        reply = self.request({"request": "watch", "rate_hz": rate_hz})
        if reply.get("class") != "WATCH":
            raise ProtocolError("expected a WATCH reply, got %r" % reply)
        self._watching = True
        wait = max(self.timeout, 3.0 / rate_hz)
        try:
            received = 0
            while count is None or received < count:
                if self._stream:
                    obj = self._stream.popleft()
                else:
                    obj = self._read_object(wait)
                cls = obj.get("class")
                if cls == "ERROR":
                    raise RequestError(obj.get("message", ""), {"request": "watch"})
                if cls != "ESTIMATE":
                    continue
                received += 1
                yield obj
        finally:
            self._watching = False
            self._stream.clear()
            if self._sock is not None:
                try:
                    self.request({"request": "watch", "enable": False})
                except (DaemonUnreachable, ProtocolError):
                    pass

    # -- mutating requests (root, the daemon's user or socket.group)
    def reset(self):
        """Restart the estimator from its initial θ̂ and covariance."""
        return self._command({"request": "reset"})

    def set_excitation(self, enable):
        """Switch the excitation signal on (True) or off (False: 0 V)."""
        return self._command({"request": "excitation", "enable": bool(enable)})

    def clear_fault(self):
        """Leave the fault state; CommandRefused while the cause is still present."""
        return self._command({"request": "clear-fault"})

    # -- the protocol
    def request(self, obj):
        """Sends one request object and returns the first reply that is not part of a watch
        stream. ERROR replies raise RequestError (PermissionDenied for privileges)."""
        self._send(obj)
        name = obj.get("request")
        while True:
            reply = self._read_object(self.timeout)
            cls = reply.get("class")
            if cls == "ESTIMATE" and name != "estimate":
                if self._watching:
                    self._stream.append(reply)
                continue
            if cls == "ERROR":
                message = reply.get("message", "")
                kind = PermissionDenied if message.startswith("permission denied") else RequestError
                raise kind(message, obj)
            if name == "watch" and obj.get("enable", True) is False and cls == "WATCH" \
                    and reply.get("enable", False):
                continue  # a late answer to an earlier watch
            return reply

    def _command(self, obj):
        reply = self.request(obj)
        if reply.get("class") != "ACK":
            raise ProtocolError("expected an ACK, got %r" % reply)
        if not reply.get("ok", False):
            raise CommandRefused(reply)
        return reply

    def _send(self, obj):
        if self._sock is None:
            raise DaemonUnreachable("the connection is closed")
        try:
            self._sock.sendall((json.dumps(obj) + "\n").encode())
        except OSError as error:
            raise DaemonUnreachable("lost the connection to %s: %s" % (self.path, error)) from error

    def _read_object(self, timeout):
        line = self._read_line(timeout)
        try:
            obj = json.loads(line)
        except ValueError as error:
            raise ProtocolError("not JSON from %s: %r" % (self.path, line[:200])) from error
        if not isinstance(obj, dict):
            raise ProtocolError("not a JSON object from %s: %r" % (self.path, line[:200]))
        return obj

    def _read_line(self, timeout):
        if self._sock is None:
            raise DaemonUnreachable("the connection is closed")
        deadline = time.monotonic() + timeout
        while b"\n" not in self._buffer:
            if len(self._buffer) > _MAX_LINE:
                raise ProtocolError("over-long line from %s" % self.path)
            left = deadline - time.monotonic()
            if left <= 0:
                raise DaemonUnreachable("no answer from %s within %g s; is the daemon stuck?"
                                        % (self.path, timeout))
            self._sock.settimeout(left)
            try:
                chunk = self._sock.recv(65536)
            except socket.timeout:
                continue
            except OSError as error:
                raise DaemonUnreachable("lost the connection to %s: %s" % (self.path, error)) \
                    from error
            if not chunk:
                raise DaemonUnreachable("the daemon closed the connection")
            self._buffer += chunk
        line, _, self._buffer = self._buffer.partition(b"\n")
        return line.decode("utf-8", errors="replace")
