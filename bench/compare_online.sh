#!/bin/bash
# Compares two builds of sonoshape online: runs `reconstruct SET --online --stats` with each, in
# pairs (alternating which goes first, as bench/compare_runs.sh), and prints per pair the sums
# over the updates of slice 10 and later of the update time and of the update time less its field
# evaluations (`evaluation_s`: the octree, smoothing and mesh passes, and the arrangement; a build
# without that stat counts it as 0), with the ratios B/A, then the medians of the ratios.
#
# Usage: bench/compare_online.sh SET.slices.json PAIRS BIN_A BIN_B [THREADS]
#   e.g. bench/compare_online.sh out/bench/online/cheburashka_sweep150.slices.json 4 /tmp/old/sonoshape build/apps/sonoshape
# (the sets: `python3 bench/online_table.py` leaves them in its work folder, or `sonoshape slice`).
set -euo pipefail
if [ $# -lt 4 ] || [ $# -gt 5 ]; then
  sed -n '2,10p' "$0" >&2
  exit 2
fi
set_path=$1 pairs=$2 bin_a=$3 bin_b=$4 threads=${5:-0}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for i in $(seq "$pairs"); do
  if [ $((i % 2)) = 0 ]; then order="a b"; else order="b a"; fi
  for which in $order; do
    if [ "$which" = a ]; then bin=$bin_a; else bin=$bin_b; fi
    "$bin" reconstruct "$set_path" --online -o "$work/out_$which" --stats "$work/$which.json" -q --threads "$threads"
  done
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
done
python3 - "$work/ratios.txt" "$pairs" <<'EOF'
import re, statistics, sys
rows = [re.findall(r"B/A ([0-9.]+), less evaluations ([0-9.]+)", line)[0] for line in open(sys.argv[1])]
print(f"{sys.argv[2]} pairs, medians: updates B/A {statistics.median(float(r[0]) for r in rows):.3f}, "
      f"less evaluations B/A {statistics.median(float(r[1]) for r in rows):.3f}")
EOF
