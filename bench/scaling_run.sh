#!/usr/bin/env bash
# Thread scaling of issue 24 on a many-core machine, from the folder that
# `bench/make_carry.sh --scaling` makes (bin/sonoshape_device_bench [bin/before_bench], lib/,
# sets/): every set reconstructed offline on 1, 2, 4, 8 and 16 threads (best of --repeat runs
# per stage), the 200-slice random set online on 1, 2 and 16 threads, and whether the meshes
# are the same bit for bit whatever the thread count (a hash of vertices and triangles).
# Writes machine.txt, results.jsonl (one JSON object per run) and summary.md to $OUT (the
# device machine's output folder) or ./scaling_results.
# Usage: scaling_run.sh [--repeat N] [--threads "1 2 4 8 16"] [--before-threads "1 16"]
#                       [--sets "random-100 ..."] [--no-online]
# (bin/before_bench, where the carry has one, runs on --before-threads only; --sets: these of
# sets/ only)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=${OUT:-$PWD/scaling_results}
repeat=3
threads="1 2 4 8 16"
before_threads="1 16"
only_sets=
online=1
while [[ $# -gt 0 ]]; do
  case $1 in
    --repeat) repeat=$2; shift ;;
    --threads) threads=$2; shift ;;
    --before-threads) before_threads=$2; shift ;;
    --sets) only_sets=$2; shift ;;
    --no-online) online=0 ;;
    *) echo "usage: scaling_run.sh [--repeat N] [--threads LIST]" >&2; exit 2 ;;
  esac
  shift
done
mkdir -p "$out"
{
  echo "commit: $(cat "$here/COMMIT" 2>/dev/null || echo unknown)"
  echo "date: $(date -u +%FT%TZ)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $(nproc) cores"
  echo "load at start: $(cut -d' ' -f1-3 /proc/loadavg)"
} > "$out/machine.txt"
cat "$out/machine.txt"
results=$out/results.jsonl
: > "$results"

binaries=(sonoshape_device_bench)
[[ -x $here/bin/before_bench ]] && binaries+=(before_bench)
for b in "${binaries[@]}"; do
  for set in "$here"/sets/*.slices.json; do
    name=$(basename "$set" .slices.json)
    [[ -n $only_sets && " $only_sets " != *" $name "* ]] && continue
    r=$repeat
    [[ $name == random-500 || $name == sector-* ]] && r=$(( repeat > 1 ? repeat - 1 : 1 ))
    list=$threads
    [[ $b == before_bench ]] && list=$before_threads
    for t in $list; do
      start_ns=$(date +%s%N)
      line=$("$here/bin/$b" "$set" --threads "$t" --repeat "$r")
      echo "{\"binary\": \"$b\", \"name\": \"$name\", \"threads\": $t, \"wall_ms\": $(( ($(date +%s%N) - start_ns) / 1000000 )), \"result\": $line}" >> "$results"
      echo "$b $name threads $t done"
    done
  done
  list="1 2 16"
  [[ $b == before_bench ]] && list=$before_threads
  (( online )) || list=
  for t in $list; do
    line=$("$here/bin/$b" "$here/sets/random-200.slices.json" --online --threads "$t")
    echo "{\"binary\": \"$b\", \"name\": \"online-random-200\", \"threads\": $t, \"result\": $line}" >> "$results"
    echo "$b online-random-200 threads $t done"
  done
done
echo "load at end: $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/machine.txt"

python3 - "$out" > "$out/summary.md" <<'PY'
import json, statistics, sys
out = sys.argv[1]
rows = [json.loads(l) for l in open(f"{out}/results.jsonl")]
print(open(f"{out}/machine.txt").read())
stages = ["arrangement_s", "face_images_s", "evaluation_s", "completion_s", "smoothing_s", "mesh_s",
          "outside_octree_s"]
# What the stats time outside the octree's sampling, its smoothing and the mesher: the slices'
# preparation and planes (the first update's arrangement and face images) and the contour keys.
for r in rows:
    for run in r["result"].get("runs", []):
        if "total_s" in run:
            run["outside_octree_s"] = run["total_s"] - run["field_s"] - run["smoothing_s"] - run["mesh_s"]
for binary in sorted({r["binary"] for r in rows}):
    print(f"\n## {binary}\n")
    print("| set | threads | total s (best) | speed-up | " + " | ".join(s[:-2] + " s" for s in stages) +
          " | cells | mesh hash |")
    print("|---" * (6 + len(stages)) + "|")
    base = {}
    for r in rows:
        if r["binary"] != binary or r["name"].startswith("online-"):
            continue
        runs = r["result"]["runs"]
        best = {k: min(run[k] for run in runs) for k in ["total_s"] + stages}
        base.setdefault(r["name"], best["total_s"])
        print(f"| {r['name']} | {r['threads']} | {best['total_s']:.3f} | "
              f"{base[r['name']] / best['total_s']:.2f} | " +
              " | ".join(f"{best[s]:.3f}" for s in stages) +
              f" | {runs[0]['cells']} | {r['result']['mesh_hash']} |")
    print("\n| online set | threads | median update ms (from the 10th) | median ms (last tenth) | mesh hash |")
    print("|---|---|---|---|---|")
    for r in rows:
        if r["binary"] != binary or not r["name"].startswith("online-"):
            continue
        steps = [s["total_s"] for s in r["result"]["runs"][0]["steps"]]
        tenth = max(1, len(steps) // 10)
        print(f"| {r['name']} | {r['threads']} | {1e3 * statistics.median(steps[9:]):.1f} | "
              f"{1e3 * statistics.median(steps[-tenth:]):.1f} | {r['result']['mesh_hash']} |")
PY
cat "$out/summary.md"
