"""The isotropic bending energy's boundary treatment (cloth/bending.py): exact second
derivatives at free edges and clamps for the fields those boundaries allow, no energy for
affine maps or held (clamped) faces. Host-side numpy only, no simulation."""
import numpy as np
import pytest

from cloth import bending
from cloth.model import build_edges, signed_material_areas
from cloth.sheet import make_sheet


def _mesh(pattern, h=0.01, length=0.13, width=0.05, u0=-0.03):
    if pattern == "irregular":
        from benchmarks.calibration import irregular_strip
        uv, faces, _ = irregular_strip(length, width, h, seed=3, cuts=(-u0,))
    else:
        uv, faces = make_sheet(length, width, int(round(length / h)) + 1,
                               int(round(width / h)) + 1, pattern, seed=2)
    uv = uv + np.array([u0, 0.0])
    ev, ef, eo = build_edges(faces)
    return uv, faces.astype(np.int64), ev, ef, eo, signed_material_areas(uv, faces)


def _trace(uv, faces, ef, eo, area, pinned):
    held = bending.held_faces(faces, pinned)
    fits = bending.FaceFits(uv, faces, ef, eo, area, held)
    return bending.trace_rows(uv, faces, fits, ~held, len(uv))


@pytest.mark.parametrize("pattern", ["regular", "alternating", "random"])
def test_trace_is_exact_up_to_the_clamp_and_the_free_edges(pattern):
    # A strip clamped at u = 0 (the vertices of u <= 0 pinned) bent as w = u^2 / 2 beyond it:
    # the clamped cantilever's shape near the root, C1 at the clamp, and X_nn = X_vv = 0 on
    # the free long edges (the moment-free edge). tr II = 1 at every live vertex, on the
    # clamp line and the long edges too (away from the free end u = 0.1, where this field's
    # X_uu = 1 is a moment the free edge does not carry). Pinned rows counted as cloth gave
    # 0.5 on the clamp line; the lumped third of the areas gave 0.75 and 1.5 at the
    # alternating pattern's two kinds of vertex.
    uv, faces, ev, ef, eo, area = _mesh(pattern)
    pinned = uv[:, 0] <= 1e-12
    w = 0.5 * np.maximum(uv[:, 0], 0.0) ** 2
    T, A = _trace(uv, faces, ef, eo, area, pinned)
    tr = T @ w
    check = (uv[:, 0] > -1e-12) & (uv[:, 0] < 0.1 - 0.015)
    assert np.all(A[check] > 0) and np.all(A[uv[:, 0] < -0.015] == 0)
    assert np.allclose(tr[check], 1.0, atol=1e-9)
    # The same bend on a tilted ledge (an affine map added everywhere) reads the same.
    tilt = w + 0.4 * uv[:, 0] - 0.2 * uv[:, 1] + 0.1
    assert np.allclose((T @ tilt)[check], 1.0, atol=1e-9)


@pytest.mark.parametrize("pattern", ["regular", "alternating", "random"])
def test_twist_has_no_trace_at_any_vertex_and_its_deviator_everywhere(pattern):
    # w = u v: X_uv = 1, X_uu = X_vv = 0, and X_nn = 0 on every edge of the rectangle, so the
    # free-edge fits and the outline's flux are exact at the boundary vertices too. Not at the
    # four corners: there the cotangent Laplacian's flux through the cell's inner sides (from
    # the faces' linear gradients) misses the twist's (+-h^2 / 4, which the interior's
    # neighbouring cells cancel), so tr II reads +-1 in one cell of h^2 / 4 per corner: an
    # error of O(h^2) in the energy of a sheet.
    uv, faces, ev, ef, eo, area = _mesh(pattern)
    w = uv[:, 0] * uv[:, 1]
    T, A = _trace(uv, faces, ef, eo, area, None)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    corner = np.all(np.isclose(uv, lo) | np.isclose(uv, hi), axis=1)
    assert corner.sum() == 4
    assert np.allclose((T @ w)[~corner], 0.0, atol=1e-9)
    assert np.abs(T @ w)[corner].max() < 1.0 + 1e-9
    assert A.sum() == pytest.approx(area.sum(), rel=1e-12)      # the cells tile the strip
    sten, C = bending.face_fit(uv, faces, ef, eo, area)
    assert np.allclose(np.einsum("fan,fn->fa", C, w[sten]), [0.0, 0.0, 1.0], atol=1e-8)


@pytest.mark.parametrize("pattern", ["regular", "alternating", "irregular"])
def test_fit_next_to_the_clamp_joins_the_held_face_with_its_slope(pattern):
    # The faces along the clamp line replace the point across it (on the flat ledge, a kink
    # away) by the held face's slope: their fit of the C1 field is exact, where a fit through
    # the ledge's vertex would average the kink into the curvature.
    uv, faces, ev, ef, eo, area = _mesh(pattern)
    pinned = uv[:, 0] <= 1e-12
    held = bending.held_faces(faces, pinned)
    fits = bending.FaceFits(uv, faces, ef, eo, area, held)
    at_clamp = (fits.kind == bending.CLAMPED_EDGE).any(axis=1)
    assert at_clamp.sum() >= 4 and not (held & at_clamp).any()
    w = 0.5 * np.maximum(uv[:, 0], 0.0) ** 2
    C = fits.coef[:, 3:6] / fits.scale[:, None, None] ** 2
    H = np.einsum("fan,fn->fa", C, w[fits.sten])
    assert np.allclose(H[at_clamp], [1.0, 0.0, 0.0], atol=1e-8)


@pytest.mark.parametrize("pattern", ["alternating", "irregular"])
def test_affine_maps_cost_nothing_and_held_faces_carry_no_energy(pattern):
    uv, faces, ev, ef, eo, area = _mesh(pattern)
    pinned = uv[:, 0] <= 1e-12
    Q = bending.isotropic_matrix(uv, faces, ev, ef, eo, area, pinned)
    scale = abs(Q).max()
    for f in (np.ones(len(uv)), uv[:, 0], uv[:, 1], 0.3 * uv[:, 0] - 2.0 * uv[:, 1] + 5.0):
        assert np.abs(Q @ f).max() < 1e-10 * scale * np.abs(f).max()
    # Held faces carry no energy: only the pinned rows next to the live faces enter (the
    # clamp line, and the row behind it through the held faces' slope); deeper in, moving a
    # pinned vertex costs nothing.
    held = bending.held_faces(faces, pinned)
    near = np.zeros(len(uv), bool)
    near[faces[~held].ravel()] = True
    near[faces[held & near[faces].any(axis=1)].ravel()] = True
    inside = ~near
    assert inside.sum() >= 3 and np.all(uv[inside, 0] < 0)
    assert abs(Q[inside]).max() == 0.0
    assert abs(Q[near & pinned]).max() > 0.0
    # A bend of the free part costs energy (no spurious zero mode there).
    w = 0.5 * np.maximum(uv[:, 0], 0.0) ** 2
    assert w @ (Q @ w) > 0.5 * 0.1 * 0.05 * 0.5


def test_one_row_of_pins_is_no_clamp():
    # A single pinned row (a hanging sheet's top row) holds positions, not the slope: no face
    # is held and the energy is the unpinned one.
    uv, faces, ev, ef, eo, area = _mesh("regular")
    row = np.abs(uv[:, 0] - 0.0) < 1e-12
    assert not bending.held_faces(faces, row).any()
    Q0 = bending.isotropic_matrix(uv, faces, ev, ef, eo, area)
    Q1 = bending.isotropic_matrix(uv, faces, ev, ef, eo, area, row)
    assert abs(Q1 - Q0).max() == 0.0


# ---- orthotropic bending ---------------------------------------------------------------------
def _strip_energy(L, W, h, pattern, field, alpha, grain_angle=0.0, clamp=True):
    """(1/2) z^T Q z of the height field ``field(u, v)`` on a strip [-2h, L] x [0, W] whose
    plate is orthotropic with stretch ``alpha`` (the warp at ``grain_angle`` from u), held
    flat on u <= 0 when ``clamp`` (field evaluated at max(u, 0))."""
    from cloth.model import grain_from_angle
    uv, faces = make_sheet(L + 2 * h, W, int(round((L + 2 * h) / h)) + 1,
                           int(round(W / h)) + 1, pattern, seed=2)
    uv = uv - np.array([2 * h, 0.0])
    ev, ef, eo = build_edges(faces)
    area = signed_material_areas(uv, faces)
    buv = bending.orthotropic_coordinates(uv, faces, grain_from_angle(grain_angle, len(faces)),
                                          alpha)
    Q = bending.isotropic_matrix(buv, faces, ev, ef, eo, area,
                                 uv[:, 0] <= 1e-12 if clamp else None)
    z = field(np.maximum(uv[:, 0], 0.0) if clamp else uv[:, 0], uv[:, 1])
    return 0.5 * z @ (Q @ z)


@pytest.mark.parametrize("pattern", ["regular", "alternating", "random"])
@pytest.mark.parametrize("ratio", [4.0, 0.1])
def test_orthotropic_plate_has_its_closed_form_energy_per_area(pattern, ratio):
    # The plate of B_warp = ratio B_weft (H = sqrt(B_warp B_weft) = 1 here): energy density
    # (1/2) (B_warp k11^2 + B_weft k22^2 + 2 H k12^2). Read far from the strip's ends as the
    # difference of a 30 and a 20 cm strip (the ends are the same stencils; adding an affine
    # map costs nothing), so the boundary layers cancel and the interior must be exact:
    # bending along the warp (u^2 / 2, clamped at u = 0: B_warp / 2 per area), along the weft
    # (the same strip with the warp turned to v: B_weft / 2) and twist (u v, all edges free:
    # H per area).
    alpha = bending.orthotropic_stretch(ratio, 1.0)
    H = 1.0
    b_warp, b_weft = H * alpha ** 4, H / alpha ** 4
    assert b_warp / b_weft == pytest.approx(ratio)
    W, dA = 0.06, 0.1 * 0.06

    def per_area(field, **kw):
        e = [_strip_energy(L, W, 0.01, pattern, field, alpha, **kw) for L in (0.2, 0.3)]
        return (e[1] - e[0]) / dA
    assert per_area(lambda u, v: 0.5 * u * u) == pytest.approx(b_warp / 2, rel=1e-8)
    assert per_area(lambda u, v: 0.5 * u * u, grain_angle=np.pi / 2) == \
        pytest.approx(b_weft / 2, rel=1e-8)
    assert per_area(lambda u, v: u * v, clamp=False) == pytest.approx(H, rel=1e-8)


def test_equal_rigidities_leave_the_isotropic_matrix_bit_for_bit():
    assert bending.orthotropic_stretch(2e-5, 2e-5) == 1.0
    uv, faces, ev, ef, eo, area = _mesh("random")
    grain = np.tile(np.eye(2), (len(faces), 1, 1))
    same = bending.orthotropic_coordinates(uv, faces, grain, 1.0)
    assert np.array_equal(same, uv)
    # The material: k_bend_warp = k_bend_weft = 0 (the default) is k_bend itself, exactly.
    from cloth.model import Material
    m = Material(k_bend=1.2345e-5)
    assert m.bend_scale() == 1.2345e-5 and m.bend_alpha() == 1.0
    m = Material(k_bend=1.0, k_bend_warp=4e-5, k_bend_weft=1e-5)
    assert m.bend_scale() == pytest.approx(2e-5) and m.bend_alpha() == pytest.approx(4 ** 0.125)


def test_orthotropic_coordinates_keep_areas_and_need_one_grain_per_piece():
    from cloth.model import grain_from_angle
    uv, faces, ev, ef, eo, area = _mesh("alternating")
    g = grain_from_angle(0.3, len(faces))
    buv = bending.orthotropic_coordinates(uv, faces, g, 1.4)
    assert np.allclose(signed_material_areas(buv, faces), area, rtol=1e-12)
    g[5] = grain_from_angle(0.0, 1)[0]
    with pytest.raises(ValueError, match="one grain per piece"):
        bending.orthotropic_coordinates(uv, faces, g, 1.4)
    # Two separate pieces may have different grains.
    uv2 = np.r_[uv, uv + [1.0, 0.0]]
    faces2 = np.r_[faces, faces + len(uv)]
    g2 = np.r_[grain_from_angle(0.0, len(faces)), grain_from_angle(np.pi / 2, len(faces))]
    b2 = bending.orthotropic_coordinates(uv2, faces2, g2, 1.4)
    assert np.allclose(b2[:len(uv), 0], uv[:, 0] / 1.4) and \
        np.allclose(b2[len(uv):, 1], (uv[:, 1]) / 1.4)
