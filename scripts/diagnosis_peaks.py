#!/usr/bin/env python3
"""Peaks of a diagnosis's fits (docs/journal/diagnose-studies.md): for the base model and every tried candidate of a
finished `demcal diagnose`, simulate the named cases of its campaign (fitted or held out) with the
fitted parameters (`demcal predict`, the candidate's extended scenes) and tabulate the RMS error,
the peak force and the displacement at the peak against the measurement's.

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
    for c in d["candidates"]:
        if not c.get("tried") or not c.get("params"):
            continue
        # the extended scenes: candidates/EFFECT, or candidates/EFFECT@TARGET for a targeted effect
        # (a support's block, a joint "a/b")
        folder = os.path.join(a.diagnosis, "candidates", c["effect"] + ("@" + c["target"] if c.get("target") else ""))
        scenes = {n: os.path.join(folder, "scene-%s.json" % n) for n in cases}
        models.append(("+ " + c["effect"], c["params"], scenes))
    rows, report = [], {}
    for label, params, scenes in models:
        tag = label.replace("+ ", "").replace(" ", "-")
        pred = predict(a.demcal, a.campaign, cases, scenes, params, os.path.join(out, tag))
        report[label] = pred
        for case in pred["cases"]:
            rows.append((label, case))
    lines = ["| model | case | RMS (kN) | peak measured (kN) at (mm) | peak simulated (kN) at (mm) | peak error |",
             "|---|---|---|---|---|---|"]
    for label, c in rows:
        lines.append("| %s | %s | %.1f | %.1f at %.1f | %.1f at %.1f | %+.0f %% |" % (
            label, c["name"], c["rms_error"] / 1e3, c["measured_peak"] / 1e3, c["measured_peak_displacement"] * 1e3,
            c["simulated_peak"] / 1e3, c["simulated_peak_displacement"] * 1e3, 100 * c["peak_error"]))
    os.makedirs(out, exist_ok=True)
    open(os.path.join(out, "peaks.md"), "w").write("\n".join(lines) + "\n")
    json.dump(report, open(os.path.join(out, "peaks.json"), "w"), indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
