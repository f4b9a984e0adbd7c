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
are also reconstructed by another binary (e.g. main's) and the table shows both; with
--before-whole, by the same binary building the whole arrangement (`reconstruct
--whole-arrangement`, the engine before cells on demand), up to --before-max slices. Families:
random, sweep, and blobs (the random planes with unknown blobs on 40 % of the slices, `slice
--unknown 0.4`).

With --online the same sets are also fed slice by slice to the online engine (`reconstruct
--online --stats`, one update per slice, one run: its figures are medians over many updates) and a
second table gives the median update time over the updates that brought the set from 0.9 N to N
slices, the median and 90th percentile over every update from the 10th, the sum of the updates and
the peak RSS. --sweep-online K adds a K-slice simulated sweep (`slice --planes sweep --count K`,
the probe moved along the horse rocking on two axes with a tremor) fed the same way, with the
median update time of each tenth of the sweep: flat when the cost per slice does not grow.
--sweep-online-fov gives each slice of that sweep a 60-degree sector field of view aimed to cover
the horse (`slice --fov sector --fov-aim cover`; the rest of the plane unknown), as every slice of
a scan has.

Usage: python3 bench/growth_table.py [--bin build/apps/sonoshape] [--before OTHER_BINARY | --before-whole]
       [--before-max 200] [--sets random,sweep,blobs] [--repeats 3] [--threads 0] [--full] [--write-doc]
       [--online] [--sweep-online 600 [--sweep-online-fov]] [--offline-max N]
Prints a Markdown table; --write-doc writes it into docs/benchmarks.md between
`<!-- growth_table:begin -->` and `<!-- growth_table:end -->`.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers

COUNTS = [30, 60, 100, 150, 200]
FULL_COUNTS = [300, 500]
STAGES = ["total_s", "arrangement_s", "face_images_s", "evaluation_s"]
# family -> (`slice --planes`, extra `slice` arguments)
FAMILIES = {"random": ("random", []), "sweep": ("sweep", []), "blobs": ("random", ["--unknown", "0.4"])}


def reconstruct(binary, slices, work, threads, extra=()):
    """One `reconstruct --stats` run: (stats dict, peak RSS MB)."""
    stats_path = os.path.join(work, "stats.json")
    args = [binary, "reconstruct", "--field", "mean-value", slices, "-o", os.path.join(work, "mesh.ply"), "--stats", stats_path,
            "--threads", str(threads), "-q"] + list(extra)
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


def reconstruct_online(binary, slices, work, threads):
    """One `reconstruct --online --stats` run: (stats dict with "steps", peak RSS MB)."""
    stats_path = os.path.join(work, "online_stats.json")
    args = [binary, "reconstruct", "--field", "mean-value", slices, "-o", os.path.join(work, "online_mesh"), "--online", "--stats",
            stats_path, "--threads", str(threads), "-q"]
    start = time.monotonic()
    with subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) as child:
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            raise RuntimeError("failed: " + " ".join(args) + "\n" + child.stderr.read())
    with open(stats_path) as f:
        stats = json.load(f)
    # The share of the run's wall time the process had a core for (per thread used): on a shared
    # machine the updates' wall times are longer than they would be alone by about its inverse.
    wall = time.monotonic() - start
    stats["cpu_share"] = (usage.ru_utime + usage.ru_stime) / wall / max(1, threads or os.cpu_count())
    return stats, max(step["peak_rss_mb"] for step in stats["steps"])


def online_row(name, stats, rss):
    """Median update ms near the end (last tenth), median / 90th percentile from the 10th update,
    the sum of the updates, the cells built at the end, peak RSS."""
    times = [step["total_s"] for step in stats["steps"]]
    tail = times[int(0.9 * len(times)):]
    later = times[9:] if len(times) > 10 else times
    return [name, f"{1000 * statistics.median(tail):.0f}", f"{1000 * statistics.median(later):.0f}",
            f"{1000 * statistics.quantiles(later, n=10)[8]:.0f}", f"{sum(times):.1f}",
            f"{stats['cells']:,}".replace(",", " "), f"{rss:.0f}", f"{stats['cpu_share']:.2f}"]


def tenths_row(stats):
    """Median update ms of each tenth of the sequence."""
    times = [step["total_s"] for step in stats["steps"]]
    n = len(times)
    return [f"{1000 * statistics.median(times[n * k // 10:max(n * (k + 1) // 10, n * k // 10 + 1)]):.0f}"
            for k in range(10)]


def best_of(binary, slices, work, repeats, threads, extra=()):
    """Best time of each stage over `repeats` runs, the cells of the last, the largest peak RSS."""
    best, rss = None, 0.0
    for _ in range(repeats):
        stats, peak = reconstruct(binary, slices, work, threads, extra)
        rss = max(rss, peak)
        if best is None:
            best = dict(stats)
        for key in STAGES:
            best[key] = min(best[key], stats[key])
    best["rss_mb"] = rss
    return best


def make_set(binary, family, count, work, extra=()):
    planes, family_extra = FAMILIES[family]
    extra = family_extra + list(extra)
    suffix = "".join(a.strip("-") for a in extra)
    path = os.path.join(work, f"horse_{family}{count}{suffix}.slices.json")
    if not os.path.exists(path):
        subprocess.run([binary, "slice", "--mesh", "1:data/models/horse.ply:horse", "--planes", planes,
                        "--count", str(count), "--seed", "3", "--size-mm", "200", "-o", path, "-q",
                        "--skip-invalid"] + extra,
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
    parser.add_argument("--before-whole", action="store_true",
                        help="measure the same binary building the whole arrangement as `before`")
    parser.add_argument("--sets", default="random",
                        help="plane families, comma-separated (random, sweep, blobs)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each reconstruction (best kept)")
    parser.add_argument("--threads", type=int, default=0, help="--threads of reconstruct (0: all cores)")
    parser.add_argument("--full", action="store_true", help=f"also {FULL_COUNTS} slices")
    parser.add_argument("--before-max", type=int, default=200,
                        help="largest slice count given to --before (its cost grows with N^3)")
    parser.add_argument("--work", default="out/bench/growth")
    parser.add_argument("--online", action="store_true", help="also feed each set to the online engine")
    parser.add_argument("--sweep-online", type=int, default=0, metavar="K",
                        help="also feed a K-slice simulated sweep to the online engine")
    parser.add_argument("--sweep-online-fov", action="store_true",
                        help="give the --sweep-online sweep's slices a sector field of view")
    parser.add_argument("--offline-max", type=int, default=100000,
                        help="largest slice count reconstructed offline (the online runs take all)")
    parser.add_argument("--write-doc", action="store_true", help="write the table into docs/benchmarks.md")
    args = parser.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    os.makedirs(args.work, exist_ok=True)
    counts = COUNTS + (FULL_COUNTS if args.full else [])
    header = ["slices", "total s", "arrangement s", "face images s", "evaluation s", "cells built", "peak RSS MB"]
    lines = []
    online_lines = []
    online_header = ["slices", "median update ms (last tenth)", "median update ms (from 10th)",
                     "90th percentile ms", "sum of updates s", "cells built", "peak RSS MB",
                     "CPU time / (wall time x threads)"]
    start, load_at_start = time.monotonic(), os.getloadavg()[0]
    for planes in args.sets.split(","):
        if not args.online:
            continue
        online_lines += [f"**{planes} planes, online (one update per slice)**", "",
                         "| " + " | ".join(online_header) + " |", "|" + "---|" * len(online_header)]
        for count in counts:
            slices = make_set(args.bin, planes, count, args.work)
            stats, rss = reconstruct_online(args.bin, slices, args.work, args.threads)
            online_lines.append("| " + " | ".join(online_row(str(stats["slices"]), stats, rss)) + " |")
            print(online_lines[-1], file=sys.stderr)
        online_lines.append("")
    if args.sweep_online:
        fov = ["--fov", "sector", "--fov-aim", "cover"] if args.sweep_online_fov else []
        slices = make_set(args.bin, "sweep", args.sweep_online, args.work, fov)
        stats, rss = reconstruct_online(args.bin, slices, args.work, args.threads)
        tenth_header = [f"{10 * k}-{10 * (k + 1)} %" for k in range(10)]
        cells = f"{stats['cells']:,}".replace(",", " ")
        online_lines += [f"**{stats['slices']}-slice sweep{' with sector fields of view' if fov else ''}, "
                         f"online: median update ms per tenth of the sweep** "
                         f"(sum {sum(s['total_s'] for s in stats['steps']):.1f} s, {cells} cells "
                         f"built, peak RSS {rss:.0f} MB, CPU time / (wall time x threads) "
                         f"{stats['cpu_share']:.2f})", "",
                         "| " + " | ".join(tenth_header) + " |", "|" + "---|" * len(tenth_header),
                         "| " + " | ".join(tenths_row(stats)) + " |", ""]
        print(online_lines[-2], file=sys.stderr)
    for planes in args.sets.split(","):
        lines += [f"**{planes} planes**", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for count in counts:
            if count > args.offline_max:
                continue
            slices = make_set(args.bin, planes, count, args.work)
            before = [("before", args.before, [])] if args.before else []
            if args.before_whole:
                before = [("whole arrangement", args.bin, ["--whole-arrangement"])]
            for name, binary, extra in before + [("after", args.bin, [])]:
                stats = None
                if name == "after" or count <= args.before_max:
                    stats = best_of(binary, slices, args.work, args.repeats, args.threads, extra)
                    stats["requested"] = count
                label = f"{count} ({name})" if before else str(count)
                lines.append("| " + " | ".join(row_cells(label, stats)) + " |")
                print(lines[-1], file=sys.stderr)
        lines.append("")
    command = "python3 bench/growth_table.py" + (f" --before {args.before}" if args.before else "") + \
        (" --before-whole" if args.before_whole else "") + \
        (f" --before-max {args.before_max}" if (args.before or args.before_whole) and args.before_max != 200 else "") + \
        (f" --sets {args.sets}" if args.sets != "random" else "") + (" --full" if args.full else "") + \
        f" --repeats {args.repeats}" + (f" --threads {args.threads}" if args.threads else "") + \
        (" --online" if args.online else "") + \
        (f" --sweep-online {args.sweep_online}" if args.sweep_online else "") + \
        (" --sweep-online-fov" if args.sweep_online_fov else "") + \
        (f" --offline-max {args.offline_max}" if args.offline_max < 100000 else "")
    text = "\n".join(lines + online_lines) + (f"\nBest of {args.repeats} runs per stage (2-core machine, shared); made by "
                               f"`{command}` in {time.monotonic() - start:.0f} s.")
    print(text)
    if args.write_doc:
        write_between_markers(root, "growth_table", text + "\n" + provenance(root, load_at_start, time.monotonic() - start))
    return 0


if __name__ == "__main__":
    sys.exit(main())
