#!/usr/bin/env bash
# A self-contained benchmark folder for a machine without our Debian libraries (the GPU machine:
# Ubuntu 24.04 with CUDA, whose OpenCL loader finds PoCL and the NVIDIA driver): the engine-only
# bench/device_bench.cpp binary (the sonoshape command pulls in OpenCV's GDAL and codecs, about
# 180 MiB), the shared libraries it needs that such a system lacks (ldd; glibc, libstdc++,
# libgcc_s and libOpenCL stay the system's, newer there and the ones its OpenCL drivers need),
# an $ORIGIN rpath, the slice sets of every figure (sliced here) and bench/gpu_run.sh. Refuses
# to finish over 64 MiB.
# Usage: bench/make_carry.sh [--scaling [--before BIN]] [OUT (default out/carry, git-ignored)]
#                            [BUILD (default build)]
# (build the targets sonoshape and sonoshape_device_bench first)
#   --scaling: the thread-scaling sets of issue 24 instead (horse, random and sweep planes,
#              30-500, 200 random planes with unknown blobs on 40 % of the slices, and 100 random
#              planes with sector fields of view) and bench/scaling_run.sh;
#   --before BIN: a sonoshape_device_bench of another commit beside ours (bin/before_bench),
#              measured on the same machine in the same run (same libraries: build it here).
set -euo pipefail
cd "$(dirname "$0")/.."
scaling=0
before=
while [[ $# -gt 0 && $1 == --* ]]; do
  case $1 in
    --scaling) scaling=1 ;;
    --before) before=$2; shift ;;
    *) echo "usage: make_carry.sh [--scaling [--before BIN]] [OUT] [BUILD]" >&2; exit 2 ;;
  esac
  shift
done
out=${1:-out/carry}
build=${2:-build}
bin=$build/apps/sonoshape  # slices the sets here
bench=$build/bench/sonoshape_device_bench
limit_mib=64
rm -rf "$out"
mkdir -p "$out/bin" "$out/lib" "$out/sets"

cp "$bench" "$out/bin/sonoshape_device_bench"
strip "$out/bin/sonoshape_device_bench"
if [[ -n $before ]]; then
  cp "$before" "$out/bin/before_bench"
  strip "$out/bin/before_bench"
fi
# Libraries the target system has (and must keep: its drivers are built against them).
system='^(linux-vdso|ld-linux|libc|libm|libdl|libpthread|librt|libresolv|libstdc\+\+|libgcc_s|libOpenCL)\.'
ldd "$bench" | awk '/=> \//{print $1, $3}' | while read -r name path; do
  if [[ "$name" =~ $system ]]; then continue; fi
  cp -L "$path" "$out/lib/$name"
  strip --strip-unneeded "$out/lib/$name" 2>/dev/null || true
done
# DT_RPATH (not RUNPATH): it also applies to the libraries' own dependencies.
for b in "$out"/bin/*; do patchelf --force-rpath --set-rpath '$ORIGIN/../lib' "$b"; done
for lib in "$out"/lib/*; do patchelf --force-rpath --set-rpath '$ORIGIN' "$lib"; done

# The slice sets: Table II (bench/device_table.py's), the offline target (horse, 30 random planes,
# seeds 1-5) and the online sets (horse, spot, cheburashka: 100 random planes, a 100-plane sweep).
slice() {  # NAME FAMILY COUNT SEED LABEL:MODEL ...
  local name=$1 family=$2 count=$3 seed=$4 m label model ext
  shift 4
  local args=()
  for m in "$@"; do
    label=${m%%:*} model=${m#*:} ext=obj
    [[ $model == horse ]] && ext=ply
    args+=(--mesh "$label:data/models/$model.$ext:$model")
  done
  "$bin" slice --planes "$family" --count "$count" --seed "$seed" --size-mm "${size_mm:-150}" \
    --skip-invalid -q -o "$out/sets/$name.slices.json" "${args[@]}" ${extra:-}
}
if (( scaling )); then
  # The growth table's sets (bench/growth_table.py: horse, seed 3, 200 mm box), one with unknown
  # blobs and one with a sector field of view on every slice (whose cells are nearly all built:
  # the completion reads the faces around the unknown sets).
  size_mm=200
  for n in 30 100 200 500; do slice "random-$n" random "$n" 3 1:horse; done
  for n in 100 500; do slice "sweep-$n" sweep "$n" 3 1:horse; done
  extra="--unknown 0.4" slice "blobs-random-200" random 200 3 1:horse
  extra="--fov sector --fov-aim cover" slice "sector-random-100" random 100 3 1:horse
  cp bench/scaling_run.sh bench/scaling_table.py "$out/"
  echo "$(git rev-parse --short HEAD)${before:+ (before_bench: $before)}" > "$out/COMMIT"
  du -sh "$out"
  exit 0
fi
for m in spot cow homer horse cheburashka fandisk rocker-arm; do
  slice "table2-$m-parallel-20" parallel 20 1 "1:$m"
  slice "table2-$m-orthogonal-30" orthogonal 30 1 "1:$m"
  slice "table2-$m-random-40" random 40 1 "1:$m"
done
for pair in spot:homer cheburashka:fandisk horse:rocker-arm cow:spot; do
  a=${pair%%:*} b=${pair#*:}
  slice "table2-$a+$b-orthogonal-30" orthogonal 30 1 "1:$a" "2:$b"
  slice "table2-$a+$b-random-30" random 30 1 "1:$a" "2:$b"
done
for seed in 1 2 3 4 5; do slice "target-horse-random-30-s$seed" random 30 "$seed" 1:horse; done
for m in horse spot cheburashka; do
  slice "online-$m-random-100" random 100 1 "1:$m"
  slice "online-$m-sweep-100" sweep 100 1 "1:$m"
done
cp bench/gpu_run.sh "$out/"
git rev-parse --short HEAD > "$out/COMMIT"

size_kib=$(du -sk "$out" | cut -f1)
echo "carry: $out, $((size_kib / 1024)) MiB ($(ls "$out/lib" | wc -l) libraries, $(ls "$out/sets" | wc -l) sets)"
if (( size_kib > limit_mib * 1024 )); then
  echo "error: the carry is over $limit_mib MiB; the largest libraries:" >&2
  du -k "$out"/lib/* | sort -n | tail -5 >&2
  exit 1
fi
