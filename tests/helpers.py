"""Small builders shared by the tests."""
import numpy as np

from cloth.model import ClothModel, Material, MeshArrays
from cloth.sheet import make_sheet


def sheet_model(n=6, size=0.5, pattern="alternating", material=None, pinned=None, x=None,
                rest_x=None, bending=None):
    uv, faces = make_sheet(size, size, n, n, pattern)
    if x is None:
        x = np.c_[uv, np.zeros(len(uv))]
    mesh = MeshArrays(uv=uv, x=x, faces=faces, pinned=pinned)
    return ClothModel(mesh, material or Material(), rest_x=rest_x, bending=bending)


def set_positions(model, x):
    model.set_positions(x)


def set_velocities(model, v):
    model.set_velocities(v)
