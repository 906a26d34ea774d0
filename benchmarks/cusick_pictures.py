"""Pictures of the Cusick drapes (docs/fabrics.md): each fabric draped by benchmarks/cusick.py,
drawn from the side (shaded triangles, the support's disk) and from above (the shadow, the
support's and the specimen's circles), with its drape coefficient and fold count.

    python -m benchmarks.cusick_pictures --out docs/fabrics              # every fabric
    python -m benchmarks.cusick_pictures --fabrics denim --h 0.005 --method none --out DIR
    python -m benchmarks.cusick_pictures --fabrics cotton-shirting --method mapping --solve reference

One run (start 0) per fabric, written to OUT/cusick_NAME.png (cusick_NAME_METHOD.png for a
strain-limiting method, then _SOLVE for a solve other than fast); the other arguments are
benchmarks/cusick.py's.
"""
import argparse
import os

import numpy as np

from . import cusick


def draw(path, r, faces, title):
    """The side and the top view of run ``r`` (cusick.run's dict) into ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    x = r["x"] - [0.0, cusick.HEIGHT, 0.0]
    fig = plt.figure(figsize=(9.0, 4.2), dpi=100)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    # Loom's y is up: plot (x, z, y)
    P = x[:, [0, 2, 1]]
    from matplotlib.colors import LightSource
    ax.plot_trisurf(P[:, 0], P[:, 1], P[:, 2], triangles=faces, color="#8fa8c8",
                    edgecolor="none", shade=True, lightsource=LightSource(azdeg=300, altdeg=35),
                    antialiased=False)
    ax.view_init(elev=18, azim=-60)
    lim = 0.155
    ax.set_box_aspect((1, 1, 0.6))
    ax.set_xlim(-lim, lim), ax.set_ylim(-lim, lim), ax.set_zlim(-0.11, 0.03)
    ax.set_axis_off()
    ax.set_title("side", fontsize=10)
    ax2 = fig.add_subplot(1, 2, 2)
    polys = x[faces][:, :, [0, 2]]
    ax2.add_collection(PolyCollection(polys, facecolors="#2b3440", edgecolors="#2b3440",
                                      linewidths=0.3))
    t = np.linspace(0, 2 * np.pi, 200)
    for rad, style in ((cusick.R_SPECIMEN, "--"), (cusick.R_SUPPORT, "-")):
        ax2.plot(rad * np.cos(t), rad * np.sin(t), style, color="#d08040", lw=1)
    ax2.set_aspect("equal")
    ax2.set_xlim(-0.16, 0.16), ax2.set_ylim(-0.16, 0.16)
    ax2.set_xticks([]), ax2.set_yticks([])
    ax2.set_title(f"shadow: DC {r['DC']:.3f}, {r['folds']} folds", fontsize=10)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fabrics", nargs="*", default=None)
    ap.add_argument("--h", type=float, default=0.005)
    ap.add_argument("--method", default="none")
    ap.add_argument("--compression", type=float, default=None)
    ap.add_argument("--solve", choices=("fast", "exact", "reference"), default="fast",
                    help="the strain solve (benchmarks.cusick.run's solve; default fast)")
    ap.add_argument("--out", default=os.path.join("docs", "fabrics"))
    a = ap.parse_args()
    from cloth import backend, fabrics
    backend.init("cpu", "f64")
    os.makedirs(a.out, exist_ok=True)
    for name in a.fabrics or fabrics.names():
        r = cusick.run(name, a.h, 0, a.method, compression=a.compression, solve=a.solve)
        faces = cusick.disk_mesh(a.h)[1]
        tag = ("" if a.method == "none" else f"_{a.method}") + \
            ("" if a.solve == "fast" else f"_{a.solve}")
        solve = "" if a.solve == "fast" else f" ({a.solve} solve)"
        path = os.path.join(a.out, f"cusick_{name}{tag}.png")
        draw(path, r, faces, f"{name}: Cusick drape, {a.method}{solve}, {100 * a.h:g} cm "
             "triangles")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
