#!/usr/bin/env bash
# Replay throughput end to end (MCAP in, MCAP and .rrd out) and peak memory
# (maximum resident set size) of `tortwin replay`, for each recording given
# (default: the reference recordings). Needs GNU time (/usr/bin/time).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
recordings=("$@")
[ ${#recordings[@]} -gt 0 ] || recordings=(tests/reference/recordings/*.mcap)
printf '%-28s %9s %12s %9s %14s %12s\n' recording size_MB contacts seconds contacts_per_s peak_RSS_MB
for rec in "${recordings[@]}"; do
  /usr/bin/time -f '%e %M' -o "$out/time" ./target/release/tortwin replay "$rec" \
    --out-mcap "$out/o.mcap" --out-rrd "$out/o.rrd" > "$out/summary"
  read -r secs kb < "$out/time"
  contacts=$(sed -n 's/.*contacts \([0-9]*\).*/\1/p' "$out/summary" | head -1)
  awk -v n="$(basename "$rec")" -v b="$(stat -c %s "$rec")" -v c="$contacts" -v s="$secs" -v k="$kb" \
    'BEGIN { printf "%-28s %9.1f %12d %9.2f %14.3g %12.1f\n", n, b / 1048576, c, s, c / s, k / 1024 }'
done
