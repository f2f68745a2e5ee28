#!/usr/bin/env bash
# A simulated week and month of traffic on a 1.5 km curve (tortwin synth,
# 40 trains a day), replayed end to end with both outputs: throughput and
# peak memory. Memory must stay flat as the recording grows.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
for days in 7 30; do
  ./target/release/tortwin synth --out "$dir/curve_1500m_${days}d.mcap" --length-m 1500 --days "$days" --seed 1 -q
done
scripts/bench-memory.sh "$dir/curve_1500m_7d.mcap" "$dir/curve_1500m_30d.mcap"
