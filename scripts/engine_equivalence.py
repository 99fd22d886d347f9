#!/usr/bin/env python3
"""Whether two builds of the engine compute the same physics, judged against the engine's own
round-off spread (docs/engine.md, "Same physics, measured against round-off").

A quasi-static masonry curve is chaotic after the first hinges form: a change of the time step in
its 14th digit moves the reference arch's peak by up to 0.3 % and its curve by 0.6-1.1 % RMS of
the peak. A change of the engine's arithmetic cannot be held to a tolerance tighter than that. This
script measures the spread and asks whether the candidate's runs belong to it:

  1. each build runs the scene once as it is and MEMBERS more times with the time step's safety
     factor scaled by 1 + k 1e-14 (k = +-1, +-2, ...): its round-off ensemble, each build with its
     own automatic time step;
  2. the distance between two runs is the RMS of their force difference over the recorded rows
     (rows are at fixed actuator travel), as a fraction of the baseline's peak;
  3. a two-sample permutation test on the energy statistic
       E = 2 mean(baseline-candidate distances) - mean(baseline pairs) - mean(candidate pairs)
     (zero when the two ensembles are alike): the p-value is the fraction of random relabellings of
     the pooled runs whose E is at least the observed one.

The candidate computes the same physics when p >= --alpha (0.05). The table also gives each
ensemble's peaks, its runs' differences from the baseline's unperturbed run, and how many of them
pass a fixed tolerance (--peak-tolerance, --rms-tolerance) that the baseline's own members would
have to pass too.

usage: engine_equivalence.py BASELINE_DEMCAL CANDIDATE_DEMCAL [--velocity 0.001] [--members 8]
                             [--scene-flags "arch --contacts-per-joint 15"] [--jobs 2] [--out DIR]
                             [--permutations 4000] [--alpha 0.05] [--seed 1] [--candidate-solver JSON]
Exit status 0 when the candidate is inside the baseline's spread, 1 when not.
"""
import argparse
import concurrent.futures
import csv
import json
import math
import os
import random
import shlex
import statistics
import subprocess
import sys
import tempfile


def simulate_scene(binary, scene, solver, out_dir):
    """Runs `binary simulate` on a copy of the scene file `scene` in `out_dir` with the keys of
    `solver` set in its solver section; returns summary.json."""
    with open(scene) as f:
        data = json.load(f)
    data["solver"].update(solver)
    os.makedirs(out_dir, exist_ok=True)
    scene_file = os.path.join(out_dir, "scene.json")
    with open(scene_file, "w") as f:
        json.dump(data, f)
    done = subprocess.run([binary, "simulate", scene_file, "--out", out_dir], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{binary} simulate {scene_file} failed: {done.stderr.strip()}")
    with open(os.path.join(out_dir, "summary.json")) as f:
        return json.load(f)


def run(binary, scene, safety_scale, out_dir, solver=None):
    """Runs `binary simulate` on `scene` with its automatic time step's safety factor scaled by
    `safety_scale` and the solver keys of `solver` set; returns (forces of the recorded rows, summary)."""
    with open(scene) as f:
        safety = json.load(f)["solver"]["time_step_safety"]
    settings = {"time_step": 0, "time_step_safety": safety * safety_scale, **(solver or {})}
    summary = simulate_scene(binary, scene, settings, out_dir)
    with open(os.path.join(out_dir, "curves.csv")) as f:
        forces = [float(row["force"]) for row in csv.DictReader(f)]
    return forces, summary


def rms_difference(forces, other):
    """RMS of the force difference over the common rows, N."""
    n = min(len(forces), len(other))
    if n == 0:
        return math.inf
    return math.sqrt(sum((forces[i] - other[i]) ** 2 for i in range(n)) / n)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("baseline")
    parser.add_argument("candidate")
    parser.add_argument("--velocity", type=float, default=0.001, help="loading velocity, m/s")
    parser.add_argument("--members", type=int, default=8, help="perturbed runs per build")
    parser.add_argument("--scene-flags", default="arch", help="`demcal scene` subcommand and flags")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--peak-tolerance", type=float, default=0.001, help="fixed peak tolerance (fraction)")
    parser.add_argument("--rms-tolerance", type=float, default=0.005, help="fixed RMS tolerance (fraction of the peak)")
    parser.add_argument("--out", default=None, help="folder for the runs (default: a temporary one)")
    parser.add_argument("--permutations", type=int, default=4000)
    parser.add_argument("--alpha", type=float, default=0.05, help="smallest p-value still called the same physics")
    parser.add_argument("--seed", type=int, default=1, help="seed of the permutations")
    parser.add_argument("--candidate-solver", default="{}",
                        help='solver keys set in the candidate\'s runs only, as JSON: one build, two settings '
                             '(e.g. \'{"time_step_stiffening": "nodes"}\')')
    args = parser.parse_args()
    candidate_solver = json.loads(args.candidate_solver)
    if args.members < 2:
        parser.error("--members must be at least 2")

    out = args.out or tempfile.mkdtemp(prefix="engine-equivalence-")
    os.makedirs(out, exist_ok=True)
    scene = os.path.join(out, "scene.json")
    flags = shlex.split(args.scene_flags)
    made = subprocess.run([args.baseline, "scene", *flags, "--velocity", str(args.velocity), "-o", scene],
                          capture_output=True, text=True)
    if made.returncode != 0:
        sys.exit(f"demcal scene {args.scene_flags} failed: {made.stderr.strip()}")

    reference, summary = run(args.baseline, scene, 1, os.path.join(out, "baseline-0"))
    scales = [0] + [(k // 2 + 1) * (1 if k % 2 == 0 else -1) for k in range(args.members)]
    jobs = [(build, binary, k) for build, binary in (("baseline", args.baseline), ("candidate", args.candidate))
            for k in scales if not (build == "baseline" and k == 0)]
    results = {"baseline": {0: (reference, summary)}, "candidate": {}}
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(run, binary, scene, 1 + k * 1e-14, os.path.join(out, f"{build}{k:+d}"),
                               candidate_solver if build == "candidate" else None): (build, k)
                   for build, binary, k in jobs}
        for future in concurrent.futures.as_completed(futures):
            build, k = futures[future]
            results[build][k] = future.result()

    stats = {}
    for build in ("baseline", "candidate"):
        runs = results[build]
        peaks = [max(forces) for forces, _ in runs.values()]
        differences = [rms_difference(forces, reference) / max(reference) for k, (forces, _) in runs.items() if build == "candidate" or k]
        peak_changes = [abs(p / max(reference) - 1) for k, p in zip(runs, peaks) if build == "candidate" or k]
        fixed_pass = sum(d <= args.rms_tolerance and c <= args.peak_tolerance for d, c in zip(differences, peak_changes))
        stats[build] = {
            "peaks": peaks, "differences": differences, "fixed_pass": fixed_pass, "compared": len(differences),
            "wall": statistics.median(s["wall_time_s"] for _, s in runs.values()),
            "steps": statistics.median(s["steps"] for _, s in runs.values()),
        }

    curves = [results["baseline"][k][0] for k in sorted(results["baseline"])] + \
             [results["candidate"][k][0] for k in sorted(results["candidate"])]
    n_base = len(results["baseline"])
    distance = [[rms_difference(a, b) / max(reference) for b in curves] for a in curves]
    observed = energy_statistic(distance, list(range(n_base)), list(range(n_base, len(curves))))
    rng = random.Random(args.seed)
    pooled = list(range(len(curves)))
    at_least = 0
    for _ in range(args.permutations):
        rng.shuffle(pooled)
        at_least += energy_statistic(distance, pooled[:n_base], pooled[n_base:]) >= observed
    p_value = (at_least + 1) / (args.permutations + 1)
    same = p_value >= args.alpha

    print(f"Scene `demcal scene {args.scene_flags} --velocity {args.velocity}`, time steps (s) "
          f"{summary['time_step']:.6g} (baseline), {results['candidate'][0][1]['time_step']:.6g} (candidate), "
          f"each scaled by 1 + k 1e-14, k in {sorted(scales)}; runs in {out}\n")
    print("| build | runs | peak (N): unperturbed, min–max | RMS difference from the baseline's unperturbed run "
          f"(% of peak): median, max | within {100 * args.peak_tolerance:g} % peak and {100 * args.rms_tolerance:g} % RMS "
          "| mean distance within the build (% of peak) | steps | wall time per run (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for build, members in (("baseline", range(n_base)), ("candidate", range(n_base, len(curves)))):
        s = stats[build]
        within = [distance[i][j] for i in members for j in members if i < j]
        print(f"| {build} | {len(s['peaks'])} | {results[build][0][1]['peak_force']:.2f}, "
              f"{min(s['peaks']):.2f}–{max(s['peaks']):.2f} | {100 * statistics.median(s['differences']):.3f}, "
              f"{100 * max(s['differences']):.3f} | {s['fixed_pass']} of {s['compared']} | "
              f"{100 * statistics.mean(within):.3f} | {s['steps']:.0f} | {s['wall']:.3f} |")
    across = [distance[i][j] for i in range(n_base) for j in range(n_base, len(curves))]
    print(f"\nMean distance between a baseline and a candidate run: {100 * statistics.mean(across):.3f} % of peak; "
          f"energy statistic {100 * observed:.4f} %, permutation p = {p_value:.3f} ({args.permutations} permutations).")
    print("Same physics." if same else f"Outside the baseline's round-off spread (p < {args.alpha:g}).")
    return 0 if same else 1


def energy_statistic(distance, first, second):
    """2 mean(d(first, second)) - mean(d within first) - mean(d within second), over distinct pairs."""
    def mean_within(group):
        pairs = [distance[i][j] for a, i in enumerate(group) for j in group[a + 1:]]
        return sum(pairs) / len(pairs)
    across = sum(distance[i][j] for i in first for j in second) / (len(first) * len(second))
    return 2 * across - mean_within(first) - mean_within(second)


if __name__ == "__main__":
    sys.exit(main())
