#!/usr/bin/env bash
# The main job on the bundled default: simulate the reference arch and print its summary.
set -euo pipefail
build=${1:-build}
out=demo-out
mkdir -p "$out"
"$build/demcal" scene arch -o "$out/arch.json"
"$build/demcal" simulate "$out/arch.json" --out "$out/arch"
cat "$out/arch/summary.json"
