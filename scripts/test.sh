#!/usr/bin/env bash
# The test command: installs what is missing, then format, lint, every test, and a check of
# every shipped graph. Used by CI (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

# A one-shot run gains nothing from incremental caches, which would roughly double the disk
# the build takes (see the debug-info note in Cargo.toml).
export CARGO_INCREMENTAL=0
# Disk again: a CI machine ran out of it while linking the tests (the build took 2.7 GB, most of
# it test binaries). Linked without debug info they are half the size; a failing assertion
# still names its file and line, and a backtrace its functions (not their lines). Each crate's
# tests are also one binary (autotests = false in its Cargo.toml), not one per file.
export CARGO_PROFILE_DEV_STRIP=debuginfo
# The shipped graphs load the example plugins from target/debug/ and the checks below run
# ./target/debug/skinflow: build there, whatever target directory the caller's shell sets.
unset CARGO_TARGET_DIR

cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
# Build first: the plugin tests load the example plugins' cdylibs, which `cargo test` does not
# make. With the workspace's resolver (Cargo.toml) the tests then reuse every dependency.
cargo build --workspace
cargo test --workspace
# `check` opens the input files a graph names: make the recordings the replay graphs read, as
# their headers say (kept when present, so a developer's own out/ is not overwritten).
[ -e out/multi.h5 ] || ./target/debug/skinflow simulate graphs/scenes/multi-contact.toml --out out/multi.h5
[ -e out/reproduce/calib.toml ] || ./target/debug/skinflow reproduce --out out/reproduce
# plugin-csv-in.toml reads the pressure CSV plugin-csv-out.toml writes (a plugin's input-path
# file, which `check` opens too).
[ -e out/plugin-pressure.csv ] || ./target/debug/skinflow run graphs/plugin-csv-out.toml > /dev/null
for g in graphs/*.toml; do
  ./target/debug/skinflow check "$g"
done
