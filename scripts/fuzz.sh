#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + UBSan) and runs each for MINUTES minutes on the
# seed corpus of fuzz/corpus/<target>/ (read-only: new inputs go to BUILD_DIR/corpus/<target>/).
# A crash leaves BUILD_DIR/crashes/<target>/crash-* and stops with a non-zero status: copy it to
# fuzz/corpus/<target>/regression-<what-it-breaks> (printed below), where `make test` replays it
# (ctest FuzzReplay.<target>), and fix the bug. The fuzzing itself is not part of `make test`.
#   scripts/fuzz.sh [BUILD_DIR=build-fuzz] [MINUTES=10] [TARGETS="csv scene campaign"]
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build-fuzz}"
minutes="${2:-10}"
targets="${3:-csv scene campaign}"
command -v clang++ >/dev/null || { echo "fuzz: needs clang (apt-get install clang)" >&2; exit 1; }
CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDEMCAL_BUILD_FUZZERS=ON \
  -DDEMCAL_BUILD_TESTS=OFF -DDEMCAL_BUILD_BENCHMARKS=OFF >/dev/null
cmake --build "$build" -j"${JOBS:-2}" --target $(for t in $targets; do printf 'fuzz_%s ' "$t"; done)
status=0
for t in $targets; do
  mkdir -p "$build/corpus/$t" "$build/crashes/$t"
  echo "fuzz: $t for $minutes min"
  start=$(date +%s)
  if ! ASAN_OPTIONS=detect_leaks=0 "$build/fuzz/fuzz_$t" -max_total_time=$((minutes * 60)) -print_final_stats=1 \
      -max_len=65536 -timeout=20 -rss_limit_mb=4096 -artifact_prefix="$build/crashes/$t/" \
      "$build/corpus/$t" "fuzz/corpus/$t" 2>"$build/fuzz_$t.log"; then
    status=1
    echo "fuzz: $t FOUND A CRASH: $(ls "$build/crashes/$t")" >&2
    echo "fuzz: keep each in the corpus that make test replays (FuzzReplay.$t), named for what it breaks:" >&2
    for crash in "$build/crashes/$t"/*; do
      echo "fuzz:   cp $crash fuzz/corpus/$t/regression-<name>" >&2
    done
  fi
  runs=$(awk '/stat::number_of_executed_units/ {print $2}' "$build/fuzz_$t.log")
  echo "fuzz: $t: $((($(date +%s) - start))) s, ${runs:-?} executions, corpus $(ls "$build/corpus/$t" | wc -l) inputs"
  tail -n 3 "$build/fuzz_$t.log" | sed "s/^/fuzz: $t: /"
done
exit $status
