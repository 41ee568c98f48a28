#!/usr/bin/env bash
# The test command: installs what is missing, then format, lint, every test, and a check of
# every shipped graph. Used by CI (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

# A one-shot run gains nothing from incremental caches, which would roughly double the disk
# the build takes (see the debug-info note in Cargo.toml).
export CARGO_INCREMENTAL=0

cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
cargo build --workspace
for g in graphs/*.toml; do
  ./target/debug/skinflow check "$g"
done
