"""Output files: OBJ meshes with material coordinates as ``vt`` and per-frame metrics CSV."""
import csv
import os

import numpy as np


def write_obj(path, x, uv, faces):
    """Positions as ``v``, material coordinates (metres) as ``vt``, faces ``f a/a b/b c/c``
    (1-based; vertex i uses texture coordinate i). Written to a temporary file and renamed, so
    a crash never leaves a half-written mesh."""
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        fh.write("# Loom cloth mesh: v = world position (m), vt = material coordinate (m)\n")
        np.savetxt(fh, np.asarray(x), fmt="v %.9g %.9g %.9g")
        np.savetxt(fh, np.asarray(uv), fmt="vt %.12g %.12g")
        f1 = np.asarray(faces, dtype=np.int64) + 1
        np.savetxt(fh, np.repeat(f1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
    os.replace(tmp, path)


def write_plain_obj(path, vertices, faces):
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        np.savetxt(fh, np.asarray(vertices), fmt="v %.9g %.9g %.9g")
        np.savetxt(fh, np.asarray(faces, dtype=np.int64) + 1, fmt="f %d %d %d")
    os.replace(tmp, path)


def read_obj_uv(path):
    """(x, uv, faces) from an OBJ written by ``write_obj`` (for tests and tools)."""
    xs, uvs, fs = [], [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                xs.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("vt "):
                uvs.append([float(t) for t in line.split()[1:3]])
            elif line.startswith("f "):
                fs.append([int(t.split("/")[0]) - 1 for t in line.split()[1:4]])
    return np.array(xs), np.array(uvs), np.array(fs, dtype=np.int64)


class MetricsWriter:
    """metrics.csv, one row per frame, flushed every row so a crash loses nothing."""

    def __init__(self, path):
        self.path = path
        self.fh = open(path, "w", newline="")
        self.writer = None

    def write(self, row):
        if self.writer is None:
            self.writer = csv.DictWriter(self.fh, fieldnames=list(row), extrasaction="ignore")
            self.writer.writeheader()
        self.writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
        self.fh.flush()

    def close(self):
        self.fh.close()


def read_metrics(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))
