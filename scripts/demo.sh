#!/usr/bin/env bash
# The demo: installs what is missing, builds skinflow (release) and runs the demo graph.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --bin skinflow
mkdir -p out
./target/release/skinflow run graphs/demo.toml "$@"
