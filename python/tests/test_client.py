"""scp_estimator against the real daemon: the protocol's second implementation, tested on the
first one."""

import json
import os
import socket
import subprocess
import sys
import threading
import time

import pytest

import scp_estimator
from scp_estimator import (
    Client,
    CommandRefused,
    DaemonUnreachable,
    PermissionDenied,
    ProtocolError,
    RequestError,
)


def wait_for_state(client, state, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = client.status()
        if status["state"] == state:
            return status
        time.sleep(0.05)
    pytest.fail("state %s not reached: %r" % (state, client.status()))


def test_greeting_and_status(daemon):
    with Client(daemon.socket) as client:
        assert client.version["class"] == "VERSION"
        assert client.version["proto_major"] == scp_estimator.PROTO_MAJOR
        status = wait_for_state(client, "running")
        assert status["class"] == "STATUS"
        assert status["driver"] == "sim"
        assert status["loop"]["cycles"] > 0


def test_socket_from_environment(daemon, monkeypatch):
    monkeypatch.setenv("SCP_ESTIMATOR_SOCKET", daemon.socket)
    with Client() as client:
        assert client.path == daemon.socket
        assert client.status()["class"] == "STATUS"


def test_estimate_has_six_parameters_and_advances(daemon):
    with Client(daemon.socket) as client:
        wait_for_state(client, "running")
        first = client.estimate()
        time.sleep(0.3)
        second = client.estimate()
    assert first["class"] == "ESTIMATE"
    assert len(first["theta_hat"]) == 6 and len(first["sigma"]) == 6
    assert len(first["theta_true"]) == 6  # the simulated driver reports the truth
    assert second["t"] > first["t"] + 0.1
    assert second["updates"] > first["updates"]


def test_watch_yields_a_timed_stream_and_the_connection_survives(daemon):
    with Client(daemon.socket) as client:
        wait_for_state(client, "running")
        start = time.monotonic()
        estimates = list(client.watch(rate_hz=20, count=10))
        elapsed = time.monotonic() - start
        assert [e["class"] for e in estimates] == ["ESTIMATE"] * 10
        times = [e["t"] for e in estimates]
        assert times == sorted(times) and times[-1] > times[0]
        # 10 objects at 20 Hz: 9 periods at least (the first may come at once).
        assert elapsed >= 0.4, elapsed
        # Stopped: an ordinary request gets its own reply, not a stream object.
        assert client.status()["class"] == "STATUS"
        assert client.estimate()["class"] == "ESTIMATE"


def test_watch_generator_closed_early_stops_the_stream(daemon):
    with Client(daemon.socket) as client:
        for i, estimate in enumerate(client.watch(rate_hz=100)):
            if i == 3:
                break
        # After break the generator is finalised; the next reply must be a STATUS.
        assert client.status()["class"] == "STATUS"


def test_requests_interleaved_with_a_watch_keep_the_stream(daemon):
    with Client(daemon.socket) as client:
        stream = client.watch(rate_hz=50, count=20)
        got = [next(stream) for _ in range(5)]
        assert client.status()["class"] == "STATUS"  # ESTIMATEs that arrive meanwhile are kept
        got += list(stream)
        assert len(got) == 20


def test_mutating_requests(daemon):
    with Client(daemon.socket) as client:
        wait_for_state(client, "running")
        ack = client.set_excitation(False)
        assert ack["class"] == "ACK" and ack["ok"] is True
        assert client.status()["excitation"] is False
        assert client.set_excitation(True)["ok"] is True
        assert client.status()["excitation"] is True
        updates_before = client.estimate()["updates"]
        assert client.reset()["ok"] is True
        assert client.estimate()["updates"] < updates_before
        assert client.clear_fault()["message"] == "no fault to clear"


def test_clear_fault_refused_while_the_cause_persists(faulty_daemon):
    with Client(faulty_daemon.socket) as client:
        status = wait_for_state(client, "fault")
        assert "temperature" in status.get("fault_reason", "")
        with pytest.raises(CommandRefused) as refused:
            client.clear_fault()
        assert refused.value.reply["ok"] is False
        assert "temperature" in refused.value.message


def test_bad_request_is_a_request_error(daemon):
    with Client(daemon.socket) as client:
        with pytest.raises(RequestError) as error:
            client.request({"request": "stats"})
        assert "unknown request 'stats'" in error.value.message
        with pytest.raises(RequestError):
            client.request({"request": "watch", "rate_hz": 5000})
        assert client.status()["class"] == "STATUS"  # errors do not close the connection


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a client as another user")
def test_permission_denied_for_an_unprivileged_peer(daemon):
    code = ("import scp_estimator, sys\n"
            "c = scp_estimator.Client(sys.argv[1])\n"
            "assert c.status()['class'] == 'STATUS'\n"
            "try:\n    c.reset()\nexcept scp_estimator.PermissionDenied as e:\n"
            "    print('denied:', e.message); sys.exit(0)\n"
            "sys.exit(3)\n")
    env = dict(os.environ, PYTHONPATH=os.path.dirname(os.path.dirname(scp_estimator.__file__)))
    # The temporary directory is 0700 by default; let nobody reach the socket in it.
    os.chmod(os.path.dirname(daemon.socket), 0o755)
    result = subprocess.run([sys.executable, "-c", code, daemon.socket], env=env, user="nobody",
                            group="nogroup", extra_groups=[], capture_output=True, text=True,
                            timeout=30)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "needs root" in result.stdout


def test_no_daemon_is_daemon_unreachable(tmp_path):
    with pytest.raises(DaemonUnreachable) as error:
        Client(str(tmp_path / "none.sock"), timeout=1)
    assert "is scp-estimatord running" in str(error.value)
    assert isinstance(error.value, ConnectionError)


def fake_server(tmp_path, greeting):
    path = str(tmp_path / "fake.sock")
    server = socket.socket(socket.AF_UNIX)
    server.bind(path)
    server.listen(1)

    def serve():
        conn, _ = server.accept()
        conn.sendall(greeting)
        time.sleep(0.5)
        conn.close()
        server.close()

    threading.Thread(target=serve, daemon=True).start()
    return path


def test_other_protocol_major_is_a_protocol_error(tmp_path):
    path = fake_server(tmp_path, json.dumps(
        {"class": "VERSION", "release": "9", "proto_major": 2, "proto_minor": 0}).encode() + b"\n")
    with pytest.raises(ProtocolError, match="protocol 2.0"):
        Client(path, timeout=2)


def test_a_peer_that_is_not_the_daemon_is_a_protocol_error(tmp_path):
    path = fake_server(tmp_path, b"220 smtp.example.org ESMTP\n")
    with pytest.raises(ProtocolError):
        Client(path, timeout=2)


def test_flatten_and_dataframe(daemon):
    with Client(daemon.socket) as client:
        estimates = list(client.watch(rate_hz=50, count=5))
    row = scp_estimator.flatten(estimates[-1])
    assert row["theta_hat[k/m]"] == estimates[-1]["theta_hat"][2]
    assert "converged.mechanical" in row and "class" not in row
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="python3-pandas"):
            scp_estimator.to_dataframe(estimates)
        return
    frame = scp_estimator.to_dataframe(estimates)
    assert len(frame) == 5 and frame.index.name == "t"
    assert list(frame["theta_hat[b/m]"]) == [e["theta_hat"][0] for e in estimates]
