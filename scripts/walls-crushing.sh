#!/usr/bin/env bash
# SW.200.1 calibrated with and without the crushing-cap effect (docs/walls.md, "Toe crushing"):
# both campaigns at the same settings, the calibrated curves by `demcal predict`, and the figure
# docs/figures/walls-SW.200.1-crushing-cap.png (measured, plain, crushing-cap). Archives are kept in
# demo-out/walls/, so a second run re-simulates nothing.
#
# Usage: scripts/walls-crushing.sh [BUILD_DIR]
set -euo pipefail
build=${1:-build}
demcal="$build/demcal"
out=demo-out/walls
for name in SW.200.1 SW.200.1-crushing-cap; do
  "$demcal" calibrate "data/walls/$name.json" --out "$out/$name"
  "$demcal" predict "data/walls/$name.json" --result "$out/$name/result.json" --out "$out/$name/fit"
done
# The best crushing-cap run that completed the travel (the best overall may collapse before the end
# of the measured curve, and objective 1 compares only the displacement window both curves share).
best_completed=$(sqlite3 "$out/SW.200.1-crushing-cap/archive.sqlite" \
  "select r.params_json from runs r join fitness f on f.run_id = r.id where r.status = 'completed' order by f.fitness limit 1")
mkdir -p "$out/SW.200.1-crushing-cap-completed"
echo "{\"best\": {\"params\": $best_completed}}" > "$out/SW.200.1-crushing-cap-completed/result.json"
"$demcal" predict data/walls/SW.200.1-crushing-cap.json --result "$out/SW.200.1-crushing-cap-completed/result.json" \
  --out "$out/SW.200.1-crushing-cap-completed/fit"
iconv -f latin1 -t utf-8 data/walls/FD_SW2001_Lourenco2005.csv | tail -n +5 > "$out/SW.200.1-measured.csv"
gnuplot <<GP
set terminal pngcairo size 800,500 font ",11"
set output "docs/figures/walls-SW.200.1-crushing-cap.png"
set datafile separator ","
set key bottom right
set xlabel "top displacement (mm)"
set ylabel "horizontal force (kN)"
set title "SW.200.1 (1.0 MPa): calibrated plain model and with crushing-cap"
set grid
set yrange [0:*]
plot "$out/SW.200.1-measured.csv" using 1:2 with points pt 7 ps 0.5 lc rgb "#000000" title "measured (Lourenço 2005)", \
     "$out/SW.200.1/fit/SW.200.1.csv" every ::2 using (\$3*1000):(\$2/1000) with lines lw 2 lc rgb "#777777" title "plain model, calibrated", \
     "$out/SW.200.1-crushing-cap/fit/SW.200.1.csv" every ::2 using (\$3*1000):(\$2/1000) with lines lw 2 lc rgb "#c0392b" title "crushing-cap, calibrated (best run; collapses)", \
     "$out/SW.200.1-crushing-cap-completed/fit/SW.200.1.csv" every ::2 using (\$3*1000):(\$2/1000) with lines lw 2 dt 2 lc rgb "#2e86c1" title "crushing-cap, best run that completes"
GP
echo "figure: docs/figures/walls-SW.200.1-crushing-cap.png"
