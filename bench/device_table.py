#!/usr/bin/env python3
"""The offline Table II sets (bench/accuracy_matrix.py's per-stage table) on each field device.

For every set of Table II (seven models x parallel-20, orthogonal-30, random-40; four pairs x
orthogonal-30, random-30; sliced as accuracy_matrix.py slices them) this runs
  sonoshape reconstruct SET --device D --threads T --stats
for each device D (cpu, opencl:P:D, ...), `--repeat` times, and prints one Markdown row per set:
the total seconds and evaluation seconds of each device (the median of the runs, or with
--best the fastest, for a machine shared with other work), each device's total against the
first one's, and whether every device wrote the same meshes as the first (byte for byte).
The OpenCL program is built (or read from its cache) once before the timed runs.

Usage: bench/device_table.py [--binary build/apps/sonoshape] [--work out/bench/device]
         [--devices cpu,opencl] [--threads 0] [--repeat 3] [--best] [--quick] [--sets a,b]
"""
import argparse
import filecmp
import json
import os
import statistics
import subprocess
import sys

MODELS = ["spot", "cow", "homer", "horse", "cheburashka", "fandisk", "rocker-arm"]
EXT = {"horse": "ply"}
FAMILIES = [("parallel", 20), ("orthogonal", 30), ("random", 40)]
PAIR_FAMILIES = [("orthogonal", 30), ("random", 30)]
PAIRS = [("spot", "homer"), ("cheburashka", "fandisk"), ("horse", "rocker-arm"), ("cow", "spot")]


def run(cmd):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(" ".join(cmd) + "\n" + result.stderr)
        raise SystemExit(1)
    return result


def sets(root, extra):
    """(name, slice command arguments) of every Table II set, then the extra ones asked for."""
    out = []
    def model(name):
        return os.path.join(root, "data", "models", f"{name}.{EXT.get(name, 'obj')}")
    for name in MODELS:
        for family, count in FAMILIES:
            out.append((f"{name}-{family}-{count}", family, count, [(1, name)]))
    for a, b in PAIRS:
        for family, count in PAIR_FAMILIES:
            out.append((f"{a}+{b}-{family}-{count}", family, count, [(1, a), (2, b)]))
    for spec in extra:  # MODEL-FAMILY-COUNT
        name, family, count = spec.rsplit("-", 2)
        out.append((spec, family, int(count), [(1, name)]))
    return [(n, f, c, [(l, m, model(m)) for l, m in meshes]) for n, f, c, meshes in out]


def slice_set(binary, work, name, family, count, meshes):
    path = os.path.join(work, name, "slices.json")
    if os.path.exists(path):
        return path
    os.makedirs(os.path.dirname(path), exist_ok=True)
    cmd = [binary, "slice", "--planes", family, "--count", str(count), "--seed", "1", "--size-mm", "150",
           "-o", path, "--skip-invalid", "-q"]
    for label, model, file in meshes:
        cmd += ["--mesh", f"{label}:{file}:{model}"]
    run(cmd)
    return path


def reconstruct(binary, slices, out, device, threads):
    stats = out + ".stats.json"
    run([binary, "reconstruct", "--field", "mean-value", slices, "-o", out, "--device", device, "--threads", str(threads),
         "--stats", stats, "-q"])
    with open(stats) as f:
        return json.load(f)


def same_meshes(a, b):
    names = sorted(os.listdir(a))
    return names == sorted(os.listdir(b)) and all(
        filecmp.cmp(os.path.join(a, n), os.path.join(b, n), shallow=False) for n in names)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--binary", default="build/apps/sonoshape")
    parser.add_argument("--work", default="out/bench/device")
    parser.add_argument("--devices", default="cpu,opencl")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--best", action="store_true", help="the fastest run instead of the median")
    parser.add_argument("--quick", action="store_true", help="one set per model family")
    parser.add_argument("--sets", default="", help="only these sets (comma-separated names)")
    parser.add_argument("--extra", default="", help="also these MODEL-FAMILY-COUNT sets")
    args = parser.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    devices = args.devices.split(",")
    chosen = sets(root, [e for e in args.extra.split(",") if e])
    if args.sets:
        wanted = set(args.sets.split(","))
        chosen = [s for s in chosen if s[0] in wanted]
    if args.quick:
        chosen = chosen[2::3]
    # Build (or read from the cache) each OpenCL program once, outside the timings.
    first = slice_set(args.binary, args.work, *chosen[0])
    for device in devices:
        reconstruct(args.binary, first, os.path.join(args.work, "warm-up"), device, args.threads)

    header = " | ".join(f"{d} total s | {d} evaluation s" for d in devices)
    ratios = " | ".join(f"{d} / {devices[0]}" for d in devices[1:])
    print(f"| set | slices | evaluations | {header} | {ratios} | same meshes |")
    print("|---" * (3 + 2 * len(devices) + len(devices) - 1 + 1) + "|")
    worst = 0.0
    for name, family, count, meshes in chosen:
        slices = slice_set(args.binary, args.work, name, family, count, meshes)
        totals, evals, outs, stats = {}, {}, {}, None
        for device in devices:
            out = os.path.join(args.work, name, "recon-" + device.replace(":", "_"))
            runs = [reconstruct(args.binary, slices, out, device, args.threads) for _ in range(args.repeat)]
            pick = min if args.best else statistics.median
            totals[device] = pick(r["total_s"] for r in runs)
            evals[device] = pick(r["evaluation_s"] for r in runs)
            outs[device] = out
            stats = runs[0]
        cells = " | ".join(f"{totals[d]:.3f} | {evals[d]:.3f}" for d in devices)
        ratio_cells = []
        for d in devices[1:]:
            ratio = totals[d] / totals[devices[0]] if totals[devices[0]] > 0 else float("nan")
            worst = max(worst, ratio)
            ratio_cells.append(f"{ratio:.2f}")
        same = all(same_meshes(outs[devices[0]], outs[d]) for d in devices[1:])
        print(f"| {name} | {stats['slices']} | {stats['field_evaluations']} | {cells} | "
              f"{' | '.join(ratio_cells)} | {'yes' if same else 'NO'} |", flush=True)
    if len(devices) > 1:
        print(f"\nworst total ratio against {devices[0]}: {worst:.2f}")


if __name__ == "__main__":
    main()
