#!/usr/bin/env bash
# What a live viewer and the Foxglove channels cost a running station, in one run: three station
# runs of D seconds each at the same settings (the paper scenario's rates, servo 600 Hz SCHED_FIFO 80
# on CPU 1, physics 1 kHz SCHED_FIFO 70 on CPU 0, mlockall, recording on), one after the other:
#   none         no viewer;
#   viewer       `station run --live` with a Foxglove WebSocket client (Python `websockets`, not ours)
#                subscribed to every channel for the whole window;
#   no-foxglove  no viewer, `record_foxglove = false` (the recording without /tf, /scene, /log).
# Prints per run the servo's wake-up p99 / p99.9 / max and overruns and physics' overruns (from
# `latency attach`, the attach window only), the recording's size per minute of session, and the
# ratios viewer/none (goal: servo p99.9 <= 1.1x, no more overruns) and none/no-foxglove (what the
# Foxglove channels add to a recording).
#
# Usage: tools/bench/live-view.sh [--quick] [--duration SECONDS]
#   default 60 s each; --quick: 3 s each (CI smoke run).
set -euo pipefail
duration=60
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) duration=3 ;;
    --duration) duration="$2"; shift ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "unknown argument: $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
root=$(cd "$(dirname "$0")/../.." && pwd)
cargo build --release --quiet --manifest-path "$root/Cargo.toml" -p coop-tools --bin latency --bin station
target=${CARGO_TARGET_DIR:-$root/target}
work=$(mktemp -d)
station_pid=; viewer_pid=
cleanup() {
  [ -n "$viewer_pid" ] && kill "$viewer_pid" 2>/dev/null
  [ -n "$station_pid" ] && kill "$station_pid" 2>/dev/null && wait "$station_pid" 2>/dev/null
  [ -n "${KEEP_WORK:-}" ] && echo "kept $work" >&2 || rm -rf "$work"
}
trap cleanup EXIT
cpu=1; [ "$(nproc)" -gt 1 ] || cpu=0

echo "# live viewer and Foxglove channels vs none: scenarios/paper.toml, servo SCHED_FIFO 80 on CPU $cpu, physics SCHED_FIFO 70 on CPU 0, mlockall, recording on, ${duration} s each"
echo "# load average before: $(cut -d' ' -f1-3 /proc/loadavg) (anything else running on these cores shows in every row)"
for run in none viewer no-foxglove; do
  [ -n "${KEEP_WORK:-}" ] && date +"%T $run" >&2
  session="lv$$${run%%-*}"
  foxglove=true; [ "$run" = no-foxglove ] && foxglove=false
  cat > "$work/$run.toml" <<TOML
session = "$session"
station = "user1"
scenario = "$root/scenarios/paper.toml"
mlockall = true
record = "$work/$run/user1.mcap"
record_foxglove = $foxglove
[servo]
cpu = $cpu
policy = "fifo"
priority = 80
[physics]
cpu = 0
policy = "fifo"
priority = 70
TOML
  mkdir -p "$work/$run"
  live=(); [ "$run" = viewer ] && live=(--live 127.0.0.1:0)
  "$target/release/station" run --config "$work/$run.toml" "${live[@]}" --duration-s $((duration + 4)) 2> "$work/$run.log" &
  station_pid=$!
  if [ "$run" = viewer ]; then
    url=
    for _ in $(seq 200); do
      url=$(grep -o 'ws://[0-9.:]*' "$work/$run.log" | head -1 || true)
      [ -n "$url" ] && break
      sleep 0.05
    done
    [ -n "$url" ] || { echo "the station printed no live view address:" >&2; cat "$work/$run.log" >&2; exit 1; }
    taskset -c 0 python3 "$root/tools/bench/live_viewer.py" "$url" $((duration + 2)) > "$work/client.json" &
    viewer_pid=$!
  fi
  sleep 1
  # The observer stays off the servo's CPU too.
  taskset -c 0 "$target/release/latency" attach user1 --session "$session" -D "${duration}s" -q --json "$work/$run.json" > /dev/null
  wait "$station_pid"; station_pid=
  if [ -n "$viewer_pid" ]; then wait "$viewer_pid"; viewer_pid=; fi
done

echo "# load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 - "$work" <<'PY'
import glob, json, os, sys
from mcap.reader import make_reader
work = sys.argv[1]
def pct(t, q):
    h = {int(k): v for k, v in t["histogram_us"].items()}
    n, seen = sum(h.values()), 0
    for b in sorted(h):
        seen += h[b]
        if seen >= q * n:
            return b
    return t["max_us"]
def per_minute(run):
    files = sorted(glob.glob(f"{work}/{run}/user1*.mcap"))
    size, first, last = 0, None, None
    for f in files:
        size += os.path.getsize(f)
        with open(f, "rb") as fh:
            for _, _, m in make_reader(fh).iter_messages(topics=["/object"]):
                first = m.log_time if first is None else first
                last = m.log_time
    return size * 60e9 / max(1, last - first), size, (last - first) / 1e9
rows = {}
for run in ("none", "viewer", "no-foxglove"):
    j = json.load(open(f"{work}/{run}.json"))["thread"]
    s, p = j["0"], j["1"]
    rows[run] = (s["cycles"], pct(s, 0.99), pct(s, 0.999), s["max_us"], s["overruns"], p["overruns"]) + per_minute(run)
print(f"{'run':<13}{'cycles':>8}{'p99 us':>8}{'p99.9 us':>10}{'max us':>9}{'servo ovr':>11}{'phys ovr':>10}{'MB/min':>9}{'recorded s':>12}")
for k, r in rows.items():
    print(f"{k:<13}{r[0]:>8}{r[1]:>8}{r[2]:>10}{r[3]:>9.0f}{r[4]:>11}{r[5]:>10}{r[6] / 1e6:>9.2f}{r[8]:>12.1f}")
a, b, c = rows["none"], rows["viewer"], rows["no-foxglove"]
ratio = lambda x, y: x / max(y, 1)
print(f"{'viewer/none':<13}{'':>8}{ratio(b[1], a[1]):>8.2f}{ratio(b[2], a[2]):>10.2f}{ratio(b[3], a[3]):>9.2f}{b[4] - a[4]:>+11}{b[5] - a[5]:>+10}")
v = json.load(open(f"{work}/client.json"))
print(f"# the viewer received {sum(v['messages'].values())} messages ({', '.join(f'{t} {n}' for t, n in sorted(v['messages'].items()))}), {sum(v['bytes'].values()) / 1e6:.2f} MB")
met = ratio(b[2], a[2]) <= 1.1 and b[4] <= a[4] and b[5] <= a[5]
print(f"# goal: with a viewer, servo p99.9 <= 1.1x none and no more overruns: {'met' if met else 'NOT met'}")
print(f"# recording per minute of session: {c[6] / 1e6:.2f} MB without the Foxglove channels, {a[6] / 1e6:.2f} MB with them ({ratio(a[6], c[6]):.2f}x)")
PY
