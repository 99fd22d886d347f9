#!/usr/bin/env python3
"""`demcal diagnose` on the records of another DEM code (data/refdem-arch/, its README gives the
declared effects and truths): one diagnosis per record, then the table of docs/diagnose.md's
"Records of another code": verdict, how often the resamples reach it, each effect parameter with
its range against the truth, the error before and after against the noise, simulations and wall time.

usage: refdem_table.py DEMCAL_BINARY OUT_DIR [--records A-control-1,A-support-1,...]
                       [--realisations in_contact:0,all:1,...] [--window common|measured] [--read-only]
                       [--solver KEY=VALUE ...] [-- FLAGS...]

FLAGS after `--` go to every `demcal diagnose` (none: its defaults). Each record gets
OUT_DIR/<record>/ (campaign.json, the diagnosis); a finished one (diagnosis.json present) is read,
not run again, so the table resumes. Writes OUT_DIR/table.json and prints the markdown table.
--read-only tabulates the finished diagnoses alone (the others as "did not finish"), without running
any and writing no table.json: a table of a study still running in the same OUT_DIR.

--realisations: each record on each round-off realisation of the engine (FACES:K, the campaign
scene's solver with time_step_faces FACES and time_step_safety 0.5 x (1 + K x 1e-14), as
tests/pipelines/test_support.hpp), in OUT_DIR/<record>/<FACES_K>/; the table then has one row per
record: its verdict on each realisation, how many agree with the first and how many are right, how
many of the stated ranges hold the truth (over every realisation, parameters with a declared truth),
and the spread of the simulations and wall time.

--solver KEY=VALUE: a key of the campaign scene's solver (repeatable; numbers as numbers), set
after the realisation's, e.g. --solver time_step_stiffening=nodes (docs/engine.md, "Integration").

--window: the campaigns' objective window ("common", the paper's, or "measured"; docs/smoothing.md);
default: the bundled campaigns' own.

"Right": every declared effect named and no other; for a control, "no effect needed". An effect
record whose diagnosis says "no effect needed" with the base fit within the noise (no candidate
calibrated, or the final fit, a base re-fitted by the removal check, at most the level at which the
loop calls a fit explained: removal_checks' explained_level, the noise in a diagnosis.json without
it) is counted right too, and marked so (the README: an effect may not stand above the noise for a
calibrated base).
A realisation table marks each verdict that is not right: "(wrong)" where it names an effect the
record does not declare, "(k of n declared)" where it names some of the declared effects and no
other, "(missed)" where it names none.
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "data", "refdem-arch")

# Declared effects and the truths of their parameters (suffix of the calibrated name -> value, SI;
# friction in degrees), from data/refdem-arch/README.md.
TRUTH = {
    "A-control": ([], {"kn": 2.9e9, "ks": 1.2e9, "friction_deg": 32.5}),
    "A-control-noisy": ([], {"kn": 3.3e9, "ks": 1.5e9, "friction_deg": 30.9}),
    "A-softening": (["friction-softening"], {"kn": 3.0e9, "ks": 1.3e9, "friction_deg": 34,
                                             "friction_loss_deg": 8, "slip_softening": 5e-4}),
    "A-support": (["support-compliance"], {"kn": 3.4e9, "ks": 1.3e9, "friction_deg": 31.5, "support_kx": 2e6}),
    # 0.8 mm open at the intrados, closed at the extrados: gap_taper -1 (beyond -1 the same wedge)
    "A-gap": (["joint-gap"], {"kn": 3.1e9, "ks": 1.2e9, "friction_deg": 31.8, "gap_opening": 8e-4, "gap_taper": -1}),
    "A-closure": (["joint-closure"], {"kn": 2.0e9, "ks": 1.1e9, "friction_deg": 31.2, "closure_max": 1.5e-4}),
    "A-closure-support": (["joint-closure", "support-compliance"],
                          {"kn": 2.2e9, "ks": 1.0e9, "friction_deg": 31.6, "closure_max": 1e-4, "support_kx": 1.5e6}),
    "B-control": ([], {"kn": 2.7e9, "ks": 1.1e9, "friction_deg": 32}),
    "B-softening": (["friction-softening"], {"kn": 2.7e9, "ks": 1.1e9, "friction_deg": 33,
                                             "friction_loss_deg": 8, "slip_softening": 1e-3}),
    "B-closure": (["joint-closure"], {"kn": 1.8e9, "ks": 0.9e9, "friction_deg": 31.5, "closure_max": 1e-4}),
}
RECORDS = sorted(f[:-4] for f in os.listdir(DATA) if f.endswith(".csv"))


def truth_of(record):
    return TRUTH[record.rsplit("-", 1)[0]]


def campaign_for(record, folder, realisation=None, window=None, solver=None):
    geometry = record.split("-")[0]
    with open(os.path.join(DATA, geometry + "-campaign.json")) as f:
        campaign = json.load(f)
    if realisation:
        faces, k = realisation.split(":")
        campaign["scene"]["solver"] = {"time_step_faces": faces, "time_step_safety": 0.5 * (1 + int(k) * 1e-14)}
    if solver:
        campaign["scene"].setdefault("solver", {}).update(solver)
    if window:
        campaign.setdefault("objective", {})["window"] = window
    campaign["measured"]["file"] = os.path.abspath(os.path.join(DATA, record + ".csv"))
    campaign["output"] = os.path.abspath(os.path.join(folder, "base-campaign"))
    path = os.path.join(folder, "campaign.json")
    with open(path, "w") as f:
        json.dump(campaign, f, indent=2)
    return path


def diagnose(binary, record, out, flags, realisation=None, window=None, run=True, solver=None):
    folder = os.path.join(out, record, realisation.replace(":", "_")) if realisation else os.path.join(out, record)
    result = os.path.join(folder, "diag", "diagnosis.json")
    if run and not os.path.exists(result):
        os.makedirs(folder, exist_ok=True)
        campaign = campaign_for(record, folder, realisation, window, solver)
        start = time.time()
        with open(os.path.join(folder, "diagnose.log"), "w") as log:
            code = subprocess.run([binary, "diagnose", campaign, "--out", os.path.join(folder, "diag"), "--no-report"] +
                                  flags, stdout=log, stderr=subprocess.STDOUT, check=False).returncode
        print("%s%s: %.0f s%s" % (record, " " + realisation if realisation else "", time.time() - start,
                                  "" if code == 0 else ", exit code %d" % code), file=sys.stderr)
    if not os.path.exists(result):  # a diagnosis that did not finish: a row that says so (run again to retry)
        return None
    with open(result) as f:
        return json.load(f)


def number(v):
    return "%.3g" % v


def effect_parameters(d, declared, truth):
    """Each parameter of the chosen effects: value, range (the bounds' check), truth, inside or not.
    An effect added at a further step is read from that step's diagnosis.json, at the value of the
    fit with every effect (the last step's, or the pair search's where two were found together), its
    range that of its entry in "added" (of its step, or for one added tentatively or in a pair, of the
    model with every effect)."""
    steps = {}
    for a in d.get("added", []):
        if a["folder"]:
            with open(os.path.join(a["folder"], "diagnosis.json")) as f:
                steps[a["effect"]] = json.load(f)
        else:
            steps[a["effect"]] = d
    final = {}
    if (d.get("pair_search") or {}).get("accepted"):  # two effects found together: the pair's fit
        final = d["pair_search"]["params"]
    elif steps:
        last = steps[d["added"][-1]["effect"]]
        final = next(c["params"] for c in last["candidates"] if c["effect"] == d["added"][-1]["effect"])
    added_bounds = {a["effect"]: a.get("bounds", {}) for a in d.get("added", [])}
    rows = []
    for effect in d["chosen"]:
        step = steps.get(effect, d)
        c = next(x for x in step["candidates"] if x["effect"] == effect)
        for name, value in sorted(c["params"].items()):
            if name in step["base"]["params"]:
                continue
            value = final.get(name, value)
            key = name.split(".")[-1]
            b = added_bounds.get(effect, {}).get(name) or c.get("bounds", {}).get(name, {})
            lower, upper = b.get("lower"), b.get("upper")
            inside = None
            if key in truth:
                inside = (lower is None or truth[key] >= lower) and (upper is None or truth[key] <= upper)
            rows.append({"name": name, "value": value, "lower": lower, "upper": upper, "truth": truth.get(key),
                         "inside": inside})
    return rows


def judged(record, d):
    declared, truth = truth_of(record)
    if d is None:
        return {"record": record, "declared": declared, "outcome": "did_not_finish", "chosen": [], "headline": "",
                "frequency": None, "parameters": [], "error_before": float("nan"), "error_after": float("nan"),
                "noise": float("nan"), "simulations": 0, "wall_s": float("nan"), "right": False,
                "within_noise": False}
    chosen = d["chosen"]
    noise = (sum(v * v for v in d["noise"].values()) / max(1, len(d["noise"]))) ** 0.5
    # the diagnosis's own rule: a base fit within the noise and scatter calibrates no candidate, and a
    # base re-fitted by the removal check is judged against the same level
    dropped = [r for r in d.get("removal_checks", []) if r.get("dropped")]
    level = dropped[-1].get("explained_level") if dropped else None
    within_noise = d["outcome"] == "no_effect_needed" and (
        not any(c["tried"] for c in d["candidates"]) or d["error_after"] <= (noise if level is None else level))
    right = (d["outcome"] == "no_effect_needed" if not declared else sorted(chosen) == sorted(declared)) or (
        declared and within_noise)
    return {"record": record, "declared": declared, "outcome": d["outcome"], "chosen": chosen,
            "headline": d["headline"], "frequency": d.get("frequency", {}).get("verdict"),
            "parameters": effect_parameters(d, declared, truth), "error_before": d["error_before"],
            "error_after": d["error_after"], "noise": noise, "simulations": d["simulations"],
            "wall_s": d["timing"]["wall_s"], "right": bool(right), "within_noise": bool(declared and within_noise)}


# How the verdict's first words read for an outcome that names no effect (diagnosis.json "outcome").
OUTCOME_WORDS = {"unexplained": "no effect found", "undecided": "undecided", "no_effect_needed": "no effect needed"}


def verdict_of(row):
    if row["chosen"]:
        return ", ".join(row["chosen"])
    return OUTCOME_WORDS.get(row["outcome"], row["outcome"].replace("_", " "))


def names_undeclared(row):
    return any(e not in row["declared"] for e in row["chosen"])


def miss_of(row):
    """"" for a right row; otherwise how it is wrong: an effect named that the record does not declare
    ("wrong"), some of the declared effects named and no other ("k of n declared"), or none ("missed")."""
    if row["right"] or row["outcome"] == "did_not_finish":
        return ""
    if names_undeclared(row):
        return " (wrong)"
    if row["chosen"]:
        return " (%d of %d declared)" % (len(row["chosen"]), len(row["declared"]))
    return " (missed)"


def markdown(rows):
    out = ["| record | declared | verdict | resamples reaching it | effect parameters (range) vs truth | "
           "error before → after (noise), N | simulations | wall (s) | right |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        verdict = verdict_of(r)
        params = "; ".join(
            "%s %s (%s–%s) vs %s%s" % (p["name"].split(".")[-1], number(p["value"]),
                                       "·" if p["lower"] is None else number(p["lower"]),
                                       "·" if p["upper"] is None else number(p["upper"]),
                                       "?" if p["truth"] is None else number(p["truth"]),
                                       "" if p["inside"] is None else (" in" if p["inside"] else " OUT"))
            for p in r["parameters"]) or "–"
        freq = "–" if r["frequency"] is None else "%.0f %%" % (100 * r["frequency"])
        out.append("| %s | %s | %s | %s | %s | %s → %s (%s) | %d | %.0f | %s |" % (
            r["record"], ", ".join(r["declared"]) or "none", verdict, freq, params, number(r["error_before"]),
            number(r["error_after"]), number(r["noise"]), r["simulations"], r["wall_s"],
            ("yes (within the noise)" if r["within_noise"] else "yes") if r["right"] else "**no**"))
    right = sum(r["right"] for r in rows)
    out.append("")
    out.append("%d of %d right." % (right, len(rows)))
    return "\n".join(out)


def spread(values, form):
    """"low–high" of `values` in `form`, one value where they print alike, "–" when there are none."""
    if not values:
        return "–"
    low, high = form % min(values), form % max(values)
    return low if low == high else low + "–" + high


def realisation_markdown(realisations, rows_by_record):
    """One row per record: its verdict on each realisation, right or not, and how many agree."""
    out = ["| record | " + " | ".join(realisations) + " | same verdict | right | truth in range | simulations | wall (s) |",
           "| --- | " + " | ".join("---" for _ in realisations) + " | --- | --- | --- | --- | --- |"]
    stable = held = stated = right = wrong = diagnoses = 0
    for record, rows in rows_by_record.items():
        verdicts = [verdict_of(r) + miss_of(r) for r in rows]
        same = sum(verdict_of(r) == verdict_of(rows[0]) for r in rows)
        finished = [r for r in rows if r["outcome"] != "did_not_finish"]
        stable += same == len(rows) == len(finished)
        diagnoses += len(finished)
        record_right = sum(r["right"] for r in finished)
        right += record_right
        wrong += sum(names_undeclared(r) for r in finished)
        ranges = [p["inside"] for r in rows for p in r["parameters"] if p["inside"] is not None]
        held += sum(ranges)
        stated += len(ranges)
        out.append("| %s | %s | %d of %d | %d of %d | %s | %s | %s |" % (
            record, " | ".join(verdicts), same, len(rows), record_right, len(rows),
            "%d of %d" % (sum(ranges), len(ranges)) if ranges else "–",
            spread([r["simulations"] for r in finished], "%d"), spread([r["wall_s"] for r in finished], "%.0f")))
    out.append("")
    out.append("%d of %d records with the same verdict on every realisation; %d of %d diagnoses right, %d naming an "
               "effect the record does not declare; the truth inside %d of %d stated ranges." % (
                   stable, len(rows_by_record), right, diagnoses, wrong, held, stated))
    return "\n".join(out)


def main():
    argv = sys.argv[1:]
    flags = []
    if "--" in argv:
        flags = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("binary")
    parser.add_argument("out")
    parser.add_argument("--records", default=",".join(RECORDS))
    parser.add_argument("--realisations", default="")
    parser.add_argument("--window", choices=["common", "measured"])
    parser.add_argument("--read-only", action="store_true")
    parser.add_argument("--solver", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    solver = {}
    for item in args.solver:
        key, _, value = item.partition("=")
        try:
            solver[key] = float(value)
        except ValueError:
            solver[key] = value
    run = not args.read_only
    binary = os.path.abspath(args.binary)
    records = args.records.split(",")
    table = {"flags": flags, "window": args.window, "solver": solver}
    if args.realisations:
        table["realisations"] = args.realisations.split(",")
        table["rows"] = {r: [dict(judged(r, diagnose(binary, r, args.out, flags, x, args.window, run, solver)), realisation=x)
                             for x in table["realisations"]] for r in records}
    else:
        table["rows"] = [judged(r, diagnose(binary, r, args.out, flags, window=args.window, run=run, solver=solver))
                         for r in records]
    if run:
        with open(os.path.join(args.out, "table.json"), "w") as f:
            json.dump(table, f, indent=2)
    print(realisation_markdown(table["realisations"], table["rows"]) if args.realisations else markdown(table["rows"]))


if __name__ == "__main__":
    main()
