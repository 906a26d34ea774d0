"""The dynamics' CG on 1 and 2 threads (docs/speed/parallel.md).

Runs ``main.py hanging --headless --no-images --frames N --resolution R`` with
``TI_CPU_MAX_NUM_THREADS`` 1 and 2, optimised kernels (LOOM_FAST_COMPILE=0), each setting
``--repeats`` times interleaved, and prints the medians over frames 2..N of ``metrics.csv``:
ms a frame (total, dynamics), CG iterations a frame, and ms per CG iteration (the dynamics'
median ms over the median iterations). For each setting the run with the lowest median
dynamics time is reported (the machine may be shared), the others listed beside it.

    python benchmarks/parallel_dynamics.py --res 23 46 91 --repeats 3
    git archive d8e013d | tar -x -C /tmp/base     # then, today's code against that commit:
    python benchmarks/parallel_dynamics.py --root . /tmp/base
"""
import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(res, threads, frames, out, extra_env=None, root=ROOT):
    env = dict(os.environ, TI_CPU_MAX_NUM_THREADS=str(threads), LOOM_FAST_COMPILE="0")
    env.update(extra_env or {})
    subprocess.run([sys.executable, os.path.join(root, "main.py"), "hanging", "--headless",
                    "--no-images", "--quiet", "--frames", str(frames), "--resolution",
                    str(res), "--out", out], env=env, check=True, cwd=root,
                   stdout=subprocess.DEVNULL)
    with open(os.path.join(out, "metrics.csv")) as fh:
        rows = [r for r in csv.DictReader(fh) if int(r["frame"]) >= 2]
    med = lambda k: statistics.median(float(r[k]) for r in rows)  # noqa: E731
    return dict(faces=int(rows[-1]["faces"]), total=med("ms_total"), dyn=med("ms_dynamics"),
                sl=med("ms_strain_limit"), iters=med("cg_iterations"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, nargs="+", default=[23, 46, 91])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--root", nargs="+", default=[ROOT],
                    help="checkouts to run (e.g. an older commit's `git archive` beside this one)")
    args = ap.parse_args()
    with open("/proc/loadavg") as fh:
        print("# load before:", fh.read().strip())
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(args.repeats):
            for res in args.res:
                for th in args.threads:
                    for ri, root in enumerate(args.root):
                        out = os.path.join(tmp, f"{res}_{th}_{rep}_{ri}")
                        r = run(res, th, args.frames, out, root=root)
                        results.setdefault((ri, res, th), []).append(r)
                        print(f"# {root} res {res} threads {th} run {rep}: total "
                              f"{r['total']:.1f} dynamics {r['dyn']:.1f} strain {r['sl']:.1f} "
                              f"cg {r['iters']:.0f}", flush=True)
    with open("/proc/loadavg") as fh:
        print("# load after:", fh.read().strip())
    print("| code | triangles | threads | ms a frame | dynamics ms | CG iterations "
          "| ms / CG iteration | dynamics, every run |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for (ri, res, th), runs in sorted(results.items(), key=lambda kv: kv[0][1:] + kv[0][:1]):
        best = min(runs, key=lambda r: r["dyn"])
        print(f"| {args.root[ri]} | {best['faces']:,} | {th} | {best['total']:.1f} | "
              f"{best['dyn']:.1f} | "
              f"{best['iters']:.0f} | {best['dyn'] / max(best['iters'], 1):.3f} | "
              + ", ".join(f"{r['dyn']:.1f}" for r in runs) + " |")


if __name__ == "__main__":
    main()
