#!/usr/bin/env python3
"""The "two cylinders with a noisy middle slice" case of Bermano et al. (2011), Figure 10.

Slices z = -15, 0, 15 cut two vertical cylinders (radius 10 mm, centres 34 mm apart, z from -25
to 25). On the middle slice a noisy blob covers the 14 mm gap and the inner 5 mm of both discs.
Writes, next to this script:
  two_cylinders_unknown.slices.json  the blob marked unknown (what sonoshape segmentation reports)
  two_cylinders_noise.slices.json    the blob taken as inside (a segmentation without "unknown")
  two_cylinders_truth/label_1.ply    the two cylinders (ground truth for sonoshape evaluate)
"""
import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))
RADIUS, CENTRES, HALF_HEIGHT = 10.0, [(-17.0, 0.0), (17.0, 0.0)], 25.0


def arc(centre, start_deg, end_deg, points=48):
    return [[centre[0] + RADIUS * math.cos(math.radians(start_deg + (end_deg - start_deg) * k / points)),
             centre[1] + RADIUS * math.sin(math.radians(start_deg + (end_deg - start_deg) * k / points))]
            for k in range(points + 1)]


def circle(centre, points=64):
    return [[centre[0] + RADIUS * math.cos(2 * math.pi * k / points),
             centre[1] + RADIUS * math.sin(2 * math.pi * k / points)] for k in range(points)]


def slice_at(z, regions):
    return {"origin": [0.0, 0.0, z], "u": [1.0, 0.0, 0.0], "v": [0.0, 1.0, 0.0], "regions": regions}


def slice_set(blob_label):
    # The parts of the discs left of x = -12 and right of x = 12 (60 degrees from the centres);
    # the blob shares the chords' end points with them.
    left, right = arc(CENTRES[0], 60.0, 300.0), arc(CENTRES[1], -120.0, 120.0)
    blob = [[-12.0, -10.0], [12.0, -10.0], right[0], right[-1], [12.0, 10.0], [-12.0, 10.0], left[0], left[-1]]
    if blob_label == "unknown":
        middle = [{"label": 1, "polygon": left}, {"label": 1, "polygon": right},
                  {"label": "unknown", "polygon": blob}]
    else:  # one material region: both disc parts joined by the blob
        middle = [{"label": 1, "polygon": right[:-1] + [[12.0, 10.0], [-12.0, 10.0]] + left + [[-12.0, -10.0], [12.0, -10.0]]}]
    slices = [slice_at(-15.0, [{"label": 1, "polygon": circle(c)} for c in CENTRES]),
              slice_at(0.0, middle),
              slice_at(15.0, [{"label": 1, "polygon": circle(c)} for c in CENTRES])]
    return {"format": "sonoshape-slices", "version": 1, "units": "mm",
            "labels": [{"id": 1, "name": "cylinders"}],
            "bounds": {"min": [-40.0, -25.0, -30.0], "max": [40.0, 25.0, 30.0]}, "slices": slices}


def cylinders_ply(path, segments=64):
    vertices, faces = [], []
    for cx, cy in CENTRES:
        base = len(vertices)
        for z in (-HALF_HEIGHT, HALF_HEIGHT):
            for k in range(segments):
                t = 2 * math.pi * k / segments
                vertices.append((cx + RADIUS * math.cos(t), cy + RADIUS * math.sin(t), z))
        vertices += [(cx, cy, -HALF_HEIGHT), (cx, cy, HALF_HEIGHT)]
        bottom, top = base + 2 * segments, base + 2 * segments + 1
        for k in range(segments):
            a, b = base + k, base + (k + 1) % segments
            faces += [(a, b, b + segments), (a, b + segments, a + segments),  # side, outward
                      (bottom, b, a), (top, a + segments, b + segments)]   # caps
    with open(path, "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
                "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (len(vertices), len(faces)))
        for v in vertices:
            f.write("%g %g %g\n" % v)
        for t in faces:
            f.write("3 %d %d %d\n" % t)


if __name__ == "__main__":
    for name, label in (("two_cylinders_unknown", "unknown"), ("two_cylinders_noise", 1)):
        with open(os.path.join(HERE, name + ".slices.json"), "w") as f:
            json.dump(slice_set(label), f, indent=1)
    os.makedirs(os.path.join(HERE, "two_cylinders_truth"), exist_ok=True)
    cylinders_ply(os.path.join(HERE, "two_cylinders_truth", "label_1.ply"))
