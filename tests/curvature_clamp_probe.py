"""Run by tests/test_exact_curvature.py in a subprocess with full optimisation (the suite
compiles fast, and the bug this guards against appeared only with Taichi's optimiser): fills
the kernels' exact curvature (c_curvature.face_c_curvature) for random triangles with every
upper mapping constraint active and prints the smallest eigenvalue of the stored 3x3 blocks
Hc over their largest entry."""
import os
import sys

import numpy as np
import taichi as ti

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from cloth import backend  # noqa: E402

backend.init("cpu", "f64")
from cloth.strain.buffers import (N_PARAMS, P_C_STEP, P_ISO, ConstraintPack,  # noqa: E402
                                  MeshPack)
from cloth.strain.c_curvature import C_STEP_F64, face_c_curvature  # noqa: E402
from cloth.strain.constraints import MAPPING_ISO, METHOD_IDS  # noqa: E402
from tests.test_constraints import random_triangles  # noqa: E402

A = ti.types.ndarray()


@ti.kernel
def fill(method: ti.template(), x: A, mesh: MeshPack, cons: ConstraintPack, mu: float):
    ti.loop_config(serialize=True)
    for _ in range(1):
        params_w = ti.Vector([mesh.params[k] for k in ti.static(range(6))])
        for f in range(mesh.n_faces):
            face_c_curvature(method, cons.n_per_face, f, x, mesh, params_w, mesh.params[P_ISO],
                             mesh.params[P_C_STEP], cons, mu)


def main():
    cases = random_triangles(np.random.default_rng(3), 20)
    X, Dm, area, grain = (np.array([c[k] for c in cases]) for k in range(4))
    n = len(X)
    vec3, mat2 = ti.types.vector(3, float), ti.types.matrix(2, 2, float)
    x = ti.ndarray(vec3, 3 * n)
    x.from_numpy(X.reshape(-1, 3))
    fv = ti.ndarray(ti.types.vector(3, ti.i32), n)
    fv.from_numpy(np.arange(3 * n, dtype=np.int32).reshape(n, 3))
    dm, gr, ra = ti.ndarray(mat2, n), ti.ndarray(mat2, n), ti.ndarray(float, n)
    dm.from_numpy(Dm)
    gr.from_numpy(grain)
    ra.from_numpy(area)
    params = np.zeros(N_PARAMS)
    params[0:6] = (-0.01, 0.01, -0.05, 0.05, 1.37, 1.46)
    params[P_ISO], params[P_C_STEP] = MAPPING_ISO, C_STEP_F64
    pa = ti.ndarray(float, N_PARAMS)
    pa.from_numpy(params)
    # Upper bounds active (lam > 0), lower ones not: the weighted strain is then curved.
    lam_np = np.zeros((n, 8))
    lam_np[:, 0::2] = 1.0
    lam, g = ti.ndarray(float, (n, 8)), ti.ndarray(float, (n, 8))
    lam.from_numpy(lam_np)
    g.from_numpy(np.zeros((n, 8)))
    curv = ti.ndarray(ti.types.vector(9, float), (n, 3))
    unused = ti.ndarray(float, 1)    # pack members face_c_curvature does not read
    mesh = MeshPack(face_verts=fv, Dm_inv=dm, grain=gr, rest_area=ra, mass=unused,
                    pinned=unused, params=pa, n_verts=3 * n, n_faces=n)
    cons = ConstraintPack(lam=lam, g=g, grad=unused, cm=unused, what=unused, kappa=unused,
                          twist=unused, curv=curv, n_per_face=8)
    fill(METHOD_IDS["mapping"], x, mesh, cons, 1.0)
    c = curv.to_numpy()
    Hc = c[:, 1][:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    print(np.linalg.eigvalsh(Hc).min() / np.abs(Hc).max())


if __name__ == "__main__":
    main()
