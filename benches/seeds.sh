#!/bin/bash
# Held-out seeds of a scenario: simulates it under other seeds and prints,
# per seed, the fused, MLAT-track and MLAT-fix horizontal RMSE and NEES, so
# that a change is judged on worlds it was not tuned on.
#
#   benches/seeds.sh SCENARIO.toml "4 5 6" [FUSE1090 [CONFIG]]
#
# FUSE1090 defaults to target/release/fuse1090 (build it first); CONFIG is
# passed to `run --config`. Work files go under ${TMPDIR:-/tmp}/fuse1090-seeds.
set -euo pipefail
scenario=$1
seeds=$2
bin=${3:-target/release/fuse1090}
config=${4:-}
work=${TMPDIR:-/tmp}/fuse1090-seeds/$(basename "$scenario" .toml)
mkdir -p "$work"
printf '%-5s %-9s %9s %6s\n' seed source rmse_m nees
for s in $seeds; do
  d=$work/seed$s
  if [ ! -f "$d/capture.txt" ]; then
    sed "s/^seed = .*/seed = $s/" "$scenario" > "$work/seed$s.toml"
    "$bin" sim --scenario "$work/seed$s.toml" --out "$d" > /dev/null
  fi
  "$bin" run --capture "$d/capture.txt" --output "$d/out.jsonl" --source-tracks ${config:+--config "$config"} > /dev/null 2>&1
  "$bin" eval --truth "$d/truth.jsonl" --tracks "$d/out.jsonl" \
    | awk -v s="$s" '/^(fused|mlat|mlat-fix) +[0-9]+ ac/ { printf "%-5s %-9s %9s %6s\n", s, $1, $5, $8 }'
done
