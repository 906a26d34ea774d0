"""A rigid union of spheres and capsules as one obstacle (the mannequin).

One obstacle with the primitives in fields costs one kernel however many primitives there are;
a separate obstacle per primitive would compile and launch one kernel each. The union's signed
distance is the minimum over the primitives: exact outside (the distance to the nearest
primitive is the distance to the union) and a lower bound of the depth inside, which is what
push-out needs.
"""
import numpy as np
import taichi as ti

from .obstacles import CollisionError, Obstacle


@ti.data_oriented
class CapsuleUnion(Obstacle):
    """Primitives as segments ``a``-``b`` inflated by ``radius`` (a sphere has a == b).

    prims: list of dicts ``{"kind": "sphere", "center", "radius"}`` or
    ``{"kind": "capsule", "a", "b", "radius"}`` (the format of ``assets/mannequin.json``)."""

    kind = "capsule-union"

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
        self.fa = ti.Vector.field(3, float, self.n)
        self.fb = ti.Vector.field(3, float, self.n)
        self.fr = ti.field(float, self.n)
        self.fa.from_numpy(self.seg_a)
        self.fb.from_numpy(self.seg_b)
        self.fr.from_numpy(self.radii)
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

    @ti.func
    def _offset(self, k, p):
        """p minus the nearest point of primitive k's segment."""
        a, b = self.fa[k], self.fb[k]
        ab = b - a
        t = 0.0
        L2 = ab.dot(ab)
        if L2 > 1e-20:
            t = ti.math.clamp((p - a).dot(ab) / L2, 0.0, 1.0)
        return p - (a + t * ab)

    @ti.func
    def sdf_local(self, p):
        best = 1e30
        for k in range(self.n):
            best = ti.min(best, self._offset(k, p).norm() - self.fr[k])
        return best

    @ti.func
    def nearest_two(self, p):
        """The two nearest primitives' distances and outward normals (exact, per capsule)."""
        d1, d2 = 1e30, 1e30
        n1 = ti.Vector([0.0, 0.0, 1.0])
        n2 = ti.Vector([0.0, 0.0, 1.0])
        for k in range(self.n):
            off = self._offset(k, p)
            dist = off.norm()
            d = dist - self.fr[k]
            nk = off / dist if dist > 1e-12 else ti.Vector([0.0, 0.0, 1.0])
            if d < d1:
                d2, n2 = d1, n1
                d1, n1 = d, nk
            elif d < d2:
                d2, n2 = d, nk
        return d1, n1, d2, n2
