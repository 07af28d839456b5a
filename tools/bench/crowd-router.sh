#!/usr/bin/env bash
# The crowd through a router: scenarios/crowd.toml (8 users, 16 pucks) under `timewarp` on real
# stations that are zenoh clients of one router (`station router`, mutual TLS and the session's
# access control, as across machines), all on this machine, driven by `session run --attach`.
# Prints what each station put and got (payload kbit/s, the `# wire:` lines: a client uploads
# each put once, to the router) and the router's total (what the stations put, in; what they got,
# out), then the session's table.
#
# Usage: tools/bench/crowd-router.sh [--quick] [--sites N] [--method M]
#   --sites N: the crowd's first N users only; --quick: --sites 2.
# Goal: upload per site <= 200 kbit/s. (8 stations need more than this machine's 2 CPUs: their
# physics overruns; the bytes they put are what this measures.)
set -euo pipefail
# shellcheck source=crowd-common.sh
source "$(dirname "$0")/crowd-common.sh" "$@"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
scenario="$root/scenarios/crowd.toml"
if [ "$sites" != 8 ]; then
  # The crowd's first N users, and the phases about those only.
  python3 "$root/tools/bench/crowd-subset.py" "$scenario" "$work/crowd$sites.toml" "$sites"
  scenario="$work/crowd$sites.toml"
fi
session="crowd-router-$$"
port=$("$target/release/session" free-port)
"$target/release/session" certs "$scenario" --out "$work/certs" --session "$session" \
  --router r1 --host r1=127.0.0.1 >/dev/null
cat >"$work/r1.toml" <<EOF
name = "r1"
listen = ["tls/127.0.0.1:$port"]
access_control = "$work/certs/acl.json5"
status_file = "$work/r1.json"
[tls]
root_ca_certificate = "$work/certs/ca.pem"
listen_certificate = "$work/certs/r1.pem"
listen_private_key = "$work/certs/r1.key"
enable_mtls = true
EOF
"$target/release/station" router run --config "$work/r1.toml" 2>"$work/r1.log" &
pids+=($!)
names=$(python3 -c 'import sys, tomllib; print(" ".join(s["name"] for s in tomllib.load(open(sys.argv[1], "rb"))["site"]))' "$scenario")
i=0
for name in $names; do
  cat >"$work/$name.toml" <<EOF
session = "$session"
station = "$name"
scenario = "$scenario"
method = "$method"
start = "session"
record = "$work/$name.mcap"
[physics]
cpu = $((i % 2))
[network]
mode = "client"
connect = ["tls/127.0.0.1:$port"]
access_control = "$work/certs/acl.json5"
[network.tls]
root_ca_certificate = "$work/certs/ca.pem"
connect_certificate = "$work/certs/$name.pem"
connect_private_key = "$work/certs/$name.key"
enable_mtls = true
EOF
  "$target/release/station" run --duration-s 120 --config "$work/$name.toml" 2>"$work/$name.log" &
  pids+=($!)
  i=$((i + 1))
done
echo "# crowd through router r1 (tls/127.0.0.1:$port): $i stations under $method, $(nproc) CPUs"
"$target/release/session" run "$scenario" --attach --session "$session" --method "$method" \
  --connect "tls/127.0.0.1:$port" --certs "$work/certs" --recordings "$work" \
  --start-timeout-s 60 --out "$work/out" | tee "$work/table.txt"
# The router's total: every put reaches it once (in), and it forwards to every subscriber (out):
# the stations' own counts, summed.
python3 - "$work/table.txt" <<'PY'
import re, sys
sent = recv = 0.0
for line in open(sys.argv[1]):
    m = re.match(r"# wire: \S+\s+\S+\s+sent ([\d.]+) kbit/s, received ([\d.]+) kbit/s", line)
    if m:
        sent += float(m.group(1)); recv += float(m.group(2))
print(f"# router r1 total (payload): in {sent:.1f} kbit/s (every station's puts), out {recv:.1f} kbit/s (what the stations got)")
PY
