#!/usr/bin/env bash
# Soak test (issue 27): a real-time simulated scan for MINUTES with three subscribers on its mesh
# stream, recording the scan's memory, update time and frame-to-mesh latency over time.
#
#   bench/soak.sh MINUTES [--out DIR] [--plot PNG] [--no-build] [--binary PATH] [--slice-budget N]
#
# The simulated hand goes back and forth over the default phantom, one pass every 20 s, as in a
# long examination that revisits the same anatomy (scan --passes), with the slice budget a long
# examination should use (scan --slice-budget, default here 240; 0: none). Subscribers:
#   fast     `listen` keeping up with every message;
#   slow     `listen --slow-ms 250 --receive-hwm 50`: takes 4 messages a second, so the publisher
#            drops for it (counted as sequence gaps on its side);
#   restart  a `listen --snapshot` that quits after 60 s and joins again, for the whole soak.
# The scan's RSS and CPU time are sampled every 5 s from /proc. At the end bench/soak_report.py
# writes DIR/soak.md (tables: RSS slope after warm-up, update time and latency per 5 minutes,
# drops by reason, each subscriber's tally) and the plot (default DIR/soak.png).
# Default DIR: out/soak. --binary runs another build's sonoshape (a copy, so that the build folder
# can change during the soak); it implies --no-build. Needs python3 with matplotlib for the plot
# (Debian python3-matplotlib).
set -euo pipefail
cd "$(dirname "$0")/.."
minutes="${1:?usage: bench/soak.sh MINUTES [--out DIR] [--plot PNG] [--no-build] [--binary PATH] [--slice-budget N]}"
shift
out=out/soak
plot=""
build=1
bin="$PWD/build/apps/sonoshape"
slice_budget=240
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    --plot) plot="$2"; shift 2 ;;
    --no-build) build=0; shift ;;
    --binary) bin="$(realpath "$2")"; build=0; shift 2 ;;
    --slice-budget) slice_budget="$2"; shift 2 ;;
    *) echo "bench/soak.sh: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
[ -n "$plot" ] || plot="$out/soak.png"
if [ "$build" = 1 ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build build -j "$(nproc)" --target sonoshape >/dev/null
fi
rm -rf "$out"
mkdir -p "$out/restart"

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
port=$(free_port)
snapshot_port=$(free_port)
endpoint="tcp://127.0.0.1:$port"
snapshot="tcp://127.0.0.1:$snapshot_port"
seconds=$((minutes * 60))
passes=$((minutes * 3))

pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

"$bin" scan --field mean-value --source sim:default --realtime --sweep-s "$seconds" --passes "$passes" \
  --slice-budget "$slice_budget" \
  --duration "$seconds" --publish "$endpoint" --snapshot "$snapshot" --publish-frames 5 \
  -o "$out/scan" >"$out/scan.log" 2>&1 &
scan_pid=$!
pids+=("$scan_pid")
start_s=$(date +%s.%N)
echo "soak: scan pid $scan_pid on $endpoint for $minutes min; results in $out"

# Memory and CPU of the scan every 5 s: elapsed s, RSS kB, CPU s (utime + stime).
(
  ticks=$(getconf CLK_TCK)
  echo "t_s,rss_kb,cpu_s" >"$out/rss.csv"
  while kill -0 "$scan_pid" 2>/dev/null; do
    rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$scan_pid/status" 2>/dev/null || true)
    cpu=$(awk -v t="$ticks" '{print ($14 + $15) / t}' "/proc/$scan_pid/stat" 2>/dev/null || true)
    now=$(date +%s.%N)
    [ -n "$rss" ] && awk -v a="$now" -v b="$start_s" -v r="$rss" -v c="$cpu" \
      'BEGIN { printf "%.1f,%s,%s\n", a - b, r, c }' >>"$out/rss.csv"
    sleep 5
  done
) &
pids+=($!)

sleep 1
"$bin" listen "$endpoint" --snapshot "$snapshot" -o "$out/fast" --duration $((seconds + 30)) \
  --until-idle >"$out/fast.log" 2>&1 &
pids+=($!)
"$bin" listen "$endpoint" --snapshot "$snapshot" -o "$out/slow" --duration $((seconds + 30)) \
  --slow-ms 250 --receive-hwm 50 >"$out/slow.log" 2>&1 &
slow_pid=$!
pids+=("$slow_pid")
(
  round=0
  while kill -0 "$scan_pid" 2>/dev/null; do
    round=$((round + 1))
    "$bin" listen "$endpoint" --snapshot "$snapshot" -o "$out/restart/$(printf %03d $round)" \
      --duration 60 >>"$out/restart.log" 2>&1 || echo "restart $round: listen exited $?" >>"$out/restart.log"
  done
) &
pids+=($!)

status=0
wait "$scan_pid" || status=$?
echo "soak: scan exited $status"
# The slow subscriber is stopped once the scan ends (its backlog is what it would have dropped).
sleep 5
kill -INT "$slow_pid" 2>/dev/null || true
wait || true
trap - EXIT
# The plot needs matplotlib: the first python3 on PATH, else Debian's.
py=python3
"$py" -c 'import matplotlib' 2>/dev/null || py=/usr/bin/python3
"$py" bench/soak_report.py "$out" --plot "$plot" --minutes "$minutes"
exit "$status"
