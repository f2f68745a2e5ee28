#!/usr/bin/env bash
# A year of freight on the 10 km example line (docs/examples/line-10km.toml:
# four curves, two applicators, six sites; tortwin synth --layout, 40
# freight trains a day both ways, the default measurements), replayed with
# the MCAP output: contacts, the replay's time, contacts per second and
# peak memory. Issue 45 asks for a year of a 10 km line with 40 freight
# trains a day in under 3 minutes, peak memory under 200 MB, and contacts
# per second no lower than on the 1.5 km section (scripts/bench-year.sh).
# Needs GNU time (/usr/bin/time) and about 1.5 GB in a temporary folder;
# writing the recording takes longer than replaying it (two engines).
#
# Usage: scripts/bench-line-year.sh [DAYS] [KEEP_DIR]   (default 365; the
# recording is kept in KEEP_DIR when given, and reused if it is there)
set -euo pipefail
cd "$(dirname "$0")/.."
days=${1:-365}
cargo build --release --quiet
if [ -n "${2:-}" ]; then
  dir=$2
  mkdir -p "$dir"
else
  dir=$(mktemp -d)
  trap 'rm -rf "$dir"' EXIT
fi
rec="$dir/line_10km_${days}d.mcap"
if [ ! -f "$rec" ]; then
  ./target/release/tortwin synth --layout docs/examples/line-10km.toml --out "$rec" \
    --days "$days" --passenger-share 0 --seed 1 -q
fi
/usr/bin/time -f '%e %M' -o "$dir/time" ./target/release/tortwin replay "$rec" \
  --out-mcap "$dir/out.mcap" > "$dir/summary"
read -r secs kb < "$dir/time"
trains=$(sed -n 's/.*trains \([0-9]*\).*/\1/p' "$dir/summary" | head -1)
contacts=$(sed -n 's/.*contacts \([0-9]*\).*/\1/p' "$dir/summary" | head -1)
measurements=$(sed -n 's/.*measurements \([0-9]*\).*/\1/p' "$dir/summary" | head -1)
mb() { awk -v b="$(stat -c %s "$1")" 'BEGIN { printf "%.1f", b / 1e6 }'; }
echo "days $days, trains $trains, contacts $contacts, measurements $measurements"
echo "input MCAP   $(mb "$rec") MB"
echo "output MCAP  $(mb "$dir/out.mcap") MB"
awk -v s="$secs" -v k="$kb" -v c="$contacts" \
  'BEGIN { printf "replay      %.1f s, %.1f M contacts/s, peak %.0f MB\n", s, c / s / 1e6, k / 1024 }'
