#!/usr/bin/env bash
# Every GPU figure of issue 25 with the CPU baseline of the same machine, in one go, from the
# folder bench/make_carry.sh makes (bin/sonoshape_device_bench, lib/, sets/): for each field
# device (the native CPU on all cores, then every OpenCL device with fp64: PoCL, the GPU)
#   - the offline Table II sets and the offline target (horse, 30 random planes, seeds 1-5):
#     total and evaluation seconds, median of --repeat runs;
#   - the online sets (horse, spot, cheburashka; 100 random planes, a 100-plane sweep): the
#     median update over slices 10-100 and the update at 100 slices;
# and whether each device's meshes equal the CPU's bit for bit (a hash of vertices and
# triangles). Writes the machine (CPU model, cores, GPU), one JSON per run and summary.md (a
# table per figure, a column per device) to $OUT (the device machine's output folder) or
# ./gpu_results.
# Usage: gpu_run.sh [--quick] [--repeat N]   (quick: the offline target and the horse online sets)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=$here/bin/sonoshape_device_bench
out=${OUT:-$PWD/gpu_results}
quick=0
repeat=3
while [[ $# -gt 0 ]]; do
  case $1 in
    --quick) quick=1 ;;
    --repeat) repeat=$2; shift ;;
    *) echo "usage: gpu_run.sh [--quick] [--repeat N]" >&2; exit 2 ;;
  esac
  shift
done
mkdir -p "$out"
# The program binaries are cached per device; the warm-up run builds them outside the timings.
export XDG_CACHE_HOME=$out/cache
# CUDA's libOpenCL where the loader path lacks it.
for d in /usr/local/cuda/lib64 /usr/local/cuda/targets/x86_64-linux/lib; do
  if [[ -e $d/libOpenCL.so.1 ]]; then export LD_LIBRARY_PATH=${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$d; fi
done

{
  echo "commit: $(cat "$here/COMMIT" 2>/dev/null || echo unknown)"
  echo "date: $(date -u +%FT%TZ)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $(nproc) cores"
  if command -v nvidia-smi >/dev/null; then nvidia-smi -L | sed 's/^/gpu: /'; fi
} > "$out/machine.txt"
"$bin" --list-devices > "$out/devices.txt" 2>&1 || true
cat "$out/machine.txt" "$out/devices.txt"

devices=(cpu)
while IFS=$'\t' read -r spec fp64 _; do
  if [[ $fp64 == fp64 ]]; then devices+=("$spec"); fi
done < <(grep '^opencl:' "$out/devices.txt")
echo "devices: ${devices[*]}"

offline_sets=("$here"/sets/table2-*.slices.json "$here"/sets/target-*.slices.json)
online_sets=("$here"/sets/online-*.slices.json)
if (( quick )); then
  offline_sets=("$here"/sets/target-*.slices.json)
  online_sets=("$here"/sets/online-horse-*.slices.json)
fi

for device in "${devices[@]}"; do
  d=${device//:/_}
  mkdir -p "$out/$d"
  "$bin" "${offline_sets[0]}" --device "$device" > /dev/null  # warm-up: builds the program
  for set in "${offline_sets[@]}"; do
    name=$(basename "$set" .slices.json)
    "$bin" "$set" --device "$device" --repeat "$repeat" > "$out/$d/$name.json"
  done
  for set in "${online_sets[@]}"; do
    name=$(basename "$set" .slices.json)
    "$bin" "$set" --device "$device" --online > "$out/$d/$name.json"
  done
  echo "done: $device"
done

python3 - "$out" "${devices[@]}" > "$out/summary.md" <<'PY'
import glob, json, os, statistics, sys
out, devices = sys.argv[1], sys.argv[2:]
dirs = {d: os.path.join(out, d.replace(":", "_")) for d in devices}
def load(d, name):
    return json.load(open(os.path.join(dirs[d], name + ".json")))
names = sorted(os.path.basename(p)[:-5] for p in glob.glob(os.path.join(dirs["cpu"], "*.json")))
print(open(os.path.join(out, "machine.txt")).read())
labels = []
for d in devices:
    j = load(d, names[0])
    labels.append(f"`{d}` = {j.get('device_name', 'native CPU, all cores')}")
print("Devices: " + "; ".join(labels) + "\n")
print("### Offline (median total s / evaluation s; meshes equal to the CPU's)\n")
print("| set | " + " | ".join(f"{d} total s | {d} eval s" for d in devices) + " | same meshes |")
print("|---" * (2 + 2 * len(devices)) + "|")
for name in [n for n in names if not n.startswith("online-")]:
    rows = [load(d, name) for d in devices]
    cells = " | ".join(f"{statistics.median(r['total_s'] for r in j['runs']):.3f} | "
                       f"{statistics.median(r['evaluation_s'] for r in j['runs']):.3f}" for j in rows)
    same = all(j["mesh_hash"] == rows[0]["mesh_hash"] for j in rows)
    print(f"| {name} | {cells} | {'yes' if same else 'NO'} |")
print("\n### Online (median update s over slices 10-100; the update at 100 slices)\n")
print("| set | " + " | ".join(f"{d} median s | {d} at 100 s" for d in devices) + " | same meshes |")
print("|---" * (2 + 2 * len(devices)) + "|")
for name in [n for n in names if n.startswith("online-")]:
    rows = [load(d, name) for d in devices]
    cells = []
    for j in rows:
        steps = j["runs"][0]["steps"]
        later = [s["total_s"] for i, s in enumerate(steps, 1) if 10 <= i <= 100]
        cells.append(f"{statistics.median(later):.4f} | {steps[min(100, len(steps)) - 1]['total_s']:.4f}")
    same = all(j["mesh_hash"] == rows[0]["mesh_hash"] for j in rows)
    print(f"| {name} | {' | '.join(cells)} | {'yes' if same else 'NO'} |")
PY
cat "$out/summary.md"
