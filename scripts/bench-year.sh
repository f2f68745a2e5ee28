#!/usr/bin/env bash
# A year of traffic on a 1.5 km curve (tortwin synth, 40 trains a day, the
# default measurements: about 2.4 M), replayed with both outputs: the size
# of the MCAP output and of the .rrd, the replay's time and peak memory.
# Issue 12 asks for at most 150 MB each, replay not slower than before.
# Needs GNU time (/usr/bin/time) and about 600 MB in a temporary folder.
#
# Usage: scripts/bench-year.sh [DAYS]   (default 365)
set -euo pipefail
cd "$(dirname "$0")/.."
days=${1:-365}
cargo build --release --quiet
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
rec="$dir/curve_1500m_${days}d.mcap"
./target/release/tortwin synth --out "$rec" --length-m 1500 --days "$days" --seed 1 -q
/usr/bin/time -f '%e %M' -o "$dir/time" ./target/release/tortwin replay "$rec" \
  --out-mcap "$dir/out.mcap" --out-rrd "$dir/out.rrd" > "$dir/summary"
read -r secs kb < "$dir/time"
trains=$(sed -n 's/.*trains \([0-9]*\).*/\1/p' "$dir/summary" | head -1)
measurements=$(sed -n 's/.*measurements \([0-9]*\).*/\1/p' "$dir/summary" | head -1)
mb() { awk -v b="$(stat -c %s "$1")" 'BEGIN { printf "%.1f", b / 1e6 }'; }
echo "days $days, trains $trains, measurements $measurements"
echo "input MCAP   $(mb "$rec") MB"
echo "output MCAP  $(mb "$dir/out.mcap") MB"
echo "output .rrd  $(mb "$dir/out.rrd") MB"
awk -v s="$secs" -v k="$kb" 'BEGIN { printf "replay      %.1f s, peak %.0f MB\n", s, k / 1024 }'
