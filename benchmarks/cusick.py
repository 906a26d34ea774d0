"""The Cusick drape of the fabric records (docs/fabrics.md): ISO 9073-9 / BS 5058 geometry, a
disk of cloth 30 cm across held between two disks 18 cm across, left to hang.

    python -m benchmarks.cusick --out /tmp/cusick                    # every fabric, h = 1 cm
    python -m benchmarks.cusick --h 0.01 0.005 --starts 3 --out DIR  # mesh convergence
    python -m benchmarks.cusick --h 0.01 --edge-h 0.01               # a uniform mesh

The specimen is a Delaunay triangulation of a hexagonal lattice of spacing h inside the disk
(near-equilateral triangles: Loom's bending reads soft on stretched ones, docs/fabrics.md),
with rings of vertices on the rim and on the support's edge; within 2.5 cm of that edge (the
skirt's bending boundary layer) the spacing is ``--edge-h``, h/2 unless given (uniform 1 cm
triangles read the drape coefficient 0.03-0.045 low there, docs/fabrics.md). Every vertex
within the support (r <= 9 cm) is pinned, so the faces there are held flat: the clamp of the
drapemeter's two disks. Material and bands: the fabric's (cloth/fabrics.py,
``apply_fabric``), method ``--method`` (mapping). Each start moves every free vertex by up to
``k`` nm vertically (k = 0, 1, 2, ...; ``--amplitude``: docs/fabrics.md found 1 nm starts read
the same, 0.1 mm starts not), and a run stops once the RMS speed stays below 1 mm/s for 10
frames (not before 1.5 s) or after ``--seconds``. Drape coefficient, from the shadow (the
draped cloth projected on the horizontal plane, rasterised at 0.5 mm):
DC = (A_shadow - A_support) / (A_specimen - A_support); the median over the starts is the
reading, with the folds (local maxima of the rim's radius around the circle).

Each (fabric, h, start) is a run of a sweep (``benchmarks.sweep``: a local cluster, one worker
process per core, or ``--scheduler tcp://HOST:PORT``; cached in --out/cusick_runs/ or, without
--out, results/cusick_runs/; --fresh runs them again).
"""
import argparse
import os
import time

import numpy as np

R_SPECIMEN, R_SUPPORT = 0.15, 0.09       # m (ISO 9073-9: 30 cm specimen, 18 cm disks)
HEIGHT = 0.5                             # m: the support's height (nothing below it)
MIN_SECONDS = 1.5                        # s: no run stops before (a flat start is calm too)


EDGE_W = 0.025                           # m: the band beyond the support's edge ``edge_h`` meshes


def _lattice(h, R):
    n = int(np.ceil(R / h)) + 2
    i, j = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
    return np.c_[(i + 0.5 * (j % 2)).ravel() * h, j.ravel() * h * np.sqrt(3) / 2]


def disk_mesh(h, R=R_SPECIMEN, r_clamp=R_SUPPORT, edge_h=None):
    """(uv, faces): the specimen meshed at spacing ``h`` (see the module docstring); with
    ``edge_h`` < h, at spacing ``edge_h`` within ``EDGE_W`` of the support's edge and inside
    it (the skirt's bending boundary layer there, docs/fabrics.md), ``h`` beyond."""
    from scipy.spatial import Delaunay
    e = h if edge_h is None or edge_h >= h else edge_h
    cut = r_clamp + EDGE_W if e < h else 0.0
    parts = []
    for hh, inside in ((e, True), (h, False)) if e < h else ((h, False),):
        pts = _lattice(hh, R)
        r = np.linalg.norm(pts, axis=1)
        keep = (r < R - 0.5 * hh) & (np.abs(r - r_clamp) > 0.45 * e)
        if e < h:
            keep &= (r <= cut) if inside else (r > cut + 0.5 * hh)
        parts.append(pts[keep])
    for rr, hh in ((R, h), (r_clamp, e)):
        m = max(int(round(2 * np.pi * rr / hh)), 12)
        t = 2 * np.pi * np.arange(m) / m
        parts.append(rr * np.c_[np.cos(t), np.sin(t)])
    uv = np.concatenate(parts)
    faces = Delaunay(uv).simplices
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    faces[area < 0] = faces[area < 0][:, ::-1]
    faces = faces[np.abs(area) > 1e-6 * e * e]
    return uv, faces.astype(np.int32)


def shadow_area(x, faces, pixel=5e-4):
    """Area (m^2) of the union of the triangles projected on the x-z plane, rasterised."""
    P = x[:, [0, 2]]
    lo = P.min(axis=0) - pixel
    n = np.ceil((P.max(axis=0) + pixel - lo) / pixel).astype(int) + 1
    covered = np.zeros(n, bool)
    for f in faces:
        a, b, c = P[f]
        bl = np.floor((np.minimum(np.minimum(a, b), c) - lo) / pixel).astype(int)
        tr = np.ceil((np.maximum(np.maximum(a, b), c) - lo) / pixel).astype(int)
        gx, gy = np.meshgrid(np.arange(bl[0], tr[0] + 1), np.arange(bl[1], tr[1] + 1),
                             indexing="ij")
        q = np.stack([gx, gy], -1) * pixel + lo
        d = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if abs(d) < 1e-18:
            continue
        l1 = ((b[0] - q[..., 0]) * (c[1] - q[..., 1]) - (b[1] - q[..., 1]) * (c[0] - q[..., 0])) / d
        l2 = ((c[0] - q[..., 0]) * (a[1] - q[..., 1]) - (c[1] - q[..., 1]) * (a[0] - q[..., 0])) / d
        inside = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
        covered[gx[inside], gy[inside]] = True
    return covered.sum() * pixel * pixel


def folds(x, uv, R=R_SPECIMEN):
    """Number of folds: local maxima of the rim's projected radius around the circle
    (smoothed over 3 rim vertices, maxima at least 10 % of the radius range prominent)."""
    rim = np.flatnonzero(np.abs(np.linalg.norm(uv, axis=1) - R) < 1e-9)
    rim = rim[np.argsort(np.arctan2(uv[rim, 1], uv[rim, 0]))]
    rad = np.linalg.norm(x[rim][:, [0, 2]], axis=1)
    rad = (np.roll(rad, 1) + rad + np.roll(rad, -1)) / 3
    span = rad.max() - rad.min()
    peak = (rad > np.roll(rad, 1)) & (rad >= np.roll(rad, -1))
    # prominence: above the mean by 10 % of the range
    return int(np.sum(peak & (rad > rad.mean() + 0.1 * span)))


def strain_summary(x, uv, faces, h):
    """Over the skirt's faces (outside the support): the 5th percentile of the smaller principal
    strain, the 95th of the larger, and the area change (area-weighted)."""
    from cloth import metrics
    F = metrics.deformation_gradients(x, faces, metrics.material_Dm_inv(uv, faces))
    s = metrics.principal_stretches(F)[0]
    skirt = np.linalg.norm(uv[faces].mean(axis=1), axis=1) > R_SUPPORT + h
    e = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
    a = np.abs(e[0][:, 0] * e[1][:, 1] - e[0][:, 1] * e[1][:, 0])[skirt]
    return dict(eps_lo=float(np.percentile(s[skirt, 1] - 1, 5)),
                eps_hi=float(np.percentile(s[skirt, 0] - 1, 95)),
                area=float((a * s[skirt, 0] * s[skirt, 1]).sum() / a.sum() - 1))


def run(fabric, h=0.01, start=0, method="mapping", seconds=4.0, log=print, compression=None,
        scale=None, edge_h=None, amplitude=1e-9, turn=0.0, band_scale=(1.0, 1.0),
        solve="fast"):
    """One drape: returns dict(fabric, h, start, DC, folds, frames, seconds, faces, x (the
    final positions), eps_lo, eps_hi, area (``strain_summary``)).
    ``compression``: the bands' lower ends set to -compression (strain) instead of the
    fabric's mirror image of the upper ends. ``scale``: {"membrane", "shear", "bend"} factors on
    the fabric's k_warp and k_weft, k_shear, and bending rigidities (the sensitivity runs of
    docs/fabrics.md). ``edge_h``: ``disk_mesh``'s finer spacing at the support's edge.
    ``amplitude`` (m): a start's largest displacement per unit of ``start``; ``turn`` (deg): the
    mesh's lattice turned from the warp; ``band_scale``: factors on the warp and weft bands and
    on the bias band (the drape's locking runs); ``solve``: the strain projection's accuracy,
    ``strain.solve`` ("fast" or "exact") or "reference": the exact solve with every Newton
    step solved by sparse Cholesky (``StrainLimiter.set_host_loop``), the reading that depends
    on neither the fast solve's nor the kernels' PCG (docs/fabrics.md)."""
    from cloth import fabrics
    from cloth.model import MeshArrays
    from cloth.simulator import SceneSetup, Simulator
    from scenes.common import material_from, resolve, scene_defaults
    uv, faces = disk_mesh(h, edge_h=edge_h)
    c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
    uv = uv @ np.array([[c, s], [-s, c]])
    x = np.c_[uv[:, 0], np.full(len(uv), HEIGHT), uv[:, 1]]
    pinned = np.linalg.norm(uv, axis=1) <= R_SUPPORT + 1e-9
    if start:
        rng = np.random.default_rng(start)
        x[~pinned, 1] += start * amplitude * rng.uniform(-1.0, 1.0, (~pinned).sum())
    cfg = resolve(scene_defaults({"strain": {"method": method}}), [])
    cfg = fabrics.apply_fabric(cfg, fabric)
    cfg["strain"]["solve"] = "exact" if solve == "reference" else solve
    for key, names in (("membrane", ("k_warp", "k_weft")), ("shear", ("k_shear",)),
                       ("bend", ("k_bend", "k_bend_warp", "k_bend_weft"))):
        for k in names:
            if k in cfg["material"]:
                cfg["material"][k] *= (scale or {}).get(key, 1.0)
    for k, f in (("warp", band_scale[0]), ("weft", band_scale[0]), ("bias", band_scale[1])):
        cfg["strain"][k] = [f * e for e in cfg["strain"][k]]
    if compression is not None:
        for k in ("warp", "weft", "bias"):
            cfg["strain"][k] = [min(-compression, cfg["strain"][k][0]), cfg["strain"][k][1]]
    cfg["output"] = dict(cfg["output"], images=False, meshes=False)
    setup = SceneSetup(mesh=MeshArrays(uv=uv, x=x, faces=faces, pinned=pinned),
                       material=material_from(cfg))
    sim = Simulator(setup, cfg)
    if solve == "reference" and sim.strain is not None:
        sim.strain.set_host_loop(True)
    t0 = time.perf_counter()
    calm, frames = 0, int(round(seconds * cfg["sim"]["fps"]))
    for f in range(frames):
        sim.step_frame()
        v = sim.model.velocities()
        rms = float(np.sqrt(np.mean(np.sum(v[~pinned] ** 2, axis=1))))
        calm = calm + 1 if rms < 1e-3 else 0
        if calm >= 10 and sim.time >= MIN_SECONDS:
            break
    xs = sim.model.positions()
    a_sup, a_spec = np.pi * R_SUPPORT ** 2, np.pi * R_SPECIMEN ** 2
    dc = (shadow_area(xs, faces) - a_sup) / (a_spec - a_sup)
    out = dict(fabric=fabric, h=h, start=start, DC=float(dc), folds=folds(xs, uv),
               frames=f + 1, rms_end=rms, seconds=time.perf_counter() - t0, faces=len(faces),
               lowest=float(HEIGHT - xs[:, 1].min()), x=xs, **strain_summary(xs, uv, faces, h))
    log(f"{fabric:17s} h={100 * h:g} cm start {start}: DC {dc:.3f}, {out['folds']} folds, "
        f"{out['frames']} frames (rms {1000 * rms:.2f} mm/s), {out['seconds']:.0f} s")
    return out


def drape(fabric, h, start, method, seconds, compression, scale, edge_h, amplitude, turn,
          band_scale, solve="fast", source=None):
    """``run`` in a sweep's worker, without the final positions (``source``: this module's
    source hash, ``module_hash``, for the cache key only)."""
    from cloth import backend
    backend.init("cpu", "f64")
    out = run(fabric, h, start, method, seconds, log=lambda m: None, compression=compression,
              scale=scale, edge_h=edge_h, amplitude=amplitude, turn=turn,
              band_scale=tuple(band_scale), solve=solve)
    out.pop("x")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fabrics", nargs="*", default=None)
    ap.add_argument("--h", nargs="*", type=float, default=[0.01])
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--method", default="mapping")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--compression", type=float, default=None,
                    help="lower ends of the bands at -this strain (default: the fabric's)")
    for k in ("membrane", "shear", "bend"):
        ap.add_argument(f"--{k}-scale", type=float, default=1.0,
                        help=f"a factor on the fabric's {k} stiffness (default 1)")
    ap.add_argument("--edge-h", type=float, nargs="*", default=None,
                    help="triangle size within 2.5 cm of the support's edge, one per --h "
                         "(default: half each --h; give the --h values for a uniform mesh)")
    ap.add_argument("--amplitude", type=float, default=1.0,
                    help="a start's largest vertical displacement per start index, nm")
    ap.add_argument("--turn", type=float, default=0.0, help="the mesh's lattice turned, deg")
    ap.add_argument("--band-scale", type=float, nargs=2, default=(1.0, 1.0),
                    metavar=("THREADS", "BIAS"), help="factors on the warp and weft bands and on "
                    "the bias band")
    ap.add_argument("--solve", choices=("fast", "exact", "reference"), default="fast",
                    help="strain.solve of every run (default fast), or the exact solve with "
                         "Cholesky Newton steps (reference)")
    ap.add_argument("--out", default=None)
    from benchmarks.sweep import add_arguments
    add_arguments(ap)
    a = ap.parse_args()
    edge = dict(zip(a.h, a.edge_h or [h / 2 for h in a.h]))
    scale = dict(membrane=a.membrane_scale, shear=a.shear_scale, bend=a.bend_scale)
    from cloth import fabrics
    from benchmarks.sweep import Run, failed_lines, module_hash, run_sweep
    plan = [(name, h, s) for name in a.fabrics or fabrics.names() for h in a.h
            for s in range(a.starts)]
    source = module_hash("benchmarks.cusick")
    sweep = [Run("benchmarks.cusick:drape",
                 [name, h, s, a.method, a.seconds, a.compression, scale, edge[h],
                  1e-9 * a.amplitude, a.turn, list(a.band_scale), a.solve, source],
                 f"{name} h={100 * h:g} cm start {s}") for name, h, s in plan]
    results = run_sweep(sweep, os.path.join(a.out or "results", "cusick_runs"), a.scheduler,
                        a.workers, a.fresh, name="cusick")
    rows = [r for r in results if "error" not in r]
    L = [] if a.solve == "fast" else [f"Strain solve: {a.solve}.", ""]
    L += ["| fabric | h (cm) | faces | DC per start | median DC | folds | frames | principal "
          "strain p5 / p95 (%) |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name in a.fabrics or fabrics.names():
        for h in a.h:
            rs = [r for r in rows if r["fabric"] == name and r["h"] == h]
            if not rs:
                continue
            at = f" ({100 * edge[h]:g} at the edge)" if edge[h] < h else ""
            L.append(f"| {name} | {100 * h:g}{at} | {rs[0]['faces']} | "
                     + ", ".join(f"{r['DC']:.3f}" for r in rs)
                     + f" | {np.median([r['DC'] for r in rs]):.3f} | "
                     + ", ".join(str(r["folds"]) for r in rs) + " | "
                     + ", ".join(str(r["frames"]) for r in rs) + " | "
                     + f"{100 * rs[0]['eps_lo']:.2f} / {100 * rs[0]['eps_hi']:.2f} |")
    L += failed_lines(sweep, results)
    print("\n".join(L))
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        with open(os.path.join(a.out, "cusick.md"), "w") as fh:
            fh.write("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
