#!/usr/bin/python3
"""A Modbus RTU slave written with Debian's python3-pymodbus (3.0), independent of libmodbus and
of this project's simulator: its own register map, its own plant, its own encoder (struct).

  usage: pymodbus_rtu_slave.py DEVICE|socket:PORT [BAUD]

DEVICE is a serial port (a pty); socket:PORT has pymodbus's serial server take its RTU frames from
TCP connections on PORT instead (0: a free port), as a device on the line would have them: without
the kernel's tty layer (serial_line_emulator --slave-port connects there; each connection is a line
of its own).

Unit 17, holding registers (0-based protocol addresses; mbpoll's -r 1001 is address 1000):
  1000-1001  x            float32, high word first, m
  1002-1003  temperature  float32, high word first, degC
  1004-1005  xdot         float32, high word first, m/s
  1006-1007  samples      uint32, high word first: reads served (a DAQ status word nobody uses)
  1008-1009  voltage      float32, high word first: the output's read-back, V
  1100       command      uint16, mV (written by the master, function 6)

The plant runs on the wall clock, advanced to the instant of each request: a first-order thermal
element (Table I's lambda, Cth, R; ambient 25 degC) integrated exactly with the voltage held since
the last write, and the actuator's length in its quasi-static equilibrium x = -alpha2 * Tbar / k.
Prints "pymodbus rtu slave ready" (with "on port N" for a socket) once it serves, and the requests
it served on SIGTERM.
"""
import asyncio
import logging
import math
import signal
import socket
import struct
import sys
import time

from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                 ModbusSlaveContext)
from pymodbus.framer.rtu_framer import ModbusRtuFramer
from pymodbus.server.async_io import StartAsyncSerialServer

UNIT = 17
FIRST = 1000
COMMAND = 1100
LAMBDA, CTH, R, ALPHA2, K, AMBIENT = 0.0540, 0.9090, 1.0, 0.01, 181.3, 25.0


def words(fmt, value):
    """Big-endian 16-bit words of value packed with struct format fmt."""
    raw = struct.pack(">" + fmt, value)
    return [int.from_bytes(raw[i:i + 2], "big") for i in range(0, len(raw), 2)]


class Plant:
    """The thermal element and the length it sets, advanced on the wall clock."""

    def __init__(self):
        self.tbar = 0.0
        self.dtbar = 0.0
        self.volts = 0.0
        self.t = time.monotonic()
        self.reads = 0
        self.writes = 0

    def advance(self):
        now = time.monotonic()
        steady = self.volts * self.volts / R / LAMBDA
        decay = math.exp(-LAMBDA / CTH * (now - self.t))
        self.tbar = steady + (self.tbar - steady) * decay
        self.dtbar = (-LAMBDA * self.tbar + self.volts * self.volts / R) / CTH
        self.t = now

    def registers(self):
        self.advance()
        self.reads += 1
        x = -ALPHA2 * self.tbar / K
        xdot = -ALPHA2 * self.dtbar / K
        return (words("f", x) + words("f", AMBIENT + self.tbar) + words("f", xdot) +
                words("I", self.reads & 0xFFFFFFFF) + words("f", self.volts))


class PlantBlock(ModbusSequentialDataBlock):
    """Holding registers whose signal block is computed from the plant when it is read."""

    def __init__(self, plant):
        super().__init__(0, [0] * (COMMAND + 1))
        self.plant = plant

    def getValues(self, address, count=1):
        if address <= FIRST + 9 and address + count > FIRST:
            regs = self.plant.registers()
            super().setValues(FIRST, regs)
        return super().getValues(address, count)

    def setValues(self, address, values):
        super().setValues(address, values)
        if address <= COMMAND < address + len(values):
            self.plant.advance()
            self.plant.volts = values[COMMAND - address] * 0.001
            self.plant.writes += 1


async def serve(device, baud, plant):
    store = ModbusSlaveContext(hr=PlantBlock(plant), zero_mode=True)
    context = ModbusServerContext(slaves={UNIT: store}, single=False)
    server = await StartAsyncSerialServer(context=context, framer=ModbusRtuFramer, port=device,
                                          baudrate=baud, bytesize=8, parity="N", stopbits=1,
                                          defer_start=True)
    await server.start()
    serving = asyncio.create_task(server.serve_forever())
    where = f" on port {device.rsplit(':', 1)[1]}" if device.startswith("socket:") else ""
    print(f"pymodbus rtu slave ready{where}", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    loop.add_signal_handler(signal.SIGINT, stop.set)
    await stop.wait()
    print(f"pymodbus rtu slave: {plant.reads} reads, {plant.writes} writes served", flush=True)
    serving.cancel()
    await server.shutdown()


def free_port():
    """A TCP port nothing listens on right now (bound and released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main():
    device = sys.argv[1]
    if device.startswith("socket:") and device.endswith(":0"):
        device = f"{device[:-2]}:{free_port()}"
    baud = int(sys.argv[2]) if len(sys.argv) > 2 else 115200
    logging.basicConfig(level=logging.WARNING)
    asyncio.run(serve(device, baud, Plant()))


if __name__ == "__main__":
    main()
