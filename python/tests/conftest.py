"""Fixtures: the real scp-estimatord (simulated actuator, real-time loop) on a temporary socket.

SCP_ESTIMATORD names the binary (ctest sets it to the build's); else it is looked up on PATH, so
the same tests run against an installed package.
"""

import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time

import pytest


def daemon_binary():
    path = os.environ.get("SCP_ESTIMATORD") or shutil.which("scp-estimatord")
    if not path:
        pytest.fail("scp-estimatord not found: set SCP_ESTIMATORD or install the package")
    return path


def base_config(directory, **sections):
    config = {
        "loop": {"period_s": 0.001,
                 "realtime": {"priority": 0, "lock_memory": False, "prefault_heap_mib": 0}},
        "actuator": {"ambient_c": 25.0, "mass_kg": 0.1, "resistance_ohm": 1.0},
        "driver": {"type": "sim"},
        "estimator": {"scale": [1000, 1, 1000, 0.1, 0.1, 1]},
        "socket": {"path": os.path.join(directory, "d.sock"), "group": "", "mode": "0666"},
        "state": {"directory": os.path.join(directory, "state"), "warm_start": False},
        "log_level": "warn",
    }
    for name, value in sections.items():
        config.setdefault(name, {}).update(value)
    return config


class Daemon:
    def __init__(self, **sections):
        self.directory = tempfile.mkdtemp(prefix="scp-py-")
        os.makedirs(os.path.join(self.directory, "state"))
        self.socket = os.path.join(self.directory, "d.sock")
        path = os.path.join(self.directory, "config.yaml")
        with open(path, "w") as f:
            json.dump(base_config(self.directory, **sections), f, indent=2)  # JSON is YAML
        self.log = open(os.path.join(self.directory, "daemon.log"), "w+")
        self.process = subprocess.Popen([daemon_binary(), "--config", path],
                                        stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                pytest.fail("scp-estimatord exited (%s): %s" % (self.process.returncode, self.output()))
            try:
                with socket.socket(socket.AF_UNIX) as probe:
                    probe.connect(self.socket)
                return
            except OSError:
                time.sleep(0.05)
        self.stop()
        pytest.fail("scp-estimatord did not open %s: %s" % (self.socket, self.output()))

    def output(self):
        self.log.seek(0)
        return self.log.read()

    def stop(self):
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()
        shutil.rmtree(self.directory, ignore_errors=True)


@pytest.fixture(scope="module")
def daemon():
    d = Daemon()
    yield d
    d.stop()


@pytest.fixture(scope="module")
def faulty_daemon():
    """A daemon whose simulated temperature sensor reads 400 °C from t = 0.2 s on: FAULT that
    clear-fault must refuse."""
    d = Daemon(driver={"type": "sim", "sim": {"fault": {
        "kind": "temperature_out_of_range", "start_s": 0.2, "duration_s": 0}}})
    yield d
    d.stop()
