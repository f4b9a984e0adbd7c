#!/usr/bin/env python3
"""Accuracy and per-stage timing of offline reconstruction on slice sets cut from data/models.

For every model and plane family (and for two-label pairs) this runs
  sonoshape slice -> sonoshape reconstruct --stats -> sonoshape evaluate --json
and prints two Markdown tables: accuracy against the ground-truth mesh beside the closest-point
baseline, and per-stage seconds like Table II of Bermano et al. (2011).

--write-doc puts the tables into docs/benchmarks.md between the markers `offline_accuracy` and
`offline_stages` (with --unknowns: `unknown_regions` and `unknown_regions_stages`), each
`<!-- NAME:begin -->` ... `<!-- NAME:end -->`, the first with the commit, machine and load.

Usage: bench/accuracy_matrix.py [--binary build/apps/sonoshape] [--work out/bench] [--quick]
                                [--unknowns] [--write-doc]
"""
import argparse
import json
import os
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers

MODELS = ["spot", "cow", "homer", "horse", "cheburashka", "fandisk", "rocker-arm"]
EXT = {"horse": "ply"}
FAMILIES = [("parallel", 20), ("orthogonal", 30), ("random", 40), ("random", 30)]
PAIRS = [("spot", "homer"), ("cheburashka", "fandisk"), ("horse", "rocker-arm"), ("cow", "spot")]


def run(cmd):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(" ".join(cmd) + "\n" + result.stderr)
        raise SystemExit(1)
    return result


def model_path(root, name):
    return os.path.join(root, "data", "models", f"{name}.{EXT.get(name, 'obj')}")


def one_case(args, root, name, meshes, family, count, extra_recon, extra_slice=()):
    case_dir = os.path.join(args.work, name)
    os.makedirs(case_dir, exist_ok=True)
    slices = os.path.join(case_dir, "slices.json")
    truth = os.path.join(case_dir, "truth")
    slice_cmd = [args.binary, "slice", "--planes", family, "--count", str(count), "--seed", "1",
                 "--size-mm", "150", "-o", slices, "--truth", truth, "--skip-invalid", "-q"]
    slice_cmd += list(extra_slice)
    for label, model in meshes:
        slice_cmd += ["--mesh", f"{label}:{model_path(root, model)}:{model}"]
    run(slice_cmd)
    out = os.path.join(case_dir, "recon")
    stats_path = os.path.join(case_dir, "stats.json")
    run([args.binary, "reconstruct", "--field", "mean-value", slices, "-o", out, "--stats", stats_path, "-q"] + extra_recon)
    eval_path = os.path.join(case_dir, "eval.json")
    eval_cmd = [args.binary, "evaluate", "--recon", out, "--slices", slices, "--json", eval_path, "-q"]
    for label, model in meshes:
        eval_cmd += ["--truth", f"{label}:{truth}/label_{label}.ply"]
    run(eval_cmd)
    with open(stats_path) as f:
        stats = json.load(f)
    with open(eval_path) as f:
        scores = json.load(f)
    with open(slices) as f:
        stats["slices_kept"] = len(json.load(f)["slices"])
    return stats, scores


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default=os.path.join(root, "build", "apps", "sonoshape"))
    parser.add_argument("--work", default=os.path.join(root, "out", "bench"))
    parser.add_argument("--quick", action="store_true", help="one family per model")
    parser.add_argument("--unknowns", action="store_true",
                        help="unknown blobs (40%% of slices) and sector fields of view instead")
    parser.add_argument("--write-doc", action="store_true",
                        help="write the tables into docs/benchmarks.md between their markers")
    args = parser.parse_args()
    args.start = (time.monotonic(), os.getloadavg()[0])
    if args.unknowns:
        unknown_tables(args, root)
        return

    cases = []
    for model in MODELS:
        for family, count in (FAMILIES[2:3] if args.quick else FAMILIES[:3]):
            cases.append((f"{model}-{family}-{count}", [(1, model)], family, count))
    for a, b in PAIRS:
        for family, count in [("orthogonal", 30), ("random", 30)]:
            cases.append((f"{a}+{b}-{family}-{count}", [(1, a), (2, b)], family, count))

    accuracy = ["| set | slices | label | IoU | baseline IoU | mean dist % | Hausdorff % | contour mean % | contour max % | closed manifold oriented |",
                "|---|---|---|---|---|---|---|---|---|---|"]
    timing = ["| set | slices | cells | arrangement s | face images s | field s | smoothing s | mesh s | total s | evaluations | triangles | peak RSS MB |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    failures = []
    for name, meshes, family, count in cases:
        stats, scores = one_case(args, root, name, meshes, family, count, [])
        for s in scores["labels"]:
            ok = s["health"]["closed_manifold_oriented"]
            beats = s["iou"] > s["baseline_iou"]
            fidelity = s["contour_mean_percent"] <= 0.5 and s["contour_max_percent"] <= 2.0
            if not (ok and beats and fidelity):
                failures.append(f"{name} label {s['label']}")
            accuracy.append(
                f"| {name} | {stats['slices_kept']} | {s['label']} {s['name']} | {s['iou']:.4f} | "
                f"{s['baseline_iou']:.4f} | {s['mean_surface_distance_percent']:.3f} | "
                f"{s['hausdorff_distance_percent']:.2f} | {s['contour_mean_percent']:.3f} | "
                f"{s['contour_max_percent']:.3f} | {'yes' if ok else 'NO'} |")
        tri = sum(stats["triangles"].values())
        timing.append(
            f"| {name} | {stats['slices']} | {stats['cells']} | {stats['arrangement_s']:.3f} | "
            f"{stats['face_images_s']:.3f} | {stats['field_s']:.3f} | {stats['smoothing_s']:.3f} | "
            f"{stats['mesh_s']:.3f} | {stats['total_s']:.3f} | {stats['field_evaluations']} | {tri} | "
            f"{stats['peak_rss_mb']:.0f} |")
        sys.stderr.write(f"{name}: done\n")
    print("### Accuracy\n")
    print("\n".join(accuracy))
    print("\n### Per-stage seconds (Table II)\n")
    print("\n".join(timing))
    failing = (f"Sets failing a goal (closed/oriented, IoU above baseline, contour mean <= 0.5 %, max <= 2 %): "
               f"{', '.join(failures) if failures else 'none'}")
    print("\n" + failing)
    if args.write_doc:
        line = provenance(root, args.start[1], time.monotonic() - args.start[0])
        write_between_markers(root, "offline_accuracy", "\n".join(accuracy) + "\n\n" + line)
        write_between_markers(root, "offline_stages", "\n".join(timing) + "\n\n" + line)


def material_area(slices_path):
    """Total area of the material regions of a slice set (mm^2)."""
    def area(ring):
        return 0.5 * abs(sum(ring[i][0] * ring[(i + 1) % len(ring)][1] - ring[(i + 1) % len(ring)][0] * ring[i][1]
                             for i in range(len(ring))))
    with open(slices_path) as f:
        slices = json.load(f)["slices"]
    return sum(area(r["polygon"]) - sum(area(h) for h in r.get("holes", []))
               for s in slices for r in s["regions"] if r["label"] != "unknown")


def unknown_tables(args, root):
    """Each model, 30 random planes: without unknowns, with blobs on 40 % of the slices, with
    60-degree sector fields of view on every slice, aimed to cover the material (as a sonographer
    sets the probe) and fixed at 80 mm centred on it (large cross-sections partly unseen)."""
    variants = [("known", []), ("blobs 40%", ["--unknown", "0.4"]),
                ("fov sector, covering", ["--fov", "sector", "--fov-aim", "cover"]),
                ("fov sector, 80 mm centred", ["--fov", "sector", "--fov-aim", "centre"])]
    rows = ["| model | set | material seen | IoU | baseline IoU | IoU - known IoU | contour max % | closed manifold oriented | "
            "total s | completion s (share) | unknown triangles | groups |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    stage_rows = ["| model | set | arrangement s | face images s | of which completion s | field s | smoothing s | "
                  "mesh s | total s | field evaluations |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
    failures = []
    # The goals beyond closed meshes and the baseline: IoU within 0.03 of the known set and
    # completion under 20 % of the run.
    misses = []
    for model in MODELS:
        known_iou = known_area = None
        for label, extra in variants:
            name = f"{model}-random-30-{label.split(',')[-1].split()[0]}"
            stats, scores = one_case(args, root, name, [(1, model)], "random", 30, [], extra)
            s = scores["labels"][0]
            seen = material_area(os.path.join(args.work, name, "slices.json"))
            if known_iou is None:
                known_iou, known_area = s["iou"], seen
            share = stats["completion_s"] / stats["total_s"] if stats["total_s"] > 0 else 0.0
            ok = s["health"]["closed_manifold_oriented"]
            if not ok or s["iou"] <= s["baseline_iou"]:
                failures.append(f"{model} {label}")
            rows.append(
                f"| {model} | {label} | {100 * seen / known_area:.0f}% | {s['iou']:.4f} | {s['baseline_iou']:.4f} | "
                f"{s['iou'] - known_iou:+.4f} | {s['contour_max_percent']:.3f} | {'yes' if ok else 'NO'} | "
                f"{stats['total_s']:.2f} | {stats['completion_s']:.2f} ({100 * share:.0f}%) | "
                f"{stats['unknown_triangles']} | {stats['cell_groups']} |")
            stage_rows.append(
                f"| {model} | {label} | {stats['arrangement_s']:.3f} | {stats['face_images_s']:.3f} | "
                f"{stats['completion_s']:.3f} | {stats['field_s']:.3f} | {stats['smoothing_s']:.3f} | "
                f"{stats['mesh_s']:.3f} | {stats['total_s']:.3f} | {stats['field_evaluations']} |")
            if known_iou - s["iou"] > 0.03:
                misses.append(f"{model} {label} (IoU {s['iou'] - known_iou:+.4f})")
            if share >= 0.2:
                misses.append(f"{model} {label} (completion {100 * share:.1f} %)")
            sys.stderr.write(f"{name}: done\n")
    summary = "\n".join(rows) + (
        f"\n\nSets failing a goal (closed/oriented, IoU above baseline): {', '.join(failures) if failures else 'none'}"
        f"\n\nSets more than 0.03 below the known set's IoU, or with completion at 20 % of the run or more: "
        f"{', '.join(misses) if misses else 'none'}")
    print(summary)
    print("\nPer-stage seconds (`face images s` includes the completion):\n")
    print("\n".join(stage_rows))
    if args.write_doc:
        line = provenance(root, args.start[1], time.monotonic() - args.start[0])
        write_between_markers(root, "unknown_regions", summary + "\n\n" + line)
        write_between_markers(root, "unknown_regions_stages", "\n".join(stage_rows))


if __name__ == "__main__":
    main()
