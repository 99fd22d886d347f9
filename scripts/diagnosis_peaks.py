#!/usr/bin/env python3
"""Peaks of a diagnosis's fits (docs/journal/diagnose-studies.md): for the base model and every tried candidate of a
finished `demcal diagnose`, and for the model with every effect the loop added, simulate the named
cases of its campaign (fitted or held out) with the fitted parameters (`demcal predict`, the
candidate's extended scenes) and tabulate against the measurement: the RMS error and its share of
the measured peak, the peak force and where it occurs, the displacement where each curve first
reaches 80 % of its peak, and whether the prediction meets the goal (peak within 15 %, that
displacement within 35 %, RMS at most 10 % of the peak).

usage: diagnosis_peaks.py DEMCAL CAMPAIGN.json DIAGNOSIS_DIR CASE[,CASE...] [--out DIR]

Writes DIR/peaks.md and DIR/peaks.json (DIR defaults to DIAGNOSIS_DIR/peaks).
"""
import argparse
import json
import os
import subprocess


def predict(demcal, campaign, cases, scenes, params, out):
    """prediction.json of the named cases, each with its scene file (None = the campaign's)."""
    base_dir = os.path.dirname(os.path.abspath(campaign))
    config = json.load(open(campaign))
    config["cases"] = [c for c in config["cases"] if c["name"] in cases]
    for case in config["cases"]:
        m = case["measured"]
        if not os.path.isabs(m["file"]):
            m["file"] = os.path.join(base_dir, m["file"])
        if scenes and scenes.get(case["name"]):
            case["scene"] = {"file": scenes[case["name"]]}
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, "campaign.json")
    json.dump(config, open(path, "w"), indent=1)
    argv = [demcal, "predict", path, "--out", out]
    for name, value in sorted(params.items()):
        argv += ["--param", "%s=%.17g" % (name, value)]
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    return json.load(open(os.path.join(out, "prediction.json")))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("demcal")
    p.add_argument("campaign")
    p.add_argument("diagnosis")
    p.add_argument("cases")
    p.add_argument("--out")
    a = p.parse_args()
    cases = a.cases.split(",")
    out = a.out or os.path.join(a.diagnosis, "peaks")
    d = json.load(open(os.path.join(a.diagnosis, "diagnosis.json")))
    models = [("base", d["base"]["params"], None)]

    def fitted(diagnosis_dir, c):
        """A candidate's fit: its parameters and its extended scenes, candidates/EFFECT, or
        candidates/EFFECT@TARGET for a targeted effect (a support's block, a joint "a/b")."""
        folder = os.path.join(diagnosis_dir, "candidates", c["effect"] + ("@" + c["target"] if c.get("target") else ""))
        return c["params"], {n: os.path.join(folder, "scene-%s.json" % n) for n in cases}

    for c in d["candidates"]:
        if c.get("tried") and c.get("params"):
            models.append(("+ " + c["effect"],) + fitted(a.diagnosis, c))
    # Each further effect the loop added: its fit, a candidate of the step's own diagnosis.
    names = [e["effect"] for e in d.get("added", [])]
    for i, e in enumerate(d.get("added", [])):
        if not e.get("folder"):
            continue
        step = json.load(open(os.path.join(e["folder"], "diagnosis.json")))
        for c in step["candidates"]:
            if c["effect"] == e["effect"] and c.get("params"):
                models.append(("+ " + " + ".join(names[:i + 1]),) + fitted(e["folder"], c))
    rows, report = [], {}
    for label, params, scenes in models:
        tag = label.replace("+ ", "").replace(" ", "-")
        pred = predict(a.demcal, a.campaign, cases, scenes, params, os.path.join(out, tag))
        report[label] = pred
        for case in pred["cases"]:
            rows.append((label, case))
    lines = ["| model | case | RMS (kN) | RMS / peak | peak measured (kN) at (mm) | peak simulated (kN) at (mm) | peak error "
             "| 80 % of peak measured / simulated (mm) | its error | within the goal |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for label, case in rows:
        # a run that collapsed before the window has no values (null): NaN, and the goal not met
        c = {k: float("nan") if v is None else v for k, v in case.items()}
        rms_share = c["rms_error"] / c["measured_peak"]
        rise_m, rise_s = c["measured_rise_displacement"], c["simulated_rise_displacement"]
        rise_error = (rise_s - rise_m) / rise_m
        # the goal of a prediction: peak within 15 %, the 80 % point within 35 %, RMS <= 10 % of the peak
        goal = abs(c["peak_error"]) <= 0.15 and abs(rise_error) <= 0.35 and rms_share <= 0.10
        lines.append("| %s | %s | %.1f | %.0f %% | %.1f at %.1f | %.1f at %.1f | %+.0f %% | %.2f / %.2f | %+.0f %% | %s |" % (
            label, c["name"], c["rms_error"] / 1e3, 100 * rms_share, c["measured_peak"] / 1e3,
            c["measured_peak_displacement"] * 1e3, c["simulated_peak"] / 1e3, c["simulated_peak_displacement"] * 1e3,
            100 * c["peak_error"], rise_m * 1e3, rise_s * 1e3, 100 * rise_error, "yes" if goal else "no"))
    os.makedirs(out, exist_ok=True)
    open(os.path.join(out, "peaks.md"), "w").write("\n".join(lines) + "\n")
    json.dump(report, open(os.path.join(out, "peaks.json"), "w"), indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
