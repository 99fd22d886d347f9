#!/usr/bin/env bash
# The main job on the bundled default: calibrate the reference arch (kn, ks, friction) against the
# synthetic measurement in data/arch/ (TBPSO, 20 iterations x 10 particles, objective 2), writing
# demo-out/calibration/{result.json,report.md,figures/,archive.sqlite}.
set -euo pipefail
build=${1:-build}
out=demo-out/calibration
mkdir -p demo-out
"$build/demcal" calibrate data/arch/campaign.json --out "$out"
echo
echo "report: $out/report.md"
python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print(json.dumps({"best": r["best"], "simulations": r["simulations"], "wall_time_s": r["wall_time_s"]}, indent=2))' "$out/result.json" 2>/dev/null || cat "$out/result.json"
