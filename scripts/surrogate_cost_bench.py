#!/usr/bin/env python3
"""Wall-time benchmark of the surrogate (docs/benchmarks.md, "Surrogate wall time"): calibrations of
the reference arch against the hidden-truth measurement (data/arch/surrogate), plain TBPSO against
`bo` variants, the same seeds, one after another on the same cores, each with --threads T.

usage: surrogate_cost_bench.py DEMCAL OUT_DIR [--seeds N] [--threads T] [--rows LABEL,...]
                               [--external SECONDS]

--external: every row's runs go to scripts/slow_arch_simulator.sh (the same arch, each run padded
to SECONDS, as a slower external code), T at a time, through the command backend.

Per row and seed: best fitness, wall time, the model's and the simulations' seconds (result.json's
"timing"), CPU seconds of the process (user + system, from wait4) and the CPU/wall ratio, the
batch and the prequential check of `bo`. Writes OUT_DIR/cost-bench.md and OUT_DIR/cost-bench.json.
Campaigns already finished in OUT_DIR are read back, so an interrupted run continues.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

ROWS = [  # label, algorithm, simulations, surrogate options (None = off)
    ("TBPSO 20 x 10", "tbpso", 200, None),
    ("bo, default", "bo", 60, {"kind": "mlp"}),
    ("bo, batch = workers, no cost adaptation", "bo", 60, {"kind": "mlp", "cost_ratio": "inf"}),
    ("bo, one point per round, full refits", "bo", 60, {"kind": "mlp", "batch": 1, "refit_growth": 1, "cost_ratio": "inf"}),
    ("bo, default, LibTorch training", "bo", 60, {"kind": "mlp", "mlp": {"backend": "libtorch"}}),
]


def run(demcal, out, algorithm, budget, surrogate, seed, threads, external=0.0):
    result_path = os.path.join(out, "result.json")
    stats_path = os.path.join(out, "process.json")
    if os.path.exists(result_path) and os.path.exists(stats_path):
        return json.load(open(result_path)), json.load(open(stats_path))
    campaign = json.load(open(os.path.join(ROOT, "data/arch/surrogate/campaign.json")))
    campaign["measured"]["file"] = os.path.join(ROOT, "data/arch/surrogate", campaign["measured"]["file"])
    campaign["optimiser"] = {"algorithm": algorithm, "population": 10, "max_evaluations": budget, "seed": seed}
    campaign.pop("surrogate", None)
    if surrogate is not None:
        campaign["surrogate"] = surrogate
    campaign["report"] = False
    if external > 0:
        script = os.path.join(ROOT, "scripts/slow_arch_simulator.sh")
        campaign["backend"] = {"type": "command", "parallel": threads,
                               "command": "%s %s %g {kn} {ks} {friction_deg} {output}" % (script, os.path.abspath(demcal), external)}
    os.makedirs(out, exist_ok=True)
    for stale in ("archive.sqlite", "result.json"):
        if os.path.exists(os.path.join(out, stale)):
            os.remove(os.path.join(out, stale))
    path = os.path.join(out, "campaign.json")
    json.dump(campaign, open(path, "w"), indent=1)
    start = time.monotonic()
    proc = subprocess.Popen([demcal, "calibrate", path, "--out", out, "--quiet", "--threads", str(threads),
                             "--fitness-threads", str(threads)])
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - start
    if status != 0:
        sys.exit("%s failed (status %d)" % (out, status))
    stats = {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime}
    json.dump(stats, open(stats_path, "w"))
    return json.load(open(result_path)), stats


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("demcal")
    ap.add_argument("out")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rows", default="")
    ap.add_argument("--external", type=float, default=0.0)
    a = ap.parse_args()
    rows = [r for r in ROWS if not a.rows or any(t in r[0] for t in a.rows.split(","))]
    table = {}
    for seed in range(1, a.seeds + 1):  # seeds outermost: every row sees the same machine state
        for label, algorithm, budget, surrogate in rows:
            tag = "row%d-s%d" % (ROWS.index((label, algorithm, budget, surrogate)), seed)
            result, stats = run(a.demcal, os.path.join(a.out, tag), algorithm, budget, surrogate, seed, a.threads, a.external)
            s = result.get("surrogate", {})
            table.setdefault(label, []).append({
                "seed": seed, "fitness": result["best"]["fitness"], "wall_s": stats["wall_s"], "cpu_s": stats["cpu_s"],
                "model_s": result["timing"]["model_s"], "simulations_s": result["timing"]["simulations_s"],
                "batch": s.get("batch"), "batch_reason": s.get("batch_reason"),
                "prequential_error": s.get("prequential_error"), "prequential_coverage90": s.get("prequential_coverage90")})
            print(label, seed, table[label][-1], flush=True)
    med = lambda xs: statistics.median(xs) if xs else float("nan")
    lines = ["| row | simulations | median fitness | fitness q1 / q3 | median wall (s) | median model (s) | model / wall | median simulations (s) | CPU / wall | prequential error | 90 % coverage |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for label, algorithm, budget, surrogate in rows:
        r = table[label]
        f = sorted(x["fitness"] for x in r)
        q = statistics.quantiles(f, n=4) if len(f) > 1 else [f[0], f[0], f[0]]
        pe = [x["prequential_error"] for x in r if x["prequential_error"] is not None]
        pc = [x["prequential_coverage90"] for x in r if x["prequential_coverage90"] is not None]
        lines.append("| %s | %d | %.0f | %.0f / %.0f | %.1f | %.1f | %.0f %% | %.1f | %.2f | %s | %s |" % (
            label, budget, med(f), q[0], q[2], med([x["wall_s"] for x in r]), med([x["model_s"] for x in r]),
            100 * sum(x["model_s"] for x in r) / sum(x["wall_s"] for x in r), med([x["simulations_s"] for x in r]), sum(x["cpu_s"] for x in r) / sum(x["wall_s"] for x in r),
            "%.2f" % med(pe) if pe else "-", "%.0f %%" % (100 * med(pc)) if pc else "-"))
    text = "\n".join(lines) + "\n"
    open(os.path.join(a.out, "cost-bench.md"), "w").write(text)
    json.dump(table, open(os.path.join(a.out, "cost-bench.json"), "w"), indent=1)
    print(text)


if __name__ == "__main__":
    main()
