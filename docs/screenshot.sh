#!/usr/bin/env bash
# Regenerate docs/rerun_viewer.png: tortwin's demo recording in the rerun viewer
# (or, given another .rrd and PNG, e.g. out/clog/residuals.rrd docs/residuals_viewer.png),
# rendered on a virtual X display with Mesa's software Vulkan (lavapipe/llvmpipe).
#
# Needs (Debian): apt-get update && apt-get install -y \
#     xvfb mesa-vulkan-drivers libvulkan1 xdotool imagemagick x11-utils
# and the viewer:  pip install rerun-sdk==0.36.3
#
# Usage: docs/screenshot.sh [RRD] [OUT_PNG]
#   defaults: out/demo.rrd (built with `tortwin replay` if missing), docs/rerun_viewer.png
#
# Notes (rerun 0.36.3, Mesa 22.3):
# - Vulkan only: the GL backend refuses to start ("Adapter does not support
#   drawing to texture format R32Float").
# - Xvfb must run WITHOUT the Composite extension. With it, the viewer gets a
#   32-bit ARGB (transparent) window and lavapipe's frames never reach the X
#   framebuffer: every grab is solid black.
# - `rerun --screenshot-to` also renders, but it shoots ~4 s after start, while
#   the file is still loading; it then panics on exit ("Failed to take store
#   hub"). Hence a real window, grabbed once the file has loaded.
# - No clicks: the recording's blueprint (crates/outputs/src/rerun_out/blueprint.rs) opens the
#   time panel on `time` following the data, i.e. at the end of the run, and
#   collapses the time, blueprint and selection panels. The only pointer move
#   parks the pointer where it draws no tooltip or hover line.
set -euo pipefail
cd "$(dirname "$0")/.."

RRD=${1:-out/demo.rrd}
OUT=${2:-docs/rerun_viewer.png}
W=1600 H=1000
DNUM=${DNUM:-99}          # X display number
PORT=${PORT:-9877}        # the viewer's gRPC port (must be free)
LOAD_WAIT=${LOAD_WAIT:-20}

if [ ! -f "$RRD" ]; then
    cargo build --release
    mkdir -p out
    ./target/release/tortwin replay --out-rrd out/demo.rrd --out-mcap out/demo.mcap
    RRD=out/demo.rrd
fi

XVFB_PID= RR_PID=
cleanup() {
    [ -n "$RR_PID" ] && kill -- "-$RR_PID" 2>/dev/null || true
    [ -n "$XVFB_PID" ] && kill "$XVFB_PID" 2>/dev/null || true
    [ -n "${STATE:-}" ] && rm -rf "$STATE" || true
}
trap cleanup EXIT

Xvfb ":$DNUM" -screen 0 "${W}x${H}x24" -extension Composite -nolisten tcp &
XVFB_PID=$!
sleep 2
export DISPLAY=":$DNUM" WGPU_BACKEND=vulkan
# A throwaway home for the viewer: it persists its UI state (panel sizes,
# blueprints edited by hand, ...) in $XDG_DATA_HOME/rerun/, and a stale one
# would be drawn instead of the recording's own layout.
STATE=$(mktemp -d)
export XDG_DATA_HOME="$STATE/data" XDG_CONFIG_HOME="$STATE/config" XDG_CACHE_HOME="$STATE/cache"
export XDG_RUNTIME_DIR="$STATE/run"
mkdir -p "$XDG_DATA_HOME" "$XDG_CONFIG_HOME" "$XDG_CACHE_HOME" "$XDG_RUNTIME_DIR"
chmod 700 "$XDG_RUNTIME_DIR"

# setsid: own process group, so cleanup takes the python shim and the viewer.
setsid python3 -m rerun "$RRD" --window-size "${W}x${H}" --hide-welcome-screen \
    --port "$PORT" >/tmp/tortwin-screenshot-viewer.log 2>&1 &
RR_PID=$!

WIN=
for _ in $(seq 60); do
    WIN=$(xdotool search --name '^Rerun$' 2>/dev/null | head -1 || true)
    [ -n "$WIN" ] && break
    sleep 1
done
[ -n "$WIN" ] || { echo "viewer window never appeared; see /tmp/tortwin-screenshot-viewer.log" >&2; exit 1; }
sleep "$LOAD_WAIT"   # let the .rrd load; the time cursor follows it to the end

# Park the pointer on the empty middle of the top bar: no tooltip, no hover
# line, no highlighted button.
xdotool mousemove 700 12
sleep 5

mkdir -p "$(dirname "$OUT")"
import -window root "$OUT"
echo "wrote $OUT"
