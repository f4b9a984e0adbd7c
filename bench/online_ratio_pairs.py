#!/usr/bin/env python3
"""Update / rebuild ratio of several builds of sonoshape on one slice set, measured in turn.

The ratio column of bench/online_table.py divides an update by a rebuild at the same slice count,
both from one build. Comparing two builds' ratios from two runs of that table mixes in the
machine's speed of each hour (on this project's shared 2-core machine single runs move by 10-30 %).
This script runs the builds in turn, REPEATS times (alternating which goes first): per build and
repeat, `reconstruct SET --online --stats` (one update per slice) and an offline reconstruction of
the first N slices in the same box for N = 10, 15, 20, ... (as online_table.py). Per build it
prints the median update of slices 10 and later and the median over those N of
median update / median rebuild, with how many N are under 0.2.

Usage: python3 bench/online_ratio_pairs.py SET.slices.json REPEATS BIN [BIN ...] [--threads 2]
"""
import argparse
import json
import os
import statistics
import subprocess
import tempfile

RATIO_EVERY = 5  # as bench/online_table.py: slices 10, 15, 20, ...


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("slices")
    parser.add_argument("repeats", type=int)
    parser.add_argument("bins", nargs="+")
    parser.add_argument("--threads", default="2")
    options = parser.parse_args()
    data = json.load(open(options.slices))
    total = len(data["slices"])
    counts = list(range(10, total + 1, RATIO_EVERY))
    with tempfile.TemporaryDirectory() as work:
        for n in counts:  # same bounds: the same box
            json.dump(dict(data, slices=data["slices"][:n]), open(os.path.join(work, f"first{n}.json"), "w"))
        updates = {b: [] for b in options.bins}
        rebuilds = {b: {n: [] for n in counts} for b in options.bins}
        stats = os.path.join(work, "stats.json")
        for repeat in range(options.repeats):
            for b in options.bins if repeat % 2 == 0 else options.bins[::-1]:
                subprocess.run([b, "reconstruct", "--field", "mean-value", options.slices, "--online", "-o", os.path.join(work, "online"),
                                "--stats", stats, "-q", "--threads", options.threads], check=True)
                updates[b].append([s["total_s"] for s in json.load(open(stats))["steps"]])
                for n in counts:
                    subprocess.run([b, "reconstruct", "--field", "mean-value", os.path.join(work, f"first{n}.json"), "-o",
                                    os.path.join(work, "rebuild"), "--stats", stats, "-q", "--threads", options.threads],
                                   check=True)
                    rebuilds[b][n].append(json.load(open(stats))["total_s"])
    for b in options.bins:
        update = [statistics.median(run[i] for run in updates[b]) for i in range(total)]
        ratios = [update[n - 1] / statistics.median(rebuilds[b][n]) for n in counts]
        print(f"{b}: median update (slices 10 and later) {1000 * statistics.median(update[9:]):.1f} ms, "
              f"median update / rebuild {statistics.median(ratios):.3f} "
              f"({sum(r < 0.2 for r in ratios)} of {len(ratios)} under 0.2)")


if __name__ == "__main__":
    main()
