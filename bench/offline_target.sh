#!/usr/bin/env bash
# The offline speed target of the engine: 30 random planes through the horse at the default
# depth, five seeds, total seconds each (goal: under 2 s on 2 cores).
# Usage: bench/offline_target.sh [--write-doc] [build/apps/sonoshape]
# --write-doc puts the table and the commit, machine and load into docs/benchmarks.md between
# `<!-- offline_target:begin -->` and `<!-- offline_target:end -->`.
set -euo pipefail
cd "$(dirname "$0")/.."
write_doc=
if [ "${1:-}" = --write-doc ]; then
  write_doc=1
  shift
fi
bin=${1:-build/apps/sonoshape}
work=out/bench/offline_target
mkdir -p "$work"
load_at_start=$(cut -d' ' -f1 /proc/loadavg)
table=$work/table.md
printf '| seed | cells | evaluations | arrangement s | face images s | field s | smoothing s | mesh s | total s | peak RSS MB |\n|---|---|---|---|---|---|---|---|---|---|\n' \
  | tee "$table"
for seed in 1 2 3 4 5; do
  "$bin" slice --mesh 1:data/models/horse.ply:horse --planes random --count 30 --seed "$seed" \
    --size-mm 150 -o "$work/horse_$seed.slices.json" -q
  "$bin" reconstruct --field mean-value "$work/horse_$seed.slices.json" -o "$work/horse_$seed.ply" \
    --stats "$work/stats_$seed.json" -q
  python3 - "$work/stats_$seed.json" "$seed" <<'PY' | tee -a "$table"
import json, sys
s = json.load(open(sys.argv[1]))
print(f"| {sys.argv[2]} | {s['cells']} | {s['field_evaluations']} | {s['arrangement_s']:.3f} | "
      f"{s['face_images_s']:.3f} | {s['field_s']:.3f} | {s['smoothing_s']:.3f} | {s['mesh_s']:.3f} | "
      f"{s['total_s']:.3f} | {s['peak_rss_mb']:.0f} |")
PY
done
if [ -n "$write_doc" ]; then
  python3 bench/doc_tables.py offline_target "$load_at_start" "$SECONDS" < "$table"
fi
