#!/usr/bin/env bash
# The cluster's cost per frame, against one node's (docs/cluster.md).
#
#   benches/cluster.sh [SCENARIO] [WORKERS]
#
# 1. One node: `run --capture` on the scenario's capture (wall time, CPU).
# 2. The same capture through NATS: the ingest stores it first (its CPU per
#    frame, and the NATS server's while it stores); then the clock, the
#    publisher and WORKERS workers (default 1) process it, timed from their
#    start to the publisher's end, each process's CPU read from /proc.
# CPU is user+system seconds; frames/s is the capture's frames over the wall
# time. Needs nats-server 2.10 or later (FUSE1090_NATS_SERVER, or .venv's).
set -euo pipefail
cd "$(dirname "$0")/.."
scenario=${1:-fixtures/scenarios/tma-busy.toml}
workers=${2:-1}
nats=${FUSE1090_NATS_SERVER:-.venv/bin/nats-server}
bin=target/release/fuse1090
cargo build --release --quiet
dir=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; sleep 0.5; rm -rf "$dir"' EXIT
$bin sim --scenario "$scenario" --out "$dir/w" >/dev/null
frames=$(grep -vc '^\(#\|receiver\)' "$dir/w/capture.txt")
hz=$(getconf CLK_TCK)
cpu() { awk -v hz="$hz" '{printf "%.2f", ($14 + $15) / hz}' "/proc/$1/stat"; }
now() { date +%s.%N; }

start=$(now)
/usr/bin/time -f "%U %S" -o "$dir/single.time" $bin run --capture "$dir/w/capture.txt" --output "$dir/single.jsonl" >/dev/null 2>&1
single_wall=$(echo "$(now) - $start" | bc)
read -r u s <"$dir/single.time"
single_cpu=$(echo "$u + $s" | bc)

port=$((20000 + RANDOM % 20000))
"$nats" -js -a 127.0.0.1 -p "$port" -sd "$dir/js" >/dev/null 2>&1 &
nats_pid=$!
sleep 1
for r in ingest clock publisher worker; do
  printf '[cluster]\nurl = "nats://127.0.0.1:%s"\nname = "bench"\npartitions = 12\nroles = ["%s"]\n' "$port" "$r" >"$dir/$r.toml"
done
before=$(cpu $nats_pid)
/usr/bin/time -f "%U %S" -o "$dir/ingest.time" $bin run --config "$dir/ingest.toml" --capture "$dir/w/capture.txt" >/dev/null
read -r u s <"$dir/ingest.time"
ingest_cpu=$(echo "$u + $s" | bc)
nats_ingest=$(echo "$(cpu $nats_pid) - $before" | bc)

before=$(cpu $nats_pid)
start=$(now)
$bin run --config "$dir/clock.toml" >/dev/null 2>&1 &
clock_pid=$!
$bin run --config "$dir/publisher.toml" --output "$dir/cluster.jsonl" >/dev/null 2>&1 &
pub_pid=$!
worker_pids=()
for _ in $(seq "$workers"); do
  $bin run --config "$dir/worker.toml" >/dev/null 2>&1 &
  worker_pids+=($!)
done
# Each process's CPU, read until it ends (the clock and the publisher end
# by themselves at the replay's end).
declare -A seen
while kill -0 $pub_pid 2>/dev/null; do
  for p in $clock_pid $pub_pid "${worker_pids[@]}"; do
    if c=$(cpu "$p" 2>/dev/null); then seen[$p]=$c; fi
  done
  sleep 0.1
done
wall=$(echo "$(now) - $start" | bc)
worker_cpu=0
for p in "${worker_pids[@]}"; do worker_cpu=$(echo "$worker_cpu + $(cpu "$p")" | bc); done
nats_run=$(echo "$(cpu $nats_pid) - $before" | bc)

per() { echo "scale=2; $1 * 1000000 / $frames" | bc; }
row() { printf '%-34s %8s %10s %s\n' "$1" "$2" "$(per "$2")" "${3:-}"; }
rate() { printf 'wall %.1f s, %.0f frames/s' "$1" "$(echo "$frames / $1" | bc)"; }
echo "frames: $frames; $workers worker(s), 12 partitions (a worker waits 2 s to register before claiming)"
printf '%-34s %8s %10s\n' "" "CPU s" "us/frame"
row "one node (run --capture)" "$single_cpu" "$(rate "$single_wall")"
row "ingest" "$ingest_cpu"
row "nats-server while ingest stores" "$nats_ingest"
row "workers" "$worker_cpu" "$(rate "$wall")"
row "clock" "${seen[$clock_pid]}"
row "publisher" "${seen[$pub_pid]}"
row "nats-server while processing" "$nats_run"
