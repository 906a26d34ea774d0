"""Strain and energy measures: the one definition used by tests, the viewer's heat maps, the
per-frame metrics and the benchmarks.

All functions take numpy arrays (host side): positions ``x`` (V, 3), the model's ``faces``,
``Dm_inv`` (F, 2, 2) and ``grain`` (F, 2, 2, columns warp and weft in material space).

Strains are stretches minus one: ``warp = ||F e_warp|| - 1``, ``weft = ||F e_weft|| - 1``,
``bias = ||F (e_warp + e_weft) / sqrt 2|| - 1`` (the 45-degree direction), and the principal
strains ``eta_j - 1`` from the singular values of F.
"""
import numpy as np


def deformation_gradients(x, faces, Dm_inv):
    """F = Ds Dm^-1 per face, (F, 3, 2)."""
    x = np.asarray(x, dtype=np.float64)
    return columns_times(x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]], Dm_inv)


def columns_times(c0, c1, B):
    """[c0 c1] B for stacks: columns c0, c1 (N, k) and B (N, 2, 2); (N, k, 2). Written out,
    as numpy's batched matmul of small matrices is several times slower."""
    return c0[:, :, None] * B[:, None, 0, :] + c1[:, :, None] * B[:, None, 1, :]


def gram_times(c0, c1, B):
    """(C B)^T (C B) for C = [c0 c1] (columns (N, k)) and B (N, 2, 2): B^T (C^T C) B, from the
    columns' three dot products (the (N, k, 2) product C B is never formed). (N, 2, 2). With
    the edge vectors and Dm^-1 it is F^T F (``cauchy_green``)."""
    g00, g11 = np.einsum("ni,ni->n", c0, c0), np.einsum("ni,ni->n", c1, c1)
    g01 = np.einsum("ni,ni->n", c0, c1)
    b00, b01, b10, b11 = B[:, 0, 0], B[:, 0, 1], B[:, 1, 0], B[:, 1, 1]
    t00, t01 = g00 * b00 + g01 * b10, g00 * b01 + g01 * b11      # (C^T C) B
    t10, t11 = g01 * b00 + g11 * b10, g01 * b01 + g11 * b11
    out = np.empty((len(B), 2, 2))
    out[:, 0, 0] = b00 * t00 + b10 * t10
    out[:, 1, 1] = b01 * t01 + b11 * t11
    out[:, 0, 1] = out[:, 1, 0] = b00 * t01 + b10 * t11
    return out


def cauchy_green(x, faces, Dm_inv):
    """C = F^T F per face (F, 2, 2), F = Ds Dm^-1, without forming F."""
    x = np.asarray(x, dtype=np.float64)
    x0 = x[faces[:, 0]]
    return gram_times(x[faces[:, 1]] - x0, x[faces[:, 2]] - x0, Dm_inv)


def material_Dm_inv(uv, faces):
    Dm = np.stack([uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]], axis=2)
    return np.linalg.inv(Dm)


def face_strains(x, uv, faces, grain, Dm_inv=None):
    """Per-face strains as a dict of (F,) arrays: warp, weft, bias, principal_max,
    principal_min. ``Dm_inv``: the faces' ``material_Dm_inv`` when the caller keeps it (a
    model does: ``ClothModel.material_Dm_inv``)."""
    # Every strain here is a length |F u| = sqrt(u^T C u) of a material direction u, so
    # C = F^T F is all it needs (at 16k faces 3x faster than forming F and F [e_warp e_weft]:
    # metrics.csv reads it every frame).
    C = cauchy_green(x, faces, material_Dm_inv(uv, faces) if Dm_inv is None else Dm_inv)
    a, b, d = C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]
    wu, wv = grain[:, :, 0], grain[:, :, 1]          # warp and weft in material space

    def length(u):
        return np.sqrt(np.maximum(a * u[:, 0] ** 2 + 2.0 * b * u[:, 0] * u[:, 1]
                                  + d * u[:, 1] ** 2, 0.0))

    eta = _stretches_of(a, b, d)
    return {
        "warp": length(wu) - 1.0,
        "weft": length(wv) - 1.0,
        "bias": length(wu + wv) / np.sqrt(2.0) - 1.0,
        "principal_max": eta[:, 0] - 1.0,
        "principal_min": eta[:, 1] - 1.0,
    }


def band_violation(strain, band):
    """How far each value lies outside ``band = (lo, hi)``; 0 inside."""
    lo, hi = band
    return np.maximum(0.0, np.maximum(strain - hi, lo - strain))


def weighted_rms(values, area):
    area = np.asarray(area, dtype=np.float64)
    return float(np.sqrt(np.sum(area * np.asarray(values) ** 2) / max(area.sum(), 1e-300)))


def summarize(values, area):
    """max |value| and area-weighted RMS, as floats."""
    values = np.asarray(values)
    if values.size == 0:
        return 0.0, 0.0
    return float(np.max(np.abs(values))), weighted_rms(values, area)


def kinetic_energy(v, mass):
    v = np.asarray(v, dtype=np.float64)
    return 0.5 * float(np.sum(mass * np.einsum("ij,ij->i", v, v)))


def default_bias_band(warp_band, weft_band):
    """The bias band (in bias-strain units) that keeps every unsheared state inside the warp
    and weft bands feasible (docs/method.md §3.2 [fix]): ||w_u + w_v|| between
    sqrt((1+warp_min)^2 + (1+weft_min)^2) and the same with the maxima, divided by sqrt 2."""
    lo = np.hypot(1.0 + warp_band[0], 1.0 + weft_band[0]) / np.sqrt(2.0) - 1.0
    hi = np.hypot(1.0 + warp_band[1], 1.0 + weft_band[1]) / np.sqrt(2.0) - 1.0
    return float(lo), float(hi)


def signed_material_areas(uv, faces):
    """Rest (material) area per face, m^2, negative where a face is flipped in material space."""
    e1, e2 = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def material_areas(uv, faces):
    """Rest (material) area per face, m^2."""
    return np.abs(signed_material_areas(uv, faces))


def dihedral_angles(x, edge_verts, edge_opp):
    """Signed dihedral angle per interior edge (0 where flat, 0 for boundary edges), with the
    same convention as the bending kernel in dynamics.py."""
    theta = np.zeros(len(edge_verts))
    inner = np.flatnonzero(edge_opp[:, 1] >= 0)
    # Coordinate columns gathered once each: numpy's row-wise cross products and einsums on
    # (N, 3) arrays cost several times this (the remesh's sizing reads it every frame).
    cols = [np.ascontiguousarray(x[:, c], dtype=np.float64) for c in range(3)]
    i0, i1 = edge_verts[inner, 0], edge_verts[inner, 1]
    i2, i3 = edge_opp[inner, 0], edge_opp[inner, 1]
    x0 = [c.take(i0) for c in cols]
    e = [c.take(i1) - a for c, a in zip(cols, x0)]
    a = [c.take(i2) - b for c, b in zip(cols, x0)]
    b = [c.take(i3) - q for c, q in zip(cols, x0)]
    n1 = _cross_columns(e, a)
    n2 = _cross_columns(b, e)
    m = _cross_columns(n1, n2)
    el = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    sin = (m[0] * e[0] + m[1] * e[1] + m[2] * e[2]) / el
    cos = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2]
    theta[inner] = np.arctan2(sin, cos)
    return theta


def _cross_columns(a, b):
    """a x b for vectors given as three coordinate arrays each."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def wrinkle_measures(x, faces, edges, edge_faces, edge_opp, uv):
    """Fold measures over interior edges (flat cloth gives 0):
    ``mean_abs_dihedral``, the mean |dihedral angle| (rad) weighted by material edge length;
    ``curvature_energy``, the discrete-shells sum 3 |e|^2 theta^2 / (A1 + A2) (dimensionless;
    kept as the wrinkle measure of the Table 1/2 documents, whatever bending energy the
    model uses: under ``bending = "hinge"`` the model's energy is k_bend / 2 times this sum
    scaled by model.BEND_CONSTANT / 3)."""
    theta = dihedral_angles(np.asarray(x, np.float64), edges, edge_opp)
    inner = edge_faces[:, 1] >= 0
    elen = np.linalg.norm(uv[edges[:, 1]] - uv[edges[:, 0]], axis=1)[inner]
    area = material_areas(uv, faces)
    a12 = area[edge_faces[inner, 0]] + area[edge_faces[inner, 1]]
    th = theta[inner]
    return {"mean_abs_dihedral": float(np.sum(elen * np.abs(th)) / max(elen.sum(), 1e-300)),
            "curvature_energy": float(np.sum(3.0 * elen ** 2 * th ** 2 / a12))}


def percentile(values, q):
    return float(np.percentile(np.asarray(values), q)) if np.size(values) else 0.0


def locate_in_material(uv, faces, points, chunk=256):
    """For material points (P, 2): the containing face and its barycentric weights, found by
    brute force in chunks (a point on an edge takes the first face found). Points outside
    the mesh take the face with the least negative weight. Returns (face (P,), bary (P, 3))."""
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    face = np.zeros(len(points), dtype=np.int64)
    bary = np.zeros((len(points), 3))
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk, None, :] - a[None, :, :]             # (p, F, 2)
        w1 = (p[..., 0] * e2[:, 1] - p[..., 1] * e2[:, 0]) / det
        w2 = (e1[:, 0] * p[..., 1] - e1[:, 1] * p[..., 0]) / det
        w0 = 1.0 - w1 - w2
        worst = np.minimum(np.minimum(w0, w1), w2)                   # >= 0 inside
        f = np.argmax(worst, axis=1)
        r = np.arange(len(f))
        face[s:s + chunk] = f
        bary[s:s + chunk] = np.stack([w0[r, f], w1[r, f], w2[r, f]], axis=1)
    return face, bary


def positions_at_material_points(x, uv, faces, points):
    """World positions of material points, interpolated linearly inside their faces."""
    face, bary = locate_in_material(uv, faces, points)
    tri = np.asarray(x)[faces[face]]                                 # (P, 3, 3)
    return np.einsum("pk,pkd->pd", bary, tri)


def material_sample_points(uv, n=21):
    """A regular n x n grid of material points inside the bounding box of ``uv``, shrunk by
    1e-9 so every point is strictly inside a rectangular sheet."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    pad = 1e-9 * (hi - lo)
    s = np.linspace(lo[0] + pad[0], hi[0] - pad[0], n)
    t = np.linspace(lo[1] + pad[1], hi[1] - pad[1], n)
    S, T = np.meshgrid(s, t, indexing="ij")
    return np.stack([S.ravel(), T.ravel()], axis=1)


def solution_error(run, reference, points):
    """RMS distance between two runs' positions at the same material points, divided by the
    cloth's size (the diagonal of its material bounding box). ``run`` and ``reference`` are
    (x, uv, faces) triples; their meshes may differ (remeshing, resolution)."""
    xa = positions_at_material_points(*run, points)
    xb = positions_at_material_points(*reference, points)
    size = float(np.linalg.norm(np.ptp(reference[1], axis=0)))
    return float(np.sqrt(np.mean(np.sum((xa - xb) ** 2, axis=1))) / size)


def gravitational_energy(x, mass, gravity):
    """-sum m g.x (J): potential energy of the masses in a uniform field ``gravity``."""
    return -float(np.sum(mass * (np.asarray(x) @ np.asarray(gravity))))


def energy_drift(total_energy, scale):
    """Energy gained where none may enter: the largest rise of the total mechanical energy
    (kinetic + elastic + gravitational) above its lowest earlier value,
    max_t (E_t - min_{s <= t} E_s), divided by ``scale`` (J; the benchmarks use the cloth's
    weight times its size, m |g| L). For a scene whose pins and obstacles stand still and
    without wind, no energy enters, so any rise is numerical error: 0 is exact, a value near 1
    means the cloth gained the energy of a fall through its own size. Backward Euler with
    damping only loses energy (its drift is 0, tested); the strain projection's velocity
    update dx / h can add some (hanging, mapping: 4.5e-3 at one substep, 6.7e-5 at four).
    (The loss itself is not an error: it is the integrator's damping.)"""
    e = np.asarray(total_energy, dtype=np.float64)
    if e.size == 0:
        return 0.0
    return float(np.max(e - np.minimum.accumulate(e)) / scale)


# -- what each method limits: its constraints on the host (the teaching view, its tests) ------
# The constraints of docs/method.md §3 in strain units (g / sqrt(a), <= 0 where they hold), in
# the order of cloth/strain/constraints.py (mapping: principal pairs ordered by alignment with
# the warp, A the principal direction nearer it, as the solver orders them). The teaching
# view's points, regions and binding map come from here; tests/test_teaching.py checks these
# values against the solver's own (``StrainLimiter.constraint_values``).
CONSTRAINT_NAMES = {
    "svd": ("eta1 min", "eta1 max", "eta2 min", "eta2 max"),
    "warp-weft": ("warp min", "warp max", "weft min", "weft max", "bias min", "bias max"),
    "mapping": ("warp via A max", "warp via A min", "warp via B max", "warp via B min",
                "weft via A max", "weft via A min", "weft via B max", "weft via B min"),
}


def _stretches(F):
    """(eta, (a, b, d)) for F (n, 3, 2): the singular values, descending, and the entries of
    C = F^T F = [[a, b], [b, d]]."""
    f0, f1 = F[:, :, 0], F[:, :, 1]
    a, b, d = (np.einsum("ni,ni->n", f0, f0), np.einsum("ni,ni->n", f0, f1),
               np.einsum("ni,ni->n", f1, f1))
    return _stretches_of(a, b, d), (a, b, d)


def _stretches_of(a, b, d):
    """The singular values (n, 2), descending, of an F with F^T F = [[a, b], [b, d]]."""
    r = np.hypot(0.5 * (a - d), b)
    # m - r by m^2 - r^2 = det C over m + r: no cancellation when the smaller stretch is small.
    lam1 = 0.5 * (a + d) + r
    lam2 = np.where(lam1 > 0, (a * d - b * b) / np.where(lam1 > 0, lam1, 1.0), 0.0)
    return np.sqrt(np.maximum(np.stack([lam1, lam2], axis=1), 0.0))


def singular_values(F):
    """eta (n, 2), the singular values of each F (n, 3, 2), descending: ``principal_stretches``
    without the directions (every frame's metrics, through ``face_strains``: numpy's batched
    SVD took 10 ms a frame at 16k faces)."""
    return _stretches(np.asarray(F, np.float64))[0]


def principal_stretches(F):
    """Thin SVD of F (n, 3, 2): ``eta`` (n, 2) descending, ``V`` (n, 2, 2) with columns the
    principal directions in material space, ``U`` (n, 3, 2) with columns their world images
    (docs/method.md §2).

    In closed form from C = F^T F (2 x 2 symmetric), about 10x faster than numpy's batched
    SVD (the teaching view calls it every frame): eta^2 = m +- r, m = (C00 + C11) / 2,
    r = |((C00 - C11) / 2, C01)|; V the rotation by theta = atan2(2 C01, C00 - C11) / 2; U =
    F V / eta (where eta = 0, U's column is 0). The signs of V's and U's columns may differ
    from numpy's SVD (tests/test_teaching.py compares them up to sign)."""
    F = np.asarray(F, np.float64)
    eta, (a, b, d) = _stretches(F)
    th = 0.5 * np.arctan2(2.0 * b, a - d)
    c, s = np.cos(th), np.sin(th)
    V = np.stack([np.stack([c, -s], axis=1), np.stack([s, c], axis=1)], axis=1)   # (n, 2, 2)
    FV = F @ V
    U = FV / np.where(eta > 0, eta, 1.0)[:, None, :]
    return eta, V, U


def mapping_factors(F, grain, iso=0.0, svd=None):
    """The inverse mapping's factors c~_ij (docs/method.md §3.3) as (n, 2, 2) [grain i (warp, weft),
    pair j (A, B)] with the principal stretches of the pairs (n, 2). A is the major principal
    direction (eta1; the one nearer the warp under strain.families.MAPPING_PAIRS_BY_ALIGNMENT). ``iso`` is the solver's closure at isotropy
    (``strain.isotropy``; constraints.MAPPING_ISO): c~ = sqrt(w c^2 + (1 - w) / 2),
    w = D^2 / (D^2 + iso^2), D = eta1^2 - eta2^2; iso = 0 is the paper's c = |e_i . v_j|.
    ``svd``: ``principal_stretches(F)`` if already computed."""
    eta, V, _ = principal_stretches(F) if svd is None else svd
    c = np.abs(np.einsum("nki,nkj->nij", np.asarray(grain, np.float64), V))
    from .strain.families import MAPPING_PAIRS_BY_ALIGNMENT
    swap = (c[:, 0, 1] > c[:, 0, 0]) & MAPPING_PAIRS_BY_ALIGNMENT
    c[swap] = c[swap][:, :, ::-1]
    eta_pair = np.where(swap[:, None], eta[:, ::-1], eta)
    if iso > 0:
        D = eta[:, 0] ** 2 - eta[:, 1] ** 2
        w = (D * D / (D * D + iso * iso))[:, None, None]
        c = np.sqrt(w * c * c + 0.5 * (1.0 - w))
    return c, eta_pair


def own_constraint_values(method, x, faces, Dm_inv, grain, bands, iso=0.0):
    """(n, K) values of ``method``'s constraints in strain units (<= 0 where they hold), in
    the order of ``CONSTRAINT_NAMES``; ``bands`` maps warp, weft and bias to (min, max) strain
    bands (bias None or missing: ``default_bias_band``). The warp-weft bias constraint bounds
    ||w_u + w_v|| = sqrt 2 (1 + bias strain), so its value is sqrt 2 x the bias strain's
    distance past its band."""
    warp, weft = tuple(bands["warp"]), tuple(bands["weft"])
    F = deformation_gradients(x, faces, Dm_inv)
    if method == "svd":
        eta = principal_stretches(F)[0] - 1.0
        cols = [warp[0] - eta[:, 0], eta[:, 0] - warp[1], weft[0] - eta[:, 1], eta[:, 1] - weft[1]]
    elif method == "warp-weft":
        bias = tuple(bands.get("bias") or default_bias_band(warp, weft))
        Fg = F @ np.asarray(grain, np.float64)
        wu, wv = Fg[:, :, 0], Fg[:, :, 1]
        s_u, s_v = np.linalg.norm(wu, axis=1) - 1.0, np.linalg.norm(wv, axis=1) - 1.0
        s_b = np.linalg.norm(wu + wv, axis=1) / np.sqrt(2.0) - 1.0
        r2 = np.sqrt(2.0)
        cols = [warp[0] - s_u, s_u - warp[1], weft[0] - s_v, s_v - weft[1],
                r2 * (bias[0] - s_b), r2 * (s_b - bias[1])]
    elif method == "mapping":
        c, eta = mapping_factors(F, grain, iso)
        s = c * (eta[:, None, :] - 1.0)                      # (n, grain i, pair j)
        cols = []
        for i, band in enumerate((warp, weft)):
            for j in range(2):
                cols += [s[:, i, j] - band[1], band[0] - s[:, i, j]]
    else:
        raise ValueError(f"unknown strain-limiting method '{method}'")
    return np.stack(cols, axis=1)


def strain_space(method, x, faces, Dm_inv, grain, bands, iso=0.0):
    """The points of the teaching view's strain-space plot, per face, in strains:
    ``principal`` (n, 2) the principal strains (eta1 - 1, eta2 - 1); ``grain`` (n, 2) the warp
    and weft thread strains; ``bias`` (n,) the bias strain; under mapping also ``mapped``
    (n, 2, 2): for the pairs A and B (axis 1) the mapped strains c~_warp,j (eta_j - 1) and
    c~_weft,j (eta_j - 1) (axis 2), the quantities its constraints bound."""
    F = deformation_gradients(x, faces, Dm_inv)
    svd = principal_stretches(F)
    eta = svd[0]
    Fg = F @ np.asarray(grain, np.float64)
    wu, wv = Fg[:, :, 0], Fg[:, :, 1]
    out = {"principal": eta - 1.0,
           "grain": np.stack([np.linalg.norm(wu, axis=1), np.linalg.norm(wv, axis=1)], 1) - 1.0,
           "bias": np.linalg.norm(wu + wv, axis=1) / np.sqrt(2.0) - 1.0}
    if method == "mapping":
        c, eta_pair = mapping_factors(F, grain, iso, svd)
        out["mapped"] = np.swapaxes(c * (eta_pair[:, None, :] - 1.0), 1, 2)
    return out


def feasible_region(method, plane, bands):
    """The box a method's constraints carve out of a plane of ``strain_space``, as
    ((x_min, x_max), (y_min, y_max)) in strains, or None where the method bounds nothing in
    that plane. svd: the principal plane, eta1 - 1 in the warp band and eta2 - 1 in the weft
    band (and eta2 <= eta1 by definition); warp-weft: the grain plane, warp x weft band (and
    the bias strain in its band, ``feasible_region(.., "bias", ..)``, an interval); mapping:
    the mapped plane, each pair's mapped warp x weft strain in warp x weft band."""
    warp, weft = tuple(bands["warp"]), tuple(bands["weft"])
    if (method, plane) in (("svd", "principal"), ("warp-weft", "grain"), ("mapping", "mapped")):
        return warp, weft
    if (method, plane) == ("warp-weft", "bias"):
        return tuple(bands.get("bias") or default_bias_band(warp, weft))
    return None


def binding_constraints(lam, n_constraints):
    """Per face, the index of the constraint that binds (the one with the largest positive
    multiplier, the solver's force holding it at its bound), -1 where none does. ``lam``
    (n, >= K) the multipliers of the method's ``n_constraints`` = K constraints: one with
    lam > 0 is at its bound within the solver's tolerance once the solve has converged
    (complementarity; tests/test_teaching.py checks it)."""
    lam = np.asarray(lam, np.float64)[:, :n_constraints]
    k = np.argmax(lam, axis=1)
    return np.where(lam[np.arange(len(k)), k] > 0.0, k, -1)
