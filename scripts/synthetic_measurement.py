#!/usr/bin/env python3
"""Makes a synthetic "measurement" with the demcal engine: a scene made by `demcal scene`, with
parameters and effects the calibration is not told, thinned and with Gaussian noise.

usage: synthetic_measurement.py DEMCAL_BINARY OUTPUT_CSV [--seed S] [--force-noise R]
                                [--displacement-noise M] [--every N] [--param NAME=VALUE ...]
                                -- SCENE_ARGS...

SCENE_ARGS go to `demcal scene` as they are (e.g. `arch --support-kx 3e7 --velocity 0.005`).
--param sets a joint-group field of the generated scene afterwards, as a campaign's parameter
does (`kn=2.6e9` every group, `arch_joints.kn=2.6e9` one group): give kn, ks and friction_deg this
way, not as scene flags, because the generator derives the actuator's stiffness from its --kn and a
calibration changes kn on the generated scene (the two would differ in the loading device).
Noise: Gaussian, standard deviation R x the peak force on the force (default 0.015) and M metres
on every displacement (default 2e-6); one row in N kept (default 5). Columns in SI with a units
row: every displacement gauge [m], force [N].
"""
import argparse
import csv
import json
import os
import random
import subprocess
import sys
import tempfile


def main():
    argv = sys.argv[1:]
    scene_args = argv[argv.index("--") + 1:] if "--" in argv else []
    own = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("binary")
    p.add_argument("output")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--force-noise", type=float, default=0.015)
    p.add_argument("--displacement-noise", type=float, default=2e-6)
    p.add_argument("--every", type=int, default=5)
    p.add_argument("--param", action="append", default=[], help="NAME=VALUE on the joint groups")
    a = p.parse_args(own)
    if not scene_args:
        p.error("give the scene after --, e.g. -- arch --support-kx 3e7")
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "scene.json")
        subprocess.run([a.binary, "scene", *scene_args, "-o", scene], check=True, stdout=subprocess.DEVNULL)
        with open(scene) as f:
            description = json.load(f)
        for item in a.param:
            name, value = item.split("=", 1)
            group, _, field = name.rpartition(".")
            groups = [group] if group else list(description["joint_groups"])
            for g in groups:
                description["joint_groups"][g][field] = float(value)
        with open(scene, "w") as f:
            json.dump(description, f)
        subprocess.run([a.binary, "simulate", scene, "--out", os.path.join(tmp, "run")], check=True,
                       stdout=subprocess.DEVNULL)
        with open(os.path.join(tmp, "run", "curves.csv")) as f:
            rows = [r for r in csv.reader(f)]
    header = [name.split(" ")[0] for name in rows[0]]
    data = [r for r in rows[1:] if r and not r[0].startswith("[")]
    force = header.index("force")
    gauges = [i for i, name in enumerate(header) if name not in ("time", "force")]
    peak = max(float(r[force]) for r in data)
    rng = random.Random(a.seed)
    with open(a.output, "w") as out:
        out.write(",".join([header[i] for i in gauges] + ["force"]) + "\n")
        out.write(",".join(["[m]"] * len(gauges) + ["[N]"]) + "\n")
        for r in data[::a.every]:
            values = [float(r[i]) + rng.gauss(0, a.displacement_noise) for i in gauges]
            values.append(float(r[force]) + rng.gauss(0, a.force_noise * peak))
            out.write(",".join("%.9g" % v for v in values) + "\n")


if __name__ == "__main__":
    main()
