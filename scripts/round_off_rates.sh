#!/usr/bin/env bash
# How often the tests on a chaotic curve pass over round-off realisations (a benchmark's figure,
# not a test): each test runs on eight realisations of the engine's round-off (both time-step face
# rules, safety factor moved by k x 1e-14 for k = 0, 1, -1, 2; tests/pipelines/test_support.hpp),
# chosen by DEMCAL_TEST_REALISATION, and the passes are counted per test.
# usage: scripts/round_off_rates.sh [BUILD_DIR] [GTEST_FILTER]
#   default filter: the diagnosis loop's effect tests and the synthetic recovery
set -uo pipefail
build=${1:-build}
filter=${2:-'DiagnoseLoop/Refdem*:DiagnoseLoop/HiddenCohesion.*:Synthetic/Recovery.*'}
declare -A passed total
for faces in all in_contact; do
  for k in 0 1 -1 2; do
    log=$(DEMCAL_TEST_REALISATION="$faces:$k" "$build/tests/test_pipelines" --gtest_filter="$filter" 2>&1)
    while read -r status name; do
      test=${name%/*}  # less the realisation's name
      total[$test]=$(( ${total[$test]:-0} + 1 ))
      [[ $status == OK ]] && passed[$test]=$(( ${passed[$test]:-0} + 1 ))
      echo "$faces:$k $status $name"
    done < <(sed -n 's/^\[ *\(OK\|FAILED\) *\] \([^ ,]*\).* ([0-9]* ms)$/\1 \2/p' <<< "$log")
  done
done
echo
echo "| test | passed | realisations |"
echo "| --- | --- | --- |"
for test in "${!total[@]}"; do echo "| $test | ${passed[$test]:-0} | ${total[$test]} |"; done
