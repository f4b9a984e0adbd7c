#!/usr/bin/env python3
"""Growth with the slice count (issue 24): how the offline engine's time, cells and memory grow
with the number of slices of one shape.

For every N in COUNTS (and FULL_COUNTS with --full) it cuts N random planes through the horse
(`sonoshape slice --mesh 1:data/models/horse.ply:horse --planes random --count N --seed 3
--size-mm 200`), reconstructs them with `sonoshape reconstruct --stats` --repeats times and keeps
the best (smallest) time of each stage: the machine is shared, and the best of a few runs is the
figure least moved by the others' load. Peak RSS is the child's own (os.wait4), the largest of the
runs. Slices whose section of the mesh self-intersects are dropped (`slice --skip-invalid`: one of
the 500 random planes), and the table says how many were kept. With --before BIN the same sets
are also reconstructed by another binary (e.g. main's) and the table shows both.

Usage: python3 bench/growth_table.py [--bin build/apps/sonoshape] [--before OTHER_BINARY]
       [--sets random,sweep] [--repeats 3] [--threads 0] [--full] [--write-doc]
Prints a Markdown table; --write-doc writes it into docs/benchmarks.md between
`<!-- growth_table:begin -->` and `<!-- growth_table:end -->`.
"""
import argparse
import json
import os
import subprocess
import sys
import time

from doc_tables import write_between_markers

COUNTS = [30, 60, 100, 150, 200]
FULL_COUNTS = [300, 500]
STAGES = ["total_s", "arrangement_s", "face_images_s", "evaluation_s"]


def reconstruct(binary, slices, work, threads):
    """One `reconstruct --stats` run: (stats dict, peak RSS MB)."""
    stats_path = os.path.join(work, "stats.json")
    args = [binary, "reconstruct", slices, "-o", os.path.join(work, "mesh.ply"), "--stats", stats_path,
            "--threads", str(threads), "-q"]
    pid = os.fork()
    if pid == 0:  # the child: exec the engine with its output discarded
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        try:
            os.execv(binary, args)
        finally:
            os._exit(127)
    _, status, usage = os.wait4(pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError("failed: " + " ".join(args))
    with open(stats_path) as f:
        return json.load(f), usage.ru_maxrss / 1024.0


def best_of(binary, slices, work, repeats, threads):
    """Best time of each stage over `repeats` runs, the cells of the last, the largest peak RSS."""
    best, rss = None, 0.0
    for _ in range(repeats):
        stats, peak = reconstruct(binary, slices, work, threads)
        rss = max(rss, peak)
        if best is None:
            best = dict(stats)
        for key in STAGES:
            best[key] = min(best[key], stats[key])
    best["rss_mb"] = rss
    return best


def make_set(binary, planes, count, work):
    path = os.path.join(work, f"horse_{planes}{count}.slices.json")
    if not os.path.exists(path):
        subprocess.run([binary, "slice", "--mesh", "1:data/models/horse.ply:horse", "--planes", planes,
                        "--count", str(count), "--seed", "3", "--size-mm", "200", "-o", path, "-q",
                        "--skip-invalid"],
                       check=True, capture_output=True)
    return path


def row_cells(name, stats):
    if stats is None:
        return [name, "–", "–", "–", "–", "–", "–"]
    return [name + (f" ({stats['slices']} kept)" if stats["slices"] != stats["requested"] else ""),
            f"{stats['total_s']:.2f}", f"{stats['arrangement_s']:.2f}", f"{stats['face_images_s']:.2f}",
            f"{stats['evaluation_s']:.2f}", f"{stats['cells']:,}".replace(",", " "), f"{stats['rss_mb']:.0f}"]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bin", default="build/apps/sonoshape", help="the engine measured")
    parser.add_argument("--before", help="another binary to measure on the same sets (e.g. main's)")
    parser.add_argument("--sets", default="random", help="plane families, comma-separated (random, sweep)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each reconstruction (best kept)")
    parser.add_argument("--threads", type=int, default=0, help="--threads of reconstruct (0: all cores)")
    parser.add_argument("--full", action="store_true", help=f"also {FULL_COUNTS} slices")
    parser.add_argument("--before-max", type=int, default=200,
                        help="largest slice count given to --before (its cost grows with N^3)")
    parser.add_argument("--work", default="out/bench/growth")
    parser.add_argument("--write-doc", action="store_true", help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    os.makedirs(args.work, exist_ok=True)
    counts = COUNTS + (FULL_COUNTS if args.full else [])
    header = ["slices", "total s", "arrangement s", "face images s", "evaluation s", "cells built", "peak RSS MB"]
    lines = []
    start = time.monotonic()
    for planes in args.sets.split(","):
        lines += [f"**{planes} planes**", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for count in counts:
            slices = make_set(args.bin, planes, count, args.work)
            for name, binary in ([("before", args.before)] if args.before else []) + [("after", args.bin)]:
                stats = None
                if name == "after" or count <= args.before_max:
                    stats = best_of(binary, slices, args.work, args.repeats, args.threads)
                    stats["requested"] = count
                label = f"{count} ({name})" if args.before else str(count)
                lines.append("| " + " | ".join(row_cells(label, stats)) + " |")
                print(lines[-1], file=sys.stderr)
        lines.append("")
    command = "python3 bench/growth_table.py" + (f" --before {args.before}" if args.before else "") + \
        (f" --sets {args.sets}" if args.sets != "random" else "") + (" --full" if args.full else "") + \
        f" --repeats {args.repeats}" + (f" --threads {args.threads}" if args.threads else "")
    text = "\n".join(lines) + (f"\nBest of {args.repeats} runs per stage (2-core machine, shared); made by "
                               f"`{command}` in {time.monotonic() - start:.0f} s.")
    print(text)
    if args.write_doc:
        write_between_markers(root, "growth_table", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
