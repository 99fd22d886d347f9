#!/usr/bin/env bash
# Calibration against the Lourenço 2005 wall tests (data/walls/, docs/walls.md):
#   1. the trials on SW.30.1: top beam held level / free to rotate; 9 / 10 courses;
#   2. one campaign per wall test (kn, ks, friction; TBPSO 10 x 10, objective 1);
#   3. the worth test: SW.30.1 + SW.100.1 calibrated together, then SW.200.1 and SW.250.1 predicted;
#   4. the fidelity check of the fast run settings: the calibrated SW.30.1 and SW.250.1 runs repeated
#      at 2 mm/s with 15 contact points per joint;
#   5. the faithful calibrations: steps 2 and 3 again with every case at 2 mm/s and 15 contact points
#      per joint (demo-out/walls/faithful/), about ten times the simulation cost;
#   6. the tables of docs/walls.md rewritten between their <!-- walls:NAME --> markers.
# Every campaign keeps its archive (demo-out/walls/<name>/archive.sqlite), so a second run of this
# script re-simulates nothing and rebuilds the tables (whose wall times are then those of the rerun).
#
# Usage: scripts/walls.sh [BUILD_DIR] [STEP...]
#   (steps: trial walls worth fidelity faithful tables; default all)
set -euo pipefail
build=${1:-build}
shift || true
steps=${*:-trial walls worth fidelity faithful tables}
demcal="$build/demcal"
out=demo-out/walls
data=data/walls
mkdir -p "$out"
has_step() { [[ " $steps " == *" $1 "* ]]; }

# Calibrate one campaign file, then simulate its cases with the best set (the calibrated curves).
# calibrate NAME [FOLDER]: data/walls/NAME.json, or FOLDER/NAME.json with its outputs in FOLDER/NAME.
calibrate() {
  local name=$1 dir=${2:-}
  local file="${dir:-$data}/$name.json" target="${dir:-$out}/$name"
  echo "== $name${dir:+ ($dir)}"
  "$demcal" calibrate "$file" --out "$target"
  "$demcal" predict "$file" --result "$target/result.json" --out "$target/fit"
}

# faithful_copy SOURCE TARGET: the campaign file with every case at the faithful settings (2 mm/s,
# 15 contact points per joint) and its measured files named by absolute path.
faithful_copy() {
  python3 - "$1" "$2" <<'PY'
import json, os, sys
source, target = sys.argv[1], sys.argv[2]
c = json.load(open(source))
for case in c["cases"]:
    case["scene"]["options"].update({"velocity": 0.002, "contacts_per_joint": 15})
    case["measured"]["file"] = os.path.abspath(os.path.join(os.path.dirname(source), case["measured"]["file"]))
c["name"] += "-faithful"
c.pop("output", None)
json.dump(c, open(target, "w"), indent=2)
PY
}

if has_step trial; then
  calibrate SW.30.1
  calibrate SW.30.1-beam-rotation
  calibrate SW.30.1-10-courses
fi

if has_step walls; then
  for wall in SW.30.2 SW.100.1 SW.100.2 SW.200.1 SW.200.2 SW.250.1; do calibrate "$wall"; done
fi

if has_step worth; then
  calibrate worth-SW30-SW100
  echo "== prediction of SW.200.1 and SW.250.1 with the SW.30.1 + SW.100.1 parameters"
  "$demcal" predict "$data/predict-SW200-SW250.json" --result "$out/worth-SW30-SW100/result.json" \
    --out "$out/worth-SW30-SW100/predict"
fi

if has_step fidelity; then
  # The same campaign cases with the slow, faithful settings: 2 mm/s, 15 contact points per joint.
  mkdir -p "$out/fidelity"
  for wall in SW.30.1 SW.250.1; do
    faithful_copy "$data/$wall.json" "$out/fidelity/$wall-slow.json"
    echo "== fidelity: $wall at 2 mm/s, 15 contact points"
    "$demcal" predict "$out/fidelity/$wall-slow.json" --result "$out/$wall/result.json" --out "$out/fidelity/$wall-slow"
    "$demcal" fitness --objective 1 -e "$out/fidelity/$wall-slow/$wall.csv" -s "$out/$wall/fit/$wall.csv" \
      > "$out/fidelity/$wall-fast-vs-slow.json"
  done
fi

if has_step faithful; then
  faithful=$out/faithful
  mkdir -p "$faithful"
  campaigns="SW.30.1 SW.30.2 SW.100.1 SW.100.2 SW.200.1 SW.200.2 SW.250.1 worth-SW30-SW100"
  for name in $campaigns predict-SW200-SW250; do faithful_copy "$data/$name.json" "$faithful/$name.json"; done
  for name in $campaigns; do calibrate "$name" "$faithful"; done
  echo "== prediction of SW.200.1 and SW.250.1 with the faithful SW.30.1 + SW.100.1 parameters"
  "$demcal" predict "$faithful/predict-SW200-SW250.json" --result "$faithful/worth-SW30-SW100/result.json" \
    --out "$faithful/worth-SW30-SW100/predict"
fi

if has_step tables; then
  python3 - "$out" docs/walls.md <<'PY'
import json, math, os, re, sys
out, doc = sys.argv[1], sys.argv[2]

def load(path):
    return json.load(open(path)) if os.path.exists(path) else None

def kN(v): return "–" if v is None else f"{v / 1e3:.1f}"
def pct(v): return "–" if v is None else f"{100 * v:+.0f} %"

def param_cells(result):
    p = result["best"]["params"]
    return [f"{p['kn'] / 1e9:.3g}", f"{p['ks'] / 1e9:.3g}", f"{p['friction_deg']:.1f}"]

def case_cells(c):
    rms_share = c["rms_error"] / c["measured_peak"] if c["rms_error"] is not None and c["measured_peak"] else None
    return [kN(c["measured_peak"]), kN(c["simulated_peak"]), pct(c["peak_error"]), f"{c['rms_error'] / 1e3:.2f}"
            if c["rms_error"] is not None else "–", "–" if rms_share is None else f"{100 * rms_share:.0f} %"]

def row(cells): return "| " + " | ".join(cells) + " |"

def numeric_rows(path, encoding="latin-1"):
    rows = []
    for line in open(path, encoding=encoding):
        try: rows.append([float(v) for v in line.strip().split(",")])
        except ValueError: continue
    return rows

def envelope(xs, fs):
    # The objective's loading envelope: keep a point only where x exceeds every earlier x; a point at
    # the same x replaces the last kept one.
    ex, ef = [], []
    for x, f in zip(xs, fs):
        if ex and x == ex[-1]: ef[-1] = f
        elif not ex or x > ex[-1]: ex.append(x); ef.append(f)
    return ex, ef

def interp(ex, ef, x):
    import bisect
    i = min(max(bisect.bisect_left(ex, x), 1), len(ex) - 1)
    t = (x - ex[i - 1]) / (ex[i] - ex[i - 1])
    return ef[i - 1] + t * (ef[i] - ef[i - 1])

def residual_split(measured_csv, simulated_csv):
    """Mean signed residual (simulated - measured, N) before and after the measured peak, over the
    objective's 200 points of the shared window (measured file in mm/kN, simulated in m/N)."""
    m = numeric_rows(measured_csv)
    mx, mf = envelope([r[0] * 1e-3 for r in m], [r[1] * 1e3 for r in m])
    s = numeric_rows(simulated_csv, "utf-8")
    sx, sf = envelope([r[2] for r in s], [r[1] for r in s])
    lo, hi = max(mx[0], sx[0]), min(mx[-1], sx[-1])
    peak_at = max(zip(mf, mx))[1]
    before, after = [], []
    for k in range(200):
        x = lo + (hi - lo) * k / 199
        (before if x <= peak_at else after).append(interp(sx, sf, x) - interp(mx, mf, x))
    mean = lambda v: sum(v) / len(v) if v else float("nan")
    return mean(before), mean(after)

tables = {}
walls = ["SW.30.1", "SW.30.2", "SW.100.1", "SW.100.2", "SW.200.1", "SW.200.2", "SW.250.1"]
stress = {"SW.30": 0.15, "SW.100": 0.50, "SW.200": 1.00, "SW.250": 1.25}
head = ["test", "σ0 (MPa)", "kn (GPa/m)", "ks (GPa/m)", "φ (°)", "objective 1 (kN)", "peak measured (kN)",
        "peak calibrated (kN)", "peak error", "RMS error (kN)", "RMS / peak", "simulations", "wall time (s)"]
lines = [row(head), row(["---"] * len(head))]
for w in walls:
    r, f = load(f"{out}/{w}/result.json"), load(f"{out}/{w}/fit/prediction.json")
    if not r or not f: lines.append(row([w] + ["not run"] + [""] * (len(head) - 2))); continue
    lines.append(row([w, f"{stress[w.rsplit('.', 1)[0]]:.2f}"] + param_cells(r) + [kN(r["best"]["fitness"])]
                     + case_cells(f["cases"][0]) + [str(r["simulations"]), f"{r['wall_time_s']:.0f}"]))
tables["per-wall"] = lines

head = ["model of SW.30.1", "kn (GPa/m)", "ks (GPa/m)", "φ (°)", "objective 1 (kN)", "peak measured (kN)",
        "peak calibrated (kN)", "peak error", "RMS error (kN)", "RMS / peak"]
lines = [row(head), row(["---"] * len(head))]
for label, name in [("9 courses, top beam held level", "SW.30.1"), ("9 courses, top beam free to rotate", "SW.30.1-beam-rotation"),
                    ("10 courses (load at the wall top), beam held level", "SW.30.1-10-courses")]:
    r, f = load(f"{out}/{name}/result.json"), load(f"{out}/{name}/fit/prediction.json")
    if not r or not f: lines.append(row([label, "not run"] + [""] * (len(head) - 2))); continue
    lines.append(row([label] + param_cells(r) + [kN(r["best"]["fitness"])] + case_cells(f["cases"][0])))
tables["boundary"] = lines

def worth_table(folder):
    """The worth test of one set of campaigns (the fast ones in out, the faithful ones in out/faithful)."""
    head = ["test", "role", "peak measured (kN)", "peak simulated (kN)", "peak error", "RMS error (kN)", "RMS / peak",
            "RMS of its own calibration (kN)", "peak at, measured / simulated (mm)",
            "mean residual before / after the measured peak (kN)"]
    codes = {"SW.30.1": "SW301", "SW.100.1": "SW1001", "SW.200.1": "SW2001", "SW.250.1": "SW2501"}
    lines = [row(head), row(["---"] * len(head))]
    r = load(f"{folder}/worth-SW30-SW100/result.json")
    fit, pred = load(f"{folder}/worth-SW30-SW100/fit/prediction.json"), load(f"{folder}/worth-SW30-SW100/predict/prediction.json")
    if not (r and fit and pred):
        return lines + [row(["not run"] + [""] * (len(head) - 1))]
    for role, doc_cases, sub in [("calibrated on", fit["cases"], "fit"), ("predicted", pred["cases"], "predict")]:
        for c in doc_cases:
            before, after = residual_split(f"data/walls/FD_{codes[c['name']]}_Lourenco2005.csv",
                                           f"{folder}/worth-SW30-SW100/{sub}/{c['name']}.csv")
            own = load(f"{folder}/{c['name']}/fit/prediction.json")
            own_rms = f"{own['cases'][0]['rms_error'] / 1e3:.2f}" if own and own["cases"][0]["rms_error"] is not None else "–"
            lines.append(row([c["name"], role] + case_cells(c) + [own_rms, f"{c['measured_peak_displacement'] * 1e3:.1f} / {c['simulated_peak_displacement'] * 1e3:.1f}",
                                                            f"{before / 1e3:+.1f} / {after / 1e3:+.1f}"]))
    p = r["best"]["params"]
    lines.append("")
    lines.append(f"Joint set calibrated on SW.30.1 + SW.100.1: kn = {p['kn'] / 1e9:.3g} GPa/m, "
                 f"ks = {p['ks'] / 1e9:.3g} GPa/m, φ = {p['friction_deg']:.1f}°; objective 1 (sum of both cases) "
                 f"= {r['best']['fitness'] / 1e3:.1f} kN after {r['simulations']} simulations ({r['wall_time_s']:.0f} s).")
    return lines

tables["worth"] = worth_table(out)
tables["worth-faithful"] = worth_table(f"{out}/faithful")

# Each wall calibrated at the fast and at the faithful settings: what the fast settings change in
# the calibrated parameters and errors, and what the faithful ones cost.
head = ["test", "settings", "kn (GPa/m)", "ks (GPa/m)", "φ (°)", "peak measured (kN)", "peak calibrated (kN)",
        "peak error", "RMS error (kN)", "RMS / peak", "simulations", "wall time (s)"]
lines = [row(head), row(["---"] * len(head))]
for w in walls:
    for label, folder in [("fast", out), ("faithful", f"{out}/faithful")]:
        r, f = load(f"{folder}/{w}/result.json"), load(f"{folder}/{w}/fit/prediction.json")
        if not r or not f: lines.append(row([w, label, "not run"] + [""] * (len(head) - 3))); continue
        lines.append(row([w, label] + param_cells(r) + case_cells(f["cases"][0])
                         + [str(r["simulations"]), f"{r['wall_time_s']:.0f}"]))
tables["faithful"] = lines

head = ["test", "settings", "peak (kN)", "peak change", "RMS difference fast vs slow (kN)", "steps", "run wall time (s)"]
lines = [row(head), row(["---"] * len(head))]
for w in ["SW.30.1", "SW.250.1"]:
    fast, slow = load(f"{out}/{w}/fit/prediction.json"), load(f"{out}/fidelity/{w}-slow/prediction.json")
    cmp_ = load(f"{out}/fidelity/{w}-fast-vs-slow.json")
    if not fast or not slow or not cmp_: lines.append(row([w, "not run"] + [""] * (len(head) - 2))); continue
    fc, sc = fast["cases"][0], slow["cases"][0]
    rms = cmp_["fitness"] / math.sqrt(200)
    lines.append(row([w, "slow: 2 mm/s, 15 points per joint", kN(sc["simulated_peak"]), "", "",
                      str(sc["engine"]["steps"]), f"{sc['wall_time_s']:.1f}"]))
    lines.append(row([w, "fast: 20 mm/s, 5 points per joint", kN(fc["simulated_peak"]),
                      pct(fc["simulated_peak"] / sc["simulated_peak"] - 1), f"{rms / 1e3:.2f}",
                      str(fc["engine"]["steps"]), f"{fc['wall_time_s']:.1f}"]))
tables["fidelity"] = lines

text = open(doc).read()
for name, lines in tables.items():
    pattern = re.compile(r"(<!-- walls:%s -->\n).*?(<!-- /walls:%s -->)" % (name, name), re.S)
    if not pattern.search(text): sys.exit(f"{doc}: no <!-- walls:{name} --> ... <!-- /walls:{name} --> markers")
    text = pattern.sub(lambda m: m.group(1) + "\n".join(lines) + "\n" + m.group(2), text)
open(doc, "w").write(text)
print(f"rewrote the tables of {doc}")
PY
fi
