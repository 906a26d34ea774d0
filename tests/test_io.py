"""Output files (cloth/io.py): a written mesh reads back as what was written."""
import numpy as np

from cloth import io


def test_obj_round_trips_positions_material_coordinates_and_faces(tmp_path, rng):
    x = rng.normal(size=(50, 3)) * [1.0, 1e-3, 1e3]
    uv = rng.random((50, 2))
    faces = rng.integers(0, 50, size=(80, 3))
    path = str(tmp_path / "m.obj")
    io.write_obj(path, x, uv, faces)
    x2, uv2, faces2 = io.read_obj_uv(path)
    np.testing.assert_allclose(x2, x, rtol=1e-8)          # %.9g
    np.testing.assert_allclose(uv2, uv, rtol=1e-11)       # %.12g
    assert np.array_equal(faces2, faces)
    lines = open(path).read().splitlines()
    assert lines[0].startswith("#") and len(lines) == 1 + 50 + 50 + 80
    a, b, c = faces[0] + 1
    assert lines[-80] == f"f {a}/{a} {b}/{b} {c}/{c}"      # vertex i uses texture coordinate i
    assert not (tmp_path / "m.obj.tmp").exists()


def test_plain_obj_writes_vertices_and_one_based_faces(tmp_path):
    path = str(tmp_path / "o.obj")
    io.write_plain_obj(path, np.eye(3, dtype=np.float32), np.array([[0, 1, 2]]))
    assert open(path).read() == "v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n"
