#!/usr/bin/env bash
# Peak memory (maximum resident set size) of `tortwin replay` with both
# outputs on, for each recording given (default: the reference recordings).
# Needs GNU time (/usr/bin/time, Debian package `time`).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
recordings=("$@")
[ ${#recordings[@]} -gt 0 ] || recordings=(../shared/reference/recordings/*.mcap)
printf '%-40s %12s %10s %14s\n' recording size_MB seconds peak_RSS_MB
for rec in "${recordings[@]}"; do
  /usr/bin/time -f '%e %M' -o "$out/time" ./target/release/tortwin replay "$rec" \
    --out-mcap "$out/o.mcap" --out-rrd "$out/o.rrd" --quiet
  read -r secs kb < "$out/time"
  awk -v n="$(basename "$rec")" -v b="$(stat -c %s "$rec")" -v s="$secs" -v k="$kb" \
    'BEGIN { printf "%-40s %12.1f %10s %14.1f\n", n, b / 1048576, s, k / 1024 }'
done
