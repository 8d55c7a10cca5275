"""An independent Modbus TCP client for the gateway's tests (pymodbus).

Each command prints one JSON object on stdout:

  read HOST PORT UNIT FC ADDRESS COUNT     {"registers": [...]} or {"exception": CODE}
  write HOST PORT UNIT ADDRESS VALUE FC    {"ok": true} or {"exception": CODE}   (FC 6 or 16)
  watch HOST PORT UNIT SECONDS PERIOD      {"samples": [{"t": s, "registers": [...]}, ...]}
  poll HOST PORT UNITS CLIENTS ROUNDS      {"clients": N, "answers": N, "failed": N,
                                            "failures": [first 10], "seconds": s,
                                            "latency_ms": {"median": .., "max": ..}}

`poll` runs CLIENTS threads, each with its own connection, each reading
all 24 registers of every unit in UNITS (comma-separated) ROUNDS times;
a client whose request gets no answer at all (its connection closed)
counts one failure and stops.
"""

import json
import sys
import threading
import time

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

REGISTERS = 24


def connect(host, port):
    c = ModbusTcpClient(host, port=int(port), timeout=5, retries=0)
    if not c.connect():
        raise SystemExit(json.dumps({"error": f"cannot connect to {host}:{port}"}))
    return c


def read(c, unit, fc, address, count):
    f = c.read_input_registers if fc == 4 else c.read_holding_registers
    try:
        rr = f(address, count=count, device_id=unit)
    except (ModbusException, OSError) as e:
        # No answer at all (the connection closed or reset, a time-out).
        return {"error": str(e)}
    if rr.isError():
        return {"exception": rr.exception_code}
    return {"registers": list(rr.registers)}


def main(argv):
    cmd, host, port = argv[0], argv[1], argv[2]
    if cmd == "read":
        unit, fc, address, count = map(int, argv[3:7])
        c = connect(host, port)
        out = read(c, unit, fc, address, count)
        c.close()
    elif cmd == "write":
        unit, address, value, fc = map(int, argv[3:7])
        c = connect(host, port)
        if fc == 6:
            rr = c.write_register(address, value, device_id=unit)
        else:
            rr = c.write_registers(address, [value], device_id=unit)
        out = {"exception": rr.exception_code} if rr.isError() else {"ok": True}
        c.close()
    elif cmd == "watch":
        unit = int(argv[3])
        seconds, period = float(argv[4]), float(argv[5])
        c = connect(host, port)
        t0 = time.monotonic()
        samples = []
        while time.monotonic() - t0 < seconds:
            r = read(c, unit, 4, 0, REGISTERS)
            r["t"] = time.monotonic() - t0
            samples.append(r)
            time.sleep(period)
        c.close()
        out = {"samples": samples}
    elif cmd == "poll":
        units = [int(u) for u in argv[3].split(",")]
        clients, rounds = int(argv[4]), int(argv[5])
        lock = threading.Lock()
        answers, failures, latencies, failed = [0], [], [], [0]
        start = threading.Barrier(clients)

        def fail(k, what):
            with lock:
                failed[0] += 1
                failures.append(f"client {k}: {what}")

        def client(k):
            # A client the server refuses (connection closed at once, or not
            # accepted) counts one failure and stops; it still takes its
            # place at the start line so that the others start together.
            c = None
            try:
                c = connect(host, port)
            except SystemExit as e:
                fail(k, e)
            try:
                start.wait()
            except threading.BrokenBarrierError:
                pass
            if c is None:
                return
            try:
                for _ in range(rounds):
                    for u in units:
                        t = time.monotonic()
                        r = read(c, u, 4, 0, REGISTERS)
                        dt = (time.monotonic() - t) * 1000
                        with lock:
                            latencies.append(dt)
                            if "registers" in r and len(r["registers"]) == REGISTERS:
                                answers[0] += 1
                        if not ("registers" in r and len(r["registers"]) == REGISTERS):
                            fail(k, f"unit {u}: {r}")
                        if "error" in r:
                            return  # no connection: this client stops
            except Exception as e:  # anything else the client library raises
                fail(k, repr(e))
            finally:
                c.close()

        threads = [threading.Thread(target=client, args=(k,)) for k in range(clients)]
        t0 = time.monotonic()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        seconds = time.monotonic() - t0
        latencies.sort()
        out = {
            "clients": clients,
            "answers": answers[0],
            "failed": failed[0],
            "failures": failures[:10],
            "seconds": seconds,
            "latency_ms": {
                "median": latencies[len(latencies) // 2] if latencies else None,
                "max": latencies[-1] if latencies else None,
            },
        }
    else:
        raise SystemExit(f"unknown command {cmd}")
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1:])
