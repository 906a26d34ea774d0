"""The three strain-limiting constraint families (docs/method.md §3) against reference data, finite
differences and the closed-form 2x2 eigen-solver."""
import json
import os

import numpy as np
import pytest

from cloth.strain import constraints as C

# Reference values from an independent float64 implementation (docs/method.md §3.3).
TESTDATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data",
                        "constraint_vectors.json")
FAMILIES = {"svd": "svd", "warp-weft": "warp_weft", "mapping": "mapping"}


def load_cases():
    with open(TESTDATA) as fh:
        return json.load(fh)["cases"]


def triangle_arrays(uv, x):
    uv, x = np.asarray(uv, float), np.asarray(x, float)
    Dm = np.stack([uv[1] - uv[0], uv[2] - uv[0]], axis=1)
    return np.linalg.inv(Dm), 0.5 * abs(np.linalg.det(Dm))


def evaluate_one(method, x, Dm_inv, area, warp, weft, shear, grain=np.eye(2), **kw):
    g, grad = C.evaluate(method, x[None], Dm_inv[None], grain[None], np.array([area]),
                         warp, weft, shear, **kw)
    return g[0], grad[0]


def numpy_mapping_pieces(x, Dm_inv, area, grain=np.eye(2)):
    """Independent numpy pieces of the mapping gradient (docs/method.md §3.3): for each (i, j) the
    eta part sqrt(a) c_ij d eta_j and the principal-frame part sqrt(a)(eta_j - 1)(e_i.dv_j),
    to be combined with the sign s_ij of e_i . v_j; also e_i . v_j itself."""
    F = np.stack([x[1] - x[0], x[2] - x[0]], axis=1) @ Dm_inv
    U, eta, Vt = np.linalg.svd(F, full_matrices=False)
    V = Vt.T
    M = [-Dm_inv[0] - Dm_inv[1], Dm_inv[0], Dm_inv[1]]
    dtheta = np.concatenate([(Mn @ V[:, 1]) * (F @ V[:, 0]) + (Mn @ V[:, 0]) * (F @ V[:, 1])
                             for Mn in M]) / (eta[0] ** 2 - eta[1] ** 2)
    sqa = np.sqrt(area)
    pieces = []
    for i in range(2):
        e = grain[:, i]
        for j in range(2):
            deta = np.concatenate([(Mn @ V[:, j]) * U[:, j] for Mn in M])
            e_dv = (e @ V[:, 1]) * dtheta if j == 0 else -(e @ V[:, 0]) * dtheta
            ev = e @ V[:, j]
            pieces.append((ev, sqa * abs(ev) * deta, sqa * (eta[j] - 1) * e_dv))
    return pieces


# ---- reference data -------------------------------------------------------------------------
@pytest.mark.parametrize("method", list(FAMILIES))
def test_reference_vectors(method):
    """All 30 reference triangles: values and gradients to ~1e-9 (values ~1e-3, gradients ~1).

    Mapping at an exact kink (|e_i . v_j| = 0 up to round-off, axis-aligned cases): |.| has
    no derivative there, and the reference picked a one-sided derivative by the sign of its
    round-off. We use the minimum-norm subgradient (sign 0) and check that the reference is
    one of the one-sided ones."""
    key = FAMILIES[method]
    kinks = 0
    for case in load_cases():
        Dm_inv, area = triangle_arrays(case["uv"], case["x"])
        assert area == pytest.approx(case["rest_area"], rel=1e-12)
        g, grad = evaluate_one(method, np.array(case["x"]), Dm_inv, case["rest_area"],
                               case["warp"], case["weft"], case["warp_weft"]["shear_band"])
        ref_g, ref_grad = np.array(case[key]["values"]), np.array(case[key]["grad"])
        np.testing.assert_allclose(g, ref_g, rtol=0, atol=1e-9, err_msg=case["kind"])
        if method != "mapping":
            np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9, err_msg=case["kind"])
            continue
        pieces = numpy_mapping_pieces(np.array(case["x"]), Dm_inv, case["rest_area"])
        for p, (ev, eta_part, frame_part) in enumerate(pieces):
            for k, sign in ((2 * p, 1.0), (2 * p + 1, -1.0)):   # upper, lower
                if abs(ev) > 1e-9:
                    np.testing.assert_allclose(grad[k], ref_grad[k], rtol=0, atol=1e-9)
                    continue
                kinks += 1
                np.testing.assert_allclose(grad[k], sign * eta_part, rtol=0, atol=1e-9)
                assert min(np.abs(ref_grad[k] - sign * (eta_part + s * frame_part)).max()
                           for s in (-1.0, 0.0, 1.0)) < 1e-9
    if method == "mapping":
        assert kinks > 0      # the data does contain axis-aligned cases


# ---- finite differences -----------------------------------------------------------------------
def random_triangles(rng, n):
    """Well-shaped material triangles, deformed by random stretch / compression / shear and a
    random rotation, with the grain rotated away from the material axes."""
    cases = []
    while len(cases) < n:
        ang = rng.uniform(0, 2 * np.pi, 3) + np.array([0, 2.1, 4.2])
        uv = 0.05 * np.c_[np.cos(ang), np.sin(ang)] + rng.normal(0, 0.003, (3, 2))
        e1, e2 = uv[1] - uv[0], uv[2] - uv[0]
        if e1[0] * e2[1] - e1[1] * e2[0] <= 0:
            uv = uv[[0, 2, 1]]
        Dm_inv, area = triangle_arrays(uv, np.zeros((3, 3)))
        if area < 1e-3:
            continue
        S = np.array([[rng.uniform(0.85, 1.15), rng.uniform(-0.2, 0.2)],
                      [0.0, rng.uniform(0.85, 1.15)]])
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        F = Q[:, :2] @ S                        # 3x2: rotated, stretched, sheared
        x = rng.normal(0, 1, 3) + uv @ F.T
        theta = rng.uniform(0, np.pi)
        grain = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        eta = np.linalg.svd(F, compute_uv=False)
        V = np.linalg.svd(F)[2].T
        # Stay away from the two non-smooth points of the mapping family: eta1 = eta2 and
        # e_i . v_j = 0 (|.| kink), where finite differences are meaningless.
        if eta[0] - eta[1] < 2e-2 or np.abs(grain.T @ V).min() < 2e-2:
            continue
        cases.append((x, Dm_inv, area, grain))
    return cases


def finite_difference(method, x, Dm_inv, area, grain, bands, h=1e-6, **kw):
    """Central differences of all constraints w.r.t. the 9 coordinates, one batched call."""
    xs = np.repeat(x[None], 18, axis=0).reshape(18, 9)
    for m in range(9):
        xs[2 * m, m] += h
        xs[2 * m + 1, m] -= h
    g, _ = C.evaluate(method, xs.reshape(18, 3, 3), np.repeat(Dm_inv[None], 18, 0),
                      np.repeat(grain[None], 18, 0), np.full(18, area), *bands, **kw)
    return ((g[0::2] - g[1::2]) / (2 * h)).T        # (K, 9)


@pytest.mark.parametrize("method", list(FAMILIES))
def test_gradients_match_finite_differences(method, rng):
    bands = ((-0.02, 0.03), (-0.04, 0.05), (1.37, 1.46))
    for x, Dm_inv, area, grain in random_triangles(rng, 25):
        _, grad = evaluate_one(method, x, Dm_inv, area, *bands, grain=grain)
        fd = finite_difference(method, x, Dm_inv, area, grain, bands)
        scale = max(np.abs(fd).max(), 1e-12)
        assert np.abs(grad - fd).max() / scale < 1e-6


@pytest.mark.parametrize("method", list(FAMILIES))
def test_constraints_come_in_bound_pairs(method, rng):
    """Constraints 2p and 2p + 1 bound the same strain from the two sides: their gradients
    are opposite and their values sum to sqrt(a) x minus the band's width. The solve stores
    one gradient per pair (al.assemble_all, al.pair_grad) on this fact."""
    bands = ((-0.02, 0.03), (-0.04, 0.05), (1.37, 1.46))
    widths = {"svd": [0.05, 0.09], "warp-weft": [0.05, 0.09, 0.09],
              "mapping": [0.05, 0.05, 0.09, 0.09]}[method]
    for x, Dm_inv, area, grain in random_triangles(rng, 10):
        g, grad = evaluate_one(method, x, Dm_inv, area, *bands, grain=grain)
        assert np.abs(grad[1::2] + grad[0::2]).max() == 0.0
        assert np.abs(grad[0::2]).max() > 0.0
        np.testing.assert_allclose(g[0::2] + g[1::2], -np.sqrt(area) * np.array(widths),
                                   rtol=1e-9, atol=1e-12)


def test_svd_gradients_meet_at_isotropy():
    """At eta1 = eta2 the svd family's eta1 and eta2 gradients are both their mean (the
    minimum-norm subgradient of max(eta1, eta2)): a uniform shrink lowers both; they blend
    back to their own within SVD_ISO_GAP of the tie."""
    uv = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]])
    Dm_inv, area = triangle_arrays(uv, np.zeros((3, 3)))
    bands = ((-0.01, 0.01), (-0.05, 0.05), (1.37, 1.46))
    x = np.c_[1.04 * uv, np.zeros(3)]
    _, grad = evaluate_one("svd", x, Dm_inv, area, *bands)
    np.testing.assert_allclose(grad[1], grad[3], atol=1e-12)          # eta1, eta2 upper
    shrink = -(x - x.mean(axis=0)).ravel()
    assert grad[1] @ shrink < 0 and grad[3] @ shrink < 0
    gap = 4 * C.SVD_ISO_GAP                                          # past the blend
    x2 = np.c_[uv * [1.04 + gap, 1.04], np.zeros(3)]
    _, grad2 = evaluate_one("svd", x2, Dm_inv, area, *bands)
    assert np.abs(grad2[1] - grad2[3]).max() > 0.1 * np.abs(grad2[1]).max()


@pytest.mark.parametrize("iso", [C.MAPPING_ISO, 0.1])
def test_mapping_closure_gradients_match_finite_differences(iso, rng):
    """The isotropy closure (c~ blended towards 1/sqrt 2) has an exact gradient; iso = 0.1 is
    wide enough that the weight's own derivative matters on these triangles."""
    bands = ((-0.02, 0.03), (-0.04, 0.05), (1.37, 1.46))
    for x, Dm_inv, area, grain in random_triangles(rng, 25):
        _, grad = evaluate_one("mapping", x, Dm_inv, area, *bands, grain=grain, iso=iso)
        fd = finite_difference("mapping", x, Dm_inv, area, grain, bands, iso=iso)
        scale = max(np.abs(fd).max(), 1e-12)
        assert np.abs(grad - fd).max() / scale < 1e-6


def test_mapping_closure_is_continuous_at_isotropy():
    """With the closure, an isotropic stretch eta has c~ = 1/sqrt 2 for every pair whatever
    frame round-off picks, and nearby states approach that value; without it (iso = 0) the
    value depends on the arbitrary frame. Far from isotropy (D >> iso) the closure is the
    paper's constraint up to (eta - 1) iso / (sqrt 2 D) (the most, where c = 0:
    c~^2 - c^2 = (1 - w)(1/2 - c^2), 1 - w <= (iso / D)^2)."""
    uv = np.array([[0.0, 0.0], [0.04, 0.0], [0.01, 0.035]])
    Dm_inv, area = triangle_arrays(uv, np.zeros((3, 3)))
    R, _ = np.linalg.qr(np.random.default_rng(7).normal(size=(3, 3)))
    bands = ((-0.01, 0.01), (-0.05, 0.05), (1.37, 1.46))
    iso, eta = C.MAPPING_ISO, 1.03
    sqa = np.sqrt(area)
    expected_upper = np.array([0.03 / np.sqrt(2) - 0.01] * 2 + [0.03 / np.sqrt(2) - 0.05] * 2)
    for turn in np.linspace(0.0, np.pi / 2, 7):      # the material frame of the stretch
        rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
        for aniso in (0.0, 1e-9, 1e-7):
            F = R[:, :2] @ rot @ np.diag([eta + aniso, eta]) @ rot.T
            g, grad = evaluate_one("mapping", uv @ F.T, Dm_inv, area, *bands, iso=iso)
            assert np.all(np.isfinite(grad))
            np.testing.assert_allclose(g[0::2] / sqa, expected_upper, atol=1e-6)
    # Far from isotropy: the paper's value, to (eta - 1) iso / (sqrt 2 D).
    F = R[:, :2] @ np.diag([1.08, 1.0])
    D = 1.08 ** 2 - 1.0
    g_closed, _ = evaluate_one("mapping", uv @ F.T, Dm_inv, area, *bands, iso=iso)
    g_paper, _ = evaluate_one("mapping", uv @ F.T, Dm_inv, area, *bands, iso=0.0)
    assert np.abs(g_closed - g_paper).max() / sqa <= 0.08 * iso / (np.sqrt(2) * D)
    assert np.abs(g_closed - g_paper).max() / sqa > 0.0


def test_warp_weft_uses_the_grain():
    """With the grain rotated 90 degrees, warp and weft swap roles."""
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    x = np.c_[uv * [1.1, 1.0], np.zeros(3)]
    Dm_inv, area = triangle_arrays(uv, x)
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])
    bands = ((-0.01, 0.01), (-0.05, 0.05), (1.3, 1.5))
    g0, _ = evaluate_one("warp-weft", x, Dm_inv, area, *bands)
    g1, _ = evaluate_one("warp-weft", x, Dm_inv, area, *bands, grain=rot)
    sqa = np.sqrt(area)
    assert g0[1] / sqa == pytest.approx(0.1 - 0.01)      # warp (u) stretched 10 %
    assert g1[3] / sqa == pytest.approx(0.1 - 0.05)      # now the weft is along u


# ---- the 2x2 symmetric eigenproblem ---------------------------------------------------------
def test_closed_form_sym_eig2(rng):
    n = 400
    A = rng.normal(size=(n, 3, 2)) * rng.uniform(0.01, 3, (n, 1, 1))
    C2 = np.einsum("nki,nkj->nij", A, A)
    p, q, r = C2[:, 0, 0], C2[:, 0, 1], C2[:, 1, 1]
    # Hard rows: exactly and nearly isotropic, nearly singular, huge ratio.
    p[:4], q[:4], r[:4] = [1.0, 1.0, 1.0, 4.0], [0.0, 1e-13, 0.0, 2.0 - 1e-9], [1.0, 1.0,
                                                                                  1.0 + 1e-12, 1.0]
    out = C.sym_eig2_numpy(p, q, r)
    lam, v1, v2 = out[:, :2], out[:, 2:4], out[:, 4:6]
    ref = np.linalg.eigvalsh(np.stack([np.c_[p, q], np.c_[q, r]], axis=1))[:, ::-1]
    scale = np.abs(ref).max(axis=1)
    assert np.all(np.isfinite(out))
    assert np.all(np.abs(lam - ref).max(axis=1) <= 1e-13 * scale + 1e-15)
    Cm = np.stack([np.c_[p, q], np.c_[q, r]], axis=1)
    for vec, l in ((v1, lam[:, 0]), (v2, lam[:, 1])):
        res = np.einsum("nij,nj->ni", Cm, vec) - l[:, None] * vec
        assert np.all(np.linalg.norm(res, axis=1) <= 1e-12 * scale + 1e-15)
    assert np.allclose(np.einsum("ni,ni->n", v1, v1), 1) and np.allclose(
        np.einsum("ni,ni->n", v1, v2), 0, atol=1e-15)
    assert np.allclose(out[0], [1, 1, 1, 0, 0, 1])      # isotropic: a fixed frame


# ---- the isotropic point of the mapping family -----------------------------------------------
def test_mapping_regularisation_at_isotropic_stretch():
    """At eta1 = eta2 the V-term's 1/(eta1^2 - eta2^2) is 0 * inf; the regularised gradient is
    finite and bounded by (eta - 1) |grad| / (2 delta); away from it, its relative error is
    delta^2/(D^2 + delta^2) (compared here with a negligible delta)."""
    uv = np.array([[0.0, 0.0], [0.04, 0.0], [0.01, 0.035]])
    Dm_inv, area = triangle_arrays(uv, np.zeros((3, 3)))
    R, _ = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))
    bands = ((-0.01, 0.01), (-0.05, 0.05), (1.37, 1.46))
    delta = C.MAPPING_DELTA
    for aniso in (0.0, 1e-12, 1e-9, 1e-7, 1e-5, 1e-3):
        F = R[:, :2] @ np.diag([1.02 + aniso, 1.02])
        x = uv @ F.T
        g, grad = evaluate_one("mapping", x, Dm_inv, area, *bands, delta=delta)
        assert np.all(np.isfinite(g)) and np.all(np.isfinite(grad))
        assert np.abs(grad).max() < 0.02 * 40.0 / (2 * delta) + 100.0
        if aniso >= 1e-3:
            _, exact = evaluate_one("mapping", x, Dm_inv, area, *bands, delta=1e-30)
            D = 1.02 ** 2 * ((1 + aniso / 1.02) ** 2 - 1)
            assert np.abs(grad - exact).max() <= 2 * delta ** 2 / D ** 2 * np.abs(exact).max()
    # Exactly isotropic: V is arbitrary (round-off picks it), so only c_11^2 + c_12^2 = 1
    # is determined: (g+_11/sqrt a + eps)^2 + (g+_12/sqrt a + eps)^2 = (eta - 1)^2.
    g, grad = evaluate_one("mapping", uv @ (1.02 * R[:, :2]).T, Dm_inv, area, *bands)
    assert np.all(np.isfinite(grad))
    s = g / np.sqrt(area)
    assert (s[0] + 0.01) ** 2 + (s[2] + 0.01) ** 2 == pytest.approx(0.02 ** 2, rel=1e-9)


def test_hard_triangles_stay_finite():
    """Sliver, collapsed, inverted (folded through) and degenerate positions."""
    uv = np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]])
    Dm_inv, area = triangle_arrays(uv, np.zeros((3, 3)))
    bands = ((-0.01, 0.01), (-0.05, 0.05), (1.37, 1.46))
    shapes = {
        "sliver": np.array([[0, 0, 0], [0.05, 0, 0], [0.025, 1e-9, 0]]),
        "collapsed": np.zeros((3, 3)),
        "segment": np.array([[0, 0, 0], [0.05, 0, 0], [0.1, 0, 0]]),
        "inverted": np.array([[0, 0, 0], [0.05, 0, 0], [0.0, -0.05, 0]]),
    }
    for method in FAMILIES:
        for name, x in shapes.items():
            g, grad = evaluate_one(method, x, Dm_inv, area, *bands)
            assert np.all(np.isfinite(g)) and np.all(np.isfinite(grad)), (method, name)


@pytest.mark.parametrize("path", ["axes turn through 45 degrees", "eta1 and eta2 cross"])
def test_mapping_values_in_the_solvers_order_are_continuous(path):
    """Each mapping constraint, in the order the solver keeps multipliers in, is a continuous
    function of the positions: along a path of deformations, consecutive values differ by
    O(step). Ordered by alignment with the warp, pairs swap where the principal axes cross 45
    degrees and the values jump by c (eta1 - eta2) (~1.4e-2 here): the AL merit then jumps
    and Newton stalls (docs/history/motion.md section 7). Ordered by magnitude they swap where
    eta1 = eta2, and the isotropy closure makes both pairs equal there."""
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    Dm_inv, area = triangle_arrays(uv, np.c_[uv, np.zeros(3)])
    bands = ((-0.01, 0.01), (-0.05, 0.05), (-1.0, 1.0))

    def values(order, n=401):
        out = []
        for s in np.linspace(-1.0, 1.0, n):
            if path.startswith("axes"):
                th = np.pi / 4 + 0.2 * s
                R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
                F2 = R @ np.diag([1.03, 1.01]) @ R.T
            else:
                th = 0.3
                R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
                F2 = R @ np.diag([1.02 + 0.01 * s, 1.02 - 0.01 * s]) @ R.T
            x = np.c_[uv @ F2.T, np.zeros(3)]
            g, _ = evaluate_one("mapping", x, Dm_inv, area, *bands, by_alignment=order,
                                iso=C.MAPPING_ISO)
            out.append(g)
        return np.array(out)

    jump = np.abs(np.diff(values(C.MAPPING_PAIRS_BY_ALIGNMENT), axis=0)).max()
    assert jump < 1e-3, jump                 # steps of 1e-3 (angle) / 5e-5 (stretch)
    if path.startswith("axes"):              # the other order fails the same check
        assert np.abs(np.diff(values(True), axis=0)).max() > 5e-3
