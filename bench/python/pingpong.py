"""The Python side of bench_python: the same as pingpong.cpp, with cpm's Python package."""
import signal
import sys
import threading
import time

import cpm
from cpm.types import VehicleState

cpm.init(sys.argv)
mode = sys.argv[1]
if mode == "pong":
    out = cpm.Writer(VehicleState, "bench_pong", reliable=True, history_depth=1)

    def echo(samples):
        for s in samples:
            out.write(s)

    reader = cpm.AsyncReader(VehicleState, "bench_ping", echo, reliable=True, history_depth=1)
    print("ready", flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    while not stop.is_set():
        stop.wait(0.02)
    reader.close()
    sys.exit(0)

n = int(sys.argv[2])
back = {"t": 0}
arrived = threading.Condition()


def on_pong(samples):
    with arrived:
        for s in samples:
            back["t"] = s.header.create_stamp.nanoseconds
        arrived.notify_all()


out = cpm.Writer(VehicleState, "bench_ping", reliable=True, history_depth=1)
reader = cpm.AsyncReader(VehicleState, "bench_pong", on_pong, reliable=True, history_depth=1)
if not out.wait_for_matched(1, 10.0):
    sys.exit("pingpong.py: no pong")
end = time.monotonic() + 10
while reader.matched_publications() < 1 and time.monotonic() < end:
    time.sleep(0.01)
lines = []
for i in range(n):
    s = VehicleState(vehicle_id=1)
    t = cpm.get_time_ns()
    cpm.stamp_message(s, t, 0)
    out.write(s)
    with arrived:
        if not arrived.wait_for(lambda: back["t"] == t, timeout=2.0):
            continue
    lines.append(str(cpm.get_time_ns() - t))
    time.sleep(0.0005)
reader.close()
print("\n".join(lines))
