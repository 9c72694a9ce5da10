#!/usr/bin/python3
"""A Modbus TCP server written with Debian's python3-pymodbus (3.0), independent of libmodbus.

Serves fixed values whose register encoding is computed here with struct (big-endian words),
so the C++ driver is checked against a peer and an encoder nobody in this project wrote.

  usage: pymodbus_server.py PORT

Map (0-based addresses, unit 1):
  input 0-1    x            int32, word order ba (low word first), scale 1e-6 m:  -1250 -> -0.00125 m
  input 2-3    temperature  float32, word order ab:                                31.5 degC
  input 4      xdot         int16, scale 1e-5 m/s:                                 -7 -> -7e-5 m/s
  holding 0    voltage      uint16 read-back, scale 0.001 V:                        1500 -> 1.5 V
  holding 10-11 command     float32 ab (written by the driver)
"""
import logging
import struct
import sys

from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext,
                                 ModbusSlaveContext)
from pymodbus.server import StartTcpServer


def words(fmt, value):
    """Big-endian 16-bit words of value packed with struct format fmt."""
    raw = struct.pack(">" + fmt, value)
    return [int.from_bytes(raw[i:i + 2], "big") for i in range(0, len(raw), 2)]


def main():
    port = int(sys.argv[1])
    x_words = words("i", -1250)
    x_words.reverse()  # word order ba: low word at the lower address
    inputs = x_words + words("f", 31.5) + words("h", -7) + [0] * 8
    holding = [1500] + [0] * 19
    store = ModbusSlaveContext(ir=ModbusSequentialDataBlock(0, inputs),
                               hr=ModbusSequentialDataBlock(0, holding),
                               zero_mode=True)
    context = ModbusServerContext(slaves={1: store}, single=False)
    logging.basicConfig(level=logging.WARNING)
    print("pymodbus server ready", flush=True)
    StartTcpServer(context=context, address=("127.0.0.1", port))


if __name__ == "__main__":
    main()
