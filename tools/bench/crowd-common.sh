# Sourced by the crowd benchmarks (crowd-stations.sh, crowd-router.sh) with their arguments: reads
# --quick, --sites N and --method M into `sites` and `method` (--help prints the sourcing script's
# header), builds `session` and `station`, and sets `root`, `target` and a fresh `work` directory
# (the caller removes it on exit).
sites=8; method=timewarp
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) sites=2 ;;
    --sites) sites="$2"; shift ;;
    --method) method="$2"; shift ;;
    -h|--help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
    *) echo "unknown argument: $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done
root=$(cd "$(dirname "$0")/../.." && pwd)
cargo build --release --quiet --manifest-path "$root/Cargo.toml" -p coop-tools --bin session --bin station
target=${CARGO_TARGET_DIR:-$root/target}
work=$(mktemp -d)
