#!/usr/bin/env python3
"""The thin-plate and mean-value fields side by side, with the nearest-slice baseline (issue 38).

Rows (each a slice set with truth meshes; fixed counts and seeds):
  - every public .csl file with a reference surface in the OReX `Data/` folder (DIR, else
    $OREX_DATA; references found as bench/public_csl.py finds them);
  - simulated families cut from data/models by `sonoshape slice --size-mm 150 --seed 1`:
    random, orthogonal, parallel and sweep planes, a nested pair (spot with a copy of itself at
    30 % inside it, as bench/segmentation_table.py builds it) cut by a sweep, random planes with
    unknown blobs on 40 % of the slices, random planes seen through covering sector fields of
    view;
  - rocking sweeps of the default phantom (convex probe, 200 frames, seed 1), `sonoshape
    simulate --trajectory rock` (the probe tilted in its own plane: the slices stay within a few
    degrees and millimetres of one plane) and `--trajectory fan` (tilted across its plane: the
    slices fan out from the contact line), each through `segment --perfect-labels` every 4th
    frame (the truth label frames through the segmenter's contours; the sector and the rib's
    shadow are unknown);
  - the default simulated scan (`scan --source sim:default --fast -o DIR`): its own segmented
    slices (DIR/slices.json), and its exact slices: the same planes and fields of view, the truth
    meshes cut exactly by each plane (here, in Python) and clipped to the field of view;
  - optionally (--nwire, on by default when the file is there) the fCal 3-N-wire recording of
    PlusLibData, every frame segmented with `--preset wires`: no truth mesh, so the wire mesh's
    connected parts, each given to the phantom's wire it lies along (NWIRE_WIRES, the fCal 1.2
    phantom definition placed by the recording's PhantomToReference): parts per wire.
For each row and field this runs
  sonoshape reconstruct SLICES -o WORK/ROW/recon-FIELD --stats ... [--field FIELD] -q
      (wall seconds and peak RSS of that process, from wait4)
  sonoshape evaluate --recon ... --truth L:MESH:NAME ... --slices SLICES --json ... -q
and prints one Markdown table: per row and organ the closest-point baseline's IoU (evaluate's
`baseline_iou`), each field's IoU, each reconstruct's seconds and MB, and the connected parts of
the truth and of each reconstruction (evaluate's `components`: 6-connected inside samples of its
grid), then summary lines computed from the table. `--write-doc` puts it into docs/benchmarks.md
between `<!-- field_table:begin -->` and `<!-- field_table:end -->`.

A binary whose `reconstruct --help` has no --field runs the mean-value field only. The exit
status is non-zero when a command fails; its name and error are printed, and its row shows
FAILED.

Usage: bench/field_table.py [DIR] [--binary build/apps/sonoshape] [--work out/bench/field_table]
                            [--only NAME]... [--quick] [--fields mean-value,thin-plate]
                            [--depth D] [--reconstruct-args "ARGS"] [--nwire REC] [--no-nwire]
                            [--keep-inputs] [--write-doc]
"""
import argparse
import json
import math
import os
import re
import statistics
import struct
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers
from public_csl import REFERENCE_OF, find_files, header_counts
from segmentation_table import NESTED_SCALE, NESTED_SHIFT, write_scaled_obj

FIELDS = ["mean-value", "thin-plate"]
SHORT = {"mean-value": "mv", "thin-plate": "tp"}
EXT = {"horse": "ply"}
# name: (meshes as (label, model), plane family, count, extra `slice` options). "inner" is spot
# scaled by NESTED_SCALE inside spot (written to WORK/phantoms/).
SLICE_SETS = {
    "horse-random-40": ([(1, "horse")], "random", 40, []),
    "cheburashka-orthogonal-30": ([(1, "cheburashka")], "orthogonal", 30, []),
    "homer-parallel-20": ([(1, "homer")], "parallel", 20, []),
    "spot-sweep-40": ([(1, "spot")], "sweep", 40, []),
    "nested-sweep-20": ([(1, "spot"), (2, "inner")], "sweep", 20, ["--layout", "asis"]),
    "homer-random-30-unknown": ([(1, "homer")], "random", 30, ["--unknown", "0.4"]),
    "horse-random-30-fov": ([(1, "horse")], "random", 30,
                            ["--fov", "sector", "--fov-aim", "cover"]),
}
SLICE_SEED = 1
# Simulated freehand sweeps through perfect labels: row name -> `simulate --trajectory`.
SWEEPS = {"rock-perfect": "rock", "fan-perfect": "fan"}
SWEEP_FRAMES, SWEEP_EVERY, SWEEP_SEED = 200, 4, 1
SCAN_ROWS = ["scan-exact", "scan-segmented"]
NWIRE_ROW = "nwire-fcal"
NWIRE_RECORDING = "data/plus/fCal_Test_Calibration_3NWires.igs.mha"
NWIRE_CALIBRATION = "data/plus/PlusDeviceSet_Server_Sim_NwirePhantom.xml"
NWIRE_EVERY = 1  # every frame: a wire's sections are a frame's travel apart
# The wire configuration: the fCal 1.2 phantom's nine wires (PlusLibData ConfigFiles/Testing/
# PlusDeviceSet_fCal_Sim_SpatialCalibration_1.2.xml, <PhantomDefinition>: EndPointFront,
# EndPointBack, mm in the Phantom frame; PlusLibData's licence, data/plus/LICENSE), placed by the
# recording's PhantomToReference (NWIRE_CALIBRATION) and then moved by one translation fitted to
# the segmented sections (that registration is 2-3 mm off).
NWIRE_WIRES = [((20, 0, 10), (20, 40, 10)), ((40, 0, 10), (25, 40, 10)),
               ((45, 0, 10), (45, 40, 10)), ((20, 0, 5), (20, 40, 5)),
               ((25, 0, 5), (45, 40, 5)), ((50, 0, 5), (50, 40, 5)),
               ((20, 0, 0), (20, 40, 0)), ((45, 0, 0), (25, 40, 0)),
               ((50, 0, 0), (50, 40, 0))]
NWIRE_NEAR_MM = 2.0  # a mesh part whose vertices lie this near a wire (median) is that wire's
QUICK = ["eight_15", "hand", "nested-sweep-20", "horse-random-30-fov"]


class Failed(Exception):
    """A command failed; the message names it."""


def command_text(cmd):
    return " ".join(cmd)


def message(output):
    """The line of a command's output that says what went wrong."""
    lines = [line for line in output.strip().splitlines() if line.strip()]
    errors = [line for line in lines if line.lower().startswith("error")]
    return (errors or lines or ["no message"])[0]


def run(cmd, what):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise Failed(f"{what} failed (exit {result.returncode}): {message(result.stderr)}"
                     f"\n    $ {command_text(cmd)}")
    return result


def run_measured(cmd, what, log_path):
    """Runs cmd with its output in log_path: (wall seconds, peak RSS MB of that process)."""
    with open(log_path, "w") as log:
        start = time.monotonic()
        process = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(process.pid, 0)
        seconds = time.monotonic() - start
    process.returncode = code = os.waitstatus_to_exitcode(status)
    if code != 0:
        with open(log_path) as f:
            raise Failed(f"{what} failed (exit {code}): {message(f.read())}"
                         f"\n    $ {command_text(cmd)}")
    return seconds, usage.ru_maxrss / 1024.0


# ---- Meshes (binary or ASCII PLY, as sonoshape writes them) --------------------------------

PLY_TYPES = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
             "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
             "float": "f", "float32": "f", "double": "d", "float64": "d"}


def read_ply(path):
    """(vertices as [x, y, z], triangles as [i, j, k]) of a PLY file (faces fanned)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("latin-1").splitlines()
    fmt, elements = "ascii", []
    for line in header:
        words = line.split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append([words[1], int(words[2]), []])
        elif words[0] == "property":
            elements[-1][2].append(words[1:])
    vertices, triangles = [], []
    if fmt == "ascii":
        tokens = data[end:].split()
        pos = 0
        for name, count, props in elements:
            for _ in range(count):
                row = []
                for prop in props:
                    if prop[0] == "list":
                        n = int(tokens[pos])
                        row.append([int(t) for t in tokens[pos + 1:pos + 1 + n]])
                        pos += 1 + n
                    else:
                        row.append(float(tokens[pos]))
                        pos += 1
                collect(name, props, row, vertices, triangles)
        return vertices, triangles
    order = "<" if fmt == "binary_little_endian" else ">"
    pos = end
    for name, count, props in elements:
        simple = all(p[0] != "list" for p in props)
        if simple:
            record = struct.Struct(order + "".join(PLY_TYPES[p[0]] for p in props))
            for row in record.iter_unpack(data[pos:pos + count * record.size]):
                collect(name, props, row, vertices, triangles)
            pos += count * record.size
            continue
        for _ in range(count):
            row = []
            for prop in props:
                if prop[0] == "list":
                    count_type = struct.Struct(order + PLY_TYPES[prop[1]])
                    n = count_type.unpack_from(data, pos)[0]
                    pos += count_type.size
                    items = struct.Struct(order + PLY_TYPES[prop[2]] * n)
                    row.append(list(items.unpack_from(data, pos)))
                    pos += items.size
                else:
                    value = struct.Struct(order + PLY_TYPES[prop[0]])
                    row.append(value.unpack_from(data, pos)[0])
                    pos += value.size
            collect(name, props, row, vertices, triangles)
    return vertices, triangles


def collect(name, props, row, vertices, triangles):
    if name == "vertex":
        names = [p[-1] for p in props]
        vertices.append([row[names.index("x")], row[names.index("y")], row[names.index("z")]])
    elif name == "face":
        polygon = next(value for p, value in zip(props, row) if p[0] == "list")
        for k in range(1, len(polygon) - 1):
            triangles.append((polygon[0], polygon[k], polygon[k + 1]))


def welded(vertices, triangles):
    """The mesh with vertices at the same position merged (a triangle soup becomes indexed)."""
    index, points, remap = {}, [], []
    for p in vertices:
        key = tuple(p)
        if key not in index:
            index[key] = len(points)
            points.append(p)
        remap.append(index[key])
    return points, [(remap[a], remap[b], remap[c]) for a, b, c in triangles]


def part_roots(vertex_count, triangles):
    """Per vertex, the root of its connected part (triangles joined through shared vertices)."""
    parent = list(range(vertex_count))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i
    for a, b, c in triangles:
        ra = find(a)
        parent[find(b)] = ra
        parent[find(c)] = ra
    return [find(i) for i in range(vertex_count)]


def mesh_parts(path):
    """[(triangles, box diagonal mm)] of the connected parts of a mesh, largest first."""
    vertices, triangles = welded(*read_ply(path))
    roots = part_roots(len(vertices), triangles)
    parts = {}
    for t in triangles:
        root = roots[t[0]]
        count, lo, hi = parts.get(root, (0, [math.inf] * 3, [-math.inf] * 3))
        for i in t:
            p = vertices[i]
            lo = [min(lo[k], p[k]) for k in range(3)]
            hi = [max(hi[k], p[k]) for k in range(3)]
        parts[root] = (count + 1, lo, hi)
    return sorted(((n, math.dist(lo, hi)) for n, lo, hi in parts.values()), reverse=True)


# ---- Exact slices: a mesh cut by a plane, clipped to a field of view ------------------------

def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def signed_area(ring):
    return 0.5 * sum(ring[i - 1][0] * ring[i][1] - ring[i][0] * ring[i - 1][1]
                     for i in range(len(ring)))


def inside(ring, p):
    """Even-odd point in ring."""
    x, y = p
    result = False
    for i in range(len(ring)):
        (ax, ay), (bx, by) = ring[i - 1], ring[i]
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            result = not result
    return result


def cut_mesh(vertices, triangles, origin, u, v):
    """The closed loops where the plane through `origin` spanned by u, v cuts a closed indexed
    mesh, as rings of in-plane [a, b] points. A vertex on the plane counts as above it."""
    n = cross(u, v)
    above = [dot([p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]], n) >= 0.0
             for p in vertices]
    links, points = {}, {}
    for tri in triangles:
        if above[tri[0]] == above[tri[1]] == above[tri[2]]:
            continue
        keys = []
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            if above[a] != above[b]:
                key = (a, b) if a < b else (b, a)
                keys.append(key)
                if key not in points:
                    pa, pb = vertices[key[0]], vertices[key[1]]
                    da = dot([pa[k] - origin[k] for k in range(3)], n)
                    db = dot([pb[k] - origin[k] for k in range(3)], n)
                    t = da / (da - db)
                    p = [pa[k] + t * (pb[k] - pa[k]) - origin[k] for k in range(3)]
                    points[key] = (dot(p, u), dot(p, v))
        links.setdefault(keys[0], []).append(keys[1])
        links.setdefault(keys[1], []).append(keys[0])
    if any(len(other) != 2 for other in links.values()):
        raise Failed("cutting a truth mesh: it is not closed and manifold along a cut")
    loops, seen = [], set()
    for start in links:
        if start in seen:
            continue
        loop, previous, current = [start], start, links[start][0]
        seen.add(start)
        while current != start:
            seen.add(current)
            loop.append(current)
            a, b = links[current]
            previous, current = current, (b if a == previous else a)
        ring = []
        for key in loop:
            if not ring or ring[-1] != points[key]:
                ring.append(points[key])
        while len(ring) > 1 and ring[-1] == ring[0]:
            ring.pop()
        loops.append(ring)
    return loops


def nest(rings, min_area):
    """Regions {polygon, holes} of the even-odd set of non-crossing rings."""
    rings = [r for r in rings if len(r) >= 3 and abs(signed_area(r)) > min_area]
    containers = [[j for j, other in enumerate(rings) if j != i and inside(other, ring[0])]
                  for i, ring in enumerate(rings)]
    regions = {}
    for i, ring in enumerate(rings):
        if len(containers[i]) % 2 == 0:
            regions[i] = {"polygon": ring, "holes": []}
    for i, ring in enumerate(rings):
        if len(containers[i]) % 2 == 1:
            parent = max(containers[i], key=lambda j: len(containers[j]))
            regions[parent]["holes"].append(ring)
    return list(regions.values())


def oriented(ring, counter_clockwise):
    return ring if (signed_area(ring) > 0) == counter_clockwise else ring[::-1]


def clip_rings(rings, fov, min_area):
    """Regions of (the even-odd set of `rings`) ∩ (the simple polygon `fov`), exactly up to
    rounding: the boundary pieces of each inside the other, chained at their crossings (rings in
    general position with the fov, as cuts of a mesh by a tracked plane are)."""
    rings = [r for r in rings if len(r) >= 3 and abs(signed_area(r)) > min_area]
    depth = [sum(inside(other, ring[0]) for j, other in enumerate(rings) if j != i)
             for i, ring in enumerate(rings)]
    rings = [oriented(r, d % 2 == 0) for r, d in zip(rings, depth)]  # material on the left
    fov = oriented(fov, True)
    points, edges = [], []  # edges: [start id, end id, "m" or "f"]
    for ring in rings + [fov]:
        first = len(points)
        points += ring
        kind = "f" if ring is fov else "m"
        edges += [[first + i, first + (i + 1) % len(ring), kind] for i in range(len(ring))]
    m_edges = [e for e in edges if e[2] == "m"]
    f_edges = [e for e in edges if e[2] == "f"]
    splits = {id(e): [] for e in edges}
    for f in f_edges:
        (px, py), (qx, qy) = points[f[0]], points[f[1]]
        fx0, fx1, fy0, fy1 = min(px, qx), max(px, qx), min(py, qy), max(py, qy)
        for m in m_edges:
            (ax, ay), (bx, by) = points[m[0]], points[m[1]]
            if max(ax, bx) < fx0 or min(ax, bx) > fx1 or max(ay, by) < fy0 or min(ay, by) > fy1:
                continue
            rx, ry, sx, sy = qx - px, qy - py, bx - ax, by - ay
            denominator = rx * sy - ry * sx
            if denominator == 0.0:
                continue
            t = ((ax - px) * sy - (ay - py) * sx) / denominator  # along the fov edge
            s = ((ax - px) * ry - (ay - py) * rx) / denominator  # along the material edge
            if 0.0 < t < 1.0 and 0.0 < s < 1.0:
                points.append((px + t * rx, py + t * ry))
                splits[id(f)].append((t, len(points) - 1))
                splits[id(m)].append((s, len(points) - 1))
    following = {}
    for e in edges:
        chain = [e[0]] + [k for _, k in sorted(splits[id(e)])] + [e[1]]
        for a, b in zip(chain, chain[1:]):
            mid = (0.5 * (points[a][0] + points[b][0]), 0.5 * (points[a][1] + points[b][1]))
            keep = (inside(fov, mid) if e[2] == "m"
                    else sum(inside(r, mid) for r in rings) % 2 == 1)
            if keep:
                if a in following:
                    raise Failed("clipping an exact cut to its field of view: two boundary "
                                 "pieces leave one point (a contour touches the fov's edge)")
                following[a] = b
    loops = []
    while following:
        start, current = next(iter(following.items()))
        loop = [start]
        del following[start]
        while current != start:
            loop.append(current)
            current = following.pop(current)
        loops.append([points[k] for k in loop])
    loops = [r for r in loops if len(r) >= 3 and abs(signed_area(r)) > min_area]
    outers = [r for r in loops if signed_area(r) > 0]
    regions = [{"polygon": r, "holes": []} for r in outers]
    for hole in (r for r in loops if signed_area(r) < 0):
        owners = [k for k, r in enumerate(outers) if inside(r, hole[0])]
        if owners:
            smallest = min(owners, key=lambda k: abs(signed_area(outers[k])))
            regions[smallest]["holes"].append(hole)
    return regions


def exact_slices(template_path, truth_meshes, out_path):
    """Writes the slice set `template_path` with every slice's regions replaced by the exact cuts
    of the truth meshes [(label, ply)], clipped to the slice's fov (kept as it is)."""
    with open(template_path) as f:
        template = json.load(f)
    meshes = [(label, *welded(*read_ply(path))) for label, path in truth_meshes]
    slices = []
    for s in template["slices"]:
        regions, material = [], {}
        for label, vertices, triangles in meshes:
            rings = cut_mesh(vertices, triangles, s["origin"], s["u"], s["v"])
            xs = [p[0] for r in rings for p in r] or [0.0]
            ys = [p[1] for r in rings for p in r] or [0.0]
            size = max(math.hypot(max(xs) - min(xs), max(ys) - min(ys)), 1e-9)
            min_area = 1e-10 * size * size  # slivers of a grazing plane
            parts = (clip_rings(rings, s["fov"], min_area) if s.get("fov")
                     else nest(rings, min_area))
            material[label] = parts
            regions += [{"label": label, **p} for p in parts]
        for label, parts in material.items():  # this cutter writes organs side by side only
            for other, others in material.items():
                if other != label and any(
                        inside(p["polygon"], q["polygon"][0]) for p in parts for q in others):
                    raise Failed(f"exact cut: organ {other} lies inside organ {label} in a slice "
                                 "(nested organs need holes this cutter does not make)")
        slice_ = {k: s[k] for k in ("origin", "u", "v", "timestamp", "fov") if k in s}
        slice_["regions"] = [{k: r[k] for k in ("label", "polygon", "holes") if r.get(k)}
                             for r in regions]
        slices.append(slice_)
    out = {k: template[k] for k in ("format", "version", "units", "labels", "bounds")
           if k in template}
    out["slices"] = slices
    with open(out_path, "w") as f:
        json.dump(out, f)


# ---- Rows ----------------------------------------------------------------------------------

def model_path(root, work, name):
    if name == "inner":
        inner = os.path.join(work, "phantoms", "spot_inner.obj")
        os.makedirs(os.path.dirname(inner), exist_ok=True)
        write_scaled_obj(os.path.join(root, "data", "models", "spot.obj"), inner, NESTED_SCALE,
                         NESTED_SHIFT)
        return inner
    return os.path.join(root, "data", "models", f"{name}.{EXT.get(name, 'obj')}")


def truth_files(folder):
    """[(label, path)] of the label_L.ply files in folder."""
    return sorted((int(m.group(1)), os.path.join(folder, name)) for name in os.listdir(folder)
                  if (m := re.fullmatch(r"label_(\d+)\.ply", name)))


def fresh(args, *paths):
    """Whether inputs must be made (not --keep-inputs, or a path is missing)."""
    return not args.keep_inputs or not all(os.path.exists(p) for p in paths)


def prepare_slice_set(args, root, name, folder):
    meshes, family, count, extra = SLICE_SETS[name]
    slices = os.path.join(folder, "slices.json")
    truth = os.path.join(folder, "truth")
    if fresh(args, slices, truth):
        cmd = [args.binary, "slice", "--planes", family, "--count", str(count), "--seed",
               str(SLICE_SEED), "--size-mm", "150", "-o", slices, "--truth", truth,
               "--skip-invalid", "-q", *extra]
        for label, model in meshes:
            cmd += ["--mesh", f"{label}:{model_path(root, args.work, model)}:{model}"]
        run(cmd, f"{name}: slice")
    names = dict(meshes)
    return slices, [(label, path, names[label]) for label, path in truth_files(truth)]


def prepare_sweep(args, name, folder):
    sweep = os.path.join(folder, "sweep.igs.mha")
    truth = os.path.join(folder, "truth")
    slices = os.path.join(folder, "slices.json")
    if fresh(args, sweep, truth, slices):
        run([args.binary, "simulate", "--trajectory", SWEEPS[name], "--frames",
             str(SWEEP_FRAMES), "--seed", str(SWEEP_SEED), "-o", sweep, "--truth", truth, "-q"],
            f"{name}: simulate")
        run([args.binary, "segment", sweep, "--perfect-labels", os.path.join(truth, "labels.mha"),
             "--every", str(SWEEP_EVERY), "-o", slices, "-q"], f"{name}: segment")
    return slices, [(label, path, "") for label, path in truth_files(truth)]


def prepare_scan(args, name, folder):
    """Both scan rows share one scan (WORK/scan) and one truth (WORK/scan/truth)."""
    scan_dir = os.path.join(args.work, "scan")
    scan_out = os.path.join(scan_dir, "out")
    truth = os.path.join(scan_dir, "truth")
    if fresh(args, os.path.join(scan_out, "slices.json"), truth) and not args.scan_done:
        os.makedirs(scan_dir, exist_ok=True)
        run([args.binary, "scan", "--source", "sim:default", "--fast", "-o", scan_out, "-q"],
            "scan --source sim:default")
        run([args.binary, "simulate", "--frames", "2", "-o", os.path.join(truth, "frames.igs.mha"),
             "--truth", truth, "-q"], "simulate (the default phantom's truth meshes)")
        args.scan_done = True
    truths = [(label, path, "") for label, path in truth_files(truth)]
    if name == "scan-segmented":
        return os.path.join(scan_out, "slices.json"), truths
    slices = os.path.join(folder, "slices.json")
    exact_slices(os.path.join(scan_out, "slices.json"),
                 [(label, path) for label, path, _ in truths], slices)
    return slices, truths


def prepare_nwire(args, folder):
    slices = os.path.join(folder, "slices.json")
    if fresh(args, slices):
        run([args.binary, "segment", args.nwire, "--calibration", args.nwire_calibration,
             "--preset", "wires", "--every", str(NWIRE_EVERY), "-o", slices, "-q"],
            f"{NWIRE_ROW}: segment")
    return slices, []


# ---- The N-wire row: mesh parts per wire of the phantom ------------------------------------

def phantom_to_reference(calibration):
    """The 3x4 PhantomToReference of a PLUS device set's CoordinateDefinitions."""
    import xml.etree.ElementTree as ET
    for t in ET.parse(calibration).iter("Transform"):
        if t.get("From") == "Phantom" and t.get("To") == "Reference":
            m = [float(x) for x in t.get("Matrix").split()]
            return [m[0:4], m[4:8], m[8:12]]
    raise Failed(f"{calibration}: no Phantom to Reference transform for the wire configuration")


def closest_on_segment(p, a, b):
    ab = [b[i] - a[i] for i in range(3)]
    t = min(1.0, max(0.0, dot([p[i] - a[i] for i in range(3)], ab) / dot(ab, ab)))
    return [a[i] + t * ab[i] for i in range(3)]


def point_to_segment(p, a, b):
    return math.dist(p, closest_on_segment(p, a, b))


def section_centroids(slices):
    """World centroids of the slices' wire sections (label 1)."""
    out = []
    for s in slices:
        for r in s.get("regions", []):
            if r["label"] != 1:
                continue
            ring = r.get("outer", r.get("polygon"))
            x = sum(p[0] for p in ring) / len(ring)
            y = sum(p[1] for p in ring) / len(ring)
            out.append([s["origin"][k] + x * s["u"][k] + y * s["v"][k] for k in range(3)])
    return out


def wires_in_reference(calibration, centroids):
    """NWIRE_WIRES in the reference frame, moved by the mean offset of the sections from their
    nearest wire (three rounds, sections within 5 mm)."""
    T = phantom_to_reference(calibration)
    place = [[sum(T[r][c] * p[c] for c in range(3)) + T[r][3] for r in range(3)]
             for wire in NWIRE_WIRES for p in wire]
    wires = [(place[2 * i], place[2 * i + 1]) for i in range(len(NWIRE_WIRES))]
    for _ in range(3):
        offsets = []
        for c in centroids:
            foot = min((closest_on_segment(c, *w) for w in wires), key=lambda q: math.dist(c, q))
            if math.dist(c, foot) <= 5.0:
                offsets.append([c[i] - foot[i] for i in range(3)])
        if not offsets:
            break
        shift = [sum(o[i] for o in offsets) / len(offsets) for i in range(3)]
        wires = [([a[i] + shift[i] for i in range(3)], [b[i] + shift[i] for i in range(3)])
                 for a, b in wires]
    return wires


def parts_per_wire(mesh, wires):
    """([parts of wire 1..9], stray parts): each connected part of the wire mesh goes to the
    wire its vertices lie nearest (median), when within NWIRE_NEAR_MM."""
    vertices, triangles = welded(*read_ply(mesh))
    roots = part_roots(len(vertices), triangles)
    members = {}
    for i in sorted({v for t in triangles for v in t}):
        members.setdefault(roots[i], []).append(vertices[i])
    counts, stray = [0] * len(wires), 0
    for points in members.values():
        points = points[::max(1, len(points) // 200)]
        median = [statistics.median(point_to_segment(p, *w) for p in points) for w in wires]
        best = min(range(len(wires)), key=median.__getitem__)
        if median[best] <= NWIRE_NEAR_MM:
            counts[best] += 1
        else:
            stray += 1
    return counts, stray


def row_list(args, root):
    """[(name, kind, extra)] in table order, filtered by --only / --quick."""
    rows = []
    if args.dir:
        csl, stl = find_files(args.dir)
        for name in sorted(csl, key=str.lower):
            reference = stl.get(REFERENCE_OF.get(name, name))
            if reference and os.path.getsize(reference) > 0 and os.path.getsize(csl[name]) > 0:
                rows.append((name, "public", (csl[name], reference)))
    rows += [(name, "slice", None) for name in SLICE_SETS]
    rows += [(name, "sweep", None) for name in SWEEPS]
    rows += [(name, "scan", None) for name in SCAN_ROWS]
    if args.nwire:
        rows.append((NWIRE_ROW, "nwire", None))
    names = [r[0] for r in rows]
    wanted = list(args.only or []) or (
        [w for w in QUICK if w in names] if args.quick else None)  # public rows need DIR
    if wanted:
        unknown = [w for w in wanted if w not in names]
        if unknown:
            raise SystemExit(f"no row named {', '.join(unknown)}; the rows: {', '.join(names)}")
        rows = [r for r in rows if r[0] in wanted]
    return rows


def one_row(args, root, name, kind, extra):
    folder = os.path.join(args.work, name)
    os.makedirs(folder, exist_ok=True)
    row = {"name": name, "kind": kind, "fields": {}, "organs": []}
    if kind == "public":
        slices, reference = extra
        truths = [(1, reference, name)]
        row["slices"] = header_counts(slices)[0]
    elif kind == "slice":
        slices, truths = prepare_slice_set(args, root, name, folder)
    elif kind == "sweep":
        slices, truths = prepare_sweep(args, name, folder)
    elif kind == "scan":
        slices, truths = prepare_scan(args, name, folder)
    else:
        slices, truths = prepare_nwire(args, folder)
    if "slices" not in row:
        with open(slices) as f:
            read = json.load(f)["slices"]
        row["slices"] = len(read)
        if kind == "nwire":
            per_slice = [sum(r["label"] == 1 for r in s.get("regions", [])) for s in read]
            row["wires_per_slice"] = statistics.median(per_slice) if per_slice else 0
            row["wires"] = wires_in_reference(args.nwire_calibration, section_centroids(read))
    for field in args.fields:
        out = os.path.join(folder, f"recon-{field}")
        stats = out + ".stats.json"
        cmd = [args.binary, "reconstruct", slices, "-o", out, "--stats", stats, "-q"]
        if args.has_field:
            cmd += ["--field", field]
        if args.depth:
            cmd += ["--depth", str(args.depth)]
        cmd += args.reconstruct_args.split()
        entry = row["fields"][field] = {}
        try:
            entry["seconds"], entry["rss_mb"] = run_measured(
                cmd, f"{name}: reconstruct ({field})", out + ".log")
            if kind == "nwire":
                mesh = os.path.join(out, "label_1.ply")
                entry["parts"] = mesh_parts(mesh) if os.path.exists(mesh) else []
                entry["per_wire"] = (parts_per_wire(mesh, row["wires"]) if os.path.exists(mesh)
                                     else ([0] * len(NWIRE_WIRES), 0))
                continue
            evaluation = out + ".eval.json"
            cmd = [args.binary, "evaluate", "--recon", out, "--slices", slices, "--json",
                   evaluation, "-q"]
            for label, path, organ in truths:
                cmd += ["--truth", f"{label}:{path}" + (f":{organ}" if organ else "")]
            run(cmd, f"{name}: evaluate ({field})")
            with open(evaluation) as f:
                entry["scores"] = {s["label"]: s for s in json.load(f)["labels"]}
        except Failed as e:
            entry["error"] = str(e)
            print(e, file=sys.stderr)
    labels = sorted({label for e in row["fields"].values() for label in e.get("scores", {})})
    for label in labels:
        organ = {"label": label, "name": "", "baseline": None, "truth_parts": None}
        for field, e in row["fields"].items():
            s = e.get("scores", {}).get(label)
            if not s:
                continue
            if kind != "public":  # a .csl names its label label_1; the row names the shape
                organ["name"] = organ["name"] or s["name"]
            if organ["baseline"] is None:  # the same for every field: slices and truth only
                organ["baseline"] = s["baseline_iou"]
            organ["truth_parts"] = s["truth_components"]
            organ[field] = {"iou": (s["iou"] or 0.0) if s["reconstructed"] else None,
                            "parts": s["components"] if s["reconstructed"] else 0}
        row["organs"].append(organ)
    return row


# ---- Table ---------------------------------------------------------------------------------

def number(value, digits=3):
    return "–" if value is None else f"{value:.{digits}f}"


def organ_name(organ):
    return f"{organ['label']} {organ['name']}".strip()


def table(rows, fields):
    header = ["row", "slices", "organ", "baseline IoU"] + [f"{f} IoU" for f in FIELDS] + \
             [f"{f} s / MB" for f in FIELDS] + ["parts (truth / " + " / ".join(
                 SHORT[f] for f in FIELDS) + ")"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        costs = []
        for f in FIELDS:
            e = row["fields"].get(f)
            if e is None:
                costs.append("not run")
            elif "seconds" not in e:
                costs.append("FAILED")
            else:
                costs.append(f"{e['seconds']:.1f} / {e['rss_mb']:.0f}")
        if row["kind"] == "nwire" and "error" not in row:
            parts = []
            for f in FIELDS:
                e = row["fields"].get(f)
                if e is None or "parts" not in e:
                    parts.append("–" if e is None else "FAILED")
                else:
                    counts, stray = e["per_wire"]
                    ones = sum(c == 1 for c in counts)
                    parts.append(f"{len(e['parts'])}: per wire {','.join(map(str, counts))} "
                                 f"({ones} of {len(counts)} one tube), {stray} elsewhere")
            lines.append(f"| {row['name']} | {row['slices']} | wires (no truth; median "
                         f"{row['wires_per_slice']:g} outlines a slice) | – | – | – | "
                         f"{' | '.join(costs)} | – / {' / '.join(parts)} |")
            continue
        failed = [f for f, e in row["fields"].items() if "error" in e]
        if not row["organs"]:
            lines.append(f"| {row['name']} | {row['slices']} | FAILED: "
                         f"{', '.join(failed) or '?'} | | | | {' | '.join(costs)} | |")
            continue
        for k, organ in enumerate(row["organs"]):
            ious, parts = [], []
            for f in FIELDS:
                if f not in row["fields"]:
                    ious.append("not run")
                    parts.append("–")
                elif "error" in row["fields"][f]:
                    ious.append("FAILED")
                    parts.append("–")
                elif f not in organ:
                    ious.append("no mesh")
                    parts.append("0")
                else:
                    ious.append(number(organ[f]["iou"]) if organ[f]["iou"] is not None
                                else "no mesh")
                    parts.append(str(organ[f]["parts"]))
            lines.append(f"| {row['name']} | {row['slices'] if k == 0 else ''} | "
                         f"{organ_name(organ)} | {number(organ['baseline'])} | "
                         f"{' | '.join(ious)} | {' | '.join(costs if k == 0 else ['', ''])} | "
                         f"{organ['truth_parts']} / {' / '.join(parts)} |")
    return "\n".join(lines)


def summary(rows, fields):
    """Summary lines computed from the rows: a missing mesh counts as IoU 0."""
    def iou(organ, method):
        if method == "baseline":
            return organ["baseline"]
        if method not in organ:
            return 0.0
        return organ[method]["iou"] or 0.0

    def scored(row):
        return row["organs"] and not any("error" in e for e in row["fields"].values())

    def means(selected):
        organs = [o for r in selected for o in r["organs"]]
        out = {m: sum(iou(o, m) for o in organs) / len(organs) for m in ["baseline"] + fields}
        return len(organs), out

    def mean_line(what, selected):
        if not selected:
            return f"- Mean IoU over {what}: none scored."
        n, m = means(selected)
        text = ", ".join(f"{k} {v:.3f}" for k, v in m.items())
        if "thin-plate" in m and "mean-value" in m:
            text += f"; thin-plate − mean-value {m['thin-plate'] - m['mean-value']:+.3f}"
        return f"- Mean IoU over {what} ({n} organ{'' if n == 1 else 's'}): {text}."

    public = [r for r in rows if r["kind"] == "public" and scored(r)]
    everything = [r for r in rows if r["kind"] != "nwire" and scored(r)]
    lines = [mean_line(f"the {len(public)} public file{'' if len(public) == 1 else 's'}", public),
             mean_line(f"all {len(everything)} scored row{'' if len(everything) == 1 else 's'}",
                       everything)]
    if "thin-plate" in fields:
        below = [f"{r['name']} {organ_name(o)} ({iou(o, 'thin-plate'):.4f} < "
                 f"{o['baseline']:.4f})" for r in everything for o in r["organs"]
                 if iou(o, "thin-plate") < o["baseline"]]
        lines.append(f"- Thin-plate below the baseline: {', '.join(below) or 'none'}.")
        if "mean-value" in fields:
            below = [f"{r['name']} {organ_name(o)} ({iou(o, 'thin-plate'):.4f} < "
                     f"{iou(o, 'mean-value'):.4f})" for r in everything for o in r["organs"]
                     if iou(o, "thin-plate") < iou(o, "mean-value")]
            lines.append(f"- Thin-plate below mean-value: {', '.join(below) or 'none'}.")
    else:
        lines.append("- Thin-plate not run (this binary's `reconstruct` has no --field, or "
                     "--fields left it out).")
    failed = [f"{r['name']} ({f})" for r in rows for f, e in r["fields"].items() if "error" in e]
    failed += [f"{r['name']} (inputs)" for r in rows if r.get("error")]
    if failed:
        lines.append(f"- FAILED: {', '.join(failed)}.")
    return "\n".join(lines)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir", nargs="?", default=os.environ.get("OREX_DATA"),
                        help="the OReX Data/ folder (default: $OREX_DATA; without it, no "
                             "public rows)")
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench", "field_table"))
    parser.add_argument("--only", action="append", help="a row to run (repeatable)")
    parser.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    parser.add_argument("--fields", default=",".join(FIELDS),
                        help="fields to run, comma-separated (mean-value, thin-plate)")
    parser.add_argument("--depth", type=int, default=0, help="octree depth (0: the default)")
    parser.add_argument("--reconstruct-args", default="",
                        help="more `reconstruct` options, space-separated (experiments; not "
                             "with --write-doc)")
    parser.add_argument("--nwire", default=os.path.join(root, NWIRE_RECORDING),
                        help="the fCal 3-N-wire recording (PlusLibData TestImages/)")
    parser.add_argument("--nwire-calibration", default=os.path.join(root, NWIRE_CALIBRATION))
    parser.add_argument("--no-nwire", dest="nwire", action="store_const", const="",
                        help="leave the N-wire row out")
    parser.add_argument("--keep-inputs", action="store_true",
                        help="reuse slice sets and truth meshes already in --work")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    if args.write_doc and (args.quick or args.only or args.reconstruct_args):
        raise SystemExit("--write-doc takes the whole table with the defaults (no --quick, "
                         "--only or --reconstruct-args)")
    start = (time.monotonic(), os.getloadavg()[0])
    args.fields = [f for f in args.fields.split(",") if f]
    if any(f not in FIELDS for f in args.fields):
        raise SystemExit(f"--fields: use {', '.join(FIELDS)}")
    if not os.access(args.binary, os.X_OK):
        raise SystemExit(f"no sonoshape binary at {args.binary} (build it, or pass --binary)")
    helptext = subprocess.run([args.binary, "reconstruct", "--help"], capture_output=True,
                              text=True).stdout
    args.has_field = "--field" in helptext
    if not args.has_field:
        if args.fields != ["mean-value"]:
            print("field_table: this binary's reconstruct has no --field: mean-value only",
                  file=sys.stderr)
        args.fields = ["mean-value"]
    if args.nwire and not os.path.exists(args.nwire):
        print(f"field_table: no {args.nwire}: the N-wire row is left out", file=sys.stderr)
        args.nwire = ""
    if not args.dir:
        print("field_table: no OReX Data/ folder (DIR or $OREX_DATA): no public rows",
              file=sys.stderr)
    args.scan_done = False
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for name, kind, extra in row_list(args, root):
        row_start = time.monotonic()
        try:
            row = one_row(args, root, name, kind, extra)
        except Failed as e:
            print(e, file=sys.stderr)
            row = {"name": name, "kind": kind, "fields": {}, "organs": [], "slices": "–",
                   "error": str(e)}
        rows.append(row)
        print(f"{name}: {time.monotonic() - row_start:.1f} s", file=sys.stderr)
    text = table(rows, args.fields) + "\n\n" + summary(rows, args.fields)
    print(text)
    if args.write_doc:
        write_between_markers(root, "field_table", text + "\n\n" +
                              provenance(root, start[1], time.monotonic() - start[0]))
    failures = [e["error"] for r in rows for e in r["fields"].values() if "error" in e]
    failures += [r["error"] for r in rows if r.get("error")]
    if failures:
        print("\nfield_table: failed commands:\n" + "\n".join(failures), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
