#!/usr/bin/env bash
# What serving the map's data costs the daemon: the demo run twice over the
# same stretch of its replay, once with nobody polling and once with N
# clients (20 by default) each fetching /data/aircraft.json and
# /data/receivers.json once a second, as tar1090 does. Prints the daemon's
# CPU time (user + system, from /proc) over the window, for each run, as a
# share of one core. Usage: benches/http_load.sh [BIN] [CLIENTS] [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/fuse1090}
clients=${2:-20}
secs=${3:-30}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
port=$((20000 + RANDOM % 20000))
http=$((port + 1))
sed -e "s#127.0.0.1:30104#127.0.0.1:$port#" -e "s#127.0.0.1:8090#127.0.0.1:$http#" \
    -e "s#fixtures/#$PWD/fixtures/#" -e 's#^kind = "stdout"#kind = "udp"\naddress = "127.0.0.1:9"#' \
    config/demo.toml > "$work/demo.toml"

cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }

run() {
  local pollers=$1
  "$bin" run --config "$work/demo.toml" 2>"$work/log" >/dev/null &
  local pid=$!
  sleep 3
  local t0 c0
  t0=$(date +%s.%N); c0=$(cpu_ticks $pid)
  if [ "$pollers" -gt 0 ]; then
    python3 - "$http" "$pollers" "$secs" <<'PY'
import sys, threading, time, urllib.request
port, n, secs = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
end = time.time() + secs
def poll():
    while time.time() < end:
        t = time.time()
        for path in ("/data/aircraft.json", "/data/receivers.json"):
            urllib.request.urlopen(f"http://127.0.0.1:{port}{path}").read()
        time.sleep(max(0.0, 1.0 - (time.time() - t)))
ts = [threading.Thread(target=poll) for _ in range(n)]
[t.start() for t in ts]; [t.join() for t in ts]
PY
  else
    sleep "$secs"
  fi
  local t1 c1
  t1=$(date +%s.%N); c1=$(cpu_ticks $pid)
  kill $pid; wait $pid 2>/dev/null || true
  echo "$pollers clients: daemon CPU $(echo "scale=2; 100 * ($c1 - $c0) / $(getconf CLK_TCK) / ($t1 - $t0)" | bc)% of a core"
}
for _ in 1 2; do run 0; run "$clients"; done
