#!/usr/bin/env python3
"""Where a label's gap to its perfect-label bound comes from, in one case of the segmentation table.

`bench/segmentation_table.py` leaves in its work folder, per case, the slices of every labelling
(WORK/CASE.METHOD.slices.json), the perfect-label slices (WORK/CASE.perfect.slices.json, the truth
label frames through the same contour and placement code, one slice per kept frame in the same
order) and the truth meshes (WORK/CASE_truth/label_L.ply). This script turns the labelling's slices
into the perfect ones in three steps, replacing whole slices (so that every intermediate set is a
valid slice set), reconstructs and scores label L after each step, and prints how much of the gap
each step closes:

  1. missed     the slices whose truth holds L but whose labelling has no region of L
                (slivers of an organ's ends below what the image resolves, organs in shadow);
  2. outlines   the slices where both hold L (the outline of the organ as segmented);
  3. elsewhere  every other slice (the other organs' outlines and the unknown areas, which
                shape L's field too: the unknown-region completion and the shared octree).

It also prints, from the labelling's frame-by-frame report (WORK/CASE.METHOD.seg.json), how many
pixels of L lie in frames whose truth has none of L.

With --missed-as-unknown M1,M2,... it asks whether a labelling that cannot see L in the missed
slices should call the place unknown rather than background: starting from the perfect slices, it
leaves L out of the missed slices (background), then instead replaces each of L's regions there
by an unknown disc about the region's vertex centroid, reaching M mm beyond its farthest vertex,
and reconstructs each set.

With --grow-perfect D1,D2,... it asks whether the perfect labels are the best input the engine can
get: it moves every outline of L in the perfect slices outwards by D mm (inwards for D < 0; each
vertex along the bisector of its edges' normals, and the hole of a region around L with it), and
reconstructs each set. Every slice from `segment` (the perfect ones included) runs its outlines a
quarter pixel inside the edges of the label's pixels (docs/segmentation.md, "Necks"), and the
engine's interpolation and smoothing round a small organ off between its slices.

The steps telescope: their sum is the whole gap. The order matters (the steps do not add up
independently), so the figures say how much each part of the slice set holds given the ones
before it.

    python3 bench/segmentation_gap.py --work out/bench/segmentation --case default_convex_sweep_low \
        --method graphcut_prior --label 2 [--depth 7] [--binary build/apps/sonoshape] \
        [--missed-as-unknown 1,2,4] [--grow-perfect=-0.1,0.1,0.2]

METHOD is the file name's method: threshold, graphcut, graphcut_prior, or issue_baseline (the
table's --issue-baseline build). The script also prints the label's area summed over the slices of
the labelling and of the perfect labels, beside its pixels in the truth frames: the perfect slices
come out smaller than those pixels by the quarter pixel their outlines run inside them.
"""
import argparse
import copy
import json
import math
import os
import sys

# The same reconstruct-and-evaluate step as the table's.
from segmentation_table import header_field, iou, scan_scores


def scan_iou(args, slices_path, label, truth_mesh):
    """Reconstructs `slices_path` and returns label's volume IoU (0 without a mesh)."""
    scores = scan_scores(args, slices_path[:-len(".slices.json")], slices_path,
                         [(label, truth_mesh)])
    return iou(scores.get(label)) or 0.0


def unknown_disc(region, margin_mm, corners=32):
    """An unknown region: a disc about the region's vertex centroid, margin_mm beyond its
    farthest vertex."""
    points = region["polygon"]
    cx = sum(p[0] for p in points) / len(points)
    cy = sum(p[1] for p in points) / len(points)
    radius = max(math.hypot(p[0] - cx, p[1] - cy) for p in points) + margin_mm
    return {"label": "unknown",
            "polygon": [[cx + radius * math.cos(2 * math.pi * k / corners),
                         cy + radius * math.sin(2 * math.pi * k / corners)] for k in range(corners)]}


def signed_area(ring):
    return 0.5 * sum(ring[i - 1][0] * ring[i][1] - ring[i][0] * ring[i - 1][1]
                     for i in range(len(ring)))


def grown_ring(ring, distance_mm):
    """`ring` moved outwards by distance_mm (inwards when negative): each vertex along the
    bisector of its two edges' outward normals, by distance / cos(half the turn), the turn's
    factor capped at 1/0.9 so that sharp corners do not shoot out (an approximation for small
    distances, not an exact offset curve)."""
    sign = 1.0 if signed_area(ring) > 0 else -1.0  # outward normal of an edge: right of it
    out = []
    for i, b in enumerate(ring):
        a, c = ring[i - 1], ring[(i + 1) % len(ring)]
        normals = []
        for u, v in ((a, b), (b, c)):
            ex, ey = v[0] - u[0], v[1] - u[1]
            length = math.hypot(ex, ey) or 1.0
            normals.append((sign * ey / length, -sign * ex / length))
        mx, my = normals[0][0] + normals[1][0], normals[0][1] + normals[1][1]
        length = math.hypot(mx, my) or 1.0
        mx, my = mx / length, my / length
        step = distance_mm / max(mx * normals[0][0] + my * normals[0][1], 0.9)
        out.append([b[0] + step * mx, b[1] + step * my])
    return out


def label_area_mm2(slice_set, label):
    """The area of `label`'s regions (holes cut out) summed over every slice."""
    return sum(abs(signed_area(region["polygon"])) -
               sum(abs(signed_area(hole)) for hole in region.get("holes", []))
               for slice_ in slice_set["slices"] for region in slice_["regions"]
               if region["label"] == label)


def grow_label(slice_set, label, distance_mm):
    """Moves every outline of `label` by distance_mm; a hole of another region that holds one of
    them (its vertex centroid within 3 mm) becomes the moved outline, so the regions still only
    share edges."""
    def centroid(ring):
        return (sum(p[0] for p in ring) / len(ring), sum(p[1] for p in ring) / len(ring))
    for slice_ in slice_set["slices"]:
        moved = []
        for region in slice_["regions"]:
            if region["label"] == label:
                region["polygon"] = grown_ring(region["polygon"], distance_mm)
                moved.append(region["polygon"])
        for region in slice_["regions"]:
            if region["label"] == label or not region.get("holes") or not moved:
                continue
            holes = []
            for hole in region["holes"]:
                nearest = min(moved, key=lambda ring: math.dist(centroid(ring), centroid(hole)))
                holes.append(nearest if math.dist(centroid(nearest), centroid(hole)) < 3.0 else hole)
            region["holes"] = holes


def holds(slice_, label):
    return any(region["label"] == label for region in slice_["regions"])


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "segmentation"))
    parser.add_argument("--case", required=True, help="e.g. default_convex_sweep_low")
    parser.add_argument("--method", default="graphcut_prior",
                        help="threshold, graphcut or graphcut_prior")
    parser.add_argument("--label", type=int, required=True)
    parser.add_argument("--depth", type=int, default=7)
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--missed-as-unknown", default="",
                        help="margins in mm, e.g. 1,2,4 (see the module's docstring)")
    parser.add_argument("--grow-perfect", default="",
                        help="distances in mm, e.g. -0.1,0.1,0.2 (see the module's docstring)")
    args = parser.parse_args()

    base = os.path.join(args.work, args.case)
    truth_mesh = os.path.join(base + "_truth", f"label_{args.label}.ply")
    with open(f"{base}.{args.method}.slices.json") as f:
        ours = json.load(f)
    with open(base + ".perfect.slices.json") as f:
        perfect = json.load(f)
    if len(ours["slices"]) != len(perfect["slices"]) or any(
            a["timestamp"] != b["timestamp"] for a, b in zip(ours["slices"], perfect["slices"])):
        sys.exit(f"{base}: the {args.method} and perfect slice sets do not hold the same frames "
                 "(rerun bench/segmentation_table.py for this case)")

    missed = [i for i, (a, b) in enumerate(zip(ours["slices"], perfect["slices"]))
              if holds(b, args.label) and not holds(a, args.label)]
    both = [i for i, (a, b) in enumerate(zip(ours["slices"], perfect["slices"]))
            if holds(b, args.label) and holds(a, args.label)]
    steps = [("missed", missed), ("outlines", both),
             ("elsewhere", [i for i in range(len(ours["slices"])) if i not in missed + both])]

    work = f"{base}.gap{args.label}"
    start = scan_iou(args, f"{base}.{args.method}.slices.json", args.label, truth_mesh)
    bound = scan_iou(args, base + ".perfect.slices.json", args.label, truth_mesh)
    print(f"{args.case}, label {args.label}, {args.method}: IoU {start:.3f}, perfect labels "
          f"{bound:.3f}, gap {bound - start:.3f}")
    # From the labelling's frame-by-frame report (segment --report): the label where the truth
    # frame has none of it (an organ made of speckle, or the label given to the wrong organ).
    report_path = f"{base}.{args.method}.seg.json"
    if os.path.exists(report_path):
        with open(report_path) as f:
            frames = json.load(f)["frames"]
        stray = [fr["labels"][str(args.label)]["ours_px"] for fr in frames
                 if fr["labels"].get(str(args.label), {}).get("ours_px", 0) > 0
                 and fr["labels"][str(args.label)].get("truth_px", 0) == 0]
        print(f"pixels of label {args.label} in frames whose truth has none of it: {sum(stray)} "
              f"in {len(stray)} of {len(frames)} frames")
    # The areas the slices give the label, beside its pixels in the truth frames (from any of the
    # table's reports: every labelling's report counts the same truth pixels).
    areas = f"area of label {args.label} over all slices: {label_area_mm2(ours, args.label):.1f} mm² " \
            f"({args.method}), {label_area_mm2(perfect, args.label):.1f} mm² (perfect labels)"
    spacing = header_field(base + ".igs.mha", "SonoshapePixelSpacingMm")
    if spacing and os.path.exists(base + ".threshold.seg.json"):
        with open(base + ".threshold.seg.json") as f:
            frames = json.load(f)["frames"]
        truth_px = sum(fr["labels"].get(str(args.label), {}).get("truth_px", 0) for fr in frames)
        areas += f", {truth_px * float(spacing) ** 2:.1f} mm² (its pixels in the truth frames)"
    print(areas)
    print("| step | slices replaced | IoU after | gap closed |")
    print("|---|---|---|---|")
    current, previous = ours, start
    for name, indices in steps:
        for i in indices:
            current["slices"][i] = perfect["slices"][i]
        path = f"{work}.{name}.slices.json"
        with open(path, "w") as f:
            json.dump(current, f)
        value = scan_iou(args, path, args.label, truth_mesh)
        print(f"| {name} | {len(indices)} | {value:.3f} | {value - previous:+.3f} |")
        previous = value

    if args.missed_as_unknown and missed:
        print(f"\nperfect slices, label {args.label} in the {len(missed)} missed slices as:")
        print("| missed slivers become | IoU |")
        print("|---|---|")
        variants = [("background", None)] + [
            (f"unknown, disc {m} mm beyond", float(m)) for m in args.missed_as_unknown.split(",")]
        for name, margin in variants:
            changed = copy.deepcopy(perfect)
            for i in missed:
                regions = changed["slices"][i]["regions"]
                kept = [r for r in regions if r["label"] != args.label]
                if margin is not None:
                    kept += [unknown_disc(r, margin) for r in regions if r["label"] == args.label]
                changed["slices"][i]["regions"] = kept
            path = f"{work}.missed_{'background' if margin is None else f'unknown{margin:g}'}.slices.json"
            with open(path, "w") as f:
                json.dump(changed, f)
            print(f"| {name} | {scan_iou(args, path, args.label, truth_mesh):.3f} |")

    if args.grow_perfect:
        print(f"\nperfect slices (IoU {bound:.3f}) with every outline of label {args.label} moved:")
        print("| outwards by | IoU |")
        print("|---|---|")
        for distance in (float(d) for d in args.grow_perfect.split(",")):
            changed = copy.deepcopy(perfect)
            grow_label(changed, args.label, distance)
            path = f"{work}.grown{distance:+g}.slices.json"
            with open(path, "w") as f:
                json.dump(changed, f)
            print(f"| {distance:+g} mm | {scan_iou(args, path, args.label, truth_mesh):.3f} |")


if __name__ == "__main__":
    main()
