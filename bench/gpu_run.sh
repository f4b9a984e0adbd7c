#!/usr/bin/env bash
# Every GPU figure of issue 25 with the CPU baseline of the same machine, in one go, from the
# folder bench/make_carry.sh makes (bin/, lib/, sets/): for each field device (the native CPU on
# all cores, then every OpenCL device with fp64 that `sonoshape devices` lists: PoCL, the GPU)
#   - the offline Table II sets and the offline target (horse, 30 random planes, seeds 1-5):
#     `reconstruct --stats`, total and evaluation seconds;
#   - the online sets (horse, spot, cheburashka; 100 random planes, a 100-plane sweep):
#     `reconstruct --online --stats`, the median update over slices 10-100;
# and whether each device's meshes equal the CPU's byte for byte. Writes the stats, the machine
# (CPU model, cores, GPU) and summary.md (one table per figure, a column per device) to $OUT
# (the device machine's output folder) or ./gpu_results.
# Usage: gpu_run.sh [--quick] (quick: the offline target and two online sets only)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=$here/bin/sonoshape
out=${OUT:-$PWD/gpu_results}
quick=${1:-}
mkdir -p "$out"
# The program binaries are cached per device; a fresh folder times the first build too (warm-up).
export XDG_CACHE_HOME=$out/cache
# CUDA's libOpenCL where the loader path lacks it.
for d in /usr/local/cuda/lib64 /usr/local/cuda/targets/x86_64-linux/lib; do
  [[ -e $d/libOpenCL.so.1 ]] && export LD_LIBRARY_PATH=${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$d
done

{
  echo "commit: $(cat "$here/COMMIT" 2>/dev/null || echo unknown)"
  echo "date: $(date -u +%FT%TZ)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $(nproc) cores"
  command -v nvidia-smi >/dev/null && nvidia-smi -L | sed 's/^/gpu: /'
} > "$out/machine.txt"
"$bin" devices > "$out/devices.txt" 2>&1 || true
cat "$out/machine.txt" "$out/devices.txt"

devices=(cpu)
while read -r spec; do devices+=("$spec"); done < <(grep -o 'device opencl:[0-9]*:[0-9]*' "$out/devices.txt" | cut -d' ' -f2)
echo "devices: ${devices[*]}"

offline_sets=("$here"/sets/table2-*.slices.json "$here"/sets/target-*.slices.json)
online_sets=("$here"/sets/online-*.slices.json)
if [[ $quick == --quick ]]; then
  offline_sets=("$here"/sets/target-*.slices.json)
  online_sets=("$here"/sets/online-horse-*.slices.json)
fi

for device in "${devices[@]}"; do
  d=${device//:/_}
  mkdir -p "$out/$d"
  # Warm-up: builds (or reads) the OpenCL program and faults the binary in.
  "$bin" reconstruct "${offline_sets[0]}" -o "$out/$d/warm-up" --device "$device" -q
  for set in "${offline_sets[@]}"; do
    name=$(basename "$set" .slices.json)
    "$bin" reconstruct "$set" -o "$out/$d/$name" --device "$device" --stats "$out/$d/$name.json" -q
  done
  for set in "${online_sets[@]}"; do
    name=$(basename "$set" .slices.json)
    "$bin" reconstruct "$set" -o "$out/$d/$name" --online --device "$device" --stats "$out/$d/$name.json" -q
  done
  echo "done: $device"
done

python3 - "$out" "${devices[@]}" > "$out/summary.md" <<'PY'
import filecmp, glob, json, os, statistics, sys
out, devices = sys.argv[1], sys.argv[2:]
dirs = {d: os.path.join(out, d.replace(":", "_")) for d in devices}
names = {}
for line in open(os.path.join(out, "devices.txt")):
    for d in devices[1:]:
        if d in line:
            names[d] = line.split(":")[0].strip().split(" (")[0]
names["cpu"] = "native CPU"
print(open(os.path.join(out, "machine.txt")).read())
def same(d, name):
    a, b = os.path.join(dirs["cpu"], name), os.path.join(dirs[d], name)
    if os.path.isdir(a):
        files = sorted(os.listdir(a))
        return files == sorted(os.listdir(b)) and all(filecmp.cmp(os.path.join(a, f), os.path.join(b, f), shallow=False) for f in files)
    return filecmp.cmp(a, b, shallow=False)
def load(d, name):
    return json.load(open(os.path.join(dirs[d], name + ".json")))
sets = sorted(os.path.basename(p)[:-5] for p in glob.glob(os.path.join(dirs["cpu"], "*.json")))
print("Devices: " + "; ".join(f"`{d}` = {names.get(d, d)}" for d in devices) + "\n")
print("### Offline (total s / evaluation s; same meshes as cpu)\n")
print("| set | " + " | ".join(f"{d} total s | {d} eval s" for d in devices) + " | same meshes |")
print("|---" * (2 + 2 * len(devices)) + "|")
for name in [s for s in sets if not s.startswith("online-")]:
    row = [load(d, name) for d in devices]
    cells = " | ".join(f"{r['total_s']:.3f} | {r['evaluation_s']:.3f}" for r in row)
    ok = all(same(d, name) for d in devices[1:])
    print(f"| {name} | {cells} | {'yes' if ok else 'NO'} |")
print("\n### Online (median update s over slices 10-100; last update s)\n")
print("| set | " + " | ".join(f"{d} median s | {d} last s" for d in devices) + " | same meshes |")
print("|---" * (2 + 2 * len(devices)) + "|")
for name in [s for s in sets if s.startswith("online-")]:
    cells = []
    for d in devices:
        steps = load(d, name)["steps"]
        later = [s["total_s"] for s in steps if 10 <= s["step"] <= 100]
        cells.append(f"{statistics.median(later):.4f} | {steps[min(100, len(steps)) - 1]['total_s']:.4f}")
    ok = all(same(d, name) for d in devices[1:])
    print(f"| {name} | {' | '.join(cells)} | {'yes' if ok else 'NO'} |")
PY
cat "$out/summary.md"
