#!/bin/bash
# Compares two builds of sonoshape on one slice set: runs `reconstruct SET --stats` with each, in
# pairs (alternating which goes first, so that a machine whose speed drifts hurts both alike).
# On this project's shared 2-core machine single runs vary by 10-15 % (sometimes far more); the
# ratio of two runs made back to back varies far less.
#
# Offline (default): prints the medians over the pairs of the ratios B/A of completion_s and
# total_s, and of each build's completion share (completion_s / total_s).
# --online: feeds the slices one by one (`--online`) and prints per pair the sums over the updates
# of slice 10 and later of the update time and of the update time less its field evaluations
# (`evaluation_s`: the octree, smoothing and mesh passes and the arrangement; a build without that
# stat counts it as 0), with the ratios B/A, then their medians.
#
# Usage: bench/compare_runs.sh [--online] SET.slices.json PAIRS THREADS BIN_A BIN_B
#   e.g. bench/compare_runs.sh out/bench/homer-random-30-80/slices.json 12 2 /tmp/old/sonoshape build/apps/sonoshape
# (the sets: `python3 bench/accuracy_matrix.py --unknowns` or `bench/online_table.py` leave them
# in their work folders, or `sonoshape slice`).
set -euo pipefail
online=
if [ "${1:-}" = --online ]; then
  online=--online
  shift
fi
if [ $# -ne 5 ]; then
  sed -n '2,17p' "$0" >&2
  exit 2
fi
set_path=$1 pairs=$2 threads=$3 bin_a=$4 bin_b=$5
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for i in $(seq "$pairs"); do
  if [ $((i % 2)) = 0 ]; then order="a b"; else order="b a"; fi
  for which in $order; do
    if [ "$which" = a ]; then bin=$bin_a; else bin=$bin_b; fi
    "$bin" reconstruct --field mean-value "$set_path" $online -o "$work/out_$which" --stats "$work/$which.json" -q --threads "$threads"
  done
  if [ -n "$online" ]; then
    python3 - "$work" <<'EOF' | tee -a "$work/ratios.txt"
import json, sys
sums = []
for which in "ab":
    steps = json.load(open(f"{sys.argv[1]}/{which}.json"))["steps"][9:]
    total = sum(s["total_s"] for s in steps)
    passes = sum(s["total_s"] - s.get("evaluation_s", 0.0) for s in steps)
    sums.append((total, passes))
(ta, pa), (tb, pb) = sums
print(f"A: updates {ta:.2f} s, less evaluations {pa:.2f} s | B: updates {tb:.2f} s, less evaluations {pb:.2f} s "
      f"| B/A {tb / ta:.3f}, less evaluations {pb / pa:.3f}")
EOF
  else
    python3 - "$work" >> "$work/ratios.txt" <<'EOF'
import json, sys
a = json.load(open(sys.argv[1] + "/a.json"))
b = json.load(open(sys.argv[1] + "/b.json"))
print(b["completion_s"] / a["completion_s"] if a["completion_s"] > 0 else 1.0, b["total_s"] / a["total_s"],
      a["completion_s"] / a["total_s"], b["completion_s"] / b["total_s"])
EOF
  fi
done
if [ -n "$online" ]; then
  python3 - "$work/ratios.txt" "$pairs" <<'EOF'
import re, statistics, sys
rows = [re.findall(r"B/A ([0-9.]+), less evaluations ([0-9.]+)", line)[0] for line in open(sys.argv[1])]
print(f"{sys.argv[2]} pairs, medians: updates B/A {statistics.median(float(r[0]) for r in rows):.3f}, "
      f"less evaluations B/A {statistics.median(float(r[1]) for r in rows):.3f}")
EOF
else
  python3 - "$work/ratios.txt" "$pairs" <<'EOF'
import statistics, sys
rows = [list(map(float, line.split())) for line in open(sys.argv[1])]
median = [statistics.median(row[i] for row in rows) for i in range(4)]
print(f"{sys.argv[2]} pairs, medians: completion B/A {median[0]:.3f}, total B/A {median[1]:.3f}, "
      f"completion share A {100 * median[2]:.1f} %, B {100 * median[3]:.1f} %")
EOF
fi
