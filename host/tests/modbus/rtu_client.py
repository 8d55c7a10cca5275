"""An independent Modbus RTU master for the virtual node's tests (pymodbus's
serial client, pinned in gateway/tests/modbus/requirements.txt).

Each command prints one JSON object on stdout:

  read PORT BAUD UNIT FC ADDRESS COUNT    {"registers": [...]} or {"exception": CODE} or {"error": ..}
  write PORT BAUD UNIT ADDRESS VALUE FC   {"ok": true} or {"exception": CODE} or {"error": ..}
  flood PORT BAUD UNIT N                  {"answers": N, "failed": N, "seconds": s}

A pseudo-terminal carries no parity bits, and pyserial cannot set even
parity on a Linux pty a second time (tcsetattr: EINVAL), so the client
opens it 8N1; the node times its silences as 8E1. A read of the whole
measurement block is a FC 03/04 of 27 registers.
"""

import json
import sys
import time

from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ModbusException


def connect(port, baud):
    c = ModbusSerialClient(
        port, baudrate=int(baud), parity="N", stopbits=1, bytesize=8, timeout=1, retries=0
    )
    if not c.connect():
        raise SystemExit(json.dumps({"error": f"cannot open {port}"}))
    return c


def answer(rr, registers):
    if rr.isError():
        return {"exception": rr.exception_code}
    if registers:
        return {"registers": list(rr.registers)}
    return {"ok": True}


def main(argv):
    cmd, port, baud = argv[0], argv[1], argv[2]
    c = connect(port, baud)
    try:
        if cmd == "read":
            unit, fc, address, count = map(int, argv[3:7])
            f = c.read_input_registers if fc == 4 else c.read_holding_registers
            out = answer(f(address, count=count, device_id=unit), True)
        elif cmd == "write":
            unit, address, value, fc = map(int, argv[3:7])
            if fc == 6:
                rr = c.write_register(address, value, device_id=unit)
            else:
                rr = c.write_registers(address, [value], device_id=unit)
            out = answer(rr, False)
        elif cmd == "flood":
            unit, n = int(argv[3]), int(argv[4])
            ok = failed = 0
            t0 = time.monotonic()
            for _ in range(n):
                try:
                    rr = c.read_input_registers(0, count=27, device_id=unit)
                    if rr.isError():
                        failed += 1
                    else:
                        ok += 1
                except ModbusException:
                    failed += 1
            out = {"answers": ok, "failed": failed, "seconds": time.monotonic() - t0}
        else:
            raise SystemExit(f"unknown command {cmd}")
    except (ModbusException, OSError) as e:
        out = {"error": str(e)}
    finally:
        c.close()
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1:])
