"""The same sheet under the three methods with a fabric's derived bands (docs/fabrics.md): a
scene run headless once per method (svd, warp-weft, mapping) with ``--fabric``, coloured by
the binding constraint, with the strain-space plot; the last frame of each is copied to
OUT/SCENE_FABRIC_METHOD.png and the frame's strains are printed as a table.

    python -m benchmarks.fabric_methods                                  # pull, cotton-shirting
    python -m benchmarks.fabric_methods --scene pull --fabric denim --frames 120 --out DIR

Each run is ``python main.py SCENE --fabric FABRIC --method M --headless --frames N
--overlay plot --color binding --set output.every=N`` (its output in RUNS/M/, default out/fabric_methods/M/).
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys

METHODS = ("svd", "warp-weft", "mapping")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def command(scene, fabric, method, frames, out):
    return [sys.executable, os.path.join(ROOT, "main.py"), scene, "--fabric", fabric,
            "--method", method, "--headless", "--frames", str(frames), "--overlay", "plot",
            "--color", "binding", "--set", f"output.every={frames}", "--out", out]


def last_row(out):
    with open(os.path.join(out, "metrics.csv")) as fh:
        return list(csv.DictReader(fh))[-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="pull")
    ap.add_argument("--fabric", default="cotton-shirting")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--methods", nargs="*", default=list(METHODS))
    ap.add_argument("--out", default=os.path.join("docs", "fabrics"))
    ap.add_argument("--runs", default=os.path.join("out", "fabric_methods"),
                    help="where the runs write their output (one directory per method)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = ["| method | final check | warp strain max (%) | weft strain max (%) | bias strain "
            "max (%) | own violation max | total energy (J) |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for m in a.methods:
        run_dir = os.path.join(a.runs, m)
        p = subprocess.run(command(a.scene, a.fabric, m, a.frames, run_dir), cwd=ROOT,
                           capture_output=True, text=True)
        check = next((line.split("final check: ", 1)[1] for line in p.stdout.splitlines()
                      if "final check: " in line), f"exit {p.returncode}")
        frame = os.path.join(run_dir, "frames", f"frame_{a.frames:04d}.png")
        dest = os.path.join(a.out, f"{a.scene}_{a.fabric}_{m}.png")
        shutil.copyfile(frame, dest)
        r = last_row(run_dir)
        rows.append(f"| {m} | {check} | {100 * float(r['warp_strain_max']):.3g} | "
                    f"{100 * float(r['weft_strain_max']):.3g} | "
                    f"{100 * float(r['bias_strain_max']):.3g} | "
                    f"{float(r['own_violation_max']):.2g} | {float(r['total_energy']):.4g} |")
        print(f"wrote {dest}", flush=True)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
