#!/usr/bin/env bash
# Hashes every simulator output for every committed scenario under the two methods that predate
# the tool exchange (naive, paper), and each scenario's `sim compare` table: run it with the binary
# before and after a change and diff the lists to show the change leaves those figures unchanged.
#
# Usage: tools/bench/sim-hashes.sh SIM_BINARY   (from the repository's top: reads scenarios/*.toml)
set -euo pipefail
case "${1:-}" in
  -h|--help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
  "") echo "missing SIM_BINARY (see --help)" >&2; exit 2 ;;
esac
[ $# -eq 1 ] || { echo "one argument, SIM_BINARY, expected; got $# (see --help)" >&2; exit 2; }
sim=$(command -v -- "$1") && [ -f "$sim" ] && [ -x "$sim" ] ||
  { echo "SIM_BINARY $1: not an executable file (a path, or a name on PATH)" >&2; exit 2; }
compgen -G "scenarios/*.toml" > /dev/null || { echo "no scenarios/*.toml here: run it from the repository's top" >&2; exit 2; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for sc in scenarios/*.toml; do
  for m in naive paper; do
    d=$out/$(basename "$sc" .toml)-$m
    "$sim" run "$sc" --method $m --out "$d" >/dev/null
    (cd "$d" && for f in $(ls | sort); do printf '%s  %s\n' "$(sha256sum < "$f" | cut -c1-16)" "$(basename "$sc" .toml)/$m/$f"; done)
  done
  printf '%s  %s\n' "$("$sim" compare "$sc" | sha256sum | cut -c1-16)" "$(basename "$sc" .toml)/compare.txt"
done
