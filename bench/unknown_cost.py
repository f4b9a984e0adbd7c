#!/usr/bin/env python3
"""What a slice set's unknown regions cost the online engine: the per-slice update time with and
without them (docs/benchmarks.md, "Live scan").

  bench/unknown_cost.py SLICES.json [--binary build/apps/sonoshape] [--threads N]

Runs `sonoshape reconstruct SLICES --online --stats` on the set as it is and on a copy whose
regions labelled "unknown" are removed (the fields of view stay), and prints each run's median and
p95 update time, field and smoothing seconds, and field evaluations.
"""
import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def run(binary, slices, threads, work, name):
    stats = work / f"{name}.stats.json"
    command = [binary, "reconstruct", "--field", "mean-value", str(slices), "--online", "--stats", str(stats),
               "-o", str(work / name)]
    if threads:
        command += ["--threads", str(threads)]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    doc = json.loads(stats.read_text())
    totals = sorted(step["total_s"] for step in doc["steps"])
    return {
        "median_ms": 1000 * statistics.median(totals),
        "p95_ms": 1000 * totals[min(len(totals) - 1, int(0.95 * len(totals)))],
        "field_s": doc["field_s"],
        "smoothing_s": doc["smoothing_s"],
        "evaluations": sum(step["field_evaluations"] for step in doc["steps"]),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("slices")
    parser.add_argument("--binary", default=str(HERE / "build" / "apps" / "sonoshape"))
    parser.add_argument("--threads", type=int, default=0, help="0: all cores")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        doc = json.loads(Path(args.slices).read_text())
        for s in doc["slices"]:
            s["regions"] = [r for r in s.get("regions", []) if r["label"] != "unknown"]
        without = work / "without_unknown.json"
        without.write_text(json.dumps(doc))
        print("| set | update median ms | p95 ms | field s | smoothing s | evaluations |")
        print("|---|---|---|---|---|---|")
        for name, path in (("as given", Path(args.slices)), ("without unknown regions", without)):
            r = run(args.binary, path, args.threads, work, name.replace(" ", "_"))
            print(f"| {name} | {r['median_ms']:.0f} | {r['p95_ms']:.0f} | {r['field_s']:.2f} | "
                  f"{r['smoothing_s']:.2f} | {r['evaluations']} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
