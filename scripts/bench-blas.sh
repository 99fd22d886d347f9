#!/usr/bin/env bash
# Smoother speed under each installed BLAS, in one run: bench_smoothing's BM_SmoothCurves (one
# curve and twenty curves, native and libtorch backends, the default 400 epochs) with the
# reference BLAS, OpenBLAS serial and OpenBLAS pthread. LibTorch from Debian links libblas.so.3;
# each variant is chosen for its run alone through LD_LIBRARY_PATH, so the system's
# update-alternatives setting is neither read nor changed. Prints a markdown table.
#   scripts/bench-blas.sh [BUILD_DIR] [extra bench_smoothing flags...]
# Needs libopenblas0-serial and libopenblas0-pthread (apt-get install); a missing variant is skipped.
set -euo pipefail
build="${1:-build}"
shift || true
bench="$build/bench/bench_smoothing"
[ -x "$bench" ] || { echo "bench-blas: no $bench (build first)" >&2; exit 1; }
libdir=/usr/lib/x86_64-linux-gnu
variants=("reference:$libdir/blas" "openblas-serial:$libdir/openblas-serial" "openblas-pthread:$libdir/openblas-pthread")
results="$(mktemp)"
trap 'rm -f "$results"' EXIT
echo "bench-blas: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg)" >&2
for entry in "${variants[@]}"; do
  name="${entry%%:*}"
  dir="${entry#*:}"
  if [ ! -e "$dir/libblas.so.3" ]; then
    echo "bench-blas: $name not installed ($dir/libblas.so.3), skipped" >&2
    continue
  fi
  loaded="$(LD_LIBRARY_PATH="$dir" ldd "$bench" | awk '/libblas.so.3/ {print $3}')"
  echo "bench-blas: $name: libblas.so.3 => $loaded" >&2
  [ "$(readlink -f "$loaded")" = "$(readlink -f "$dir/libblas.so.3")" ] ||
    { echo "bench-blas: $name did not take effect" >&2; exit 1; }
  LD_LIBRARY_PATH="$dir" "$bench" --benchmark_filter='BM_SmoothCurves' --benchmark_format=csv "$@" 2>/dev/null |
    awk -F, -v blas="$name" '/^"BM_SmoothCurves/ {gsub(/"/, "", $1); print blas "," $1 "," $3 "," $4}' >>"$results"
done
echo "| BLAS | curves | backend | wall (ms) | CPU (ms) |"
echo "| --- | --- | --- | --- | --- |"
awk -F, '{
  split($2, p, "/"); sub("curves:", "", p[2]); backend = (p[3] ~ /libtorch:1/) ? "libtorch" : "native";
  printf "| %s | %s | %s | %.1f | %.1f |\n", $1, p[2], backend, $3, $4 }' "$results"
