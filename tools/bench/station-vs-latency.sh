#!/usr/bin/env bash
# Servo loop jitter inside a running station (via `latency attach`) next to the standalone `latency`
# tool at the same settings: 1 kHz, SCHED_FIFO 80, CPU 1, mlockall, D seconds each, one after the
# other in one run. Prints p99, p99.9, max and overruns for both and the ratio station/standalone.
#
# Usage: tools/bench/station-vs-latency.sh [--quick] [--duration SECONDS]
#   default 60 s each; --quick: 3 s each (CI smoke run).
# Goal: station servo p99.9 <= 1.5x the standalone tool's; zero overruns at 1 kHz over 60 s
# on an idle machine.
set -euo pipefail
duration=60
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) duration=3 ;;
    --duration) duration="$2"; shift ;;
    -h|--help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
    *) echo "unknown argument: $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
root=$(cd "$(dirname "$0")/../.." && pwd)
cargo build --release --quiet --manifest-path "$root/Cargo.toml" -p coop-tools --bin latency --bin station
target=${CARGO_TARGET_DIR:-$root/target}
work=$(mktemp -d)
session="bench$$"
cleanup() { [ -n "${station_pid:-}" ] && kill "$station_pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
cpu=1; [ "$(nproc)" -gt 1 ] || cpu=0

echo "# station servo vs standalone latency: 1000 us, SCHED_FIFO 80, CPU $cpu, mlockall, ${duration} s each"
"$target/release/latency" -i 1000 -p 80 --policy fifo -a "$cpu" -m -D "${duration}s" -q --json "$work/standalone.json" > /dev/null

cat > "$work/station.toml" <<TOML
session = "$session"
station = "user1"
scenario = "$root/scenarios/zero-delay.toml"
mlockall = true
[servo]
cpu = $cpu
policy = "fifo"
priority = 80
[physics]
cpu = 0
policy = "fifo"
priority = 70
TOML
"$target/release/station" run --config "$work/station.toml" --duration-s $((duration + 4)) 2> "$work/station.log" &
station_pid=$!
sleep 1
# The observer stays off the servo's CPU too.
taskset -c 0 "$target/release/latency" attach user1 --session "$session" -D "${duration}s" -q --json "$work/station.json" > /dev/null
wait "$station_pid"; station_pid=

python3 - "$work" <<'PY'
import json, sys
work = sys.argv[1]
def load(name):
    t = json.load(open(f"{work}/{name}.json"))["thread"]["0"]
    h = {int(k): v for k, v in t["histogram_us"].items()}
    n = sum(h.values())
    def pct(q):
        seen = 0
        for b in sorted(h):
            seen += h[b]
            if seen >= q * n:
                return b
        return t["max_us"]
    return n, pct(0.99), pct(0.999), t["max_us"], t["overruns"]
rows = {"standalone": load("standalone"), "station servo": load("station")}
print(f"{'loop':<15}{'cycles':>9}{'p99 us':>9}{'p99.9 us':>10}{'max us':>10}{'overruns':>10}")
for k, (n, p99, p999, mx, ov) in rows.items():
    print(f"{k:<15}{n:>9}{p99:>9}{p999:>10}{mx:>10.0f}{ov:>10}")
a, b = rows["standalone"], rows["station servo"]
r = lambda i: b[i] / max(a[i], 1)
print(f"{'ratio':<15}{'':>9}{r(1):>9.2f}{r(2):>10.2f}{r(3):>10.2f}")
print(f"# goal: station servo p99.9 <= 1.5x standalone: {'met' if r(2) <= 1.5 else 'NOT met'}; overruns at 1 kHz: {b[4]} (goal 0 over 60 s)")
rt = json.load(open(f"{work}/station.json"))["roundtrip"]
print(f"# servo -> physics -> servo round trip across processes ({rt['samples']} samples): p50 {rt['p50_us']} us, p99 {rt['p99_us']} us, max {rt['max_us']:.0f} us")
PY
