"""A rigid union of spheres and capsules as one obstacle (the mannequin).

One obstacle with the primitives in an array (an ndarray argument of the collision kernels, see
``shape.py``) costs one launch per pass however many primitives there are, where a separate
obstacle per primitive would launch once each. The union's signed distance is the minimum over
the primitives (``geom.sdf_capsule_union``): exact outside (the distance to the nearest
primitive is the distance to the union) and a lower bound of the depth inside, which is what
push-out needs. Its gradient is by central differences; its contact planes are those of its two
nearest primitives (``geom.nearest_two_capsules``).
"""
import numpy as np

from . import shape
from .obstacles import CollisionError, Obstacle


class CapsuleUnion(Obstacle):
    """Primitives as segments ``a``-``b`` inflated by ``radius`` (a sphere has a == b).

    prims: list of dicts ``{"kind": "sphere", "center", "radius"}`` or
    ``{"kind": "capsule", "a", "b", "radius"}`` (the format of ``assets/mannequin.json``)."""

    kind = "capsule-union"
    kind_id = shape.UNION

    def __init__(self, prims, mu=0.3, position=(0.0, 0.0, 0.0), rotation=None, path=None):
        if not prims:
            raise CollisionError("a capsule union needs at least one primitive")
        a, b, r = [], [], []
        for p in prims:
            if p["kind"] == "sphere":
                a.append(p["center"]), b.append(p["center"])
            elif p["kind"] == "capsule":
                a.append(p["a"]), b.append(p["b"])
            else:
                raise CollisionError(f"unknown primitive kind '{p['kind']}': use sphere or capsule")
            if not p["radius"] > 0:
                raise CollisionError(f"primitive radius must be > 0 (got {p['radius']})")
            r.append(p["radius"])
        self.seg_a, self.seg_b = np.array(a, np.float64), np.array(b, np.float64)
        self.radii = np.array(r, np.float64)
        self.n = len(r)
        super().__init__(mu=mu, position=position, rotation=rotation, path=path)

    def size(self):
        return float(self.radii.min())

    def ccd_step(self, thickness):
        # As for one capsule: the thinnest primitive decides.
        r = float(self.radii.min())
        return min(r, np.sqrt(8.0 * r * thickness))

    def local_mesh(self):
        import trimesh      # here: 0.7 s to import, and only meshes need it
        parts = []
        for a, b, r in zip(self.seg_a, self.seg_b, self.radii):
            d = b - a
            length = float(np.linalg.norm(d))
            if length < 1e-9:
                m = trimesh.creation.icosphere(subdivisions=2, radius=r)
            else:
                m = trimesh.creation.capsule(height=length, radius=r, count=[16, 16])
                z = np.array([0.0, 0.0, 1.0])
                m.apply_transform(trimesh.geometry.align_vectors(z, d / length))
            m.apply_translation(0.5 * (a + b))
            parts.append(m)
        m = trimesh.util.concatenate(parts)
        return np.asarray(m.vertices), np.asarray(m.faces)

    def host_prims(self):
        """Rows (a, b, radius), the layout of ``shape.py``'s ``prims``."""
        return np.c_[self.seg_a, self.seg_b, self.radii]
