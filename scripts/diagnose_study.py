#!/usr/bin/env python3
"""The goal study of `demcal diagnose` (docs/journal/diagnose-studies.md): for every hidden effect and a control
with none, measurements made by the engine with parameters the diagnosis is not told plus force
noise, one diagnosis per noise seed; then the table of how often the right effect was named, how
well its parameters came back (within 25 %, and inside the bounds the diagnosis states), how far
the error fell (3 x, or to the level at which the loop calls a fit explained), and how often all
three parts of the goal held at once.

usage: diagnose_study.py DEMCAL_BINARY OUT_DIR [--cases none,support-compliance,...] [--seeds 5] [--first-seed 1]
                         [--velocity 0.001] [--contacts-per-joint 5] [--max-displacement 0.008]
                         [--candidate-simulations 80] [--surrogate-kind mlp] [--fit-abutment] [--window measured] [--magnitude 1]
                         [--every 5] [--match-sampling] [--kn-upper 1e10] [--candidates N] [--jobs 1]

Each case and seed gets OUT_DIR/<case>/seed-<s>/ (measured.csv, campaign.json, the diagnosis in
diag/). A finished diagnosis (diag/diagnosis.json) is read, not run again, so the study resumes.
Writes OUT_DIR/study.json and prints the markdown table.
"""
import argparse
import concurrent.futures
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

# The truth the measurement is made with: base parameters (set on the joint groups, as a
# calibration sets them), then per case the `demcal scene arch` flags of the hidden effect and the
# effect parameters that a diagnosis should recover (suffix of the calibrated parameter's name).
BASE_TRUTH = {"kn": 2.6e9, "ks": 0.9e9, "friction_deg": 32.3}


def hidden_effect(case, magnitude=1.0):
    """(scene flags, truth) of a case with its effect at `magnitude` x the study's default strength:
    the departure from the plain model grows with it (a support's compliance, a friction drop, a
    joint's inverse maximum closure, a cohesion, a crushing cap's inverse strength, a beam's
    rotational stiffness)."""
    m = magnitude
    if case == "none":
        return [], {}
    if case == "support-compliance":
        return (["--support-kx", "%g" % (5e6 / m), "--support-ky", "1e9", "--support-kr", "1e9",
                 "--support-blocks", "abutment_right"], {"support_kx": 5e6 / m})
    if case == "friction-softening":
        residual = BASE_TRUTH["friction_deg"] - 10.3 * m
        # the scene's own friction set to the truth too, which the residual may not exceed
        return (["--friction-deg", "%r" % BASE_TRUTH["friction_deg"], "--friction-residual-deg", "%g" % residual,
                 "--slip-softening", "0.001"],
                {"friction_loss_deg": 10.3 * m, "slip_softening": 0.001})
    if case == "joint-closure":
        # the hyperbola departs from the linear law the more, the smaller its maximum closure
        return ["--closure-max", "%g" % (1e-4 / m)], {"closure_max": 1e-4 / m}
    if case == "cohesion":
        return (["--cohesion", "%g" % (3e4 * m), "--tensile-strength", "%g" % (3e4 * m)],
                {"cohesion": 3e4 * m, "tensile_strength": 3e4 * m})
    if case == "crushing-cap":
        return ["--compressive-strength", "%g" % (2e6 / m)], {"compressive_strength": 2e6 / m}
    if case == "boundary-restraint":
        return ["--beam-kr", "%g" % (3e4 * m)], {"beam_kr": 3e4 * m}
    if case == "joint-gap":
        # a wedge open at the extrados of the joint under the load, where the plain model's hinge forms
        # (a taper of 1: closed at the intrados)
        return (["--gap-joint", GAP_JOINT, "--gap-extrados", "%g" % (1e-3 * m)],
                {"gap_opening": 1e-3 * m, "gap_taper": 1.0})
    raise KeyError(case)


GAP_JOINT = "voussoir_5/voussoir_6"
CASES = ["none", "support-compliance", "friction-softening", "joint-closure", "cohesion", "crushing-cap",
         "boundary-restraint", "joint-gap"]


def chosen_fit(diagnosis, case):
    """The accepted candidate of the hidden effect, at the hidden joint for a gap; None otherwise."""
    for c in diagnosis["candidates"]:
        if c["effect"] == case and c["verdict"] == "accepted":
            return c if case != "joint-gap" or c.get("target") == GAP_JOINT else None
    return None


def campaign(measured, args):
    scene_options = {"contacts_per_joint": args.contacts_per_joint, "velocity": args.velocity,
                     "max_displacement": args.max_displacement}
    if args.match_sampling:
        # the simulation recorded where the measurement was: its rows are every `every`-th of a
        # record at the generator's default interval (max_displacement / 1200)
        scene_options["record_interval"] = args.every * args.max_displacement / 1200
    return {
        "name": "diagnose-study",
        "scene": {"generator": "arch", "options": scene_options},
        "measured": measured,
        "parameters": [{"name": "kn", "lower": 1e8, "upper": args.kn_upper, "scale": "log10"},
                       {"name": "ks", "lower": 1e8, "upper": 1e10, "scale": "log10"},
                       {"name": "friction_deg", "lower": 25, "upper": 45}],
        # by default the abutment gauge is not fitted (docs/journal/diagnose-studies.md): it is the check on data not
        # fitted; --fit-abutment fits it too
        "objective": {"type": 1, "weights": {} if args.fit_abutment else {"abutment_horizontal": 0},
                      "window": args.window},
        "optimiser": {"algorithm": "tbpso", "population": 10, "iterations": 6, "seed": 1},
        "polish": {"algorithm": "LN_SBPLX", "max_evaluations": 20},
        "report": False,
    }


def run_one(binary, args, case, seed):
    folder = os.path.join(args.out, case, "seed-%d" % seed)
    result = os.path.join(folder, "diag", "diagnosis.json")
    if not os.path.exists(result):
        os.makedirs(folder, exist_ok=True)
        measured = os.path.join(folder, "measured.csv")
        flags, _ = hidden_effect(case, args.magnitude)
        params = ["--param=%s=%r" % (k, v) for k, v in BASE_TRUTH.items()]
        subprocess.run([sys.executable, os.path.join(HERE, "synthetic_measurement.py"), binary, measured,
                        "--seed", str(seed), "--displacement-noise", "0", "--every", str(args.every), *params, "--", "arch",
                        "--contacts-per-joint", str(args.contacts_per_joint), "--velocity", str(args.velocity),
                        "--max-displacement", str(args.max_displacement), *flags],
                       check=True, stdout=subprocess.DEVNULL)
        with open(os.path.join(folder, "campaign.json"), "w") as f:
            json.dump(campaign(os.path.abspath(measured), args), f, indent=2)
        with open(os.path.join(folder, "diagnose.log"), "w") as log:
            subprocess.run([binary, "diagnose", os.path.join(folder, "campaign.json"), "--out",
                            os.path.join(folder, "diag"), "--effects", args.effects, "--candidate-simulations",
                            str(args.candidate_simulations), "--no-report",
                            *(["--surrogate-kind", args.surrogate_kind] if args.surrogate_kind else []),
                            *(["--candidates", str(args.candidates)] if args.candidates else [])],
                           check=True, stdout=log, stderr=subprocess.STDOUT)
    with open(result) as f:
        return json.load(f)


def recovered(diagnosis, case, magnitude):
    """Largest relative error of the hidden effect's parameters in the chosen fit (None: not chosen);
    a gap's taper as the engine reads it (beyond +-1: +-1)."""
    _, truth = hidden_effect(case, magnitude)
    c = chosen_fit(diagnosis, case)
    if c is None:
        return None
    worst = 0.0
    for suffix, value in truth.items():
        found = [v for k, v in c["params"].items() if k.split(".")[-1] == suffix]
        if not found:
            return None
        v = max(-1.0, min(1.0, found[0])) if suffix == "gap_taper" else found[0]
        worst = max(worst, abs(v - value) / abs(value))
    return worst


def bounded(diagnosis, case, magnitude):
    """Whether every hidden parameter lies inside the bounds the diagnosis states for the chosen fit
    (step 7; a side without a bound is open). None: the effect was not chosen."""
    _, truth = hidden_effect(case, magnitude)
    if not any(c["effect"] == case and c["verdict"] == "accepted" for c in diagnosis["candidates"]):
        return None
    c = chosen_fit(diagnosis, case)
    if c is None:  # a gap at another joint
        return False
    bounds = c.get("bounds", {})
    for suffix, value in truth.items():
        found = [b for k, b in bounds.items() if k.split(".")[-1] == suffix]
        if not found:
            return False
        lower = found[0]["lower"] if found[0]["lower"] is not None else -math.inf
        upper = found[0]["upper"] if found[0]["upper"] is not None else math.inf
        if not lower <= value <= upper:
            return False
    return True


def error_goal(diagnosis, ratio=1.25, scatter_floor_ratio=1.0):
    """The goal's error part: the error after at most a third of the error before, or at most the
    level at which the loop calls a fit explained (ratio x the noise and the simulation's scatter,
    the scatter counted up to scatter_floor_ratio x the noise: demcal's defaults)."""
    def rms(values):
        v = [x for x in values if x is not None and math.isfinite(x)]
        return math.sqrt(sum(x * x for x in v) / len(v)) if v else 0.0
    noise, scatter = rms(diagnosis["noise"].values()), rms(diagnosis.get("scatter", {}).values())
    floor = math.hypot(noise, min(scatter, scatter_floor_ratio * noise))
    before, after = diagnosis["error_before"], diagnosis["error_after"]
    return after <= before / 3 or after <= ratio * floor


def summarise(rows):
    table = ["| hidden effect | seeds | right verdict | effect named (seeds) | parameters within 25 % | "
             "truth within the stated bounds | error 3 x lower or at the floor | all three parts of the goal | "
             "error before / after (median, N) | after / before | noise (median, N) | simulations (median) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    by_case = {}
    for r in rows:
        by_case.setdefault(r["case"], []).append(r)
    for case, rs in by_case.items():
        def median(key):
            v = sorted(x[key] for x in rs if x[key] is not None and math.isfinite(x[key]))
            return v[len(v) // 2] if v else float("nan")
        right = sum(1 for r in rs if r["right"])
        within = sum(1 for r in rs if r["recovery"] is not None and r["recovery"] <= 0.25)
        named = ", ".join("/".join(r["chosen"]) or "none" for r in rs)
        in_bounds = sum(1 for r in rs if r["right"] and r.get("bounded"))
        error_met = sum(1 for r in rs if r["right"] and r.get("error_goal"))
        goal = sum(1 for r in rs if r["right"] and (case == "none" or (r.get("bounded") and r.get("error_goal"))))
        count = lambda n: "-" if case == "none" else "%d/%d" % (n, len(rs))
        table.append("| %s | %d | **%d/%d** | %s | %s | %s | %s | **%d/%d** | %.0f / %.0f | %.2f | %.0f | %.0f |" % (
            case, len(rs), right, len(rs), named, count(within), count(in_bounds), count(error_met), goal, len(rs),
            median("before"), median("after"), median("ratio"), median("noise"), median("simulations")))
    return "\n".join(table)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("binary")
    p.add_argument("out")
    p.add_argument("--cases", default=",".join(CASES))
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--first-seed", type=int, default=1, help="noise seeds first-seed .. first-seed + seeds - 1")
    p.add_argument("--velocity", type=float, default=0.001)
    p.add_argument("--contacts-per-joint", type=int, default=5)
    p.add_argument("--max-displacement", type=float, default=0.008)
    p.add_argument("--candidate-simulations", type=int, default=80)
    p.add_argument("--effects", default="all", help="effects the diagnosis considers")
    p.add_argument("--fit-abutment", action="store_true",
                   help="fit the abutment gauge's channel too (default: weight 0, a check on data not fitted)")
    p.add_argument("--window", default="common", choices=["common", "measured"],
                   help="the objective's displacement window per channel (docs/smoothing.md)")
    p.add_argument("--surrogate-kind", default="", help="the searches' surrogate (gp | mlp; default: demcal's)")
    p.add_argument("--magnitude", type=float, default=1.0,
                   help="strength of the hidden effects, x the study's default (detection limits; > 0)")
    p.add_argument("--every", type=int, default=5,
                   help="one simulated row in N kept as a measured row (1: the simulation's own sampling)")
    p.add_argument("--match-sampling", action="store_true",
                   help="the campaign's simulation recorded at the measurement's rate (record_interval)")
    p.add_argument("--kn-upper", type=float, default=1e10,
                   help="top of the campaign's kn range (Pa/m; the base fit of stiffening joints presses against it)")
    p.add_argument("--candidates", type=int, default=0,
                   help="effects each diagnosis calibrates, best signatures first (0: demcal's default)")
    p.add_argument("--jobs", type=int, default=1)
    args = p.parse_args()
    if not args.magnitude > 0:
        p.error("--magnitude must be > 0, got %r" % args.magnitude)
    binary = os.path.abspath(args.binary)
    cases = [c for c in args.cases.split(",") if c]
    for c in cases:
        if c not in CASES:
            p.error("unknown case %r (known: %s)" % (c, ", ".join(CASES)))
    work = [(c, s) for c in cases for s in range(args.first_seed, args.first_seed + args.seeds)]
    rows = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {pool.submit(run_one, binary, args, c, s): (c, s) for c, s in work}
        for future in concurrent.futures.as_completed(futures):
            case, seed = futures[future]
            try:
                d = future.result()
            except subprocess.CalledProcessError as e:
                print("%s seed %d: failed (%s)" % (case, seed, e), file=sys.stderr)
                continue
            chosen = d["chosen"]
            right = chosen == ([] if case == "none" else [case]) and (case == "none" or chosen_fit(d, case) is not None)
            before, after = d["error_before"], d["error_after"]
            noise = math.sqrt(sum(v * v for v in d["noise"].values()) / max(1, len(d["noise"])))
            rows.append({"case": case, "seed": seed, "chosen": chosen, "right": right,
                         "recovery": recovered(d, case, args.magnitude), "bounded": bounded(d, case, args.magnitude),
                         "error_goal": error_goal(d), "before": before, "after": after,
                         "ratio": after / before if before else float("nan"), "noise": noise,
                         "simulations": d["simulations"], "verdict": d["verdict"]})
            print("%s seed %d: chosen %s, error %.0f -> %.0f N" % (case, seed, chosen or "none", before, after),
                  file=sys.stderr)
    rows.sort(key=lambda r: (cases.index(r["case"]), r["seed"]))
    with open(os.path.join(args.out, "study.json"), "w") as f:
        json.dump({"settings": vars(args), "rows": rows}, f, indent=2)
    print(summarise(rows))


if __name__ == "__main__":
    main()
