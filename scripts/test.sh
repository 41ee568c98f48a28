#!/usr/bin/env bash
# The test command: installs what is missing, then format, lint, every test, and a check of
# every shipped graph. Used by CI (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
cargo build --workspace
for g in graphs/*.toml; do
  ./target/debug/skinflow check "$g"
done
