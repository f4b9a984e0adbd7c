#!/bin/bash
# Compares two builds of sonoshape on one slice set: runs `reconstruct SET --stats` with each, in
# pairs (alternating which goes first, so that a machine whose speed drifts hurts both alike), and
# prints the medians over the pairs of the ratios B/A of completion_s and total_s, and of each
# build's completion share (completion_s / total_s). On this project's shared 2-core machine single
# runs vary by 10-15 %; the ratio of two runs made back to back varies far less.
#
# Usage: bench/compare_runs.sh SET.slices.json PAIRS THREADS BIN_A BIN_B
#   e.g. bench/compare_runs.sh out/bench/homer-random-30-80/slices.json 12 2 /tmp/old/sonoshape build/apps/sonoshape
# (the set: `python3 bench/accuracy_matrix.py --unknowns` leaves it there, or `sonoshape slice`).
set -euo pipefail
if [ $# -ne 5 ]; then
  sed -n '2,10p' "$0" >&2
  exit 2
fi
set_path=$1 pairs=$2 threads=$3 bin_a=$4 bin_b=$5
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for i in $(seq "$pairs"); do
  if [ $((i % 2)) = 0 ]; then order="a b"; else order="b a"; fi
  for which in $order; do
    if [ "$which" = a ]; then bin=$bin_a; else bin=$bin_b; fi
    "$bin" reconstruct "$set_path" -o "$work/out_$which" --stats "$work/$which.json" -q --threads "$threads"
  done
  python3 - "$work" >> "$work/ratios.txt" <<'EOF'
import json, sys
a = json.load(open(sys.argv[1] + "/a.json"))
b = json.load(open(sys.argv[1] + "/b.json"))
print(b["completion_s"] / a["completion_s"] if a["completion_s"] > 0 else 1.0, b["total_s"] / a["total_s"],
      a["completion_s"] / a["total_s"], b["completion_s"] / b["total_s"])
EOF
done
python3 - "$work/ratios.txt" "$pairs" <<'EOF'
import statistics, sys
rows = [list(map(float, line.split())) for line in open(sys.argv[1])]
median = [statistics.median(row[i] for row in rows) for i in range(4)]
print(f"{sys.argv[2]} pairs, medians: completion B/A {median[0]:.3f}, total B/A {median[1]:.3f}, "
      f"completion share A {100 * median[2]:.1f} %, B {100 * median[3]:.1f} %")
EOF
