#!/usr/bin/env python3
"""Writes the lane graphs intersection.json and ring.json (metres, radians) beside this script.

intersection.json, a 4.5 x 4 m lab road map:
  - a ring of two lanes driven counter-clockwise (inner and outer lane, 0.36 m apart, corner
    radii 0.75 m and 1.11 m: the 1:10 cars, 0.40 x 0.20 m, turn no tighter than 0.62 m, and two
    of them pass each other in a corner 6 cm apart), with a lane change out on its bottom
    straight and one back in on its top straight;
  - a cross of two two-way roads through the middle (right-hand traffic), meeting at a central
    four-way intersection; where they leave and join the ring, turning lanes cross each other.
ring.json: one lane, one loop.

Every edge is sampled at most 0.04 m apart. Run: python3 scenarios/lanes/make_lanes.py
"""
import json
import math
import os

STEP = 0.04
LANE = 0.36


def line(p0, p1):
    n = max(1, math.ceil(math.dist(p0, p1) / STEP))
    return [(p0[0] + (p1[0] - p0[0]) * i / n, p0[1] + (p1[1] - p0[1]) * i / n) for i in range(n + 1)]


def arc(centre, r, a0, a1):
    """From angle a0 to a1 (radians, counter-clockwise when a1 > a0) around centre."""
    n = max(1, math.ceil(abs(a1 - a0) * r / STEP))
    return [(centre[0] + r * math.cos(a0 + (a1 - a0) * i / n), centre[1] + r * math.sin(a0 + (a1 - a0) * i / n))
            for i in range(n + 1)]


def lane_change(p0, p1):
    """A cosine-blended change between two parallel straight lanes, from p0 to p1 (axis-aligned)."""
    horizontal = abs(p1[0] - p0[0]) > abs(p1[1] - p0[1])
    length = abs(p1[0] - p0[0]) if horizontal else abs(p1[1] - p0[1])
    n = math.ceil(length * 1.1 / STEP)
    pts = []
    for i in range(n + 1):
        u = i / n
        w = (1 - math.cos(math.pi * u)) / 2
        if horizontal:
            pts.append((p0[0] + (p1[0] - p0[0]) * u, p0[1] + (p1[1] - p0[1]) * w))
        else:
            pts.append((p0[0] + (p1[0] - p0[0]) * w, p0[1] + (p1[1] - p0[1]) * u))
    return pts


class Graph:
    def __init__(self):
        self.nodes = {}  # rounded (x, y) -> node
        self.edges = []

    def node(self, p, yaw):
        key = (round(p[0], 3), round(p[1], 3))
        if key not in self.nodes:
            self.nodes[key] = {"id": len(self.nodes), "x": key[0], "y": key[1], "yaw": round(math.atan2(math.sin(yaw), math.cos(yaw)), 6)}
        return self.nodes[key]["id"]

    def edge(self, points, yaw0, yaw1):
        a = self.node(points[0], yaw0)
        b = self.node(points[-1], yaw1)
        self.edges.append({"from": a, "to": b, "points": [[round(x, 4), round(y, 4)] for x, y in points]})

    def write(self, path, lane_width):
        doc = {"lane_width": lane_width, "nodes": sorted(self.nodes.values(), key=lambda n: n["id"]),
               "edges": self.edges}
        with open(path, "w") as f:
            f.write("{\n")
            f.write('  "lane_width": %s,\n' % lane_width)
            f.write('  "nodes": [\n    ' + ",\n    ".join(json.dumps(n) for n in doc["nodes"]) + "\n  ],\n")
            f.write('  "edges": [\n    ' + ",\n    ".join(json.dumps(e) for e in doc["edges"]) + "\n  ]\n}\n")


E, N, W, S = 0.0, math.pi / 2, math.pi, -math.pi / 2
PI = math.pi


def rounded_rectangle(g, x0, y0, x1, y1, r, splits):
    """A counter-clockwise loop; corners of radius r; `splits` are extra nodes on the straights
    as {side: [coordinates along it]} with side one of bottom, right, top, left."""
    cx0, cy0, cx1, cy1 = x0 + r, y0 + r, x1 - r, y1 - r
    sides = [  # start, end, heading, corner centre and angles that follow
        ("bottom", (cx0, y0), (cx1, y0), E, (cx1, cy0), -PI / 2, 0),
        ("right", (x1, cy0), (x1, cy1), N, (cx1, cy1), 0, PI / 2),
        ("top", (cx1, y1), (cx0, y1), W, (cx0, cy1), PI / 2, PI),
        ("left", (x0, cy1), (x0, cy0), S, (cx0, cy0), PI, 3 * PI / 2),
    ]
    for name, p0, p1, yaw, centre, a0, a1 in sides:
        stops = [p0]
        horizontal = name in ("bottom", "top")
        for c in splits.get(name, []):
            stops.append((c, p0[1]) if horizontal else (p0[0], c))
        stops.append(p1)
        for a, b in zip(stops, stops[1:]):
            g.edge(line(a, b), yaw, yaw)
        g.edge(arc(centre, r, a0, a1), yaw, yaw + PI / 2)


def intersection():
    g = Graph()
    r, h = 0.75, LANE / 2          # turning radius of the cross's lanes; half the lane spacing
    vx, hy = 2.25, 2.0             # the cross's centre lines
    nb, sb, eb, wb = vx + h, vx - h, hy - h, hy + h   # the four lanes of the cross
    # The ring: inner lane x 0.65..3.85, y 0.65..3.35 (corners r 0.75); outer lane LANE further out
    # (lanes this far apart let two cars pass in the corners).
    o = LANE
    rounded_rectangle(g, 0.65, 0.65, 3.85, 3.35, 0.75,
                      {"bottom": [nb - r, sb + r], "top": [sb + r, nb - r], "right": [wb - r, eb + r], "left": [eb + r, wb - r]})
    rounded_rectangle(g, 0.65 - o, 0.65 - o, 3.85 + o, 3.35 + o, 0.75 + o, {})
    # Lane changes: out to the outer lane on the bottom straight, back in on the top one (one
    # way each, so that they do not cross and a car may wait beside them).
    g.edge(lane_change((nb - r, 0.65), (3.10, 0.65 - o)), E, E)
    g.edge(lane_change((3.10, 3.35 + o), (nb - r, 3.35)), W, W)
    # The cross (right-hand traffic): each lane leaves the ring with a left turn, crosses the
    # centre and joins the ring with a left turn.
    g.edge(arc((nb - r, 1.40), r, -PI / 2, 0), E, N)        # bottom ring -> northbound
    g.edge(line((nb, 1.40), (nb, 2.60)), N, N)
    g.edge(arc((nb - r, 2.60), r, 0, PI / 2), N, W)         # northbound -> top ring
    g.edge(arc((sb + r, 2.60), r, PI / 2, PI), W, S)        # top ring -> southbound
    g.edge(line((sb, 2.60), (sb, 1.40)), S, S)
    g.edge(arc((sb + r, 1.40), r, PI, 3 * PI / 2), S, E)    # southbound -> bottom ring
    g.edge(arc((1.40, eb + r), r, PI, 3 * PI / 2), S, E)    # left ring -> eastbound
    g.edge(line((1.40, eb), (3.10, eb)), E, E)
    g.edge(arc((3.10, eb + r), r, -PI / 2, 0), E, N)        # eastbound -> right ring
    g.edge(arc((3.10, wb - r), r, 0, PI / 2), N, W)         # right ring -> westbound
    g.edge(line((3.10, wb), (1.40, wb)), W, W)
    g.edge(arc((1.40, wb - r), r, PI / 2, PI), W, S)        # westbound -> left ring
    return g


def ring():
    g = Graph()
    rounded_rectangle(g, 0.5, 0.5, 4.0, 3.5, 0.9, {})
    return g


if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    intersection().write(os.path.join(here, "intersection.json"), LANE)
    ring().write(os.path.join(here, "ring.json"), LANE)
