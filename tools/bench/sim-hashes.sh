#!/usr/bin/env bash
# Hashes every simulator output for every committed scenario and method: sim-hashes.sh SIM_BINARY
set -euo pipefail
sim=$1; out=$(mktemp -d)
for sc in scenarios/*.toml; do
  for m in naive paper; do
    d=$out/$(basename $sc .toml)-$m
    "$sim" run "$sc" --method $m --out "$d" >/dev/null
    (cd "$d" && for f in $(ls | sort); do printf '%s  %s\n' "$(sha256sum < "$f" | cut -c1-16)" "$(basename $sc .toml)/$m/$f"; done)
  done
  printf '%s  %s\n' "$("$sim" compare "$sc" | sha256sum | cut -c1-16)" "$(basename $sc .toml)/compare.txt"
done
rm -rf "$out"
