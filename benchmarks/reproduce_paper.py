"""Reproduce the paper's experiments as numbers and pictures.

    python -m benchmarks.reproduce_paper --table 1 --resolution 25 --out docs/table1
    python -m benchmarks.reproduce_paper --table 1 --quick --out /tmp/t1   # coarse smoke test
    python -m benchmarks.reproduce_paper --table 1 --remesh --out docs/table1_remesh
    python -m benchmarks.reproduce_paper --table 2 --frames 90 --seeds 3 --out docs/table2

Table 1 (paper section 6): the cloth hanging from its two top corners at rest, for the three
methods x two band settings (vertical +-1 % / horizontal +-5 %, and swapped); the warp hangs
vertically. Writes ``table1.md`` (strain distributions, violations, wrinkle measures, size,
time), ``table1.json`` and ``table1.png`` (shaded and warp-strain images from one camera).
Table 2: the T-shirt at rest under three settings (``benchmarks/table2.py``): ``table2.md``,
``table2.json``, ``table2.png``. Each table's runs are a sweep (``benchmarks.sweep``: a local
cluster, one worker process per core, or ``--scheduler tcp://HOST:PORT``; cached in
--out/table1_runs/ or table2_runs/); the pictures are drawn here from the runs' final meshes.
"""
import argparse
import os
import time


from benchmarks.paper_common import (BANDS, METHODS, label, measure,  # noqa: F401
                                     render_pair, settle)


def table1_overrides(res, frames, band_name, method, remesh=False):
    ov = {"cloth": {"resolution": res}, "sim": {"frames": frames},
          "strain": dict(method=method, **BANDS[band_name])}
    if remesh:
        ov["remesh"] = {"enabled": True}
    return ov


def table1_run(res, frames, band_name, method, remesh=False):
    """One cell of Table 1 (in a sweep's worker): the hanging cloth settled, its measures and
    its final mesh (positions; with remeshing also the mesh's own uv, faces, grain and pins)
    for the picture."""
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    sim, ms, late_viol = settle(scenes.get("hanging"),
                                [table1_overrides(res, frames, band_name, method, remesh)],
                                frames)
    r = measure(sim)
    m = sim.model
    r.update(method=method, bands=band_name, ms_per_frame=ms, late_violation=late_viol,
             faces=int(m.n_faces), x=m.positions().tolist(),
             remeshes=int(sim.remeshes_applied))
    if remesh:
        r.update(uv=m.uv.tolist(), tri=m.faces.tolist(), grain=m.grain.tolist(),
                 pinned=m.pinned.tolist())
    return r


def table1_picture(renderer, res, frames, r, remesh=False):
    """The shaded and warp-strain pair of a run's final state: a Simulator built here on the
    run's mesh (remeshed: the mesh it returned), its positions set, not stepped."""
    import numpy as np
    import scenes
    from cloth.model import MeshArrays
    from cloth.simulator import Simulator
    from scenes.common import resolve
    module = scenes.get("hanging")
    cfg = resolve(module.DEFAULTS, [table1_overrides(res, frames, r["bands"], r["method"])])
    setup = module.build(cfg)
    x = np.asarray(r["x"])
    if remesh:
        setup.mesh = MeshArrays(uv=np.asarray(r["uv"]), x=x, faces=np.asarray(r["tri"]),
                                pinned=np.asarray(r["pinned"], bool),
                                grain=np.asarray(r["grain"]))
    sim = Simulator(setup, cfg)
    sim.model.set_positions(x)
    return render_pair(renderer, sim)


def table1(args):
    import numpy as np
    from benchmarks.sweep import Run, failed_lines, run_sweep
    res = 13 if args.quick else args.resolution
    frames = 40 if args.quick else args.frames
    plan = [(res, frames, band_name, method, bool(args.remesh))
            for band_name in BANDS for method in METHODS]
    sweep = [Run("benchmarks.reproduce_paper:table1_run", list(p), f"{p[2]} {p[3]}",
                 scene=("hanging", table1_overrides(*p))) for p in plan]
    results = run_sweep(sweep, os.path.join(args.out, "table1_runs"), args.scheduler,
                        args.workers, args.fresh, name="table1")
    renderer = None
    if not args.no_images:
        from ui.render import ClothRenderer, open_window
        window = open_window("table1", (400, 400), show_window=False)
        renderer = ClothRenderer(window, {"position": [0.0, 1.4, 2.9], "lookat": [0.0, 1.42, 0.0]})
    rows, tiles = [], {}
    for r in results:
        if "error" in r:
            continue
        if renderer is not None:
            tiles[(r["bands"], r["method"])] = label(
                table1_picture(renderer, res, frames, r, args.remesh),
                f"{r['method']}  {r['bands']}")
        for k in ("x", "uv", "tri", "grain", "pinned", "wall_s", "worker"):
            r.pop(k, None)
        rows.append(r)
        print(f"{r['bands']} {r['method']:9s} warp max {r['warp_max']:.4f} weft max "
              f"{r['weft_max']:.4f} viol {r['own_violation_max']:.2e} "
              f"{r['ms_per_frame']:.1f} ms/frame", flush=True)
    if not rows:
        raise SystemExit("table1: every run failed: " + results[0]["error"][-600:])
    os.makedirs(args.out, exist_ok=True)
    write_table1_md(rows, os.path.join(args.out, "table1.md"), res, frames, args.remesh,
                    args.cmd, time.time() - args.t0, failed_lines(sweep, results))
    if len(tiles) == len(plan):
        import imageio.v2 as imageio
        grid = np.concatenate([np.concatenate([tiles[(b, m)] for m in METHODS], axis=1)
                               for b in BANDS], axis=0)
        imageio.imwrite(os.path.join(args.out, "table1.png"), grid)
    return rows


def write_table1_md(rows, path, res, frames, remeshed=False, cmd=None, seconds=None,
                    failed=()):
    from benchmarks.harness import header, write_json
    cmd = cmd or "python -m benchmarks.reproduce_paper --table 1"
    write_json(os.path.dirname(path) or ".", "table1", {"rows": rows}, cmd, seconds)
    cols = [("bands", "bands"), ("method", "method"), ("warp_max", "warp max"),
            ("warp_rms", "warp RMS"), ("warp_p95", "warp p95"), ("weft_max", "weft max"),
            ("weft_rms", "weft RMS"), ("weft_p95", "weft p95"), ("bias_max", "|bias| max"),
            ("own_violation_max", "own viol. max"), ("mean_abs_dihedral", "mean |dihedral| (rad)"),
            ("curvature_energy", "curv. energy"), ("height", "height (m)"), ("width", "width (m)"),
            ("ms_per_frame", "ms/frame"), ("sl_iterations", "SL rounds")]
    if remeshed:
        cols.insert(2, ("faces", "triangles"))
        cols.insert(3, ("remeshes", "remeshes applied"))
    size = ("remeshed at the default sizes from a grid of "
            f"{res} x {res} vertices; triangles at the end in the table" if remeshed
            else f"{rows[0]['faces']} triangles")
    lines = [f"# Paper Table 1: hanging cloth at rest ({size}, "
             f"{frames} frames at 30 fps, one substep)", "", header(cmd, seconds), "",
             "Strains are stretch - 1; V1H5 = warp (vertical) +-1 %, weft (horizontal) +-5 %."
             + (" The paper remeshes every frame; Loom computes a remesh every frame and "
                "applies it when it changes enough of the mesh (`remesh.defer_ops`: more "
                "operations than 5 % of the faces, or after `remesh.defer_frames` = 4 frames "
                "deferred), in the frames counted under *remeshes applied*."
                if remeshed else ""), "",
             "| " + " | ".join(c[1] for c in cols) + " |",
             "|" + "---|" * len(cols)]
    for r in rows:
        cells = []
        for key, _ in cols:
            v = r[key]
            cells.append(f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    lines += list(failed)
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", type=int, choices=[1, 2], required=True)
    ap.add_argument("--out", default=None)
    ap.add_argument("--resolution", type=int, default=31)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-images", action="store_true")
    ap.add_argument("--remesh", action="store_true",
                    help="remesh (the scene's default sizes), as the paper: Table 1's sheet or "
                         "Table 2's shirt")
    ap.add_argument("--seeds", type=int, default=1,
                    help="Table 2: runs per setting; runs after the first start from positions "
                         "perturbed by 1 micrometre, to show how much the measures move by chance")
    ap.add_argument("--edge", type=float, default=None,
                    help="Table 2: the shirt's material edge length in m (default: the shipped "
                         "mesh, 3 cm, 2,385 triangles; 1.5 cm gives 9,548)")
    from benchmarks.sweep import add_arguments
    add_arguments(ap)           # each table's runs are a sweep (docs/sweeps.md)
    args = ap.parse_args(argv)
    args.out = args.out or os.path.join("results", f"table{args.table}")
    from benchmarks.harness import command
    args.cmd, args.t0 = command("benchmarks.reproduce_paper", argv), time.time()
    from cloth import backend
    backend.init("cpu", "f64")
    if args.table == 1:
        table1(args)
    else:
        from benchmarks.table2 import table2
        table2(args)
    print(f"wrote {args.out}/")


if __name__ == "__main__":
    main()
