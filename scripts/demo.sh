#!/usr/bin/env bash
# The main job on the bundled default: calibrate the reference arch (kn, ks, friction) against the
# synthetic measurement in data/arch/ (TBPSO, 20 iterations x 10 particles, objective 2), writing
# demo-out/calibration/{result.json,report.md,figures/,archive.sqlite}; then diagnose a record made
# by another DEM code whose effect it does not declare (data/refdem-arch/A-support-1.csv, a right
# abutment on a spring) into demo-out/diagnosis/, and print the verdict. The diagnosis is shortened
# to fit a demo: two candidates calibrated, 40 simulations each (the default is 80), no further
# search, no parameter bounds, no removal check, one effect at most (--max-effects 1; without it an
# accepted effect is followed by a diagnosis of the model with it).
#
# The output folder is emptied first: the archive reuses a run whose scene and parameters it already
# holds, whatever engine version made it, so a demo after an engine change must not read old runs.
# Pass --keep as the second argument to keep (and reuse) the previous archive.
set -euo pipefail
build=${1:-build}
keep=${2:-}
out=demo-out/calibration
diag=demo-out/diagnosis
if [[ "$keep" != "--keep" ]]; then rm -rf "$out" "$diag"; fi
mkdir -p demo-out
"$build/demcal" calibrate data/arch/campaign.json --out "$out"
echo
echo "report: $out/report.md"
python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print(json.dumps({"best": r["best"], "simulations": r["simulations"], "wall_time_s": r["wall_time_s"]}, indent=2))' "$out/result.json" 2>/dev/null || cat "$out/result.json"

echo
echo "diagnosing data/refdem-arch/A-support-1.csv (another code's record, effect not declared) ..."
"$build/demcal" diagnose data/refdem-arch/A-campaign.json --out "$diag" --quiet --candidates 2 --candidate-simulations 40 --close-target-share 1 \
  --continued-simulations 0 --no-parameter-bounds --no-removal-check --max-effects 1 > "$diag.log"
python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); t=d["timing"]; print("verdict:", d["headline"]); print("force error %.0f N -> %.0f N, %d simulations, %.0f s (simulations %.0f s, model %.0f s)" % (d["error_before"], d["error_after"], d["simulations"], t["wall_s"], t["simulations_s"], t["model_s"]))' "$diag/diagnosis.json"
echo "report: $diag/report.md"
