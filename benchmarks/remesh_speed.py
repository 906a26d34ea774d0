"""Remeshing speed: steady-state ms per remesh (cloth/remesh.py) on a moving 1 m sheet, at ~1k,
~5k and ~20k faces, for a gently curved hanging shape and a drifting sharp fold.

    python -m benchmarks.remesh_speed
"""
import numpy as np

from cloth.remesh import MeshArrays, RemeshParams, remesh


def sheet_shape(uv, kind, t):
    """World positions and velocities of a 1 m sheet at time t: 'hanging' (gently curved,
    slowly swaying) or 'fold' (a sharp fold whose line drifts across the sheet)."""
    u, v = uv[:, 0], uv[:, 1]
    if kind == "hanging":
        # A generalised cylinder (isometric, like hanging drapes): the u-lines follow a plane
        # curve of curvature 4 sin(4 pi u + t) per metre, the v-lines hang straight down.
        s = np.linspace(0.0, 1.0, 2001)
        phi = -np.cos(4 * np.pi * s + t) / np.pi
        cx = np.concatenate([[0], np.cumsum(np.cos(phi[1:]) + np.cos(phi[:-1])) * 2.5e-4])
        cy = np.concatenate([[0], np.cumsum(np.sin(phi[1:]) + np.sin(phi[:-1])) * 2.5e-4])
        x = np.c_[np.interp(u, s, cx), np.interp(u, s, cy), -v]
        vel = np.c_[np.zeros_like(u), 0.05 * np.sin(np.pi * u) * v, np.zeros_like(u)]
        return x, vel
    at = 0.4 + 0.02 * t
    d = u - at
    x = np.c_[np.where(d < 0, u, at + d * np.cos(2.0)), v, np.where(d < 0, 0.0, d * np.sin(2.0))]
    return x, np.zeros_like(x)


def bench(frames=6, verbose=False, quiet=False):
    """Grids of ~1k, ~5k, ~20k faces with size_max 1.8 x the grid spacing (flat parts then
    neither split nor coarsen), 4 frames to settle, then the mean over ``frames`` frames.
    Prints a table (unless ``quiet``) and returns its rows as dicts."""
    from cloth.sheet import make_sheet
    keys = ("faces_out", "ms", "ms_sizing", "ms_cpu", "splits", "flips", "collapses")
    if not quiet:
        print("kind     faces   ms/remesh  (sizing)  cpu ms   splits/flips/collapses per frame")
    table = []
    for kind in ("hanging", "fold"):
        for n in (23, 51, 101):
            size_max = 1.8 / (n - 1)
            params = RemeshParams(size_min=size_max / 5, size_max=size_max)
            uv, faces = make_sheet(1.0, 1.0, n, n, pattern="alternating")
            mesh = MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces)
            rows = []
            for frame in range(frames + 4):
                mesh.x, mesh.v = sheet_shape(mesh.uv, kind, 0.1 * frame)
                mesh, _, st = remesh(mesh, params)
                if verbose:
                    print(frame, st)
                if frame >= 4:
                    rows.append([st[k] for k in keys])
            r = np.mean(rows, axis=0)
            table.append(dict(zip(("faces",) + keys[1:], r), kind=kind))
            if not quiet:
                print(f"{kind:8s} {r[0]:6.0f}   {r[1]:8.1f}  ({r[2]:5.1f})  {r[3]:6.1f}    "
                      f"{r[4]:.0f}/{r[5]:.0f}/{r[6]:.0f}")
    return table


if __name__ == "__main__":
    bench()
