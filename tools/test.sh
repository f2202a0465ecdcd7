#!/usr/bin/env bash
# The project's test command (README "Quick start"): sets up the Python reader venv if it is
# missing, then runs every test in release mode, including those that drive the Python
# `mcap` reader over real run files.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
.venv/bin/pip install --quiet --disable-pip-version-check -r tools/requirements.txt
export MPS_PYTHON="$PWD/.venv/bin/python"
cargo test --release -- --include-ignored
