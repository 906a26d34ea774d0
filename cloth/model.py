"""The cloth model (what changes only when the mesh changes) and its state (x, v).

Every array lives in a Taichi ndarray allocated with spare capacity; ``n_verts``, ``n_faces``
and ``n_edges`` say how much of each is active, so a remesh refills the arrays instead of
reallocating them every frame (when capacity runs out the Simulator builds a bigger model).
The arrays are ndarrays, never fields, because every kernel takes them as arguments: a kernel
then compiles once per process, not once per model (a field captured by a kernel is baked
into it, so every new model recompiled every kernel: 4-10 s per Simulator).

Units are SI throughout: metres, kilograms, seconds, newtons.

Triangle kinematics (docs/method.md §2): for face (i, j, k) with material coordinates u_n and
world positions x_n, ``Dm = [u_j - u_i, u_k - u_i]`` and ``F = Ds Dm^-1``. We store
``face_Dm_inv`` and the grain frame ``face_grain`` (columns: warp and weft unit directions in
material space), so the strain along the warp is ``||F e_warp|| - 1``.
"""
from dataclasses import dataclass, field as dc_field

import numpy as np
import taichi as ti
from taichi.lang.util import to_numpy_type

from . import bending as bending_energy, metrics, ndarrays
from .metrics import dihedral_angles, signed_material_areas  # noqa: F401 (re-exported)
from .materials import MATERIAL_PRESETS

_COTTON = MATERIAL_PRESETS["cotton"]


class ModelError(ValueError):
    """Bad mesh or material input; the message names the fix."""


class CapacityExceeded(RuntimeError):
    """A mesh does not fit in a model's arrays (remeshing grew it past the spare capacity)."""

    def __init__(self, nv, nf, ne, caps, nq=0):
        super().__init__(f"mesh of {nv} vertices, {nf} faces, {ne} edges ({nq} bending "
                         f"entries) exceeds the capacity {caps}")
        self.needed = (nv, nf, ne)


# The bending energy of an interior edge e is k_bend w_e (theta_e - theta0_e)^2 / 2 with
# w_e = BEND_CONSTANT |e|^2 / (A1 + A2) (material-space edge length and areas of its two faces).
# The discrete-shells weight (Grinspun et al. 2003) has 3 here, the constant for which the sum
# approximates the integral of the squared mean curvature when curvature is spread evenly over
# the edges of a mesh. Cloth bends (nearly) developably: a cylinder of curvature k bends only
# the edges along its generators, each by k times the spacing d of those edge lines, and a
# weight of |e|^2 / (A1 + A2) = |e| / d then gives exactly the plate energy (B / 2) k^2 per
# area. Free of such an ideal fold, a strip also finds lower-energy (twisting, zig-zag) ways to
# share its curvature among the mesh's other edges, softening it by 10-19 %. The constant is
# therefore measured (benchmarks/calibration.py, docs/calibration/calibration.md): a strip
# under its own weight, 0.5-2 cm triangles, regular / alternating / random triangulations,
# along the mesh's warp or weft lines, chord 7 or 41.5 deg, then matches the inextensible
# elastica of flexural rigidity B = k_bend: 0.96-1.07 B at 0.5-1 cm, 0.95-1.11 B at 2 cm (the
# high end: random triangulation, large deflection); with 3 it read 2.44-2.71 B.
# Limit of the hinge energy: a strip cut at 45 deg to the mesh lines reads 0.84-1.04 B on the
# regular pattern when its diagonals run across the strip (fold lines), 2.2-2.7 B when they
# run along it (none), 1.2-1.8 B on the alternating and random patterns, stiffer the finer
# the mesh (same document). No per-edge weight can cure that (on
# the regular pattern the three edge directions fix the curvature tensor, so any weights give
# a direction-dependent energy); it takes a bending energy that couples a triangle's edges.
# That is the isotropic energy (cloth/bending.py), the default for a flat rest shape; the
# hinge stays for a curved rest shape (rest_x) and as ``sim.bending = "hinge"``. The energies
# compared: docs/history/bending_models.md.
BEND_CONSTANT = 1.17


@dataclass
class Material:
    """Fabric parameters (SI), as a textile lab reports them. Stretch stiffnesses are per unit
    width (N/m): the 2-D membrane moduli of the cloth, i.e. Young's modulus times thickness,
    along warp and weft and in shear. ``k_bend`` is the flexural rigidity B (N m = N m^2 per
    m of width) of the plate energy (B / 2) kappa^2 per unit area, the number a cantilever
    test (ASTM D1388: B = w c^3 with w the weight per area, N/m^2, and c the bending length)
    or a KES-FB2 bending test (its B is per unit width, N m^2/m) reports; isotropic (the same
    about warp and weft)."""
    # Defaults: the "cotton" preset (cloth/materials.py, where its numbers and sources live).
    density: float = _COTTON["density"]          # kg/m^2 (areal density)
    k_warp: float = _COTTON["k_warp"]            # N/m, stretch stiffness along the warp
    k_weft: float = _COTTON["k_weft"]            # N/m, stretch stiffness along the weft
    k_shear: float = _COTTON["k_shear"]          # N/m, in-plane shear stiffness
    k_bend: float = _COTTON["k_bend"]            # N m, flexural rigidity B (BEND_CONSTANT)
    damp_mass: float = _COTTON["damp_mass"]      # 1/s, mass-proportional (air) damping
    damp_stiff: float = _COTTON["damp_stiff"]    # s, stiffness-proportional damping
    # N m, B along the warp and along the weft (0: k_bend). When they differ the plate is
    # orthotropic (cloth/bending.py: orthotropic_coordinates), its twisting rigidity
    # sqrt(B_warp B_weft); read when the model is built (a load), not every step.
    k_bend_warp: float = _COTTON["k_bend_warp"]
    k_bend_weft: float = _COTTON["k_bend_weft"]

    def validate(self):
        for name in ("density", "k_warp", "k_weft"):
            if not getattr(self, name) > 0:
                raise ModelError(f"material.{name} must be > 0 (got {getattr(self, name)})")
        for name in ("k_shear", "k_bend", "damp_mass", "damp_stiff", "k_bend_warp",
                     "k_bend_weft"):
            if not getattr(self, name) >= 0:
                raise ModelError(f"material.{name} must be >= 0 (got {getattr(self, name)})")

    def bend_rigidities(self):
        """(B_warp, B_weft), N m: k_bend_warp and k_bend_weft, each k_bend where it is 0."""
        return (self.k_bend_warp or self.k_bend, self.k_bend_weft or self.k_bend)

    def bend_scale(self):
        """The factor the kernels multiply the bending matrix by: k_bend when bending is
        isotropic (exactly), else sqrt(B_warp B_weft) (the orthotropic plate's matrix is the
        isotropic one on mapped coordinates, ``bending.orthotropic_coordinates``)."""
        bw, bf = self.bend_rigidities()
        return self.k_bend if bw == bf == self.k_bend else float(np.sqrt(bw * bf))

    def bend_alpha(self):
        """``bending.orthotropic_stretch`` of this material (1.0: isotropic)."""
        bw, bf = self.bend_rigidities()
        return bending_energy.orthotropic_stretch(bw, bf) if bw > 0 and bf > 0 else 1.0


@dataclass
class MeshArrays:
    """A cloth mesh as numpy arrays, the exchange format between builders, remeshing and
    the Taichi arrays. ``grain`` is (F, 2, 2): columns warp and weft in material space."""
    uv: np.ndarray                 # (V, 2) material coordinates, m
    x: np.ndarray                  # (V, 3) world positions, m
    faces: np.ndarray              # (F, 3) int, counter-clockwise in material space
    v: np.ndarray = None           # (V, 3) velocities, m/s
    pinned: np.ndarray = None      # (V,) bool
    pin_target: np.ndarray = None  # (V, 3) rest target of pinned vertices
    grain: np.ndarray = None       # (F, 2, 2)
    extras: dict = dc_field(default_factory=dict)

    def __post_init__(self):
        self.uv = np.ascontiguousarray(self.uv, dtype=np.float64)
        self.x = np.ascontiguousarray(self.x, dtype=np.float64)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int32)
        nv = len(self.uv)
        if self.v is None:
            self.v = np.zeros((nv, 3))
        if self.pinned is None:
            self.pinned = np.zeros(nv, dtype=bool)
        if self.pin_target is None:
            self.pin_target = self.x.copy()
        if self.grain is None:
            self.grain = np.tile(np.eye(2), (len(self.faces), 1, 1))
        self.v = np.asarray(self.v, dtype=np.float64)
        self.pinned = np.asarray(self.pinned, dtype=bool)
        self.pin_target = np.asarray(self.pin_target, dtype=np.float64)
        self.grain = np.asarray(self.grain, dtype=np.float64)


def grain_from_angle(angle, n_faces):
    """Grain frames for ``n_faces`` faces with the warp rotated by ``angle`` (radians) from the
    material u axis; weft perpendicular (counter-clockwise)."""
    c, s = np.cos(angle), np.sin(angle)
    g = np.array([[c, -s], [s, c]])
    return np.tile(g, (n_faces, 1, 1))


def build_edges(faces):
    """Unique edges with their adjacent faces and opposite vertices.

    Returns (edge_verts (E,2), edge_faces (E,2), edge_opp (E,2)); for a boundary edge the
    second face and opposite vertex are -1. For an interior edge (a, b), face 0 holds a->b in
    its counter-clockwise order, face 1 holds b->a. Raises ModelError if an edge has more than
    two faces or two faces traverse it in the same direction (inconsistent orientation)."""
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    # Half-edges: (a, b) directed as in the face, with the opposite vertex.
    a = faces[:, [0, 1, 2]].reshape(-1)
    b = faces[:, [1, 2, 0]].reshape(-1)
    opp = faces[:, [2, 0, 1]].reshape(-1)
    fid = np.repeat(np.arange(nf), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (faces.max() + 1 if nf else 1) + hi
    order = np.argsort(key, kind="stable")
    key_s = key[order]
    starts = np.flatnonzero(np.r_[True, key_s[1:] != key_s[:-1]])
    counts = np.diff(np.r_[starts, len(key_s)])
    if np.any(counts > 2):
        raise ModelError("mesh is not edge-manifold: an edge has more than two faces; "
                         "split the mesh along that edge")
    ne = len(starts)
    edge_verts = np.zeros((ne, 2), dtype=np.int32)
    edge_faces = -np.ones((ne, 2), dtype=np.int32)
    edge_opp = -np.ones((ne, 2), dtype=np.int32)
    h0 = order[starts]
    edge_verts[:, 0], edge_verts[:, 1] = a[h0], b[h0]
    edge_faces[:, 0], edge_opp[:, 0] = fid[h0], opp[h0]
    two = counts == 2
    h1 = order[starts[two] + 1]
    if np.any(a[h1] == a[h0[two]]):
        raise ModelError("inconsistent face orientation: two faces traverse an edge in the "
                         "same direction; orient all faces counter-clockwise in material space")
    edge_faces[two, 1], edge_opp[two, 1] = fid[h1], opp[h1]
    return edge_verts, edge_faces, edge_opp


class ClothModel:
    """Rest shape, topology and material of one cloth, in Taichi ndarrays.

    Arrays (capacity rows; the first ``n_*`` are active):
      vert_uv (V, vec2, m)            material coordinates
      vert_mass (V, kg)               lumped mass, density * area / 3 from each face
      vert_pinned (V, i32)            1 where the vertex follows ``vert_pin_target``
      vert_pin_target (V, vec3, m)    where a pinned vertex must be (updated by the scene)
      face_verts (F, ivec3)           counter-clockwise in material space
      face_Dm_inv (F, mat2, 1/m)      inverse of the material edge matrix
      face_rest_area (F, m^2)
      face_grain (F, mat2)            columns: warp and weft unit directions in material space
      edge_verts, edge_faces, edge_opp (E, ivec2)  see ``build_edges``
      edge_rest_angle (E, rad), edge_rest_len (E, m), edge_bend_weight (E, 1):
      w_e, the edge's share of k_bend (BEND_CONSTANT); zero under isotropic bending
      bend_ptr (n_verts + 1, i32), bend_col (Q, i32), bend_val (Q):  the isotropic bending matrix
      (cloth/bending.py) by rows, each row's diagonal first; ``n_bend`` entries, none (every
      row empty) under the hinge energy. Built by ``load`` from the mesh and its pins: faces
      with three pinned vertices are a clamp, held flat (``set_vertex_pin`` does not rebuild
      it; the next load, e.g. a remesh, does)

    ``bending``: "isotropic" (the default for a flat rest shape; k_bend is the plate's B in
    every direction) or "hinge" (the discrete-shells energy: needed for a curved rest shape
    ``rest_x``, which is also its default there; its B depends on the direction, 0.9-3 B).
    """

    BENDING = ("isotropic", "hinge")

    def __init__(self, mesh: MeshArrays, material: Material, capacity_factor=1.5,
                 rest_x=None, bending=None):
        material.validate()
        if bending is None:
            bending = "hinge" if rest_x is not None else "isotropic"
        if bending not in self.BENDING:
            raise ModelError(f"unknown bending '{bending}': use isotropic or hinge")
        if bending == "isotropic" and rest_x is not None:
            raise ModelError("isotropic bending has a flat rest shape: use bending='hinge' for "
                             "a curved rest shape (rest_x)")
        self.bending = bending
        self.material = material
        self.capacity_factor = capacity_factor
        self.v_cap = self.f_cap = self.e_cap = self.q_cap = 0
        self._bending = bending_energy.IsotropicBending()   # per-face terms kept across loads
        self.bend_alpha = 1.0     # the orthotropic stretch the bending matrix was built with
        self.n_verts = self.n_faces = self.n_edges = self.n_bend = 0
        self.load(mesh, rest_x=rest_x)

    # -- allocation ---------------------------------------------------------------------------
    def _allocate(self, nv, nf, ne, nq):
        cf = self.capacity_factor
        self.v_cap, self.f_cap, self.e_cap = (max(int(n * cf) + 8, 16) for n in (nv, nf, ne))
        # Bending entries: ~19 per vertex on grids (its two rings); room for 24 per vertex.
        self.q_cap = max(int(nq * cf) + 8, 24 * self.v_cap if nq else 1)
        V, F, E = self.v_cap, self.f_cap, self.e_cap
        vec, mat2 = ti.types.vector, ti.types.matrix(2, 2, float)
        self.vert_uv = ti.ndarray(vec(2, float), V)
        self.vert_mass = ti.ndarray(float, V)
        self.vert_pinned = ti.ndarray(ti.i32, V)
        self.vert_pin_target = ti.ndarray(vec(3, float), V)
        self.face_verts = ti.ndarray(vec(3, ti.i32), F)
        self.face_Dm_inv = ti.ndarray(mat2, F)
        self.face_rest_area = ti.ndarray(float, F)
        self.face_grain = ti.ndarray(mat2, F)
        self.edge_verts = ti.ndarray(vec(2, ti.i32), E)
        self.edge_faces = ti.ndarray(vec(2, ti.i32), E)
        self.edge_opp = ti.ndarray(vec(2, ti.i32), E)
        self.edge_rest_angle = ti.ndarray(float, E)
        self.edge_bend_weight = ti.ndarray(float, E)
        self.bend_ptr = ti.ndarray(ti.i32, V + 1)
        self.bend_col = ti.ndarray(ti.i32, self.q_cap)
        self.bend_val = ti.ndarray(float, self.q_cap)
        self.state = ClothState(V)

    def fits(self, nv, nf, ne, nq=0):
        return nv <= self.v_cap and nf <= self.f_cap and ne <= self.e_cap and nq <= self.q_cap

    # -- filling from numpy -------------------------------------------------------------------
    def load(self, mesh: MeshArrays, rest_x=None, vertex_map=None):
        """(Re)fill every array from ``mesh`` within the allocated capacity; raises
        CapacityExceeded when it does not fit (build a new ClothModel then). ``vertex_map``
        (old vertex -> new, -1 where removed): ``mesh`` is a remesh of the loaded one, and
        the bending matrix is updated where the remesh changed it instead of rebuilt
        (``bending.IsotropicBending``; the same matrix to round-off)."""
        uv, faces = mesh.uv, mesh.faces
        if uv.ndim != 2 or uv.shape[1] != 2 or mesh.x.shape != (len(uv), 3):
            raise ModelError("mesh arrays have the wrong shape: uv must be (V,2) and x (V,3)")
        if len(faces) == 0:
            raise ModelError("mesh has no faces")
        if faces.min() < 0 or faces.max() >= len(uv):
            raise ModelError("a face refers to a vertex that does not exist")
        area = signed_material_areas(uv, faces)
        scale = max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1]), 1e-12)
        bad = np.flatnonzero(area <= 1e-10 * scale * scale)
        if len(bad):
            raise ModelError(
                f"{len(bad)} degenerate or clockwise material triangle(s) (first: face {bad[0]}, "
                f"area {area[bad[0]]:.3g} m^2): remove zero-area faces and orient every face "
                "counter-clockwise in material (u, v) space")
        if np.any(mesh.pinned) and not np.all(np.isfinite(mesh.pin_target[mesh.pinned])):
            raise ModelError("pin targets must be finite")
        if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(mesh.x))):
            raise ModelError("mesh coordinates must be finite")
        ev, ef, eo = build_edges(faces)
        nv, nf, ne = len(uv), len(faces), len(ev)
        if self.bending == "isotropic":
            alpha = self.material.bend_alpha()
            if alpha != self.bend_alpha:
                # The per-face terms were of other coordinates: start the cache afresh.
                self._bending = bending_energy.IsotropicBending()
                self.bend_alpha = alpha
            buv = uv
            if alpha != 1.0:
                try:
                    buv = bending_energy.orthotropic_coordinates(uv, faces, mesh.grain, alpha)
                except ValueError as e:
                    raise ModelError(str(e)) from None
            Q = self._bending.matrix(buv, faces, ef, eo, area, mesh.pinned, vertex_map)
            bend_ptr, bend_col, bend_val = bending_energy.rows_with_diagonal_first(Q)
        else:
            bend_ptr, bend_col, bend_val = np.zeros(nv + 1, np.int32), np.zeros(0, np.int32), \
                np.zeros(0)
        nq = len(bend_col)
        if not self.fits(nv, nf, ne, nq):
            if self.v_cap > 0:
                # The solvers size their work arrays from the model's capacities, so a model
                # never reallocates itself: the owner builds a new model and solvers
                # (Simulator._rebuild_for; nothing recompiles).
                raise CapacityExceeded(nv, nf, ne, (self.v_cap, self.f_cap, self.e_cap,
                                                    self.q_cap), nq)
            self._allocate(nv, nf, ne, nq)
            # Fresh arrays: the first fill clears every row past the mesh.
            self._filled = (self.v_cap, self.f_cap, self.e_cap, self.q_cap)
        self.n_verts, self.n_faces, self.n_edges, self.n_bend = nv, nf, ne, nq

        # Per-face rest quantities (docs/method.md §2).
        Dm_inv = metrics.material_Dm_inv(uv, faces)    # (F, 2, 2): inverse of the edge matrix
        grain = mesh.grain / np.linalg.norm(mesh.grain, axis=1, keepdims=True)
        mass = np.zeros(nv)
        np.add.at(mass, faces.reshape(-1), np.repeat(area * self.material.density / 3.0, 3))

        # Bending weight BEND_CONSTANT |e|^2 / (A1 + A2) of the hinge energy, in material
        # space so it does not change as the cloth deforms; with it k_bend is the plate's
        # flexural rigidity B (see BEND_CONSTANT).
        inner = (ef[:, 1] >= 0) & (self.bending == "hinge")
        elen = np.linalg.norm(uv[ev[:, 1]] - uv[ev[:, 0]], axis=1)
        weight = np.zeros(ne)
        weight[inner] = BEND_CONSTANT * elen[inner] ** 2 / (area[ef[inner, 0]] + area[ef[inner, 1]])
        rx = mesh.x if rest_x is None else np.asarray(rest_x, dtype=np.float64)
        rest_angle = dihedral_angles(rx, ev, eo) if rest_x is not None else np.zeros(ne)

        # Active rows only, and zeros over the rows a longer earlier mesh left behind
        # (ndarrays.put_rows: the capacity is sized for the finest mesh a remesh may make).
        pv, pf, pe, pq = self._filled
        put = ndarrays.put_rows
        put(self.vert_uv, uv, pv)
        put(self.vert_mass, mass, pv)
        put(self.vert_pinned, mesh.pinned.astype(np.int32), pv)
        put(self.vert_pin_target, mesh.pin_target, pv)
        put(self.face_verts, faces, pf)
        put(self.face_Dm_inv, Dm_inv, pf)
        put(self.face_rest_area, area, pf)
        put(self.face_grain, grain, pf)
        put(self.edge_verts, ev, pe)
        put(self.edge_faces, ef, pe)
        put(self.edge_opp, eo, pe)
        put(self.edge_rest_angle, rest_angle, pe)
        put(self.edge_bend_weight, weight, pe)
        # The kernels loop over every row of bend_ptr, so it has exactly n_verts + 1 rows
        # (not the capacity's: a remeshed cloth's arrays have room for its finest mesh, often
        # ten times its vertices, and the empty rows cost the dynamics' CG ~30 % at 900
        # faces). A new length is a new ndarray (the kernels take arrays as arguments).
        if self.bend_ptr.shape[0] != nv + 1:
            self.bend_ptr = ti.ndarray(ti.i32, nv + 1)
        put(self.bend_ptr, bend_ptr)
        put(self.bend_col, bend_col, pq)
        put(self.bend_val, bend_val, pq)
        put(self.state.x, mesh.x, pv)
        put(self.state.v, mesh.v, pv)
        self._filled = (nv, nf, ne, nq)
        self.state.n = nv
        self.state.step_start_valid = False
        self._np_cache = dict(faces=faces.copy(), uv=uv.copy(), area=area, Dm_inv=Dm_inv,
                              pinned=mesh.pinned.copy(),
                              grain=grain, edges=ev, edge_faces=ef, edge_opp=eo, mass=mass,
                              bend_rows=np.repeat(np.arange(nv), np.diff(bend_ptr)),
                              bend_cols=bend_col)

    @staticmethod
    def _fill_vec(fld, arr, cap):
        """Write ``arr`` into the first rows of ``fld`` (the rest zeroed)."""
        arr = np.asarray(arr)
        full = np.zeros((cap,) + arr.shape[1:], dtype=to_numpy_type(fld.dtype))
        full[: len(arr)] = arr
        fld.from_numpy(full)

    # -- numpy views (for I/O, metrics on the host, remeshing) -------------------------------
    @property
    def faces(self):
        return self._np_cache["faces"]

    @property
    def uv(self):
        return self._np_cache["uv"]

    @property
    def rest_area(self):
        return self._np_cache["area"]

    @property
    def material_Dm_inv(self):
        """(F, 2, 2) inverse edge matrices in material space (``metrics.material_Dm_inv``)."""
        return self._np_cache["Dm_inv"]

    @property
    def pinned(self):
        return self._np_cache["pinned"]

    @property
    def grain(self):
        return self._np_cache["grain"]

    @property
    def mass(self):
        return self._np_cache["mass"]

    @property
    def edges(self):
        return self._np_cache["edges"]

    def edge_topology(self):
        """(edge_verts, edge_faces, edge_opp) of the loaded mesh, as ``build_edges`` gives."""
        c = self._np_cache
        return c["edges"], c["edge_faces"], c["edge_opp"]

    def bend_pattern(self):
        """(rows, cols) of the isotropic bending matrix's entries, in the kernels' order
        (empty under the hinge energy): the block pattern needs them."""
        return self._np_cache["bend_rows"], self._np_cache["bend_cols"]

    def positions(self):
        return ndarrays.get_rows(self.state.x, self.n_verts)

    def velocities(self):
        return ndarrays.get_rows(self.state.v, self.n_verts)

    def set_positions(self, x):
        """Overwrite the first n_verts positions (spare capacity keeps its values). The
        substep's start is then unknown until the next ``mark_step_start``."""
        ndarrays.put_rows(self.state.x, np.asarray(x).reshape(self.n_verts, 3))
        self.state.step_start_valid = False

    def mark_step_start(self):
        """Keep the positions as the substep's start (the dynamics step calls this before it
        moves anything). The strain projection needs where each vertex started: the
        collision pass between the dynamics and the projection moves x without the matching
        v, so x - h v is not the start at contact vertices (measured on the resting drape:
        x - h v broke the limits by 17 %, the true start met them to 4e-6)."""
        ndarrays.copy_rows(self.state.x, self.state.x_step, self.n_verts)
        self.state.step_start_valid = True

    def set_velocities(self, v):
        ndarrays.put_rows(self.state.v, np.asarray(v).reshape(self.n_verts, 3))

    def mesh_arrays(self):
        """The current mesh and state as numpy arrays (the input a remesh needs)."""
        return MeshArrays(uv=self.uv, x=self.positions(), faces=self.faces, v=self.velocities(),
                          pinned=self.pinned,
                          pin_target=ndarrays.get_rows(self.vert_pin_target, self.n_verts),
                          grain=self.grain)

    def all_finite(self, n):
        """1 if the first ``n`` positions and velocities are finite (and below 1e30)."""
        return _all_finite(n, self.state.x, self.state.v)

    def typical_edge(self):
        """The typical edge length (m): the square root of the mean rest area. The scale that
        turns contact and step lengths into strain-like numbers, wherever one is needed."""
        return float(np.sqrt(np.mean(self.rest_area[:self.n_faces])))

    def set_vertex_pin(self, v, pinned, target=None):
        """Pin vertex ``v`` to ``target`` (m) or free it. The array the kernels read and the
        ``pinned`` array the host reads change together."""
        self.vert_pinned[v] = int(bool(pinned))
        self._np_cache["pinned"][v] = bool(pinned)
        if target is not None:
            self.vert_pin_target[v] = [float(c) for c in target]

    def set_pin_targets(self, targets):
        ndarrays.put_rows(self.vert_pin_target, np.asarray(targets).reshape(self.n_verts, 3))


class ClothState:
    """What changes every substep: positions ``x`` (V, vec3, m) and velocities ``v``
    (V, vec3, m/s); ``n`` rows are active. ``x_step``: the positions where the current
    substep started (``ClothModel.mark_step_start``), valid while ``step_start_valid``."""

    def __init__(self, capacity):
        self.x = ti.ndarray(ti.types.vector(3, float), capacity)
        self.v = ti.ndarray(ti.types.vector(3, float), capacity)
        self.x_step = ti.ndarray(ti.types.vector(3, float), capacity)
        self.step_start_valid = False
        self.n = 0


@ti.kernel
def _all_finite(n: ti.i32, x: ti.types.ndarray(), v: ti.types.ndarray()) -> ti.i32:
    ok = 1
    for i in range(n):
        xi, vi = x[i], v[i]
        for c in ti.static(range(3)):
            # NaN fails every comparison; inf fails the bound.
            if not (ti.abs(xi[c]) < 1e30 and ti.abs(vi[c]) < 1e30):
                ok = 0
    return ok
