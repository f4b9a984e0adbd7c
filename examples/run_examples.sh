#!/usr/bin/env bash
# The examples test: each example program as a user runs it.
# usage: run_examples.sh RECONSTRUCT_SLICES FOLLOW_STREAM SONOSHAPE DATA_DIR WORK_DIR
set -euo pipefail
reconstruct=$1 follow=$2 sonoshape=$3 data=$4 work=$5
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAILED: $*" >&2; exit 1; }

# 1. The engine through the library: one mesh per label of a two-label set.
"$reconstruct" "$data/examples/two_labels.slices.json" "$work/meshes" thin-plate > "$work/reconstruct.log" ||
  { cat "$work/reconstruct.log"; fail "reconstruct_slices"; }
for label in 1 2; do
  [ -s "$work/meshes/label_$label.ply" ] || fail "reconstruct_slices wrote no label_$label.ply"
done

# 2. The mesh stream from a program of one's own, joined through the snapshot.
pub="ipc://$work/pub" snapshot="ipc://$work/snapshot"
"$sonoshape" scan --source sim:default --width-px 160 --height-px 160 --frame-rate 5 --depth 5 \
  --sweep-s 3 --realtime --publish "$pub" --snapshot "$snapshot" -o "$work/scan" > "$work/scan.log" 2>&1 &
scan=$!
trap 'kill $scan 2>/dev/null || true' EXIT
for _ in $(seq 400); do
  grep -q "publishing scan" "$work/scan.log" && break
  sleep 0.025
done
grep -q "publishing scan" "$work/scan.log" || { cat "$work/scan.log"; fail "the scan did not publish"; }
"$follow" "$pub" "$snapshot" 60 > "$work/follow.log" 2>&1 || { cat "$work/follow.log"; fail "follow_stream"; }
wait $scan || { cat "$work/scan.log"; fail "the scan"; }
grep -q "mesh\.1: [1-9][0-9]* vertices" "$work/follow.log" || { cat "$work/follow.log"; fail "no mesh.1 received"; }
grep -q "state idle" "$work/follow.log" || { cat "$work/follow.log"; fail "no idle status received"; }
echo "examples: $(grep -c '^seq' "$work/follow.log") stream messages followed, meshes in $work/meshes"
