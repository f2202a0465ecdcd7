#!/usr/bin/env bash
# Opens a report page in a real headless browser and saves a screenshot to look at
# (docs/cli.md "Reports"). Needs Chromium (Debian: `apt-get install chromium`).
#   tools/check_report.sh [RUN.mcap|SWEEP_DIR]   (default: a fresh smoke_2d run)
# Prints the page and the screenshot's path; fails when the browser cannot render the page.
set -euo pipefail
cd "$(dirname "$0")/.."
browser=$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)
if [ -z "$browser" ]; then
    echo "error: no Chromium found (Debian: apt-get install chromium)" >&2
    exit 2
fi
cargo build --release --quiet --bin runner
work=$(mktemp -d)
target=${1:-}
if [ -z "$target" ]; then
    target=$(target/release/runner experiments/smoke_2d.yaml --out "$work/runs" --quiet | tail -n 1)
fi
page=$(target/release/runner report "$target" --out "$work/report" | tail -n 1)
shot="$work/report/screenshot.png"
"$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
    --window-size=1280,2400 --screenshot="$shot" "file://$(realpath "$page")" 2>/dev/null
test -s "$shot"
echo "page: $page"
echo "screenshot: $shot"
