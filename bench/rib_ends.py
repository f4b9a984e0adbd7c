#!/usr/bin/env python3
"""The default scan's rib with flat ends and with round ends, moved along the sweep (issue 38).

`field_table`'s `scan-exact` row cuts the default phantom's truth meshes exactly with the default
scan's planes and fields of view. Its rib is a 48-sided prism along the sweep with flat ends,
and there the thin-plate field scores below the nearest-slice baseline. This script asks whether
that is the ends' shape or the planes' placement. It cuts two ribs with the same planes:

- `flat`: the phantom's rib as it is (flat ends across the sweep);
- `round`: a capsule of the same axis, radius, 48-sided section and overall length, its ends
  hemispheres;

each moved along its axis by several shifts (mm), so that the planes fall elsewhere on the ends.
The spot and cheburashka truths are cut too, as in the row, so every reconstruction has the row's
three organs. Per rib and shift it prints the rib's IoU under the closest-point baseline and
under both fields (`sonoshape evaluate --slices`: IoU on its 200³ grid over the slices' box), and
a summary line per rib: the thin-plate field's margin over the baseline, least to largest.

--write-doc puts the table into docs/benchmarks.md between `<!-- rib_ends:begin -->` and
`<!-- rib_ends:end -->`.

Usage: bench/rib_ends.py [--binary build/apps/sonoshape] [--work out/bench/rib_ends]
                         [--shifts 0,0.25,0.5,0.75,1] [--keep-inputs] [--write-doc]
"""
import argparse
import json
import math
import os
import struct
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import field_table as ft  # noqa: E402  (the scan, the exact cuts and the PLY reader)
from doc_tables import provenance, write_between_markers  # noqa: E402

FIELDS = ["mean-value", "thin-plate"]
SECTION_SIDES = 48  # the phantom's rib is a 48-sided prism
CAP_RINGS = 12      # rings of a hemisphere of the round-ended rib


def write_ply(path, vertices, triangles):
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(triangles)}\nproperty list uchar int vertex_indices\n"
                 "end_header\n").encode())
        for v in vertices:
            f.write(struct.pack("<3f", *v))
        for t in triangles:
            f.write(struct.pack("<B3i", 3, *t))


def rib_frame(vertices):
    """(axis index, centre [x, y, z], radius, half length) of a round rod along a coordinate
    axis, from its box; raises Failed for any other shape (a changed phantom)."""
    low = [min(v[a] for v in vertices) for a in range(3)]
    high = [max(v[a] for v in vertices) for a in range(3)]
    size = [high[a] - low[a] for a in range(3)]
    axis = max(range(3), key=lambda a: size[a])
    across = sorted(size[a] for a in range(3) if a != axis)
    if across[1] - across[0] > 0.01 * across[1] or size[axis] <= across[1]:
        raise ft.Failed(f"the phantom's rib is no longer a round rod along an axis (its box is "
                        f"{size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm): this script "
                        "needs rib_frame() and round_ended() made for its new shape")
    centre = [0.5 * (low[a] + high[a]) for a in range(3)]
    return axis, centre, 0.5 * across[1], 0.5 * size[axis]


def round_ended(axis, centre, radius, half_length):
    """A capsule along `axis`: SECTION_SIDES-sided rings, hemispherical ends, the same length."""
    b, c = [a for a in range(3) if a != axis]
    straight = half_length - radius
    profile = []  # (ring radius, position along the axis)
    for end, sign in ((-1, -1.0), (1, 1.0)):
        for i in range(CAP_RINGS + 1):
            angle = 0.5 * math.pi * i / CAP_RINGS  # from the pole to the equator
            if end == 1:
                angle = 0.5 * math.pi - angle      # from the equator to the pole
            profile.append((radius * math.sin(angle),
                            sign * (straight + radius * math.cos(angle))))
    vertices, rings = [], []
    for ring_radius, along in profile:
        if ring_radius < 1e-9 * radius:
            p = list(centre)
            p[axis] += along
            rings.append([len(vertices)] * SECTION_SIDES)
            vertices.append(p)
            continue
        ring = []
        for k in range(SECTION_SIDES):
            t = 2.0 * math.pi * k / SECTION_SIDES
            p = list(centre)
            p[axis] += along
            p[b] += ring_radius * math.cos(t)
            p[c] += ring_radius * math.sin(t)
            ring.append(len(vertices))
            vertices.append(p)
        rings.append(ring)
    triangles = []
    for lower, upper in zip(rings, rings[1:]):
        for k in range(SECTION_SIDES):
            k1 = (k + 1) % SECTION_SIDES
            for t in ((lower[k], lower[k1], upper[k1]), (lower[k], upper[k1], upper[k])):
                if len(set(t)) == 3:
                    triangles.append(t)
    # Outward normals whatever the axis: a closed mesh facing outwards has a positive volume.
    if signed_volume(vertices, triangles) < 0.0:
        triangles = [(t[0], t[2], t[1]) for t in triangles]
    return vertices, triangles


def signed_volume(vertices, triangles):
    total = 0.0
    for i, j, k in triangles:
        total += ft.dot(vertices[i], ft.cross(vertices[j], vertices[k])) / 6.0
    return total


def moved(vertices, axis, shift_mm):
    out = [list(v) for v in vertices]
    for v in out:
        v[axis] += shift_mm
    return out


def rib_scores(args, slices, recon, rib_label, rib_mesh):
    """(the reconstruction's rib IoU, the closest-point baseline's rib IoU) from `evaluate`."""
    out = ft.run([args.binary, "evaluate", "--recon", recon, "--slices", slices, "--truth",
                  f"{rib_label}:{rib_mesh}:rib"], "evaluate").stdout
    for line in out.splitlines():
        words = line.split()
        if len(words) >= 4 and words[0] == str(rib_label):
            return float(words[2]), float(words[3])
    raise ft.Failed(f"evaluate printed no line for label {rib_label}:\n{out}")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "rib_ends"))
    parser.add_argument("--shifts", default="0,0.25,0.5,0.75,1",
                        help="mm along the rib's axis, comma-separated")
    parser.add_argument("--keep-inputs", action="store_true",
                        help="reuse the scan and truth meshes already in --work")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    start = (time.monotonic(), os.getloadavg()[0])
    shifts = [float(s) for s in args.shifts.split(",") if s]
    if not os.access(args.binary, os.X_OK):
        raise SystemExit(f"no sonoshape binary at {args.binary} (build it, or pass --binary)")
    args.scan_done = False
    os.makedirs(args.work, exist_ok=True)
    # The scan and the phantom's truths, as field_table makes them for its scan rows.
    ft.prepare_scan(args, "scan-segmented", args.work)
    template = os.path.join(args.work, "scan", "out", "slices.json")
    truths = ft.truth_files(os.path.join(args.work, "scan", "truth"))
    with open(template) as f:
        labels = json.load(f)["labels"]
    rib_label = next(l["id"] for l in labels if l.get("name") == "rib")
    others = [(label, path) for label, path in truths if label != rib_label]
    flat_vertices, flat_triangles = ft.read_ply(dict(truths)[rib_label])
    axis, centre, radius, half_length = rib_frame(flat_vertices)
    round_vertices, round_triangles = round_ended(axis, centre, radius, half_length)

    rows = []
    for name, (vertices, triangles) in (("flat", (flat_vertices, flat_triangles)),
                                        ("round", (round_vertices, round_triangles))):
        for shift in shifts:
            folder = os.path.join(args.work, f"{name}-{shift:g}")
            os.makedirs(folder, exist_ok=True)
            mesh = os.path.join(folder, "rib.ply")
            write_ply(mesh, moved(vertices, axis, shift), triangles)
            slices = os.path.join(folder, "slices.json")
            ft.exact_slices(template, others + [(rib_label, mesh)], slices)
            row = {"rib": name, "shift": shift}
            for field in FIELDS:
                recon = os.path.join(folder, f"recon-{field}")
                ft.run([args.binary, "reconstruct", slices, "-o", recon, "--field", field, "-q"],
                       f"reconstruct --field {field} ({name}, {shift:g} mm)")
                row[field], row["baseline"] = rib_scores(args, slices, recon, rib_label, mesh)
            rows.append(row)
            print(f"{name} {shift:g} mm: baseline {row['baseline']:.4f}, "
                  f"mean-value {row['mean-value']:.4f}, thin-plate {row['thin-plate']:.4f}",
                  file=sys.stderr)

    lines = ["| rib ends | shift (mm) | baseline IoU | mean-value IoU | thin-plate IoU | "
             "thin-plate − baseline |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['rib']} | {r['shift']:g} | {r['baseline']:.4f} | "
                     f"{r['mean-value']:.4f} | {r['thin-plate']:.4f} | "
                     f"{r['thin-plate'] - r['baseline']:+.4f} |")
    lines.append("")
    for name in ("flat", "round"):
        margins = [r["thin-plate"] - r["baseline"] for r in rows if r["rib"] == name]
        above = sum(m >= 0.0 for m in margins)
        lines.append(f"- {name} ends: thin-plate − baseline from {min(margins):+.4f} to "
                     f"{max(margins):+.4f}; at or above the baseline at {above} of "
                     f"{len(margins)} shifts.")
    text = "\n".join(lines)
    print(text)
    if args.write_doc:
        write_between_markers(root, "rib_ends", text + "\n\n" +
                              provenance(root, start[1], time.monotonic() - start[0]))


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ft.Failed as e:
        raise SystemExit(f"rib_ends: {e}")
