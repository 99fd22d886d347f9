#!/usr/bin/env bash
# Runs the benchmark programs (figures for docs/benchmarks.md). The engine studies take minutes:
# they run only with STUDIES=1.
set -euo pipefail
build=${1:-build}
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), load $(cut -d' ' -f1-3 /proc/loadavg)"
for program in "$build"/bench/bench_dem "$build"/bench/bench_smoothing "$build"/bench/bench_optimise \
               "$build"/bench/pagmo/bench_optimise_pagmo "$build"/bench/bench_pipelines; do
  [ -x "$program" ] || continue
  echo; echo "== $(basename "$program")"
  "$program"
done
if [ "${STUDIES:-0}" = 1 ]; then
  echo; echo "== bench_dem_studies"
  "$build"/bench/bench_dem_studies all
fi
