#!/usr/bin/env bash
# Real stations with a world of several objects, beside the paper's world of one, in one run:
# `session run` of scenarios/crowd.toml (8 users, 16 pucks; 8 stations on this machine, each its
# servo, physics and network processes) and of scenarios/paper.toml (2 stations), both under
# `timewarp` (the method whose physics does the most: it steps every tool on every object and rolls
# back). Prints per scenario: stations, physics compute p99 (worst station, and the median of the
# stations; a loop's compute is its wall time from wake to done, so a CPU shared by several
# stations' physics shows in it), physics overruns during the session (all stations), rollbacks
# and their deepest, the ticks re-simulated per second per station (the work the crowd adds),
# fallbacks, hash mismatches (and confirmed states adopted), phases passed, and the ratio
# crowd/paper of the compute p99; and the CPU time the stations' processes took, by role, per
# station per second of session. `session run` gives the stations' physics the CPUs in turn.
#
# Usage: tools/bench/crowd-stations.sh [--quick] [--sites N] [--method M]
#   --sites N: the crowd's first N users only (their stations, and the phases about them alone);
#   --quick: --sites 2 (CI smoke run).
# Goal: the crowd's physics compute p99 inside its 1 ms period, no overruns.
set -euo pipefail
# shellcheck source=crowd-common.sh
source "$(dirname "$0")/crowd-common.sh" "$@"
trap 'rm -rf "$work"' EXIT
crowd="$root/scenarios/crowd.toml"
if [ "$sites" != 8 ]; then
  # The crowd's first N users, and the phases about those only.
  python3 "$root/tools/bench/crowd-subset.py" "$crowd" "$work/crowd$sites.toml" "$sites"
  crowd="$work/crowd$sites.toml"
fi
echo "# real stations, method $method, $(nproc) CPUs, commit $(git -C "$root" rev-parse --short HEAD)"
for sc in "$root/scenarios/paper.toml" "$crowd"; do
  name=$(basename "$sc" .toml)
  sed -n 's/^duration_s *= *\([0-9.]*\).*/\1/p' "$sc" | head -1 > "$work/$name.duration"
  # The CPU time the stations' processes took, by role (polled from /proc while they run).
  python3 - "$work/$name.cpu" "$target/release/session" run "$sc" --method "$method" --json --out "$work/$name" \
    > "$work/$name.json" 2> "$work/$name.log" <<'PY' || { echo "session run $sc failed:"; tail -20 "$work/$name.log"; exit 1; }
import collections, json, os, re, subprocess, sys, time
out, cmd = sys.argv[1], sys.argv[2:]
p = subprocess.Popen(cmd)
seen, hz = {}, os.sysconf("SC_CLK_TCK")
while p.poll() is None:
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            a = open(f"/proc/{pid}/cmdline", "rb").read().replace(b"\0", b" ").decode(errors="replace")
            f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if " station " in f" {a} " and "session run" not in a:
            m = re.search(r"\b(servo|physics|network)\b", a)
            seen[pid] = (m.group(1) if m else "supervisor", (int(f[11]) + int(f[12])) / hz)
    time.sleep(0.2)
roles = collections.defaultdict(float)
for role, cpu in seen.values():
    roles[role] += cpu
json.dump(roles, open(out, "w"))
sys.exit(p.returncode)
PY
done
python3 - "$work" "$method" "$(basename "$crowd" .toml)" <<'PY'
import json, os, statistics, sys
work, method, crowd = sys.argv[1], sys.argv[2], sys.argv[3]
rows = {}
for name in ["paper", crowd]:
    v = json.load(open(f"{work}/{name}.json"))["methods"][method]
    st = v["stations"]
    p99 = [s["live"]["loops"]["physics"]["compute_us"]["p99"] for s in st.values()]
    over = sum(s["live"]["overruns_during_session"]["physics"] for s in st.values())
    rb = [s["live"]["physics"]["rollback"] or {} for s in st.values()]
    real = v["real"]
    rows[name] = p99
    dur = float(open(f"{work}/{name}.duration").read())
    print(f"{name:<8} stations {len(st):>2}  physics compute p99 us: worst {max(p99):>6} median {statistics.median(p99):>6.0f}"
          f"  overruns {over:>4}  rollbacks {sum(r.get('rollbacks', 0) for r in rb):>6}"
          f" (deepest {max(r.get('max_depth', 0) for r in rb)} ticks)"
          f"  re-simulated ticks/s per station {sum(r.get('resimulated_ticks', 0) for r in rb) / len(st) / dur:>7.0f}"
          f"  fallbacks {sum(r.get('fallbacks', 0) for r in rb)}"
          f"  hash mismatches {sum(r.get('hash_mismatches', 0) for r in rb)}"
          f" (adopted {sum(r.get('adopted_states', 0) for r in rb)})"
          f"  phases {real['phases_passed']}/{real['phases_total']}"
          f"  objects {len(v.get('objects') or []) or 1}")
    cpu = json.load(open(f"{work}/{name}.cpu"))
    print(f"{'':<8} CPU time of the stations' processes per station per second of session: "
          + ", ".join(f"{r} {cpu.get(r, 0) / len(st) / dur:.3f}" for r in ["servo", "physics", "network", "supervisor"])
          + f"  (all stations: {sum(cpu.values()) / dur:.2f} CPUs of {os.cpu_count()})")
print(f"# crowd/paper physics compute p99 (worst station): {max(rows[crowd]) / max(max(rows['paper']), 1):.2f}x")
PY
