"""What each term of the remesher's sizing metric asks on a cloth state written by a run.

    python -m benchmarks.remesh_sizing out/drape/meshes/frame_0030.obj [--config CONFIG.toml]
                                       [--set size_min=0.01 ...]
    python -m benchmarks.remesh_sizing drape --trace 30 [--set remesh.size_min=0.01 ...]
    python -m benchmarks.remesh_sizing A.obj --picture OUT.png --vs B.obj --titles "a,b"

Reads the OBJ (world positions and material coordinates) and the run's ``config.toml`` next to
``meshes/`` (the scene's obstacles and the remesh settings), and prints for the whole metric and
for each term alone (``cloth.remesh.face_sizing_terms``): the faces it asks and the share of
the area it puts at ``size_min``. The velocity term is left out (an OBJ has no velocities; at
rest they are small).

*Asked faces*: the count of triangles equilateral with unit edges in the metric, the sum over
faces of area sqrt(det M) / (sqrt(3) / 4), with each face's metric clamped (``clamp_metric``).
*Vertex sizing*: the same with the metric the remesher works with (``vertex_sizing``: the
clamped face metrics averaged to the vertices, a face's metric the mean of its three). A mesh
the remesher made has about twice the asked count (docs/remesh/drape.md). The area is split
into the cloth *lying* on an obstacle (every vertex of the face within ``2 * thickness`` of
it) and the rest. ``--picture``: the drape's OBJs side by side as wireframes, coloured by
triangle size on one scale (size_min to size_max), the sphere drawn as the scene's.
"""
import argparse
import math
import os

import numpy as np


def asked(M, area, params):
    """(asked faces, share of the area with its finer size at size_min) of face metrics M."""
    from cloth.remesh import _sym_eig2, clamp_metric
    Mc = clamp_metric(M, params)
    det = Mc[:, 0, 0] * Mc[:, 1, 1] - Mc[:, 0, 1] ** 2
    n = float((area * np.sqrt(np.maximum(det, 0.0))).sum() / (math.sqrt(3.0) / 4.0))
    lam, _ = _sym_eig2(Mc)
    at_min = lam[:, 1] >= (1.0 - 1e-9) / params.size_min ** 2
    return n, float(area[at_min].sum() / area.sum())


def load(obj, config, sets=()):
    """(mesh, params, obstacle_distance or None, thickness) for an OBJ of a run."""
    import scenes
    from cloth import backend
    from cloth.config import load_toml, parse_assignment
    from cloth.io import read_obj_uv
    from cloth.model import MeshArrays
    from cloth.remesh import RemeshParams
    from scenes.common import resolve
    backend.init("cpu", "f64")
    x, uv, faces = read_obj_uv(obj)
    data = load_toml(config)
    name = data.pop("scene")
    module = scenes.get(name)
    cfg = resolve(module.DEFAULTS, [data] + [parse_assignment("remesh." + s) for s in sets])
    setup = module.build(cfg)
    rcfg = dict(cfg["remesh"])
    rcfg.pop("enabled", None)
    params = RemeshParams(**rcfg)
    params.validate()
    mesh = MeshArrays(uv=uv, x=x, faces=faces)
    obstacles = setup.obstacles          # at t = 0: the obstacles as they start
    dist = (lambda p: np.min([o.distance(p) for o in obstacles], axis=0)) if obstacles \
        else None
    return mesh, params, dist, float(cfg["collision"]["thickness"])


def report(mesh, params, dist, thickness):
    """The table of asked faces per term on one state (its velocities as they are)."""
    from cloth.model import build_edges
    from cloth.remesh import face_sizing, face_sizing_terms, vertex_sizing
    edges = build_edges(mesh.faces)
    terms, area = face_sizing_terms(mesh, params, dist, edges)
    if not np.any(terms["velocity"]):
        terms.pop("velocity")
    lying = np.zeros(len(mesh.faces), bool)
    if dist is not None:
        lying = (dist(mesh.x)[mesh.faces] < 2.0 * thickness).all(axis=1)
    M = face_sizing(mesh, params, dist, edges)[0]
    rows = [("all terms", M)] + list(terms.items())
    print(f"{len(mesh.faces)} faces, {len(mesh.uv)} vertices; lying on an obstacle: "
          f"{area[lying].sum() / area.sum():.0%} of the area")
    print("| metric | asked faces | area at size_min | lying: asked / at size_min "
          "| rest: asked / at size_min |")
    print("| --- | --- | --- | --- | --- |")
    for name, T in rows:
        n, s = asked(T, area, params)
        nl, sl = asked(T[lying], area[lying], params) if lying.any() else (0.0, 0.0)
        nr, sr = asked(T[~lying], area[~lying], params)
        print(f"| {name} | {n:,.0f} | {s:.0%} | {nl:,.0f} / {sl:.0%} | {nr:,.0f} / {sr:.0%} |")
    Mv = vertex_sizing(M, area, mesh.faces, len(mesh.uv), params)
    n, _ = asked(Mv[mesh.faces].mean(axis=1), area, params)
    print(f"vertex sizing asks {n:,.0f} faces ({len(mesh.faces) / n:.2f} x that in the mesh)")


def trace(scene, frames, sets=()):
    """Run ``scene`` remeshed in this process and print, after every frame, its faces and
    what the metric and each term alone (velocities included) ask on the frame's state."""
    from cloth import backend
    backend.init("cpu", "f64")
    from benchmarks.harness import configure
    from cloth.config import parse_assignment
    from cloth.model import build_edges
    from cloth.remesh import face_sizing, face_sizing_terms
    from cloth.simulator import Simulator
    over = [{"remesh": {"enabled": True}}] + [parse_assignment(a) for a in sets]
    _, cfg, setup = configure(scene, over)
    sim = Simulator(setup, cfg)
    remesher = sim.remesher[1]
    print("| frame | faces | asked | " + " | ".join(
        ("curvature", "velocity", "compression", "obstacle")) + " |")
    for frame in range(1, frames + 1):
        sim.step_frame()
        mesh = sim.model.mesh_arrays()
        dist = sim._obstacle_distance if setup.obstacles else None
        edges = build_edges(mesh.faces)
        terms, area = face_sizing_terms(mesh, remesher, dist, edges)
        n = asked(face_sizing(mesh, remesher, dist, edges)[0], area, remesher)[0]
        per = [asked(T, area, remesher)[0] for T in terms.values()]
        print(f"| {frame} | {len(mesh.faces):,} | {n:,.0f} | "
              + " | ".join(f"{v:,.0f}" for v in per) + " |", flush=True)


def picture(objs, titles, out, lo=15.0, hi=80.0):
    """OBJs of the drape (world y up) side by side, each triangle coloured by the edge of an
    equilateral triangle of its rest area (mm, ``lo``..``hi``), edges drawn."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from cloth.io import read_obj_uv
    from scenes.drape import DEFAULTS
    centre, radius = DEFAULTS["sphere"]["center"], DEFAULTS["sphere"]["radius"]
    fig = plt.figure(figsize=(6 * len(objs), 6), dpi=100)
    cmap = plt.get_cmap("viridis")
    for n, (path, title) in enumerate(zip(objs, titles)):
        x, uv, f = read_obj_uv(path)
        e1, e2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        edge = 1e3 * np.sqrt(4.0 * area / math.sqrt(3.0))
        ax = fig.add_subplot(1, len(objs), n + 1, projection="3d")
        p = x[:, [0, 2, 1]]                                  # world y up -> plot z
        ax.add_collection3d(Poly3DCollection(
            p[f], facecolors=cmap(np.clip((edge - lo) / (hi - lo), 0.0, 1.0)),
            edgecolors=(0, 0, 0, 0.5), linewidths=0.2))
        u, v = np.mgrid[0:2 * np.pi:40j, 0:np.pi:20j]
        r = 0.97 * radius
        ax.plot_wireframe(centre[0] + r * np.cos(u) * np.sin(v),
                          centre[2] + r * np.sin(u) * np.sin(v),
                          centre[1] + r * np.cos(v), color="0.8", linewidth=0.3)
        ax.set_xlim(centre[0] - 0.36, centre[0] + 0.36)
        ax.set_ylim(centre[2] - 0.36, centre[2] + 0.36)
        ax.set_zlim(centre[1] - 0.3, centre[1] + 0.35)
        ax.set_box_aspect((0.72, 0.72, 0.65), zoom=1.45)
        ax.view_init(elev=30, azim=-62)
        ax.set_axis_off()
        ax.set_title(f"{title}: {len(f):,} faces", fontsize=11)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(lo, hi))
    fig.colorbar(sm, ax=fig.axes, shrink=0.6,
                 label="triangle size (mm, equilateral edge of its rest area)")
    import io
    from PIL import Image
    buf = io.BytesIO()
    fig.savefig(buf, bbox_inches="tight")
    Image.open(buf).convert("RGB").quantize(colors=128).save(out, optimize=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("obj", help="a run's meshes/frame_NNNN.obj, or with --trace a scene")
    ap.add_argument("--config", help="the run's config.toml (default: beside meshes/)")
    ap.add_argument("--set", action="append", default=[],
                    help="a remesh setting, e.g. size_min=0.01 (repeatable); with --trace "
                         "any setting, e.g. remesh.size_min=0.01")
    ap.add_argument("--trace", type=int, metavar="FRAMES",
                    help="run the scene (OBJ names a scene) remeshed for FRAMES frames and "
                         "print the asks after every frame")
    ap.add_argument("--picture", metavar="PNG", help="draw OBJ (and --vs OBJs) side by side")
    ap.add_argument("--vs", action="append", default=[], help="another OBJ for --picture")
    ap.add_argument("--titles", help="comma-separated titles for --picture")
    args = ap.parse_args(argv)
    if args.picture:
        objs = [args.obj] + args.vs
        titles = args.titles.split(",") if args.titles else objs
        return picture(objs, titles, args.picture)
    if args.trace:
        return trace(args.obj, args.trace, args.set)
    config = args.config or os.path.join(os.path.dirname(os.path.dirname(
        os.path.abspath(args.obj))), "config.toml")
    report(*load(args.obj, config, args.set))


if __name__ == "__main__":
    main()
