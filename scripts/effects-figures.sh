#!/usr/bin/env bash
# The reference arch (10 mm/s, 15 points per joint, published kn, ks, friction) with each effect of
# the engine beside the plain model: docs/figures/effect-<name>.png and a table of peaks on stdout
# (docs/engine.md, "Effects"). Runs in about a minute.
#
# Usage: scripts/effects-figures.sh [BUILD_DIR]
set -euo pipefail
build=${1:-build}
demcal="$build/demcal"
out=demo-out/effects
figures=docs/figures
mkdir -p "$out" "$figures"

# name | demcal scene arch flags | legend
cases=(
  "plain||plain model"
  "joint-closure|--closure-max 1e-4|closure_max 0.1 mm"
  "friction-softening|--friction-residual-deg 20 --slip-softening 2e-3|friction 30.5 -> 20 deg over 2 mm of slip"
  "cohesion|--cohesion 2e4 --tensile-strength 1e4|cohesion 20 kPa, tensile strength 10 kPa"
  "crushing-cap|--compressive-strength 1e6 --crushing-softening 1e-3|compressive strength 1 MPa, softening over 1 mm"
  "support-compliance|--support-kx 5e6|both abutments on 5 MN/m horizontal springs"
  "joint-gap|--gap-joint voussoir_9/voussoir_10 --gap-extrados 1e-3|wedge gap at voussoir 9/10, 1 mm at the extrados"
  "boundary-restraint|--beam-kr 2e3|loaded voussoir on a 2 kN m/rad rotational spring"
  "shear-stiffening|--shear-stiffening-stress 2e5|shear stiffness doubled at 0.2 MPa of normal stress"
)

printf "| effect | settings | status | peak (kN) | force at 12 mm (kN) | hinges |\n|---|---|---|---|---|---|\n"
for c in "${cases[@]}"; do
  IFS='|' read -r name flags legend <<<"$c"
  # shellcheck disable=SC2086
  "$demcal" scene arch $flags -o "$out/$name.json" >/dev/null
  rm -rf "$out/$name"
  "$demcal" simulate "$out/$name.json" --out "$out/$name" >/dev/null
  python3 - "$out/$name" "$name" "$legend" <<'PY'
import json, sys, csv
d, name, legend = sys.argv[1:]
s = json.load(open(d + "/summary.json"))
rows = list(csv.reader(open(d + "/curves.csv")))
last = float(rows[-1][1]) if len(rows) > 1 else float("nan")
print(f"| {name} | {legend} | {s['status']} | {s['peak_force']/1e3:.2f} | {last/1e3:.2f} | {', '.join(s['hinges'])} |")
PY
done

for c in "${cases[@]:1}"; do
  IFS='|' read -r name flags legend <<<"$c"
  gnuplot <<GP
set terminal pngcairo size 800,500 font ",11"
set output "$figures/effect-$name.png"
set datafile separator ","
set key top right
set xlabel "vertical displacement of the loading point (mm)"
set ylabel "force (kN)"
set title "Reference arch, 10 mm/s: $name"
set grid
plot "$out/plain/curves.csv" every ::1 using (\$3*1000):(\$2/1000) with lines lw 2 lc rgb "#777777" title "plain model", \
     "$out/$name/curves.csv" every ::1 using (\$3*1000):(\$2/1000) with lines lw 2 lc rgb "#c0392b" title "$legend"
GP
done
echo "figures: $figures/effect-*.png"
