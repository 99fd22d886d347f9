#!/usr/bin/env bash
# Installs the Debian packages demcal builds and runs with, when any is missing, and the further
# packages named as arguments (`make test-sanitize` names clang's).
# Needs root (or sudo) only when something must be installed; prints what it does.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libtorch-dev libnlopt-cxx-dev nlohmann-json3-dev libcli11-dev
  libsqlite3-dev libgtest-dev libbenchmark-dev
  libopenmpi-dev openmpi-bin gnuplot-nox libpagmo-dev
  # An optimised BLAS for LibTorch (it links libblas.so.3, the reference BLAS unless an alternative
  # is installed): the serial OpenBLAS measured fastest per CPU second (docs/benchmarks.md).
  libopenblas0-serial
  "$@"
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
as_root=()
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root to install: ${missing[*]}" >&2; exit 1; }
  as_root=(sudo)
fi
export DEBIAN_FRONTEND=noninteractive
"${as_root[@]}" apt-get update -qq
"${as_root[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
