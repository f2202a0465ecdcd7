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
# The viewers' decoder (protobufjs, @mcap/core) for tests/integration/foxglove.rs, pinned by its lock file.
if [ ! -d tools/foxglove/node_modules ]; then
    npm ci --prefix tools/foxglove --no-audit --no-fund --silent
fi
# The library, binary and integration tests; not the examples, whose release builds each
# instantiate the generic solver again (200 s of CPU, more than the unit and integration tests'
# 140 s; docs/tests.md): they are checked below instead, which needs no code generation.
cargo test --release --lib --bins --tests -- --include-ignored
cargo check --release --examples --quiet
# `cargo test` has built target/release/runner for the integration tests; a separate `cargo
# build` would compile the library once more (without the dev-dependencies' features).

# Determinism gate (docs/cli.md "Verify, resume, interrupts"): a small run on 1 and on 2 threads,
# each replayed bit for bit by `runner verify`, and their checkpoint hashes compared.
gate=$(mktemp -d)
trap 'rm -rf "$gate"' EXIT
runner=target/release/runner
for t in 1 2; do
    "$runner" experiments/smoke_2d.yaml --threads "$t" --out "$gate/t$t" --quiet > "$gate/path$t"
    "$runner" verify "$(tail -n 1 "$gate/path$t")" --threads "$t" --quiet --print-hashes \
        | tail -n +3 > "$gate/hashes$t"
done
if ! cmp -s "$gate/hashes1" "$gate/hashes2" || [ ! -s "$gate/hashes1" ]; then
    echo "determinism gate FAILED: checkpoint hashes differ between 1 and 2 threads" >&2
    diff "$gate/hashes1" "$gate/hashes2" >&2 || true
    exit 1
fi
echo "determinism gate ok: $(wc -l < "$gate/hashes1") checkpoints identical on 1 and 2 threads, each verified"
