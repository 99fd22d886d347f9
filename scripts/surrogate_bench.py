#!/usr/bin/env python3
"""Surrogate benchmark (docs/benchmarks.md, "Surrogate pre-screening"): calibrations of the reference
arch against a measurement with a hidden truth (data/arch/surrogate), over seeds, for TBPSO alone and
PSO/TBPSO/GA with pre-screening and Bayesian optimisation; then one wall campaign (data/walls).

usage: surrogate_bench.py DEMCAL OUT_DIR [--seeds N] [--threads T] [--wall-seeds N] [--skip-wall]
                          [--skip-arch] [--rows TEXT,...]

--rows keeps the arch rows whose label contains one of the texts (e.g. "mlp,bo").

Writes OUT_DIR/surrogate-bench.md (the tables) and OUT_DIR/surrogate-bench.json (every number).
Campaigns already finished in OUT_DIR are read back (result.json), so an interrupted run continues.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TRUE_FRICTION = 32.3

ARCH_ROWS = [  # label, algorithm, budget, surrogate options (None = off)
    ("TBPSO 20 x 10 alone", "tbpso", 200, None),
    ("PSO + screen (EI)", "pso", 80, {"k": 5, "pool_factor": 5, "acquisition": "ei"}),
    ("TBPSO + screen (EI)", "tbpso", 80, {"k": 5, "pool_factor": 5, "acquisition": "ei"}),
    ("GA + screen (EI)", "ga", 80, {"k": 5, "pool_factor": 5, "acquisition": "ei"}),
    ("TBPSO + screen (LCB)", "tbpso", 80, {"k": 5, "pool_factor": 5, "acquisition": "lcb"}),
    ("bo (EI)", "bo", 80, {"acquisition": "ei"}),
    ("TBPSO + screen (EI, mlp)", "tbpso", 80, {"k": 5, "pool_factor": 5, "acquisition": "ei", "kind": "mlp"}),
    ("bo (EI, mlp)", "bo", 80, {"acquisition": "ei", "kind": "mlp"}),
]


def quartiles(values):
    """q1, median, q3 (linear interpolation between order statistics); inf (target not reached)
    sorts last, and a quartile that touches an inf is nan ("n/a")."""
    v = sorted(values)
    if not v:
        return (float("nan"),) * 3
    out = []
    for p in (0.25, 0.5, 0.75):
        pos = p * (len(v) - 1)
        lo, hi = int(pos), min(int(pos) + 1, len(v) - 1)
        if v[hi] == float("inf") or v[lo] == float("inf"):
            out.append(float("nan"))
        else:
            out.append(v[lo] + (pos - lo) * (v[hi] - v[lo]))
    return tuple(out)


def campaign_tag(stem, surrogate, seed):
    """A campaign's folder name: the stem, the surrogate kind unless gp, the seed."""
    kind = (surrogate or {}).get("kind", "gp")
    return "%s%s-s%d" % (stem, "" if kind == "gp" else "-" + kind, seed)


def run_campaign(demcal, base, out, algorithm, budget, surrogate, seed, threads):
    result = os.path.join(out, "result.json")
    if os.path.exists(result):
        return json.load(open(result))
    campaign = json.load(open(base))
    base_dir = os.path.dirname(base)
    for case in campaign.get("cases", [campaign]):
        m = case["measured"]
        if not os.path.isabs(m["file"]):
            m["file"] = os.path.join(base_dir, m["file"])
    campaign["optimiser"] = {"algorithm": algorithm, "population": 10, "max_evaluations": budget, "seed": seed}
    campaign.pop("polish", None)
    if surrogate is not None:
        campaign["surrogate"] = surrogate
    else:
        campaign.pop("surrogate", None)
    campaign["report"] = False
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, "campaign.json")
    json.dump(campaign, open(path, "w"), indent=1)
    subprocess.run([demcal, "calibrate", path, "--out", out, "--quiet", "--threads", str(threads),
                    "--fitness-threads", str(threads)], check=True)
    return json.load(open(result))


def truth_fitness(demcal, out):
    """Objective 2 of the hidden truth itself (simulated as the campaigns simulate)."""
    os.makedirs(out, exist_ok=True)
    scene = os.path.join(out, "truth.json")
    subprocess.run([demcal, "scene", "arch", "--kn", "2.6e9", "--ks", "0.9e9", "--friction-deg", "32.3", "-o", scene],
                   check=True, stdout=subprocess.DEVNULL)
    subprocess.run([demcal, "simulate", scene, "--out", os.path.join(out, "run")], check=True, stdout=subprocess.DEVNULL)
    # The measurement in SI (mm -> m, kN -> N), as the campaign's column mapping reads it.
    si = os.path.join(out, "measured-si.csv")
    with open(os.path.join(ROOT, "data/arch/surrogate/measured.csv")) as f, open(si, "w") as o:
        lines = f.read().split("\n")
        o.write(lines[0] + "\n")
        for line in lines[2:]:
            if line.strip():
                v, h, force = (float(x) for x in line.split(","))
                o.write("%.9g,%.9g,%.9g\n" % (v * 1e-3, h * 1e-3, force * 1e3))
    r = subprocess.run([demcal, "fitness", "--experiment", si,
                        "--simulation", os.path.join(out, "run", "curves.csv"), "--objective", "2"],
                       check=True, capture_output=True, text=True)
    return json.loads(r.stdout)["fitness"]


def first_within(convergence, target):
    for i, v in enumerate(convergence):
        if v is not None and v <= target:
            return i + 1
    return None


def fmt_q(q, digits=0):
    return " / ".join(("%.*f" % (digits, x)) if x == x else "n/a" for x in q)


def arch_table(a, results, report):
    try:
        truth = truth_fitness(a.demcal, os.path.join(a.out, "truth"))
    except Exception as e:  # the table still stands on the campaigns' own best
        print("truth fitness failed:", e, file=sys.stderr)
        truth = float("inf")
    best_known = min([truth] + [r["best"]["fitness"] for r in results.values() if r["best"]["fitness"] is not None])
    target = 1.02 * best_known
    lines = ["| row | budget | simulations to within 2 % (q1 / median / q3) | reached | simulations to within 10 % (q1 / median / q3) | reached | best at 60 simulations (median) | final fitness (median) | friction error deg (q1 / median / q3) | within 1 deg |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for label, algorithm, budget, surrogate in a.arch_rows:
        sims, sims10, at60, errors, finals = [], [], [], [], []
        for seed in range(1, a.seeds + 1):
            r = results[(label, seed)]
            n = first_within(r["convergence"], target)
            sims.append(n if n is not None else float("inf"))
            n10 = first_within(r["convergence"], 1.10 * best_known)
            sims10.append(n10 if n10 is not None else float("inf"))
            at60.append(r["convergence"][min(59, len(r["convergence"]) - 1)])
            errors.append(abs(r["best"]["params"]["friction_deg"] - TRUE_FRICTION))
            finals.append(r["best"]["fitness"])
        reached = sum(1 for s in sims if s != float("inf"))
        q = quartiles(sims)
        lines.append("| %s | %d | %s | %d/%d | %s | %d/%d | %.0f | %.0f | %s | %d/%d |" % (
            label, budget, fmt_q(q), reached, len(sims), fmt_q(quartiles(sims10)),
            sum(1 for s in sims10 if s != float("inf")), len(sims10), statistics.median(at60),
            statistics.median(finals), fmt_q(quartiles(errors), 2), sum(1 for e in errors if e <= 1.0), len(errors)))
        report["arch"][label] = {"budget": budget, "simulations_to_2pct": [None if s == float("inf") else s for s in sims],
                                 "friction_error_deg": errors, "final_fitness": finals,
                                 "simulations_to_10pct": [None if s == float("inf") else s for s in sims10],
                                 "best_at_60": at60}
    report["arch_best_known"] = best_known
    report["arch_truth_fitness"] = truth
    return ["### Reference arch, hidden truth (kn 2.6e9, ks 0.9e9, friction 32.3 deg, 1.5 %% noise), objective 2, %d seeds" % a.seeds,
          "", "Best fitness known for the problem: %.1f (the truth's own: %.1f); target (+2 %%): %.1f." % (best_known, truth, target),
          "'n/a' in a quartile: fewer than that share of the seeds reached the target within the budget.", ""] + lines



def main():
    p = argparse.ArgumentParser()
    p.add_argument("demcal")
    p.add_argument("out")
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--wall-seeds", type=int, default=3)
    p.add_argument("--skip-wall", action="store_true")
    p.add_argument("--skip-arch", action="store_true")
    p.add_argument("--rows", default="")
    a = p.parse_args()
    wanted = [t for t in a.rows.split(",") if t]
    a.arch_rows = [r for r in ARCH_ROWS if not wanted or any(t in r[0] for t in wanted)]
    os.makedirs(a.out, exist_ok=True)
    report = {"arch": {}, "wall": {}}
    base = os.path.join(ROOT, "data/arch/surrogate/campaign.json")
    results = {}
    md = []
    for seed in range(1, 0 if a.skip_arch else a.seeds + 1):  # seed-major: every row has the same seeds done at any time
        for label, algorithm, budget, surrogate in a.arch_rows:
            tag = campaign_tag("%s-%d-%s" % (algorithm, budget, (surrogate or {}).get("acquisition", "off")), surrogate, seed)
            results[(label, seed)] = run_campaign(a.demcal, base, os.path.join(a.out, "arch", tag), algorithm, budget,
                                                  surrogate, seed, a.threads)
            print("done", label, seed, results[(label, seed)]["best"]["fitness"], flush=True)
    if not a.skip_arch:
        md = arch_table(a, results, report)

    if not a.skip_wall:
        wall = os.path.join(ROOT, "data/walls/SW.30.1.json")
        wall_rows = [("TBPSO alone", "tbpso", 100, None), ("TBPSO + screen (EI)", "tbpso", 30, {"k": 5, "pool_factor": 5}),
                     ("bo (EI)", "bo", 30, {}),
                     ("TBPSO + screen (EI, mlp)", "tbpso", 30, {"k": 5, "pool_factor": 5, "kind": "mlp"}),
                     ("bo (EI, mlp)", "bo", 30, {"kind": "mlp"})]
        wlines = ["| row | budget | best fitness at 30 simulations (per seed) | best fitness at the budget (per seed) |",
                  "| --- | --- | --- | --- |"]
        for label, algorithm, budget, surrogate in wall_rows:
            at30, final = [], []
            for seed in range(1, a.wall_seeds + 1):
                tag = campaign_tag("%s-%d" % (algorithm, budget), surrogate, seed)
                r = run_campaign(a.demcal, wall, os.path.join(a.out, "wall", tag), algorithm, budget, surrogate, seed, a.threads)
                conv = r["convergence"]
                at30.append(conv[min(29, len(conv) - 1)])
                final.append(r["best"]["fitness"])
                print("done wall", label, seed, final[-1], flush=True)
            wlines.append("| %s | %d | %s | %s |" % (label, budget, ", ".join("%.0f" % v for v in at30),
                                                      ", ".join("%.0f" % v for v in final)))
            report["wall"][label] = {"budget": budget, "at_30": at30, "final": final}
        md += ["", "### Wall SW.30.1 (data/walls), objective 1, %d seeds" % a.wall_seeds, ""] + wlines
    open(os.path.join(a.out, "surrogate-bench.md"), "w").write("\n".join(md) + "\n")
    json.dump(report, open(os.path.join(a.out, "surrogate-bench.json"), "w"), indent=1)
    print("\n".join(md))


if __name__ == "__main__":
    main()
