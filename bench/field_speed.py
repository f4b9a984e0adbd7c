#!/usr/bin/env python3
"""Speed and memory of the thin-plate field beside the mean-value field (issue 38, point 4).

Three runs per field, each the command a user would type:
  - offline: `sonoshape reconstruct SET --field F --stats S` on 40 random horse planes
    (`slice --planes random --count 40 --seed 1 --size-mm 150`) at the default depth: the
    stats' total seconds and peak RSS (best of --repeats);
  - online: `reconstruct SET --online --field F --stats S` on 100 random horse planes (seed 1):
    the median and 90th percentile of the per-update total, the solve's median and its median
    conjugate-gradient iterations (of --repeats runs, the one whose median is the median);
  - live: `scan --source sim:default --sweep-s 10 --realtime --width-px 512 --height-px 512
    --field F -o DIR`: scan.json's update median, frame-to-mesh p95 and frames dropped for being
    behind (segmentation or reconstruction), of --repeats scans the one whose median is the
    median.
Prints one Markdown table; `--write-doc` puts it into docs/benchmarks.md between
`<!-- field_speed:begin -->` and `<!-- field_speed:end -->`. Run it on a quiet machine.

Usage: bench/field_speed.py [--binary build/apps/sonoshape] [--work out/bench/field_speed]
                            [--repeats 3] [--write-doc]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from doc_tables import provenance, write_between_markers

FIELDS = ["mean-value", "thin-plate"]


def run(cmd):
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(" ".join(cmd) + "\n" + result.stdout + result.stderr)
        raise SystemExit(f"field_speed: {cmd[1]} failed")
    return result


def cut(binary, root, work, count):
    path = os.path.join(work, f"horse-random-{count}.slices.json")
    if not os.path.exists(path):
        run([binary, "slice", "--mesh", "1:" + os.path.join(root, "data", "models", "horse.ply"),
             "--planes", "random", "--count", str(count), "--seed", "1", "--size-mm", "150",
             "--skip-invalid", "-q", "-o", path])
    return path


def offline(binary, work, slices, field, repeats):
    best = None
    for r in range(repeats):
        stats = os.path.join(work, f"offline-{field}.json")
        run([binary, "reconstruct", slices, "-o", os.path.join(work, f"offline-{field}"), "--field", field,
             "--stats", stats, "-q"])
        with open(stats) as f:
            s = json.load(f)
        if best is None or s["total_s"] < best["total_s"]:
            best = s
    return best


def online(binary, work, slices, field, repeats):
    """The run (of `repeats`) whose median update is the median: one noisy run moves it less."""
    runs = []
    for r in range(repeats):
        stats = os.path.join(work, f"online-{field}.json")
        run([binary, "reconstruct", slices, "-o", os.path.join(work, f"online-{field}"), "--field",
             field, "--online", "--stats", stats, "-q"])
        with open(stats) as f:
            steps = json.load(f)["steps"]
        total = sorted(1000 * s["total_s"] for s in steps)
        runs.append({"median": statistics.median(total), "p90": total[int(0.9 * (len(total) - 1))],
                     "solve": statistics.median(1000 * s.get("solve_s", 0.0) for s in steps),
                     "iterations": statistics.median(s.get("solve_iterations", 0) for s in steps),
                     "rebuilds": sum(1 for s in steps if s.get("full_rebuild"))})
    runs.sort(key=lambda n: n["median"])
    return runs[len(runs) // 2]


def live(binary, work, field, repeats):
    """The scan (of `repeats`) whose update median is the median: a live scan's timing moves by a
    few milliseconds from run to run."""
    runs = []
    for r in range(repeats):
        out = os.path.join(work, f"scan-{field}-{r}")
        run([binary, "scan", "--source", "sim:default", "--sweep-s", "10", "--realtime", "--width-px",
             "512", "--height-px", "512", "--field", field, "-q", "-o", out])
        with open(os.path.join(out, "scan.json")) as f:
            s = json.load(f)
        behind = s["dropped"]["segmentation_behind"] + s["dropped"]["reconstruction_behind"]
        runs.append({"update": s["update_ms"]["median"], "p95": 1000 * s["latency_s"]["p95"],
                     "behind": behind, "updates": s["updates"], "slices": s["slices"]})
    runs.sort(key=lambda n: n["update"])
    return runs[len(runs) // 2]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--binary", default="build/apps/sonoshape")
    parser.add_argument("--work", default="out/bench/field_speed")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--write-doc", action="store_true")
    args = parser.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    os.makedirs(args.work, exist_ok=True)
    load, start = os.getloadavg()[0], time.monotonic()
    set40, set100 = cut(args.binary, root, args.work, 40), cut(args.binary, root, args.work, 100)
    lines = ["| field | offline, 40 random horse planes: s / peak MB | online, 100 random horse planes: "
             "update median / p90 ms | online solve median ms (iterations) | live 512×512 scan: update "
             "median ms | live: frame-to-mesh p95 ms | live: dropped behind |",
             "|---|---|---|---|---|---|---|"]
    for field in FIELDS:
        o = offline(args.binary, args.work, set40, field, args.repeats)
        n = online(args.binary, args.work, set100, field, args.repeats)
        s = live(args.binary, args.work, field, args.repeats)
        solve = f"{n['solve']:.0f} ({n['iterations']:.0f})" if field == "thin-plate" else "–"
        lines.append(f"| {field} | {o['total_s']:.2f} / {o['peak_rss_mb']:.0f} | {n['median']:.0f} / "
                     f"{n['p90']:.0f} | {solve} | {s['update']:.0f} | {s['p95']:.0f} | {s['behind']} |")
        print(lines[-1], file=sys.stderr)
    text = "\n".join(lines)
    print(text)
    if args.write_doc:
        write_between_markers(root, "field_speed",
                              text + "\n\n" + provenance(root, load, time.monotonic() - start))


if __name__ == "__main__":
    main()
