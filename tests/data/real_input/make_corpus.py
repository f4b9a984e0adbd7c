#!/usr/bin/env python3
"""Writes the small .csl / .slices.json corpus of tests/real_input_test.cpp.

Each file reproduces one convention or fault found in public cross-section datasets (the OReX
collection: hand, Vertebrae, Abdomen, rose, ...) on a shape whose volume and topology are known:
stacks of parallel planes z = 0, 4, ..., 20, closed by empty planes at z = -2 and z = 22.
Run it from anywhere; it rewrites the files next to itself. Deterministic (fixed noise seed).
"""
import json
import math
import os
import random

HERE = os.path.dirname(os.path.abspath(__file__))
ZS = [0.0, 4.0, 8.0, 12.0, 16.0, 20.0]
CAPS = [-2.0, 22.0]
N = 32  # points per circle


def circle(cx, cy, r, n=N, start=0.0, clockwise=False):
    s = -1.0 if clockwise else 1.0
    return [(cx + r * math.cos(start + s * 2 * math.pi * k / n),
             cy + r * math.sin(start + s * 2 * math.pi * k / n)) for k in range(n)]


def num(x):
    text = "%.10f" % x
    return "0.0000000000" if text == "-0.0000000000" else text


def write_csl(name, n_labels, planes, d_sign=1.0, z_noise=0.0):
    """planes: list of (z, [(head, label, points)]); head is "" or "h<parent>".

    The plane is written 0 0 1 D with D = -z * d_sign (d_sign = -1 flips D, as rose.csl does).
    """
    rng = random.Random(7)
    ordered = sorted(planes + [(z, []) for z in CAPS], key=lambda p: p[0])
    out = ["CSLC", "%d %d" % (len(ordered), n_labels), ""]
    for index, (z, comps) in enumerate(ordered, start=1):
        n_vertices = sum(len(pts) for _, _, pts in comps)
        out.append("%d %d %d 0 0 1 %s" % (index, n_vertices, len(comps), num(-z * d_sign)))
        for _, _, pts in comps:
            for x, y in pts:
                dz = rng.uniform(-z_noise, z_noise) if z_noise else 0.0
                out.append("%s %s %s" % (num(x), num(y), num(z + dz)))
        next_index = 0
        for head, label, pts in comps:
            ids = " ".join(str(next_index + k) for k in range(len(pts)))
            next_index += len(pts)
            out.append("%d%s %d %s" % (len(pts), head, label, ids))
        out.append("")
    with open(os.path.join(HERE, name), "w") as f:
        f.write("\n".join(out))


def stack(components):
    return [(z, components) for z in ZS]


def lemniscate(a, n=2 * N):
    """Bernoulli's lemniscate: a figure-8 crossing itself at the origin, lobes of area a^2 / 2."""
    pts = []
    for k in range(n):
        t = 2 * math.pi * (k + 0.5) / n  # no sample exactly at the crossing
        s = 1 + math.sin(t) ** 2
        pts.append((a * math.cos(t) / s, a * math.sin(t) * math.cos(t) / s))
    return pts


def pinched():
    """Two circles of radius 5 touching at the origin, traced as one contour through it."""
    a = circle(-5, 0, 5, start=0.0)  # starts at the origin
    b = circle(5, 0, 5, start=math.pi)  # starts at the origin too
    return a + b


def small_loop():
    """A circle of radius 10 whose contour curls once, inside, around a 2 x 2 patch near (0, -9)."""
    pts = []
    for k in range(N):
        t = -math.pi / 2 + 2 * math.pi * k / N
        pts.append((10 * math.cos(t), 10 * math.sin(t)))
        if k == 0:  # at (0, -10): go right, up into the disc, left, back down across the path
            pts += [(1.0, -10.0 + 0.05), (1.0, -7.0), (-1.0, -7.0), (-1.0, -9.6), (1.2, -9.6)]
    return pts


def spike():
    """A circle of radius 10 with a spike out to (15, 0) and back along the same line."""
    pts = circle(0, 0, 10)
    return pts[:1] + [(15.0, 0.0)] + pts


def main():
    outer = circle(0, 0, 10)
    hole = circle(0, 0, 4, clockwise=True)
    # A tube (genus 1): the three conventions for a hole that is the outside.
    for name, hole_label in [("hole_label_parent.csl", 1), ("hole_label_zero.csl", 0),
                             ("hole_label_nlabels.csl", 2)]:
        write_csl(name, 2, stack([("", 1, outer), ("h0", hole_label, hole)]))
    # A tube of material 1 filled by material 2 through the hole's label (nLabels = 3).
    write_csl("hole_filled_by_material.csl", 3, stack([("", 1, outer), ("h0", 2, hole)]))
    # Nested materials as Abdomen writes them: a hole with the parent's label, and a component of
    # material 2 inside it, and material 3 inside a hole of material 2; nLabels = 20.
    write_csl("nested_materials.csl", 20,
              stack([("", 1, outer), ("h0", 1, circle(0, 0, 6, clockwise=True)),
                     ("", 2, circle(0, 0, 5)), ("h2", 2, circle(0, 0, 2.5, clockwise=True)),
                     ("", 3, circle(0, 0, 1.8))]))
    write_csl("figure_eight.csl", 2, stack([("", 1, lemniscate(10.0))]))
    write_csl("pinched_ring.csl", 2, stack([("", 1, pinched())]))
    write_csl("small_loop.csl", 2, stack([("", 1, small_loop())]))
    write_csl("spike.csl", 2, stack([("", 1, spike())]))
    write_csl("flipped_d.csl", 2, stack([("", 1, outer)]), d_sign=-1.0)
    write_csl("off_plane_noise.csl", 2, stack([("", 1, outer)]), z_noise=1e-4)

    # The figure-8 again as a JSON slice set, for the JSON reader's repair.
    slices = [{"origin": [0, 0, z], "u": [1, 0, 0], "v": [0, 1, 0], "regions": []} for z in CAPS]
    for z in ZS:
        slices.append({"origin": [0, 0, z], "u": [1, 0, 0], "v": [0, 1, 0],
                       "regions": [{"label": 1, "polygon": [[round(x, 10), round(y, 10)]
                                                            for x, y in lemniscate(10.0)]}]})
    slices.sort(key=lambda s: s["origin"][2])
    with open(os.path.join(HERE, "figure_eight.slices.json"), "w") as f:
        json.dump({"format": "sonoshape-slices", "version": 1, "units": "mm", "slices": slices}, f)
        f.write("\n")


if __name__ == "__main__":
    main()
