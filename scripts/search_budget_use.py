#!/usr/bin/env python3
"""How the searches of finished `demcal diagnose` runs used their budgets, and where the runs went.

usage: search_budget_use.py DIAGNOSIS_DIR [DIAGNOSIS_DIR ...]

Each DIAGNOSIS_DIR is a diagnosis's --out folder (diagnosis.json and a result.json per search,
at any depth). Per kind of search (base calibration, refinement, candidate, removal check): the
median share of its budget after which its best-so-far (result.json "convergence") first came
within 2 % and 5 % of its final best, and how many came within 2 % only in the second half. Then
the simulations by stage; the direct runs (re-runs, probes, bounds' trials) are the diagnosis's
count less its searches' (docs/journal/diagnosis-cost.md, 2026-12-03).
"""
import glob
import json
import os
import statistics
import sys


def kind_of(relative):
    if relative.startswith("base" + os.sep) or "base-refined" in relative:
        return "base calibration" if relative.startswith("base" + os.sep) else "refinement"
    return "removal check" if "without-" in relative else "candidate"


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    shares = {}
    runs = {"base calibration": 0, "refinement": 0, "candidate": 0, "removal check": 0, "direct runs": 0}
    for folder in sys.argv[1:]:
        with open(os.path.join(folder, "diagnosis.json")) as f:
            direct = json.load(f)["simulations"]
        for path in glob.glob(os.path.join(folder, "**", "result.json"), recursive=True):
            with open(path) as f:
                result = json.load(f)
            kind = kind_of(os.path.relpath(path, folder))
            runs[kind] += result["simulations"]
            direct -= result["simulations"]
            best_so_far = result.get("convergence") or []
            if best_so_far:
                final = best_so_far[-1]
                first = lambda tol: next(i + 1 for i, v in enumerate(best_so_far) if v <= final * (1 + tol))
                shares.setdefault(kind, []).append((first(0.02) / len(best_so_far), first(0.05) / len(best_so_far)))
        runs["direct runs"] += direct
    print("| search | searches | within 2 % at (median share of budget) | within 5 % at | within 2 % only in the second half |")
    print("| --- | --- | --- | --- | --- |")
    for kind, s in sorted(shares.items()):
        print("| %s | %d | %.2f | %.2f | %.0f %% |" % (kind, len(s), statistics.median(x[0] for x in s),
                                                    statistics.median(x[1] for x in s),
                                                    100 * sum(x[0] > 0.5 for x in s) / len(s)))
    total = sum(runs.values())
    print("\nsimulations: %d; " % total + ", ".join("%s %.0f %%" % (k, 100 * v / max(1, total)) for k, v in runs.items()))


if __name__ == "__main__":
    main()
