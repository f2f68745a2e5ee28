#!/usr/bin/env bash
# `tortwin live` beside a logger at the pace issue 31 names: a 3-day
# synthetic recording (its nozzle clogged from day 2) written again by tests/python/live_writer.py (the
# Python mcap package's writer, 4 kB chunks, each write in two halves) at
# SPEED times real time (default 1000: 4.3 minutes), followed as it grows,
# then checked message for message against `tortwin replay` of the
# finished file (tests/python/check_live.py). tests/live.rs does the same
# at 10 000 times real time. Prints the follower's wall and CPU time.
#
# Usage: scripts/live-demo.sh [SPEED] [--hourly]
set -euo pipefail
cd "$(dirname "$0")/.."
speed=${1:-1000}
hourly=${2:-}
cargo build --release --quiet
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
t=./target/release/tortwin
# Its nozzle clogged from day 2, as in tests/live.rs: the outputs hold an alert.
$t synth --days 3 --seed 3 --out "$dir/rec.mcap" -q \
  --hidden generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T00:00:00Z,f=0.3
if [ "$hourly" = "--hourly" ]; then
  target="$dir/hours"
else
  target="$dir/logger.mcap"
fi
python3 tests/python/live_writer.py "$dir/rec.mcap" "$target" --speed "$speed" $hourly &
writer=$!
while [ ! -e "$target" ]; do sleep 0.05; done
start=$(date +%s.%N)
/usr/bin/time -f '%e s wall, %U s user, %S s system, %M KB peak' -o "$dir/time" \
  $t live "$target" --out-dir "$dir/live" --idle-exit-s 5 -q
wait $writer
echo "writer at ${speed}x real time; follower: $(cat "$dir/time")"
if [ "$hourly" = "--hourly" ]; then
  prev=()
  replays=()
  for f in $(ls "$target"); do
    $t replay "$target/$f" "${prev[@]}" --state-out "$dir/$f.state" --out-mcap "$dir/$f.out" -q
    prev=(--state-in "$dir/$f.state")
    replays+=("$dir/$f.out")
  done
  $t replay "$dir/rec.mcap" --out-mcap "$dir/whole.mcap" -q
  python3 tests/python/check_live.py "$dir/live" "${replays[@]}" --whole "$dir/whole.mcap"
else
  $t replay "$target" --out-mcap "$dir/replay.mcap" -q
  python3 tests/python/check_live.py "$dir/live" "$dir/replay.mcap"
fi
