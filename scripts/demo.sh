#!/usr/bin/env bash
# The main job on the bundled default: calibrate the reference arch (kn, ks, friction) against the
# synthetic measurement in data/arch/ (TBPSO, 20 iterations x 10 particles, objective 2), writing
# demo-out/calibration/{result.json,report.md,figures/,archive.sqlite}.
#
# The output folder is emptied first: the archive reuses a run whose scene and parameters it already
# holds, whatever engine version made it, so a demo after an engine change must not read old runs.
# Pass --keep as the second argument to keep (and reuse) the previous archive.
set -euo pipefail
build=${1:-build}
keep=${2:-}
out=demo-out/calibration
if [[ "$keep" != "--keep" ]]; then rm -rf "$out"; fi
mkdir -p demo-out
"$build/demcal" calibrate data/arch/campaign.json --out "$out"
echo
echo "report: $out/report.md"
python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print(json.dumps({"best": r["best"], "simulations": r["simulations"], "wall_time_s": r["wall_time_s"]}, indent=2))' "$out/result.json" 2>/dev/null || cat "$out/result.json"
