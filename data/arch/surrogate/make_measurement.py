#!/usr/bin/env python3
"""Makes the surrogate benchmark's synthetic measurement of the reference arch (measured.csv here).

usage: make_measurement.py DEMCAL_BINARY OUTPUT_CSV

Runs the demcal engine on the reference arch (defaults as published, the campaign's own loading
velocity) with parameters the benchmark campaigns are not told: kn = 2.6e9 Pa/m, ks = 0.9e9 Pa/m,
friction 32.3 deg. Keeps one row in 10 and adds Gaussian noise of 1.5 % of each column's largest
absolute value (seed 2026). Columns: load_vertical [mm], abutment_horizontal [mm], force [kN].
"""
import csv
import os
import random
import subprocess
import sys
import tempfile

TRUTH = {"kn": "2.6e9", "ks": "0.9e9", "friction": "32.3"}


def main(binary, output):
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "arch.json")
        subprocess.run([binary, "scene", "arch", "--kn", TRUTH["kn"], "--ks", TRUTH["ks"], "--friction-deg",
                        TRUTH["friction"], "-o", scene], check=True, stdout=subprocess.DEVNULL)
        subprocess.run([binary, "simulate", scene, "--out", os.path.join(tmp, "run")], check=True,
                       stdout=subprocess.DEVNULL)
        with open(os.path.join(tmp, "run", "curves.csv")) as f:
            rows = [r for r in csv.reader(f)]
    header = rows[0]
    data = [r for r in rows[1:] if r and not r[0].startswith("[")]
    col = {name.split(" ")[0]: i for i, name in enumerate(header)}
    names = [("load_vertical", 1e3), ("abutment_horizontal", 1e3), ("force", 1e-3)]  # SI -> mm, mm, kN
    kept = data[::10]
    scale = {n: max(abs(float(r[col[n]])) * f for r in kept) for n, f in names}
    rng = random.Random(2026)
    with open(output, "w") as out:
        out.write("load_vertical,abutment_horizontal,force\n[mm],[mm],[kN]\n")
        for row in kept:
            values = [float(row[col[n]]) * f + rng.gauss(0, 0.015 * scale[n]) for n, f in names]
            out.write("%.6f,%.6f,%.6f\n" % tuple(values))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
