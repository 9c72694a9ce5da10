"""Python client of scp-estimatord, the online estimator of super-coiled polymer actuators.

It speaks the daemon's socket protocol (docs/protocol.md, proto 1.x) with the standard library
only; pandas is needed only for to_dataframe().

    >>> from scp_estimator import Client
    >>> with Client() as daemon:                 # /run/scp-estimator/scp-estimator.sock
    ...     print(daemon.status()["state"])
    ...     for estimate in daemon.watch(rate_hz=10, count=50):
    ...         print(estimate["t"], estimate["theta_hat"])
"""

from .client import DEFAULT_SOCKET, PROTO_MAJOR, Client
from .errors import (
    CommandRefused,
    DaemonUnreachable,
    PermissionDenied,
    ProtocolError,
    RequestError,
    ScpError,
)
from .frames import PARAMETERS, flatten, to_dataframe

__version__ = "0.1.0"

__all__ = [
    "Client",
    "DEFAULT_SOCKET",
    "PROTO_MAJOR",
    "ScpError",
    "DaemonUnreachable",
    "ProtocolError",
    "RequestError",
    "PermissionDenied",
    "CommandRefused",
    "PARAMETERS",
    "flatten",
    "to_dataframe",
]
