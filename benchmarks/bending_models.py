"""Bending energies compared on the calibration's strips, without the simulator:

    python -m benchmarks.bending_models --out docs/calibration   # -> bending_models_table.md

Every energy here is quadratic in the positions, E = (B / 2) sum_c x_c^T K x_c over the three
coordinates (constant Hessian K, exact for an isometric bend of the flat sheet, see below), so
two cheap measures tell them apart:

cylinder   the strip (2 L x 8 cm, the cantilever's, ``benchmarks.calibration.strip_mesh``)
           wrapped isometrically on a cylinder of curvature kappa along it: E / ((B / 2)
           kappa^2 area) should be 1 in every direction.
cantilever the calibration cantilever at small deflection, linearised: out-of-plane w only,
           load q per area, the middle line held (w = 0); B_eff = q L^4 / (8 w_tip). It
           reproduces the simulator's G = 1 readings (docs/calibration/calibration.md) to
           about 1 % for the hinge energy and 2 % for the face fit.

Energies (B = 1):

hinge      the simulator's: BEND_CONSTANT |e|^2 / (A1 + A2) theta^2 / 2 per interior edge. Its
           stiffness at the flat state, and at every state that of the quadratic model
           c / (A1 + A2) |sum_n K_n x_n|^2 (K: the edge's cotangent weights, the affine-free
           combination of its four vertices, |sum K x| = |e| 2 sin(theta / 2) under isometry)
           with c = BEND_CONSTANT / 2, which is therefore the same energy to O(theta^2).
face fit   per face, the quadratic X(u) through its three vertices and the three across its
           edges (across a boundary edge: X_nn = 0, the moment-free edge); energy
           A (|X_uu|^2 + |X_vv|^2 + 2 |X_uv|^2) / 2. Exact for quadratic fields, isotropic.
mixed      (tr H)^2 / 2 by finite volumes over the vertices' cells (the cotangent Laplacian,
           plus the flux through the outline at free edges and clamps) plus the face fit's
           deviatoric part |dev H|^2: again |H|^2 in the continuum. The simulator's isotropic
           bending (cloth/bending.py).

ledge      (mixed only) the linearised ledge cantilever of ``calibration.ledge`` at widths
           2-16 cm: the clamp (pinned rows) and the free long edges, which the back-to-back
           strips do not test.
"""
import argparse
import os
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

L_HALF, WIDTH = 0.20, 0.08
PATTERNS = ("regular", "alternating", "random")
DIRECTIONS = ("warp", "bias", "bias-")
SIZES = (0.005, 0.01, 0.02)


def _mesh(pattern, direction, h):
    from benchmarks.calibration import cantilever_mesh
    from cloth.model import build_edges, signed_material_areas
    uv, faces, _ = cantilever_mesh(L_HALF, WIDTH, h, pattern, direction)
    ev, ef, eo = build_edges(faces)
    return dict(uv=uv, faces=faces.astype(np.int64), ev=ev, ef=ef, eo=eo,
                area=signed_material_areas(uv, faces))


def _sparse(rows, cols, vals, shape):
    return sp.csr_matrix((np.ravel(vals), (np.ravel(rows), np.ravel(cols))), shape)


# ---- hinge / per-edge quadratic -------------------------------------------------------------
def edge_cot_weights(m):
    """(idx (E, 4), K (E, 4)) per edge: x0 x1 x2 x3 and weights with sum K = 0, sum K u = 0,
    K2 = -|e| / d2, K3 = -|e| / d3; zero for boundary edges."""
    uv, ev, eo = m["uv"], m["ev"], m["eo"]
    inner = eo[:, 1] >= 0
    idx = np.stack([ev[:, 0], ev[:, 1], eo[:, 0], np.where(inner, eo[:, 1], ev[:, 0])], 1)
    P = uv[idx]
    el = np.linalg.norm(P[:, 1] - P[:, 0], axis=1)
    t = (P[:, 1] - P[:, 0]) / el[:, None]

    def height(p):
        d = p - P[:, 0]
        return np.abs(t[:, 0] * d[:, 1] - t[:, 1] * d[:, 0])
    K = np.zeros((len(ev), 4))
    K[:, 2] = -el / height(P[:, 2])
    K[inner, 3] = -el[inner] / height(P[:, 3])[inner]
    s2 = ((P[:, 2] - P[:, 0]) * t).sum(1)
    s3 = ((P[:, 3] - P[:, 0]) * t).sum(1)
    K[:, 1] = -(K[:, 2] * s2 + K[:, 3] * s3) / el
    K[:, 0] = -(K[:, 1] + K[:, 2] + K[:, 3])
    K[~inner] = 0.0
    return idx, K


def K_hinge(m):
    """Stiffness of the hinge energy at the flat state = Hessian of the per-edge quadratic
    model with c = BEND_CONSTANT / 2."""
    from cloth.model import BEND_CONSTANT
    idx, K = edge_cot_weights(m)
    ef, A = m["ef"], m["area"]
    inner = ef[:, 1] >= 0
    w = np.zeros(len(idx))
    w[inner] = BEND_CONSTANT / (A[ef[inner, 0]] + A[ef[inner, 1]])
    n = len(m["uv"])
    vals = w[:, None, None] * K[:, :, None] * K[:, None, :]
    return _sparse(np.repeat(idx[:, :, None], 4, 2), np.repeat(idx[:, None, :], 4, 1), vals, (n, n))


def hinge_energy_exact(m, x):
    """The simulator's hinge energy (nonlinear in theta) at positions x, B = 1."""
    from cloth.model import BEND_CONSTANT, dihedral_angles
    ev, ef, eo, A, uv = m["ev"], m["ef"], m["eo"], m["area"], m["uv"]
    inner = ef[:, 1] >= 0
    th = dihedral_angles(x, ev, eo)
    el = np.linalg.norm(uv[ev[:, 1]] - uv[ev[:, 0]], axis=1)
    w = np.zeros(len(ev))
    w[inner] = BEND_CONSTANT * el[inner] ** 2 / (A[ef[inner, 0]] + A[ef[inner, 1]])
    return 0.5 * float(np.sum(w * th ** 2))


# ---- the isotropic energies (cloth/bending.py) -----------------------------------------------
def K_face_fit(m):
    """The face fit alone: A (|X_uu|^2 + |X_vv|^2 + 2 |X_uv|^2) / 2 per face."""
    from cloth.bending import _face_rows, face_fit
    sten, C = face_fit(m["uv"], m["faces"], m["ef"], m["eo"], m["area"])
    H = _face_rows(sten, [C[:, 0], C[:, 1], np.sqrt(2.0) * C[:, 2]], len(m["uv"]))
    return H.T @ sp.diags(np.repeat(m["area"], 3)) @ H


def K_mixed(m):
    """The simulator's isotropic energy: finite-volume trace plus face-fit deviator, with the
    clamp where ``m`` has pins."""
    from cloth.bending import isotropic_matrix
    return isotropic_matrix(m["uv"], m["faces"], m["ev"], m["ef"], m["eo"], m["area"],
                            m.get("pinned"))


MODELS = (("hinge (= per-edge quadratic)", K_hinge), ("face fit", K_face_fit), ("mixed", K_mixed))


# ---- measures --------------------------------------------------------------------------------
def cylinder_ratio(m, K=None, kappa=2.0):
    uv = m["uv"]
    x = np.c_[np.sin(kappa * uv[:, 0]) / kappa, (1 - np.cos(kappa * uv[:, 0])) / kappa, uv[:, 1]]
    E = hinge_energy_exact(m, x) if K is None else 0.5 * sum(x[:, c] @ (K @ x[:, c]) for c in range(3))
    return E / (0.5 * kappa ** 2 * m["area"].sum())


def cantilever_ratio(m, K):
    uv, faces, A = m["uv"], m["faces"], m["area"]
    load = np.zeros(len(uv))
    np.add.at(load, faces.ravel(), np.repeat(A / 3, 3))
    free = np.abs(uv[:, 0] - L_HALF) > 1e-12
    Kf = K[free][:, free] + 1e-12 * sp.eye(int(free.sum()))   # the two halves' common tilt
    w = np.zeros(len(uv))
    w[free] = spl.spsolve(Kf.tocsc(), load[free])
    tip = np.mean([w[np.abs(uv[:, 0] - e) < 1e-12].mean() for e in (0.0, 2 * L_HALF)])
    return L_HALF ** 4 / (8.0 * tip)


def ledge_ratio(pattern, direction, h, width, K_of=K_mixed):
    """B_eff / B of the linearised ledge cantilever (``calibration.ledge``'s strip: its
    vertices on the ledge, u <= 0, pinned; overhang L_HALF): w_tip = q L^4 / (8 B)."""
    from benchmarks.calibration import ledge_mesh
    from cloth.model import build_edges, signed_material_areas
    uv, faces, _ = ledge_mesh(width, h, pattern, direction, L=L_HALF)
    ev, ef, eo = build_edges(faces)
    A = signed_material_areas(uv, faces)
    free = uv[:, 0] > 1e-12
    m = dict(uv=uv, faces=faces.astype(np.int64), ev=ev, ef=ef, eo=eo, area=A, pinned=~free)
    K = K_of(m)
    load = np.zeros(len(uv))
    np.add.at(load, faces.ravel(), np.repeat(A / 3, 3))
    w = np.zeros(len(uv))
    w[free] = spl.spsolve(K[free][:, free].tocsc(), load[free])
    return L_HALF ** 4 / (8.0 * w[np.abs(uv[:, 0] - L_HALF) < 1e-12].mean())


def run_ledge():
    from benchmarks.calibration import IRREGULAR, WIDTHS
    rows = []
    for pattern in PATTERNS + (IRREGULAR,):
        for h in SIZES:
            for direction in (("warp",) if pattern == IRREGULAR else ("warp", "weft") + DIRECTIONS[1:]):
                rows.append(dict(pattern=pattern, h=h, direction=direction, ratios=[
                    ledge_ratio(pattern, direction, h, w) if w >= 2 * h - 1e-9 else None
                    for w in WIDTHS]))
    return rows


def run():
    rows = []
    for pattern in PATTERNS:
        for h in SIZES:
            for direction in DIRECTIONS:
                m = _mesh(pattern, direction, h)
                r = dict(pattern=pattern, h=h, direction=direction,
                         cyl_hinge_exact=cylinder_ratio(m))
                for name, fn in MODELS:
                    K = fn(m)
                    r["cyl " + name] = cylinder_ratio(m, K)
                    r["cant " + name] = cantilever_ratio(m, K)
                rows.append(r)
    return rows


def report(rows, out, seconds, ledge_rows=(), cmd="python -m benchmarks.bending_models"):
    """bending_models_table.md and bending_models_table.json in ``out``."""
    from benchmarks.harness import header, write_json
    names = [n for n, _ in MODELS]
    write_json(out, "bending_models_table", {"rows": rows, "ledge_rows": list(ledge_rows)}, cmd,
               seconds)
    L = ["# Bending energies on the calibration strips: hinge, per-edge quadratic, isotropic fits\n",
         header(cmd, seconds) + "\n",
         "The energies and measures are defined in the module docstring "
         "(benchmarks/bending_models.py). "
         "B_eff / B of the linearised cantilever (small deflection, G -> 0) and E / E_plate of "
         "an isometric cylinder along the strip (curvature 2 / m), 2 x 20 cm strips 8 cm wide.\n",
         "| pattern | h (cm) | direction | " + " | ".join(f"cantilever: {n}" for n in names)
         + " | " + " | ".join(f"cylinder: {n}" for n in names) + " |",
         "|" + " --- |" * (3 + 2 * len(names))]
    for r in rows:
        L.append(f"| {r['pattern']} | {r['h'] * 100:g} | {r['direction']} | "
                 + " | ".join(f"{r['cant ' + n]:.3f}" for n in names) + " | "
                 + " | ".join(f"{r['cyl ' + n]:.3f}" for n in names) + " |")
    L.append("")
    L.append("The exact (nonlinear) hinge energy of the same cylinders divided by its quadratic "
             "stand-in: " + f"{min(r['cyl_hinge_exact'] / r['cyl ' + names[0]] for r in rows):.4f}"
             " ... " + f"{max(r['cyl_hinge_exact'] / r['cyl ' + names[0]] for r in rows):.4f}.")
    if ledge_rows:
        from benchmarks.calibration import WIDTHS
        v = [x for r in ledge_rows for x in r["ratios"] if x is not None]
        L += ["", "## Linearised ledge cantilever (isotropic energy)\n",
              "The ledge of `calibration.ledge` linearised like the cantilever above: the "
              "strip's vertices on the 10 cm ledge pinned, the 20 cm overhang under its weight; "
              "B_eff / B = q L^4 / (8 B w_tip), by strip width (cm); a dash where the strip is "
              f"narrower than two triangles. All: **{min(v):.3f} ... {max(v):.3f}**.\n",
              "| pattern | h (cm) | direction | " + " | ".join(f"{100 * w:g}" for w in WIDTHS)
              + " |", "|" + " --- |" * (3 + len(WIDTHS))]
        for r in ledge_rows:
            L.append(f"| {r['pattern']} | {r['h'] * 100:g} | {r['direction']} | " + " | ".join(
                "-" if x is None else f"{x:.3f}" for x in r["ratios"]) + " |")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "bending_models_table.md"), "w") as fh:
        fh.write("\n".join(L) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "calibration"))
    a = ap.parse_args()
    t0 = time.perf_counter()
    rows, ledge_rows = run(), run_ledge()
    from benchmarks.harness import command
    report(rows, a.out, time.perf_counter() - t0, ledge_rows, command("benchmarks.bending_models"))
    print(f"wrote {os.path.join(a.out, 'bending_models_table.md')}")


if __name__ == "__main__":
    main()
