"""How far the drape scene's sheet falls around the sphere, per strain solve: does the
constrained step's inexactness hold the cloth back?

    python -m benchmarks.drape_depth --out docs/speed     # ~3 min -> drape_depth.md / .json
    python -m benchmarks.drape_depth --probe max_newton=20 cg_rtol=0.01   # one row, JSON

The default drape (soft cloth, mapping +-1 % / +-5 %, coupling "implicit", 25 x 25 vertices)
runs 30 frames. The measure is the lowest vertex height at frames 10, 20 and 30: the sphere
spans y = 0.25 ... 0.85 m, with its equator at 0.55.

Each run varies the strain solve's Newton steps:
- the default per-method PCG budget (``CG_BUDGET`` in cloth/strain/solver.py);
- larger PCG budgets (``StrainLimiter.max_cg``);
- exact steps from a sparse Cholesky factorisation (``strain.linear_solver = "cholesky"``).

A solve that stops before the minimiser keeps x near where it started, and acts like extra
damping. Once the cloth stops sliding, friction holds it where it is, so the difference
persists. Each configuration runs in its own process.
"""
import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAMES = (10, 20, 30)
# (bending, Newton solve): "default", a PCG budget, or "cholesky".
PLAN = [(b, s) for b in ("isotropic", "hinge") for s in ("default", 50, 200, "cholesky")]


def child(bending, solve, overrides=None):
    """One run; ``overrides``: StrainLimiter attributes set after the build (a probe)."""
    from cloth import backend
    backend.init("cpu", "f64")
    import numpy as np
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    mod = scenes.get("drape")
    cfg = resolve(mod.DEFAULTS, [{"sim": {"bending": bending}}])
    sim = Simulator(mod.build(cfg), cfg)
    if solve == "cholesky":
        sim.strain.linear_solver = "cholesky"
    elif solve != "default":
        sim.strain.max_cg = int(solve)
    for key, value in (overrides or {}).items():
        if not hasattr(sim.strain, key):
            raise SystemExit(f"--probe: StrainLimiter has no setting '{key}'")
        setattr(sim.strain, key, value)
    sim.strain._upload_params()
    lowest, ms = [], []
    for frame in range(1, FRAMES[-1] + 1):
        sim.step_frame()
        ms.append(sim.stage("strain_limit").ms)
        if frame in FRAMES:
            lowest.append(float(sim.model.positions()[:, 1].min()))
    return dict(bending=bending, solve=str(solve), overrides=overrides or {}, lowest=lowest,
                sl_ms_median=float(np.median(ms[1:])), faces=sim.model.n_faces)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "speed"))
    ap.add_argument("--child")
    ap.add_argument("--probe", nargs="*", metavar="ATTR=JSON",
                    help="one run of the default drape with these StrainLimiter attributes")
    ap.add_argument("--bending", default="isotropic", choices=("isotropic", "hinge"))
    a = ap.parse_args()
    if a.probe is not None:
        overrides = {k: json.loads(v) for k, _, v in (item.partition("=") for item in a.probe)}
        print(json.dumps(child(a.bending, "default", overrides)))
        return
    if a.child:
        print(json.dumps(child(*json.loads(a.child))))
        return
    from benchmarks.harness import commit, machine
    t0, rows = time.time(), []
    for i, args in enumerate(PLAN):
        print(f"[{i + 1}/{len(PLAN)}] {args} ({time.time() - t0:.0f} s)", file=sys.stderr,
              flush=True)
        out = subprocess.run([sys.executable, "-m", "benchmarks.drape_depth", "--child",
                              json.dumps(args)], capture_output=True, text=True, cwd=ROOT)
        if out.returncode != 0:
            rows.append(dict(bending=args[0], solve=str(args[1]), error=out.stderr[-300:]))
        else:
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "drape_depth.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    L = ["# Drape depth against the strain solve's exactness\n",
         f"Command: `python -m benchmarks.drape_depth` ({time.time() - t0:.0f} s). Machine: "
         f"{machine()}; commit {commit()}. The default drape scene, 30 frames; lowest vertex "
         "height (m) at frames 10 / 20 / 30 (sphere: y = 0.25 ... 0.85, equator 0.55), and "
         "the median strain-limiting ms per frame. Solve: the Newton steps of the AL "
         "projection, by PCG with the default per-method budget or a larger one "
         "(`StrainLimiter.max_cg`), or exact (`strain.linear_solver = \"cholesky\"`).\n",
         "| bending | solve | lowest y, frame 10 | frame 20 | frame 30 | SL ms/frame |",
         "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        if "error" in r:
            L.append(f"| {r['bending']} | {r['solve']} | error: {r['error'][-80:]} | | | |")
            continue
        L.append(f"| {r['bending']} | {r['solve']} | " + " | ".join(
            f"{v:.3f}" for v in r["lowest"]) + f" | {r['sl_ms_median']:.1f} |")
    L.append("")
    with open(os.path.join(a.out, "drape_depth.md"), "w") as fh:
        fh.write("\n".join(L))
    print(f"wrote {os.path.join(a.out, 'drape_depth.md')}")


if __name__ == "__main__":
    main()
