#!/usr/bin/env python3
"""A platoon on the ring, as a Python high-level controller (cpm.hlc): each car at --speed,
never closer to the car ahead than --gap seconds at its speed plus 0.45 m. The same controller
as examples/hlc_platoon in C++.

    cpm lab run scenarios/labs/platoon_python.yaml

cpm lab run starts it as  python3 platoon.py --lanes RING.json … --vehicle_ids 1,2,3,4 --dds_domain D
"""
import argparse
import bisect
import json
import math
import sys

import cpm
from cpm.types import TrajectoryPoint, VehicleCommandTrajectory

MIN_GAP, ACCEL, STEP, HORIZON = 0.45, 0.8, 0.1, 1.5


class Ring:
    """A lane graph that is one loop, as a polyline with its arc length."""

    def __init__(self, path):
        graph = json.load(open(path))
        edges = graph["edges"]
        order, e = [], 0
        while True:
            order.append(e)
            nxt = [i for i, x in enumerate(edges) if x["from"] == edges[e]["to"]]
            if len(nxt) != 1:
                sys.exit(f"platoon.py: {path}: the lane graph is not one loop (edge {e})")
            e = nxt[0]
            if e == 0:
                break
            if len(order) > len(edges):
                sys.exit(f"platoon.py: {path}: the lane graph is not one loop")
        # each edge after the first begins where the one before ended
        self.points = edges[order[0]]["points"] + [p for i in order[1:] for p in edges[i]["points"][1:]]
        self.s = [0.0]
        for a, b in zip(self.points, self.points[1:]):
            self.s.append(self.s[-1] + math.dist(a, b))
        self.length = self.s[-1] + math.dist(self.points[-1], self.points[0])

    def project(self, x, y):
        """The arc length of the nearest point of the loop."""
        i = min(range(len(self.points)), key=lambda k: (self.points[k][0] - x) ** 2 + (self.points[k][1] - y) ** 2)
        return self.s[i]

    def pose_at(self, s):
        s %= self.length
        i = max(0, bisect.bisect_right(self.s, s) - 1)
        a, b = self.points[i], self.points[(i + 1) % len(self.points)]
        seg = math.dist(a, b) or 1e-9
        f = (s - self.s[i]) / seg
        return a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), math.atan2(b[1] - a[1], b[0] - a[0])


def main():
    cpm.init(sys.argv)
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lanes", required=True, help="a lane graph that is one loop (scenarios/lanes/ring.json)")
    parser.add_argument("--vehicle_ids", required=True, help="the cars, e.g. 1,2,3,4")
    parser.add_argument("--speed", type=float, default=0.6, help="m/s")
    parser.add_argument("--gap", type=float, default=1.0, help="s of time gap to the car ahead")
    args, _ = parser.parse_known_args()  # cpm's own flags (--dds_domain, …) were read by cpm.init
    ids = [int(i) for i in args.vehicle_ids.split(",")]
    ring = Ring(args.lanes)
    hlc = cpm.hlc.Communicator(ids)
    out = cpm.Writer(VehicleCommandTrajectory, "vehicleCommandTrajectory")

    def step(state_list):
        at = {s.vehicle_id: (ring.project(s.pose.x, s.pose.y), s.speed) for s in state_list.state_list}
        for vid, (mine, v) in at.items():
            ahead = min([(theirs - mine) % ring.length for other, (theirs, _) in at.items() if other != vid] or [ring.length])
            target = min(args.speed, max(0.0, (ahead - MIN_GAP) / args.gap))
            command = VehicleCommandTrajectory(vehicle_id=vid)
            cpm.stamp_message(command, state_list.t_now, 0)
            points, s, k = [], mine, 0
            while k * STEP <= HORIZON + 1e-9:
                x, y, yaw = ring.pose_at(s)
                p = TrajectoryPoint(px=x, py=y, vx=v * math.cos(yaw), vy=v * math.sin(yaw))
                p.t.nanoseconds = state_list.t_now + round(k * STEP * 1e9)
                points.append(p)
                v = min(target, v + ACCEL * STEP) if v < target else max(target, v - 2 * ACCEL * STEP)
                s += v * STEP
                k += 1
            command.trajectory_points = points
            if not out.write(command):
                cpm.log.warn(f"DDS refused vehicle {vid}'s trajectory")

    hlc.on_first_timestep(lambda l: cpm.log.info(f"first step with {len(l.state_list)} of {len(ids)} cars"))
    hlc.on_each_timestep(step)
    hlc.start()
    print(json.dumps({"steps": hlc.steps, "cancelled": hlc.cancelled_steps, "failed": hlc.failed_steps}))


if __name__ == "__main__":
    main()
