#!/usr/bin/env bash
# Thread scaling of issue 24 on a many-core machine, from the folder that
# `bench/make_carry.sh --scaling` makes (bin/sonoshape_device_bench [bin/before_bench], lib/,
# sets/): every set reconstructed offline on 1, 2, 4, 8 and 16 threads (best of --repeat runs
# per stage), the 200-slice random set online on 1, 2 and 16 threads, and whether the meshes
# are the same bit for bit whatever the thread count (a hash of vertices and triangles).
# Writes machine.txt, results.jsonl (one JSON object per run) and summary.md (the tables of
# bench/scaling_table.py) to $OUT (the device machine's output folder) or ./scaling_results.
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
    *) echo "usage: scaling_run.sh [--repeat N] [--threads LIST] [--before-threads LIST]" \
            "[--sets LIST] [--no-online]" >&2; exit 2 ;;
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
    [[ $name == random-500 || $name == sector-* || $name == blobs-* ]] && r=$(( repeat > 1 ? repeat - 1 : 1 ))
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

python3 "$here/scaling_table.py" "$out" > "$out/summary.md"
cat "$out/summary.md"
