#!/usr/bin/env python3
"""How far each scene's automatic time step is from the first step at which the run fails.

For every scene (a `demcal scene` command line, or a scene file), the scene runs once with its
automatic step, then with fixed steps of FACTOR x that automatic step (the step at the end of the
automatic run, `time_step` in summary.json). A run fails when its status is not the automatic run's
(a loaded run that stops short of its target travel, a self-weight run that finds no equilibrium,
a block that becomes unstable or collapses). The table gives each factor's status and peak force,
and the margin: the smallest failing factor.

usage: time_step_margin.py DEMCAL [--scene "arch --velocity 0.01" ...] [--scene-file FILE ...]
                           [--factors 1.5,2,2.5,3,4] [--faces in_contact|all] [--out DIR] [--jobs 2]
"""
import argparse
import concurrent.futures
import os
import shlex
import subprocess
import sys
import tempfile

from engine_equivalence import simulate_scene


def simulate(binary, scene_file, time_step, faces, out_dir):
    """Runs `binary simulate` with the given fixed step (0: automatic); returns summary.json."""
    solver = {"time_step": time_step}
    if faces:
        solver["time_step_faces"] = faces
    return simulate_scene(binary, scene_file, solver, out_dir)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("binary")
    parser.add_argument("--scene", action="append", default=[], help="`demcal scene` subcommand and flags")
    parser.add_argument("--scene-file", action="append", default=[], help="a scene JSON file")
    parser.add_argument("--factors", default="1.5,2,2.5,3,4")
    parser.add_argument("--faces", default="", help="the scenes' solver.time_step_faces (default: as written)")
    parser.add_argument("--out", default=None)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    factors = [float(f) for f in args.factors.split(",")]
    if not args.scene and not args.scene_file:
        parser.error("give at least one --scene or --scene-file")

    out = args.out or tempfile.mkdtemp(prefix="time-step-margin-")
    os.makedirs(out, exist_ok=True)
    scenes = []
    for i, flags in enumerate(args.scene):
        path = os.path.join(out, f"scene{i}.json")
        made = subprocess.run([args.binary, "scene", *shlex.split(flags), "-o", path], capture_output=True, text=True)
        if made.returncode != 0:
            sys.exit(f"demcal scene {flags} failed: {made.stderr.strip()}")
        scenes.append((flags, path))
    scenes += [(os.path.basename(p), p) for p in args.scene_file]

    print("| scene | automatic step (s), status, peak (N) | " + " | ".join(f"{f:g} x" for f in factors) +
          " | first failing factor |")
    print("|---|---|" + "---|" * len(factors) + "---|")
    for i, (name, path) in enumerate(scenes):
        auto = simulate(args.binary, path, 0, args.faces, os.path.join(out, f"s{i}-auto"))
        step = auto["time_step"]
        with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = list(pool.map(lambda f: simulate(args.binary, path, f * step, args.faces, os.path.join(out, f"s{i}-x{f:g}")),
                                 factors))
        failing = [f for f, r in zip(factors, runs) if r["status"] != auto["status"]]
        cells = [f"{r['status']}, {r['peak_force']:.0f}" for r in runs]
        margin = f"{min(failing):g}" if failing else f"none up to {max(factors):g}"
        print(f"| `{name}` | {step:.4g}, {auto['status']}, {auto['peak_force']:.0f} | " + " | ".join(cells) +
              f" | {margin} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
