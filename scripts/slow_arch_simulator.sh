#!/usr/bin/env bash
# An external simulator that takes SECONDS per run, for the surrogate's wall-time benchmark
# (docs/benchmarks.md, "Surrogate wall time"): demcal's reference arch with the given joint
# parameters, then a sleep until SECONDS have passed, as a slower code (3DEC) would take.
# usage: slow_arch_simulator.sh DEMCAL SECONDS KN KS FRICTION_DEG OUTPUT
set -euo pipefail
demcal=$1 seconds=$2 kn=$3 ks=$4 friction=$5 output=$6
start=$(date +%s.%N)
dir=$(dirname "$output")
"$demcal" scene arch --kn "$kn" --ks "$ks" --friction-deg "$friction" -o "$dir/scene.json" > /dev/null
"$demcal" simulate "$dir/scene.json" --out "$dir/run" > /dev/null
cp "$dir/run/curves.csv" "$output"
left=$(python3 -c "import sys,time; print(max(0.0, float(sys.argv[1]) - (time.time() - float(sys.argv[2]))))" "$seconds" "$start")
sleep "$left"
