#!/usr/bin/env bash
# latency vs cyclictest: the same settings (1 kHz, SCHED_FIFO 80, pinned to one CPU, mlockall), run
# alternately (cyclictest, latency, cyclictest, latency, ...) so machine noise hits both, then both
# tools' p99, p99.9 and max and the ratio latency/cyclictest.
#
# Percentiles of both come from their 1 us histograms in their JSON, by the same code below, so the
# comparison does not depend on either tool's own percentile arithmetic. Both histograms hold one
# sample per wake-up (cyclictest's semantics); latency's view that also counts every deadline missed
# during a stall (no coordinated omission) is printed on its own line, not compared.
#
# Usage: tools/bench/latency-vs-cyclictest.sh [--quick] [--duration SECONDS] [--rounds N] [--cpu N]
#   default: 60 s per run, 2 rounds, CPU 1.   --quick: 3 s, 1 round (CI smoke run).
# Needs: cyclictest (Debian package rt-tests), python3, root for SCHED_FIFO.
# Goal: latency's p99.9 <= 1.2x cyclictest's.
set -euo pipefail

duration=60 rounds=2 cpu=1
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) duration=3 rounds=1 ;;
    --duration) duration="$2"; shift ;;
    --rounds) rounds="$2"; shift ;;
    --cpu) cpu="$2"; shift ;;
    -h|--help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
    *) echo "unknown argument: $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
command -v cyclictest >/dev/null || { echo "cyclictest not found: apt-get install rt-tests" >&2; exit 2; }
[ "$(nproc)" -gt "$cpu" ] || cpu=0

root=$(cd "$(dirname "$0")/../.." && pwd)
cargo build --release --quiet --manifest-path "$root/Cargo.toml" -p coop-tools --bin latency
target=${CARGO_TARGET_DIR:-$root/target}
latency="$target/release/latency"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

hist_limit=20000   # us; both tools get the same histogram range
echo "# latency vs cyclictest: 1000 us interval, SCHED_FIFO 80, CPU $cpu, mlockall, ${duration} s per run, $rounds round(s)"
for r in $(seq 1 "$rounds"); do
  cyclictest -m -p 80 -i 1000 -a "$cpu" -t 1 -D "$duration" -q -h "$hist_limit" \
    --json="$work/cyclictest.$r.json" > /dev/null
  "$latency" -m -p 80 --policy fifo -i 1000 -a "$cpu" -t 1 -D "${duration}s" -q \
    --json "$work/latency.$r.json" > /dev/null
done

python3 - "$work" "$rounds" "$hist_limit" <<'PY'
import json, sys
work, rounds, limit = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])

def load(tool, missed=False):
    """Sum the 1 us histograms of every round of one tool; returns (buckets, samples, max_us)."""
    buckets, cycles, mx = {}, 0, 0.0
    for r in range(1, rounds + 1):
        t = json.load(open(f"{work}/{tool}.{r}.json"))["thread"]["0"]
        if missed:
            t = dict(t["with_missed_deadlines"], cycles=t["with_missed_deadlines"]["samples"], max_us=t["max_us"])
        h = t.get("histogram") or t.get("histogram_us") or {}
        for k, v in h.items():
            buckets[int(k)] = buckets.get(int(k), 0) + v
        cycles += t["cycles"]
        mx = max(mx, float(t.get("max", t.get("max_us", 0))))
    return buckets, cycles, mx

def pct(buckets, cycles, mx, q):
    need, seen = q * cycles, 0
    for b in sorted(buckets):
        seen += buckets[b]
        if seen >= need:
            return float(b)
    return mx  # in the overflow: the maximum is the best bound we have

rows = {}
for tool in ("cyclictest", "latency"):
    b, c, mx = load(tool)
    rows[tool] = (c, pct(b, c, mx, 0.99), pct(b, c, mx, 0.999), mx)
print(f"{'tool':<12}{'cycles':>10}{'p99 us':>10}{'p99.9 us':>10}{'max us':>10}")
for tool, (c, p99, p999, mx) in rows.items():
    print(f"{tool:<12}{c:>10}{p99:>10.0f}{p999:>10.0f}{mx:>10.0f}")
ratio = lambda i: rows["latency"][i] / max(rows["cyclictest"][i], 1.0)
print(f"{'ratio':<12}{'':>10}{ratio(1):>10.2f}{ratio(2):>10.2f}{ratio(3):>10.2f}")
print(f"# goal: latency p99.9 <= 1.2x cyclictest: {'met' if ratio(2) <= 1.2 else 'NOT met'}")
b, c, mx = load("latency", missed=True)
if c > rows["latency"][0]:
    print(f"# latency counting the {c - rows['latency'][0]} missed deadlines too (no coordinated omission): "
          f"p99 {pct(b, c, mx, 0.99):.0f} us, p99.9 {pct(b, c, mx, 0.999):.0f} us")
PY
