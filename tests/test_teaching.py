"""The teaching view (docs/teaching.md): what it plots is what the solver limits. The points and
regions come from ``cloth.metrics`` (checked against the solver's own constraint values),
every triangle of a converged frame lies in the drawn region, the binding map names
constraints that are at their bounds, and drawing it leaves the simulation untouched.
The offscreen images of the overlays are compared in tests/test_app.py."""
import numpy as np
import pytest

from cloth import metrics

METHODS = ("svd", "warp-weft", "mapping")
RES = 9                 # 128 faces: the limits bind on the sides after 30 frames
# By 60 frames the sheet hangs (at 30 warp-weft's bias bound still bound on more faces than
# the warp's while the sheet swung: 15 against 11; at 60, 14 against 21).
FRAMES = 60


def converged(method, frames=FRAMES, res=RES):
    from ui.state import AppState
    st = AppState.from_scene("hanging", [{"cloth": {"resolution": res},
                                          "strain": {"method": method}}])
    for _ in range(frames):
        st.sim.step_frame()
    assert method == "none" or st.sim.strain.last_converged
    return st.sim


@pytest.fixture(scope="module")
def sims():
    return {m: converged(m) for m in METHODS}


def host_values(sim):
    m = sim.model
    return metrics.own_constraint_values(sim.method, m.positions(), m.faces,
                                         metrics.material_Dm_inv(m.uv, m.faces), m.grain,
                                         sim.bands(), sim.strain.isotropy)


@pytest.mark.parametrize("method", METHODS)
def test_host_constraints_are_the_solvers(sims, method):
    """metrics.own_constraint_values (what the plot and the key are built from) equals the
    solver's constraint values, constraint by constraint, in its order and units."""
    sim = sims[method]
    g = sim.strain.constraint_values()
    h = host_values(sim)
    assert h.shape == g.shape == (sim.model.n_faces, len(metrics.CONSTRAINT_NAMES[method]))
    assert np.abs(g - h).max() < 1e-9
    assert g.max() > -1e-3          # something is near its bound: not a vacuous comparison


@pytest.mark.parametrize("method", METHODS)
def test_every_point_of_a_converged_frame_lies_in_the_drawn_region(sims, method):
    from ui.teaching import binding, panels_inside, strain_plot
    sim = sims[method]
    m = sim.model
    tol = sim.settings.strain.tol
    panels, sp = strain_plot(method, m.positions(), m.faces,
                             metrics.material_Dm_inv(m.uv, m.faces), m.grain, sim.bands(),
                             sim.strain.isotropy, binding(sim))
    drawn = panels_inside(panels, tol)
    assert len(drawn) == 1                  # each method has its region in one plane
    title, outside = drawn[0]
    assert outside <= tol, f"{method}: a point lies {outside:.2e} outside '{title}'"
    region = next(p for p in panels if p.region is not None)
    (x0, x1), (y0, y1) = region.region
    pts = np.asarray(region.points)
    # Pressed against the boundary: the cloud reaches the box's upper warp edge.
    assert pts[:, 0].max() > x1 - 2 * tol
    if method == "warp-weft":
        lo, hi = metrics.feasible_region("warp-weft", "bias", sim.bands())
        assert sp["bias"].min() >= lo - tol and sp["bias"].max() <= hi + tol
    if method == "mapping":
        # The threads themselves pass the box (the sqrt 2 of docs/method.md §3.3): the faint points.
        assert region.faint[:, 0].max() > x1 + 1e-3


def test_a_free_sheet_lies_outside_the_region_the_check_reports_it():
    """The region check can fail: the unlimited sheet's principal strains leave svd's box."""
    from ui.teaching import panels_inside, strain_plot
    sim = converged("none", frames=10)
    m = sim.model
    panels, _ = strain_plot("svd", m.positions(), m.faces,
                            metrics.material_Dm_inv(m.uv, m.faces), m.grain, sim.bands())
    assert panels_inside(panels, 1e-4)[0][1] > 0.02


@pytest.mark.parametrize("method", METHODS)
def test_binding_map_names_constraints_at_their_bounds(sims, method):
    """A face coloured by a constraint has that constraint at its bound (within the solver's
    tolerance); a face coloured free has every constraint satisfied; the warp (eta1 for svd)
    upper bound is the one that binds most, as the sheet hangs from its corners."""
    from ui.colormap import binding_colors
    from ui.teaching import binding
    sim = sims[method]
    tol = sim.settings.strain.tol
    g = sim.strain.constraint_values()
    idx = binding(sim)
    names = metrics.CONSTRAINT_NAMES[method]
    bound = idx >= 0
    assert 0 < bound.sum() < len(idx)
    assert np.abs(g[bound, idx[bound]]).max() <= tol
    assert g[~bound].max() <= tol
    top = names[np.bincount(idx[bound], minlength=len(names)).argmax()]
    assert top in ("eta1 max", "warp max", "warp via A max", "warp via B max"), top
    rgb, key = binding_colors(method, idx, len(idx))
    assert sum(n for _, _, n in key) == len(idx)
    assert {lab for lab, _, _ in key[:-1]} == {names[k] for k in set(idx[bound])}


def test_binding_picks_the_largest_positive_multiplier():
    lam = np.array([[0.0, 0.0, 0.0, 9.0], [0.1, 0.3, 0.0, 0.0], [0.0, 0.0, 2e-9, 0.0]])
    assert list(metrics.binding_constraints(lam, 3)) == [-1, 1, 2]


def test_mapping_factors_pair_a_is_the_major_axis():
    """Stretch 3 % along the weft only: the major axis (pair A, the solver's order) is the
    weft, so A maps 3 % onto the weft and nothing onto the warp; pair B (the warp, unstretched)
    maps nothing."""
    from cloth.sheet import make_sheet
    uv, faces = make_sheet(1, 1, 3, 3)
    x = np.c_[uv[:, 0], 1.03 * uv[:, 1], np.zeros(len(uv))]
    grain = np.tile(np.eye(2), (len(faces), 1, 1))
    sp = metrics.strain_space("mapping", x, faces, metrics.material_Dm_inv(uv, faces), grain,
                              {"warp": (-0.01, 0.01), "weft": (-0.05, 0.05)})
    assert np.allclose(sp["mapped"][:, 0], [0.0, 0.03], atol=1e-12)    # pair A: weft 3 %
    assert np.allclose(sp["mapped"][:, 1], 0.0, atol=1e-12)            # pair B: no stretch
    assert np.allclose(sp["principal"], [0.03, 0.0], atol=1e-12)


def test_glyphs_thin_out_on_fine_meshes():
    from cloth.sheet import make_sheet
    from ui.teaching import MAX_SITES, glyph_sites
    counts = {}
    for n in (9, 25, 49, 97):
        uv, faces = make_sheet(1, 1, n, n)
        sites, size = glyph_sites(uv, faces)
        counts[len(faces)] = len(sites)
        assert len(np.unique(sites)) == len(sites) <= max(MAX_SITES, 0)
        assert size >= np.sqrt(1.0 / len(faces))
    assert counts[128] == 64                        # coarse: one per grid square
    assert counts[1152] == 144 and counts[4608] == 256 and counts[18432] <= MAX_SITES


def test_glyphs_follow_the_principal_directions():
    """A sheet stretched 4 % along u and 1 % along v: the long stroke lies along u, the
    short along v, both through the centroid, and the threads are F e."""
    from cloth.sheet import make_sheet
    from ui.teaching import axis_glyphs, glyph_sites
    uv, faces = make_sheet(1, 1, 4, 4)
    x = np.c_[1.04 * uv[:, 0], 1.01 * uv[:, 1], np.zeros(len(uv))]
    grain = np.tile(np.eye(2), (len(faces), 1, 1))
    sites, size = glyph_sites(uv, faces)
    g = axis_glyphs(x, faces, metrics.material_Dm_inv(uv, faces), grain, sites, size,
                    {"warp": (-0.01, 0.01), "weft": (-0.05, 0.05)})
    seg = g["principal"][:, 1] - g["principal"][:, 0]
    major, minor = seg[0::2], seg[1::2]
    assert np.allclose(np.abs(major[:, 0]), np.linalg.norm(major, axis=1))
    assert np.allclose(np.abs(minor[:, 1]), np.linalg.norm(minor, axis=1))
    assert (np.linalg.norm(major, axis=1) > np.linalg.norm(minor, axis=1)).all()
    threads = g["grain"][:, 1] - g["grain"][:, 0]
    assert np.allclose(threads[0::2], [1.04 * size, 0, 0])
    assert np.allclose(g["principal"].mean(axis=1)[0::2], g["centroids"])


def test_drawing_the_teaching_view_leaves_the_simulation_untouched():
    """Two runs of the same scene, one read by the teaching view every frame (binding map,
    plot, glyphs, host constraint values): identical positions bit for bit."""
    from ui.state import AppState
    from ui.teaching import axis_glyphs, binding, glyph_sites, strain_plot
    runs = []
    for read in (False, True):
        st = AppState.from_scene("hanging", [{"cloth": {"resolution": 7}}])
        sim, m = st.sim, st.sim.model
        for _ in range(8):
            sim.step_frame()
            if read:
                Dm = metrics.material_Dm_inv(m.uv, m.faces)
                strain_plot(sim.method, m.positions(), m.faces, Dm, m.grain, sim.bands(),
                            sim.strain.isotropy, binding(sim))
                sites, size = glyph_sites(m.uv, m.faces)
                axis_glyphs(m.positions(), m.faces, Dm, m.grain, sites, size, sim.bands())
                sim.strain.constraint_values()
        runs.append(m.positions())
    assert np.array_equal(runs[0], runs[1])


def test_overlay_flag_is_checked():
    import main
    assert main.main(["--overlay", "axes,nope", "--list"]) == main.EXIT_BAD_INPUT
    assert main.main(["--tour", "drape"]) == main.EXIT_BAD_INPUT


def test_tour_captions_quote_the_state(sims):
    from ui.tour import STEPS, caption, facts
    for step in STEPS:
        f = facts(sims[step.method])
        text = caption(step, f)
        assert text.startswith(f"{step.method} at t = ")
        if step.view == "binding":
            assert "Binding: " in text and f["bound"] > 0
    f = facts(sims["mapping"])
    assert f["warp"] > 1.0 + 1e-3 and 1.0 < f["ratio"] <= np.sqrt(2) + 0.01


def test_tour_ends_on_two_fabrics_and_their_captions_say_what_binds():
    """The tour's last stages restart the sheet under mapping in a knit and a woven; a fabric
    pause quotes its derived bands and the strains, and says whether the limits act."""
    from ui.tour import FABRICS, STAGES, STEPS, Step, caption, stage_steps, step_name
    assert STAGES[-2:] == [("mapping", f) for f in FABRICS] and len(set(FABRICS)) == 2
    assert [s.fabric for s in STEPS[-2:]] == list(FABRICS)
    assert all(len(stage_steps(stage)) >= 1 for stage in STAGES)
    assert step_name(7, STEPS[-2]) == f"step_07_mapping_{FABRICS[0]}.png"
    f = {"t": 5.0, "ke": 1e-7, "own": 1e-6, "n": 1152, "warp": 0.12, "weft": 0.03,
         "bands": {"warp": [-0.57, 0.57], "weft": [-0.57, 0.57], "bias": [-2.8, 3.3]},
         "ratio": 0.21, "bound": 0, "counts": {}}
    text = caption(Step("mapping", "binding", "denim"), f)
    assert text.startswith("mapping at t = ") and "fabric denim" in text
    assert "warp +-0.57 %" in text and "Binding: none" in text and "21 % of its warp" in text
    f.update(bound=4, counts={"weft via A max": 3, "warp via A max": 1}, ratio=0.9)
    text = caption(Step("mapping", "binding", "cotton-jersey"), f)
    assert "Binding: weft via A max on 3, warp via A max on 1 of 1152" in text


def test_closed_form_principal_stretches_equal_numpys_svd():
    """metrics.principal_stretches (closed form, per frame in the teaching view) against
    numpy's SVD: the same stretches, the same directions up to sign, F = U diag(eta) V^T;
    isotropic and near-isotropic faces included."""
    rng = np.random.default_rng(1)
    for scale in (1.0, 0.05, 1e-7):
        F = np.tile(np.eye(3, 2), (500, 1, 1)) + scale * rng.normal(size=(500, 3, 2))
        F[0], F[1] = np.eye(3, 2), 1.01 * np.eye(3, 2)
        eta, V, U = metrics.principal_stretches(F)
        u, s, vt = np.linalg.svd(F, full_matrices=False)
        assert np.abs(eta - s).max() < 1e-13
        assert np.abs(U @ (eta[:, :, None] * np.swapaxes(V, 1, 2)) - F).max() < 1e-13
        assert np.abs(np.swapaxes(V, 1, 2) @ V - np.eye(2)).max() < 1e-13
        distinct = (s[:, 0] - s[:, 1]) > 1e-6
        dots = np.abs(np.einsum("nij,nji->nj", V, vt))[distinct]
        assert len(dots) > 0 or scale < 1e-6
        assert np.abs(dots - 1.0).max(initial=0.0) < 1e-9
