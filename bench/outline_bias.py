#!/usr/bin/env python3
"""How far a slice set's outlines sit outside (+) or inside (-) the truth, per organ, in mm.

For every slice of SLICES (a slices.json, e.g. a scan's) and every organ of the truth meshes
(TRUTH/label_L.ply, as `sonoshape simulate --truth` writes them), the organ's exact cut by the
slice's plane, clipped to the slice's fov (bench/field_table.py's cutter), is compared with the
slice's regions of that label where the slice does not say unknown (a shadow is no outline
error): the outline's mean offset is (area ours - area exact) / perimeter exact, both outside
the slice's unknown regions (areas by scanlines 0.02 mm apart; the perimeter of the exact
outline's edges whose midpoint is not unknown). Printed per organ: the slices that hold it in
both, the median offset over those slices (robust to a missed sliver or a joined gap), the
pooled offset (sum of area differences over sum of perimeters) and the mean distance of the
outlines from the exact ones (the area in one but not the other, outside the unknown regions,
over the exact perimeter, pooled).

Usage: bench/outline_bias.py SLICES TRUTH_DIR [--json FILE]
"""
import argparse
import json
import math
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from field_table import (clip_rings, cut_mesh, inside, nest, read_ply,  # noqa: E402
                         truth_files, welded)

UNKNOWN = "unknown"  # the unknown label of slices.json


def exact_regions(mesh, s):
    vertices, triangles = mesh
    rings = cut_mesh(vertices, triangles, s["origin"], s["u"], s["v"])
    if not rings:
        return []
    xs = [p[0] for r in rings for p in r]
    ys = [p[1] for r in rings for p in r]
    size = max(math.hypot(max(xs) - min(xs), max(ys) - min(ys)), 1e-9)
    min_area = 1e-10 * size * size
    return clip_rings(rings, s["fov"], min_area) if s.get("fov") else nest(rings, min_area)


ROW_MM = 0.02


def crossings(rings, y):
    """Sorted x where the horizontal line at y crosses the rings (even-odd intervals)."""
    xs = []
    for ring in rings:
        for i in range(len(ring)):
            (ax, ay), (bx, by) = ring[i - 1], ring[i]
            if (ay > y) != (by > y):
                xs.append(ax + (y - ay) * (bx - ax) / (by - ay))
    xs.sort()
    return list(zip(xs[0::2], xs[1::2]))


def minus_length(intervals, cut):
    """Total length of `intervals` outside `cut` (both sorted, disjoint)."""
    total = 0.0
    for a, b in intervals:
        length = b - a
        for c, d in cut:
            length -= max(0.0, min(b, d) - max(a, c))
        total += length
    return total


def union(a, b):
    """The union of two sets of sorted intervals, sorted and disjoint."""
    merged = []
    for lo, hi in sorted(a + b):
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def known_symmetric_difference(a, b, unknown, y0, y1):
    """Area in one set of rings but not the other, outside the unknown rings."""
    area, y = 0.0, y0 + 0.5 * ROW_MM
    while y < y1:
        ia, ib, iu = crossings(a, y), crossings(b, y), crossings(unknown, y)
        area += (minus_length(ia, union(ib, iu)) + minus_length(ib, union(ia, iu))) * ROW_MM
        y += ROW_MM
    return area


def known_area(rings, unknown, y0, y1):
    area, y = 0.0, y0 + 0.5 * ROW_MM
    while y < y1:
        area += minus_length(crossings(rings, y), crossings(unknown, y)) * ROW_MM
        y += ROW_MM
    return area


def rings_of(regions):
    return [ring for r in regions for ring in [r["polygon"]] + list(r.get("holes", []))]


def inside_any(rings, p):
    return sum(inside(ring, p) for ring in rings) % 2 == 1


def known_perimeter(rings, unknown):
    total = 0.0
    for ring in rings:
        for i in range(len(ring)):
            a, b = ring[i - 1], ring[i]
            if not inside_any(unknown, ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)):
                total += math.dist(a, b)
    return total


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("slices")
    parser.add_argument("truth")
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    with open(args.slices) as f:
        document = json.load(f)
    slices = document["slices"]
    names = {entry["id"]: entry.get("name", "") for entry in document.get("labels", [])}
    meshes = {}
    for label, path in truth_files(args.truth):
        meshes[label] = welded(*read_ply(path))
    result = {}
    for label, mesh in meshes.items():
        offsets, area_diff, apart, length = [], 0.0, 0.0, 0.0
        for s in slices:
            exact = rings_of(exact_regions(mesh, s))
            ours = rings_of([r for r in s.get("regions", []) if r["label"] == label])
            if not exact or not ours:
                continue
            unknown = rings_of([r for r in s.get("regions", []) if r["label"] == UNKNOWN])
            ys = [p[1] for ring in exact + ours for p in ring]
            a_exact = known_area(exact, unknown, min(ys), max(ys))
            a_ours = known_area(ours, unknown, min(ys), max(ys))
            p_exact = known_perimeter(exact, unknown)
            if a_exact <= 0.0 or a_ours <= 0.0 or p_exact <= 0.0:
                continue
            offsets.append((a_ours - a_exact) / p_exact)
            area_diff += a_ours - a_exact
            apart += known_symmetric_difference(ours, exact, unknown, min(ys), max(ys))
            length += p_exact
        result[label] = {
            "slices": len(offsets),
            "median_offset_mm": statistics.median(offsets) if offsets else None,
            "pooled_offset_mm": area_diff / length if length else None,
            "mean_distance_mm": apart / length if length else None,
        }
    print("| organ | slices | median offset (mm) | pooled offset (mm) | mean distance (mm) |")
    print("|---|---|---|---|---|")
    for label, r in result.items():
        def fmt(x):
            return "-" if x is None else f"{x:+.3f}"
        print(f"| {label} {names.get(label, '')}".rstrip() +
              f" | {r['slices']} | {fmt(r['median_offset_mm'])} | {fmt(r['pooled_offset_mm'])}"
              f" | {fmt(r['mean_distance_mm']).lstrip('+')} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
