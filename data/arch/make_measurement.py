#!/usr/bin/env python3
"""Makes the bundled synthetic measurement of the reference arch (data/arch/measured.csv).

usage: make_measurement.py DEMCAL_BINARY OUTPUT_CSV

Runs the demcal engine on the reference arch with parameters the demo campaign is not told
(kn = 3.2e9 Pa/m, ks = 2.1e9 Pa/m, friction 30.2 deg) and an effect it is not told either (loading
at 5 mm/s instead of the campaign's 10 mm/s), keeps one row in 10, and adds Gaussian noise
(20 N on the force, 2 um on each displacement; seed 2024). Columns: load_vertical [mm],
abutment_horizontal [mm], force [kN] (the campaign maps them to SI).
"""
import csv
import os
import random
import subprocess
import sys
import tempfile


def main(binary, output):
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "arch.json")
        subprocess.run([binary, "scene", "arch", "--kn", "3.2e9", "--ks", "2.1e9", "--friction-deg", "30.2",
                        "--velocity", "0.005", "-o", scene], check=True, stdout=subprocess.DEVNULL)
        subprocess.run([binary, "simulate", scene, "--out", os.path.join(tmp, "run")], check=True,
                       stdout=subprocess.DEVNULL)
        with open(os.path.join(tmp, "run", "curves.csv")) as f:
            rows = [r for r in csv.reader(f)]
    header = rows[0]
    data = [r for r in rows[1:] if r and not r[0].startswith("[")]
    col = {name.split(" ")[0]: i for i, name in enumerate(header)}
    rng = random.Random(2024)
    with open(output, "w") as out:
        out.write("load_vertical,abutment_horizontal,force\n[mm],[mm],[kN]\n")
        for row in data[::10]:
            v = float(row[col["load_vertical"]]) * 1e3 + rng.gauss(0, 0.002)
            h = float(row[col["abutment_horizontal"]]) * 1e3 + rng.gauss(0, 0.002)
            force = float(row[col["force"]]) / 1e3 + rng.gauss(0, 0.02)
            out.write("%.6f,%.6f,%.6f\n" % (v, h, force))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
