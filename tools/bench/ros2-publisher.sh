#!/usr/bin/env bash
# The servo's wake-up latency with the ROS 2 publisher on vs off: scenarios/paper.toml under
# `timewarp` on real stations, alternately without and with `--ros2` (every station also
# publishes its poses, force, /tf and /rosout through a zenoh router standing in for rmw_zenohd,
# to a zenoh-ros2-sdk subscriber taking every topic), in one run. Prints per session each
# station's servo wake-up p99.9 and what it put on ROS 2, then the ratio of the medians on/off.
# The ROS side (the router and the Python subscriber, which a real deployment runs on other
# machines) is held to the first CPU, where the stations' network processes run, off the servos'.
#
# Usage: tools/bench/ros2-publisher.sh [--quick] [--rounds N]
#   default 5 rounds (each: one session off, one on); --quick: 1 round (CI smoke run).
# Goal: servo wake-up p99.9 with the publisher on <= 1.1x off.
set -euo pipefail
rounds=5
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) rounds=1 ;;
    --rounds) rounds="$2"; shift ;;
    -h|--help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
    *) echo "unknown argument: $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
root=$(cd "$(dirname "$0")/../.." && pwd)
cargo build --release --quiet --manifest-path "$root/Cargo.toml" -p coop-tools --bin session --bin station
target=${CARGO_TARGET_DIR:-$root/target}
work=$(mktemp -d)
pids=()
cleanup() {
  touch "$work/stop"
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
port=$("$target/release/session" free-port)
cat >"$work/router.toml" <<EOF
name = "ros"
listen = ["tcp/127.0.0.1:$port"]
status_file = "$work/router.json"
EOF
pin=(); [ "$(nproc)" -gt 1 ] && pin=(taskset -c 0)
"${pin[@]}" "$target/release/station" router run --config "$work/router.toml" 2>"$work/router.log" &
pids+=($!)
session="r2bench$$"
"${pin[@]}" python3 "$root/tools/tests/fixtures/ros2_client.py" subscribe --router "127.0.0.1:$port" \
  --namespace "/coop/${session}_timewarp" --sites user1,user2 --until-file "$work/stop" \
  --out "$work/got.json" 2>"$work/client.log" &
pids+=($!)
echo "# servo wake-up p99.9 with the ROS 2 publisher off/on: paper.toml, timewarp, $rounds round(s), $(nproc) CPUs"
echo "# round ros2 user1_p999_us user2_p999_us ros2_sent_kbit_s"
for r in $(seq 1 "$rounds"); do
  for mode in off on; do
    args=()
    [ "$mode" = on ] && args=(--ros2 --ros2-router "tcp/127.0.0.1:$port")
    "$target/release/session" run "$root/scenarios/paper.toml" --method timewarp --json \
      --session "$session" --out "$work/out-$r-$mode" "${args[@]}" >"$work/$r-$mode.json"
    python3 - "$work/$r-$mode.json" "$r" "$mode" <<'PY' | tee -a "$work/rows.txt"
import json, sys
v = json.load(open(sys.argv[1]))
st = v["methods"]["timewarp"]["stations"]
p = [st[s]["live"]["loops"]["servo"]["wake_us"]["p999"] for s in ("user1", "user2")]
ros = sum(k["sent_kbit_s"] for s in ("user1", "user2") for k in st[s]["live"]["network"]["traffic"] if k["kind"] == "ros2")
print(sys.argv[2], sys.argv[3], p[0], p[1], round(ros, 1))
PY
  done
done
python3 - "$work/rows.txt" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
med = {m: statistics.median(float(x) for r in rows if r[1] == m for x in r[2:4]) for m in ("off", "on")}
print(f"median servo wake-up p99.9: off {med['off']:.0f} us, on {med['on']:.0f} us, on/off {med['on'] / max(med['off'], 1e-9):.2f} (goal <= 1.1)")
PY
