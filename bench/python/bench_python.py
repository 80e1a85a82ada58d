#!/usr/bin/env python3
"""bench_python: one-way latency of cpm's Python package against C++ in the same run.

Case 1, latency. A ping sends a VehicleState (156 bytes of CDR) on bench_ping, a pong sends it back on
bench_pong, one at a time; one-way = round trip / 2. Python ping with Python pong against C++
ping with C++ pong (pingpong.cpp), same QoS (reliable, keep last 1), same transports (this
host: shared memory), interleaved in blocks so that the machine's state is shared.
Target: Python p50 <= 1.5x C++ p50.

Case 2, a recording read into columns: a topic of 100,000 VehicleStates (made with cpm record
import) read from the file into columns of times and fields, by Python (cpm.open_recording(…)
.table(…), every field) and by C++ (read_recording.cpp: HistoryClient::open_recording, six
fields). Both include loading the file. No target: the figure says what Python costs.

usage: bench_python.py BUILD_DIR [--count 2000] [--blocks 3]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("build")
parser.add_argument("--count", type=int, default=2000)
parser.add_argument("--blocks", type=int, default=3)
parser.add_argument("--samples", type=int, default=100_000, help="case 2: samples in the recording")
args = parser.parse_args()
env = dict(os.environ, PYTHONPATH=os.path.join(args.build, "python"))
env.setdefault("CPM_DOMAIN_ID", "97")


def block(kind):
    if kind == "cpp":
        pong = [os.path.join(args.build, "bin", "bench_pingpong"), "pong"]
        ping = [os.path.join(args.build, "bin", "bench_pingpong"), "ping", str(args.count)]
    else:
        pong = ["/usr/bin/python3", os.path.join(here, "pingpong.py"), "pong"]
        ping = ["/usr/bin/python3", os.path.join(here, "pingpong.py"), "ping", str(args.count)]
    p = subprocess.Popen(pong, stdout=subprocess.PIPE, text=True, env=env)
    assert p.stdout.readline().strip() == "ready"
    out = subprocess.run(ping, capture_output=True, text=True, env=env, timeout=300)
    p.send_signal(2)
    p.wait(10)
    if out.returncode != 0:
        sys.exit(f"bench_python: {kind} ping failed: {out.stderr}")
    return [int(x) / 2 / 1000 for x in out.stdout.split()]  # one-way, µs


def pct(values, p):
    values = sorted(values)
    return values[min(len(values) - 1, int(p * len(values)))]


results = {"cpp": [], "python": []}
for b in range(args.blocks):
    for kind in ("cpp", "python"):
        results[kind] += block(kind)
print(f"one-way latency, µs ({args.blocks} blocks of {args.count}, interleaved)")
print(f"{'case':24} {'n':>6} {'p50':>8} {'p90':>8} {'p99':>8}")
for kind, label in (("cpp", "C++ ping / C++ pong"), ("python", "Python ping / Python pong")):
    v = results[kind]
    print(f"{label:24} {len(v):6d} {pct(v, .5):8.1f} {pct(v, .9):8.1f} {pct(v, .99):8.1f}")
ratio = pct(results["python"], .5) / pct(results["cpp"], .5)
met = ratio <= 1.5
print(f"Python / C++ p50: {ratio:.2f} (target <= 1.5x): {'met' if met else 'NOT met'}")
if os.environ.get("CPM_BENCH_JSON"):
    with open(os.environ["CPM_BENCH_JSON"], "a") as f:
        for what, p in (("one-way p50", .5), ("one-way p99", .99)):
            c, py = pct(results["cpp"], p), pct(results["python"], p)
            f.write(json.dumps({"bench": "python", "case": f"VehicleState {what}", "unit": "µs", "cpm": py, "peer": "cpm C++",
                                "peer_value": c, "ratio": py / c, "target": "<= 1.5x peer" if p == .5 else "",
                                "met": (1 if met else 0) if p == .5 else -1}) + "\n")


# ---- case 2: a recording read into columns ------------------------------------------------------
import tempfile
import time

with tempfile.TemporaryDirectory() as tmp:
    csv = os.path.join(tmp, "states.csv")
    with open(csv, "w") as f:
        f.write("data_ns,valid_after_ns,key,vehicle_id,pose.x,pose.y,pose.yaw,speed,odometer_distance,battery_voltage\n")
        for i in range(args.samples):
            t = 1_000_000_000 + i * 20_000_000
            f.write(f"{t},{t + 1_000_000},1,1,{i * 0.01},{i * 0.002},{i * 1e-4},{0.5 + (i % 7) * 0.01},{i * 0.01},8.1\n")
    rec = os.path.join(tmp, "states.db")
    subprocess.run([os.path.join(args.build, "bin", "cpm"), "record", "import", csv, "--topic", "vehicleState", "--type", "VehicleState",
                    "--out", rec], check=True, capture_output=True, env=env)
    cpp_runs, py_runs = [], []
    for _ in range(args.blocks):
        out = subprocess.run([os.path.join(args.build, "bin", "bench_read_recording"), rec], capture_output=True, text=True, check=True, env=env)
        n, secs = out.stdout.split()
        assert int(n) == args.samples, f"C++ read {n} of {args.samples}"
        cpp_runs.append(float(secs))
        code = ("import sys, time, cpm\nfrom cpm.types import VehicleState\nt = time.perf_counter()\n"
                "c = cpm.open_recording(sys.argv[1]).table(VehicleState, 'vehicleState', 1)\n"
                "print(len(c['speed']), time.perf_counter() - t, len(c))")
        out = subprocess.run(["/usr/bin/python3", "-c", code, rec], capture_output=True, text=True, check=True, env=env)
        n, secs, columns = out.stdout.split()
        assert int(n) == args.samples, f"Python read {n} of {args.samples}"
        py_runs.append(float(secs))
    c, p = statistics.median(cpp_runs), statistics.median(py_runs)
    print(f"\na recording of {args.samples} VehicleStates read into columns (median of {args.blocks}, s):")
    print(f"  C++ (HistoryClient::open_recording, 6 fields): {c:.3f}")
    print(f"  Python (cpm.open_recording(...).table(...), {columns} columns): {p:.3f}   ({p / c:.1f}x)")
    if os.environ.get("CPM_BENCH_JSON"):
        with open(os.environ["CPM_BENCH_JSON"], "a") as f:
            f.write(json.dumps({"bench": "python", "case": f"{args.samples} samples from a recording into columns", "unit": "s", "cpm": p,
                                "peer": "cpm C++", "peer_value": c, "ratio": p / c, "target": "", "met": -1}) + "\n")
