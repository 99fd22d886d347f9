#!/usr/bin/env python3
"""A stand-in for an external simulator (3DEC, UDEC, YADE ...), used by the pipelines tests.

usage: toy_simulator.py STIFFNESS FRICTION_DEG OUTPUT [--hang-above DEG] [--crash-above DEG]
                        [--noise AMPLITUDE_N --seed S]

Writes OUTPUT as CSV with columns force (N) and top_horizontal (m): a wall pushed sideways under a
10 kN vertical load, force = N tan(phi) (1 - exp(-k d / (N tan(phi)))) for d in [0, 10 mm].
--hang-above: sleeps (with a child process) instead when FRICTION_DEG exceeds the value.
--crash-above: dies of SIGSEGV instead when FRICTION_DEG exceeds the value.
With TOY_SIMULATOR_LOG set, appends 'STIFFNESS FRICTION_DEG' to that file after a finished run.
"""
import math
import os
import random
import signal
import subprocess
import sys
import time


def main(argv):
    args = list(argv[1:])
    options = {}
    while len(args) > 3 and args[-2].startswith("--"):
        options[args[-2]] = float(args[-1])
        args = args[:-2]
    k, phi, output = float(args[0]), float(args[1]), args[2]
    if "--hang-above" in options and phi > options["--hang-above"]:
        subprocess.Popen(["sleep", "1000"])
        time.sleep(1000)
    if "--crash-above" in options and phi > options["--crash-above"]:
        os.kill(os.getpid(), signal.SIGSEGV)
    rng = random.Random(int(options.get("--seed", 1)))
    noise = options.get("--noise", 0.0)
    normal = 10e3
    capacity = normal * math.tan(math.radians(phi))
    log = os.environ.get("TOY_SIMULATOR_LOG")
    with open(output, "w") as out:
        out.write("top_horizontal,force\n")
        for i in range(101):
            d = 0.01 * i / 100
            force = capacity * (1 - math.exp(-k * d / capacity)) + rng.gauss(0, noise) * (noise > 0)
            out.write("%.17g,%.17g\n" % (d, force))
    if log:
        with open(log, "a") as f:
            f.write("%r %r\n" % (k, phi))


if __name__ == "__main__":
    main(sys.argv)
