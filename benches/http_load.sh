#!/usr/bin/env bash
# What serving the map costs the daemon: the demo run twice over the same
# stretch of its replay, once with nobody polling and once with N clients
# (20 by default) each doing what the live map at / does in a browser: load
# the page and its files (the 1.2 MB coastlines among them) once, then fetch
# /data/aircraft.json once a second and /data/receivers.json every tenth
# time, as the map's script does (tar1090 polls aircraft.json alike). Prints the daemon's
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
get = lambda path: urllib.request.urlopen(f"http://127.0.0.1:{port}{path}").read()
def poll():
    for path in ("/", "/leaflet.css", "/style.css", "/leaflet.js", "/app.js", "/data/map.json",
                 "/data/receiver.json", "/world.json"):
        get(path)
    n = 0
    while time.time() < end:
        t = time.time()
        if n % 10 == 0:
            get("/data/receivers.json")
        get("/data/aircraft.json")
        n += 1
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
