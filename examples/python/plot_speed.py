#!/usr/bin/env python3
"""Plots a car's speed over a finished run from its recording:

    python3 examples/python/plot_speed.py runs/platoon-…/recording.db --vehicle 2 --out speed.png

The recording answers from Python as `cpm history --file` does (cpm.open_recording); the plot
is drawn by matplotlib when it is installed, else by gnuplot (which cpm lab run uses too).
"""
import argparse
import shutil
import subprocess
import sys

import cpm
from cpm.types import VehicleState


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", help="a run's recording.db")
    parser.add_argument("--vehicle", type=int, required=True, help="the car's id")
    parser.add_argument("--out", default="speed.png", help="the PNG to write (default speed.png)")
    args = parser.parse_args()
    try:
        run = cpm.open_recording(args.recording)
    except cpm.Error as e:
        sys.exit(f"plot_speed.py: {e}")
    columns = run.table(VehicleState, "vehicleState", args.vehicle, by="data")
    if not len(columns["data_ns"]):
        sys.exit(f"plot_speed.py: {args.recording} holds no vehicleState of car {args.vehicle}")
    t0 = columns["data_ns"][0]
    t = [(x - t0) / 1e9 for x in columns["data_ns"]]
    speed = list(columns["speed"])
    title = f"car {args.vehicle}: speed over the run ({len(t)} states)"
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        plt.figure(figsize=(9.6, 4.8))
        plt.plot(t, speed)
        plt.xlabel("s since its first state")
        plt.ylabel("speed (m/s)")
        plt.title(title)
        plt.grid(True)
        plt.savefig(args.out)
    except ImportError:
        if not shutil.which("gnuplot"):
            sys.exit("plot_speed.py: neither matplotlib nor gnuplot is installed")
        script = (f"set terminal png size 960,480\nset output '{args.out}'\nset grid\nset title '{title}'\n"
                  "set xlabel 's since its first state'\nset ylabel 'speed (m/s)'\nplot '-' with lines title 'speed'\n"
                  + "".join(f"{a} {b}\n" for a, b in zip(t, speed)) + "e\n")
        subprocess.run(["gnuplot"], input=script, text=True, check=True)
    print(f"plot_speed.py: {args.out}: car {args.vehicle}, {len(t)} states, top speed {max(speed):.2f} m/s")


if __name__ == "__main__":
    main()
