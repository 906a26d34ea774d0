"""ClothModel: rest quantities, topology, capacity and input validation."""
import numpy as np
import pytest

from cloth.model import ClothModel, Material, MeshArrays, ModelError, build_edges
from cloth.sheet import make_sheet

from .helpers import sheet_model


@pytest.mark.parametrize("pattern", ["regular", "alternating", "random"])
def test_sheet_counts_area_and_mass(pattern):
    n, size = 7, 0.6
    m = sheet_model(n=n, size=size, pattern=pattern, material=Material(density=0.2))
    assert m.n_verts == n * n and m.n_faces == 2 * (n - 1) ** 2
    # Euler for a disc: V - E + F = 1.
    assert m.n_verts - m.n_edges + m.n_faces == 1
    assert np.isclose(m.rest_area.sum(), size * size, rtol=1e-12)
    assert np.isclose(m.mass.sum(), 0.2 * size * size, rtol=1e-12)
    assert np.all(m.rest_area > 0)


def test_edges_know_their_faces_and_opposite_vertices():
    uv, faces = make_sheet(1.0, 1.0, 4, 4, "random", seed=3)
    ev, ef, eo = build_edges(faces)
    for (a, b), (f0, f1), (o0, o1) in zip(ev, ef, eo):
        tri0 = list(faces[f0])
        k = tri0.index(a)
        assert tri0[(k + 1) % 3] == b and tri0[(k + 2) % 3] == o0  # a->b counter-clockwise in f0
        if f1 >= 0:
            tri1 = list(faces[f1])
            k = tri1.index(b)
            assert tri1[(k + 1) % 3] == a and tri1[(k + 2) % 3] == o1
    boundary = (ef[:, 1] < 0).sum()
    assert boundary == 4 * 3


def test_dm_inverse_maps_material_edges_to_identity():
    m = sheet_model(n=4, pattern="random")
    Dm_inv = m.face_Dm_inv.to_numpy()[: m.n_faces]
    uv, f = m.uv, m.faces
    Dm = np.stack([uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]], axis=2)
    assert np.allclose(Dm @ Dm_inv, np.eye(2), atol=1e-12)


def test_reload_within_capacity_keeps_fields_and_refuses_to_overflow():
    from cloth.model import CapacityExceeded
    m = sheet_model(n=6)
    handle = m.state.x
    uv, faces = make_sheet(0.5, 0.5, 5, 5)
    m.load(MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces))
    assert m.state.x is handle and m.n_verts == 25
    uv, faces = make_sheet(0.5, 0.5, 12, 12)
    with pytest.raises(CapacityExceeded):
        m.load(MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces))


def test_degenerate_and_clockwise_triangles_are_refused_with_a_fix():
    uv = np.array([[0, 0], [1, 0], [2, 0], [0, 1.0]])
    x = np.c_[uv, np.zeros(4)]
    with pytest.raises(ModelError, match="degenerate or clockwise.*counter-clockwise"):
        ClothModel(MeshArrays(uv=uv, x=x, faces=[[0, 1, 2]]), Material())
    with pytest.raises(ModelError, match="counter-clockwise"):
        ClothModel(MeshArrays(uv=uv, x=x, faces=[[0, 3, 1]]), Material())


def test_inconsistent_orientation_is_refused():
    faces = np.array([[0, 1, 2], [1, 2, 3]])  # both traverse 1->2
    with pytest.raises(ModelError, match="orientation"):
        build_edges(faces)


def test_bad_material_is_refused():
    with pytest.raises(ModelError, match="density"):
        sheet_model(material=Material(density=0.0))
