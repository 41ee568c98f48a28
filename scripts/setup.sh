#!/usr/bin/env bash
# Installs what skinflow needs on a fresh Debian/Ubuntu machine, only when missing:
# pkg-config, the system HDF5 (libhdf5-dev), fontconfig and freetype via apt-get.
# Rust (cargo) must be present.
set -euo pipefail

need=()
command -v pkg-config >/dev/null 2>&1 || need+=(pkg-config)
if ! pkg-config --exists hdf5 2>/dev/null && ! pkg-config --exists hdf5-serial 2>/dev/null; then
  need+=(libhdf5-dev)
fi
# Plot rendering (plotters) links the system fontconfig and freetype.
pkg-config --exists fontconfig 2>/dev/null || need+=(libfontconfig1-dev)
pkg-config --exists freetype2 2>/dev/null || need+=(libfreetype-dev)
command -v cc >/dev/null 2>&1 || need+=(gcc libc6-dev)

if [ ${#need[@]} -gt 0 ]; then
  echo "setup: installing ${need[*]}" >&2
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo_cmd=(sudo); else
      echo "setup: need root or sudo to install ${need[*]}" >&2; exit 1
    fi
  fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust 1.95 or newer (https://rustup.rs) and retry" >&2
  exit 1
fi
