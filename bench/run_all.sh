#!/usr/bin/env bash
# Regenerates the tables of docs/benchmarks.md, in the document's order: one step per table (or
# per run that makes several), each calling the bench script or binary that its section names.
# Steps whose script has --write-doc write their table into docs/benchmarks.md; the others print
# it (their sections say so). Prints the commit, the date and the machine first, builds the
# targets a step needs before running it, and stops at the first step that fails, naming it.
#
# Usage: bench/run_all.sh [--list] [--quick] [--no-build] [--only STEP]... [--skip STEP]...
#   --list      print the steps in order with their commands, run nothing
#   --quick     the quick mode of the scripts that have one (accuracy_matrix, field_table,
#               device_table, growth_table, online_table); those steps then print their tables and leave the document alone
#   --no-build  do not build the steps' targets (use what build/ holds)
#   --only STEP run only these steps (repeatable); --skip STEP leave these out (repeatable)
# Data sonoshape does not ship: OREX_DATA (the Data/ folder of github.com/haimsaw/OReX) for
# public_csl and field_table, PLUS_LIB_DATA (a github.com/PlusToolkit/PlusLibData checkout or mirror) for plus_recordings.
set -euo pipefail
cd "$(dirname "$0")/.."

# The steps in the document's order: step NAME "BUILD TARGETS" "COMMAND" ["QUICK COMMAND"].
# Commands run with bash -euo pipefail from the repository root.
NAMES=() TARGETS=() COMMANDS=() QUICK=()
step() {
  NAMES+=("$1") TARGETS+=("$2") COMMANDS+=("$3") QUICK+=("${4:-}")
}

step offline "sonoshape" \
  "python3 bench/accuracy_matrix.py --write-doc" \
  "python3 bench/accuracy_matrix.py --quick"

step public_csl "sonoshape" \
  "python3 bench/public_csl.py \"\${OREX_DATA:?set OREX_DATA to the Data/ folder of a haimsaw/OReX checkout, or --skip public_csl}\" --write-doc"

step field_table "sonoshape" \
  "python3 bench/field_table.py \"\${OREX_DATA:?set OREX_DATA to the Data/ folder of a haimsaw/OReX checkout, or --skip field_table}\" --write-doc" \
  "python3 bench/field_table.py \"\${OREX_DATA:-}\" --quick"

step rib_ends "sonoshape" \
  "python3 bench/rib_ends.py --write-doc"

step field_speed "sonoshape" \
  "python3 bench/field_speed.py --write-doc" \
  "python3 bench/field_speed.py --repeats 1"

step devices "sonoshape" \
  "python3 bench/device_table.py --devices cpu,opencl:0:0 --repeat 5 --best" \
  "python3 bench/device_table.py --quick"

step offline_target "sonoshape" \
  "bench/offline_target.sh --write-doc"

step atan2 "sonoshape_atan2_bench" \
  "build/bench/sonoshape_atan2_bench --benchmark_repetitions=3"

step pictures "sonoshape_render" \
  "test -f out/bench/offline_target/horse_1.ply -a -f out/bench/horse-random-40/truth/label_1.ply || { echo 'pictures draws the outputs of the offline and offline_target steps: run those first' >&2; exit 1; }
build/bench/sonoshape_render --slices out/bench/offline_target/horse_1.slices.json -o docs/images/horse_random30.png out/bench/offline_target/horse_1.ply
build/bench/sonoshape_render -o docs/images/horse_truth.png out/bench/horse-random-40/truth/label_1.ply"

step growth "sonoshape" \
  "python3 bench/growth_table.py --sets random,sweep,blobs --before-whole --full --threads 2 --write-doc" \
  "python3 bench/growth_table.py --sets random,sweep,blobs --repeats 1"

step unknowns "sonoshape" \
  "python3 bench/accuracy_matrix.py --unknowns --write-doc"

step two_cylinders "sonoshape" \
  "python3 data/examples/make_two_cylinders.py
for v in unknown noise; do build/apps/sonoshape reconstruct --field mean-value data/examples/two_cylinders_\$v.slices.json -o out/cyl_\$v -q; build/apps/sonoshape evaluate --recon out/cyl_\$v --slices data/examples/two_cylinders_\$v.slices.json --truth 1:data/examples/two_cylinders_truth/label_1.ply; done"

step online "sonoshape" \
  "python3 bench/online_table.py --write-doc" \
  "python3 bench/online_table.py --quick"

step keyframes "sonoshape_keyframe_bench" \
  "build/bench/sonoshape_keyframe_bench --every 12 --every 4
build/bench/sonoshape_keyframe_bench --trajectory fan --every 24 3:2 4:2.5 5:3 8:5"

step live_scan "sonoshape" \
  "build/apps/sonoshape simulate --frames 2 --truth out/truth -o out/x.igs.mha -q
for field in thin-plate mean-value; do for sweep in 10 20; do
  build/apps/sonoshape scan --field \$field --source sim:default --sweep-s \$sweep --realtime --width-px 512 --height-px 512 -o out/scan512-\$field-\$sweep --publish tcp://127.0.0.1:5701
  build/apps/sonoshape evaluate --recon out/scan512-\$field-\$sweep --truth 1:out/truth/label_1.ply --truth 2:out/truth/label_2.ply --truth 3:out/truth/label_3.ply
done; done"

step plus_spine_replay "sonoshape sonoshape_render" \
  "build/apps/sonoshape scan --field mean-value --source replay:data/plus/SpinePhantomFreehand.igs.mha --calibration data/plus/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml --fast -o out/plus
build/bench/sonoshape_render -o docs/images/plus_spine_replay.png --slices out/plus/slices.json out/plus/label_1.ply"

step segmentation "sonoshape" \
  "python3 bench/segmentation_table.py --seeds 1,2,3 --write-doc"

step patient "sonoshape" \
  "mkdir -p out/bench/patient && cd out/bench/patient
../../../build/apps/sonoshape simulate -o sweep.igs.mha --truth truth -q
../../../build/apps/sonoshape segment sweep.igs.mha --every 4 -o slices.json -q
../../../build/apps/sonoshape reconstruct --field mean-value slices.json -o recon --stats stats.json -q
python3 -c 'import json; s = json.load(open(\"stats.json\")); print({k: round(s[k], 2) for k in (\"total_s\", \"field_s\", \"smoothing_s\", \"face_images_s\", \"completion_s\")})'
../../../build/apps/sonoshape evaluate --recon recon --truth 1:truth/label_1.ply --truth 2:truth/label_2.ply --truth 3:truth/label_3.ply --slices slices.json"

step segmentation_speed "sonoshape sonoshape_seg_speed" \
  "python3 bench/segmentation_speed.py --write-doc"

step plus_recordings "sonoshape" \
  "python3 bench/plus_recordings.py \"\${PLUS_LIB_DATA:?set PLUS_LIB_DATA to a PlusToolkit/PlusLibData checkout, or --skip plus_recordings}\" --write-doc"

step viewer "sonoshape sonoshape_viewer_publisher" \
  "node bench/viewer_bench.mjs build/apps/sonoshape build/bench/sonoshape_viewer_publisher out/bench/viewer"

list=0 quick=0 build=1
only=() skip=()
known() {
  local n
  for n in "${NAMES[@]}"; do [ "$n" = "$1" ] && return 0; done
  echo "run_all: no step '$1'; the steps: ${NAMES[*]}" >&2
  exit 2
}
while [ $# -gt 0 ]; do
  case $1 in
    --list) list=1 ;;
    --quick) quick=1 ;;
    --no-build) build=0 ;;
    --only) known "${2:-}"; only+=("$2"); shift ;;
    --skip) known "${2:-}"; skip+=("$2"); shift ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) echo "run_all: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done

chosen() {  # chosen NAME: whether --only and --skip keep the step
  local n
  for n in "${skip[@]+"${skip[@]}"}"; do [ "$n" = "$1" ] && return 1; done
  [ ${#only[@]} -eq 0 ] && return 0
  for n in "${only[@]}"; do [ "$n" = "$1" ] && return 0; done
  return 1
}

command_of() {  # command_of INDEX: the command step INDEX runs in this mode
  if [ "$quick" = 1 ] && [ -n "${QUICK[$1]}" ]; then
    printf '%s\n' "${QUICK[$1]}"
  else
    printf '%s\n' "${COMMANDS[$1]}"
  fi
}

if [ "$list" = 1 ]; then
  for i in "${!NAMES[@]}"; do
    chosen "${NAMES[$i]}" || continue
    printf '%2d %s  (builds: %s)\n' "$((i + 1))" "${NAMES[$i]}" "${TARGETS[$i]}"
    command_of "$i" | sed 's/^/     /'
  done
  exit 0
fi

commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- . ':!docs/benchmarks.md' ':!docs/images' ||
  commit="$commit (with uncommitted changes)"
echo "run_all: sonoshape at commit $commit, $(date -u '+%Y-%m-%d %H:%M UTC'); $(nproc) cores" \
     "($(uname -m), $(uname -s)), load average $(cut -d' ' -f1 /proc/loadavg)"
if [ "$build" = 1 ] && [ ! -f build/build.ninja ]; then
  echo "run_all: no build/ here: configure it first (cmake -S . -B build -G Ninja" \
       "-DCMAKE_BUILD_TYPE=Release), or pass --no-build with the binaries in place" >&2
  exit 1
fi
mkdir -p out/bench
for i in "${!NAMES[@]}"; do
  name=${NAMES[$i]}
  chosen "$name" || continue
  cmd=$(command_of "$i")
  echo
  echo "=== $name ($(date -u +%H:%M:%S), load average $(cut -d' ' -f1 /proc/loadavg))"
  printf '%s\n' "$cmd" | sed 's/^/$ /'
  start=$SECONDS
  # shellcheck disable=SC2086  # the targets are words
  if [ "$build" = 1 ] &&
     ! cmake --build build --target ${TARGETS[$i]} >out/bench/run_all_build.log 2>&1; then
    tail -20 out/bench/run_all_build.log >&2
    echo "run_all: step $name failed: building ${TARGETS[$i]} (out/bench/run_all_build.log)" >&2
    exit 1
  fi
  status=0
  bash -euo pipefail -c "$cmd" || status=$?
  if [ "$status" != 0 ]; then
    echo "run_all: step $name failed (exit status $status) after $((SECONDS - start)) s" >&2
    exit "$status"
  fi
  echo "=== $name: done in $((SECONDS - start)) s"
done
