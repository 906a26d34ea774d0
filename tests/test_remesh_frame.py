"""What a remesh sets off, done locally: the bending matrix updated from the faces a remesh
changed, the block pattern and the factor preconditioner built over reused arrays, the model
refilled row by row, per-vertex data carried like x and v, small remeshes deferred; each must
equal what a rebuild gives (to round-off), and the limits must hold after every frame's
remesh."""
import numpy as np
import pytest
import scipy.sparse as sp

from cloth import bending, linalg, ndarrays, system_matrix
from cloth.model import ClothModel, Material, MeshArrays, build_edges, signed_material_areas
from cloth.remesh import RemeshParams, mesh_sizing, pending_operations, remesh, \
    transfer_vertex_data
from cloth.sheet import make_sheet
from tests.test_scenes import make_sim


def _sheet(n=15, pattern="alternating", clamp=True):
    """A 1 m sheet with a bump (curvature to refine for) and, with ``clamp``, two pinned rows
    along u = 0 (a clamp: faces with three pinned vertices, clamped edges beside them)."""
    uv, faces = make_sheet(1.0, 1.0, n, n, pattern)
    x = np.c_[uv, 0.2 * np.exp(-((uv[:, 0] - 0.6) ** 2 + (uv[:, 1] - 0.5) ** 2) / 0.02)]
    pinned = uv[:, 0] < 1.5 / (n - 1) if clamp else np.zeros(len(uv), bool)
    return MeshArrays(uv=uv, x=x, faces=faces, pinned=pinned)


def _rebuild(mesh):
    ev, ef, eo = build_edges(mesh.faces)
    area = signed_material_areas(mesh.uv, mesh.faces)
    return bending.isotropic_matrix(mesh.uv, mesh.faces, ev, ef, eo, area, mesh.pinned)


def _update(bend, mesh, vertex_map=None):
    _, ef, eo = build_edges(mesh.faces)
    area = signed_material_areas(mesh.uv, mesh.faces)
    return bend.matrix(mesh.uv, mesh.faces, ef, eo, area, mesh.pinned, vertex_map)


def _same(Q, R):
    """Equal to round-off: entries within 1e-12 of the largest."""
    return abs(Q - R).max() <= 1e-12 * abs(R).max()


# The three kinds of operation, each made to happen on its own mesh: a bump on a coarse
# sheet splits (and flips), a flat fine sheet with a large size_max collapses (and flips).
CASES = {
    "split": (dict(n=9), RemeshParams(size_min=0.03, size_max=0.2, refine_angle=0.15)),
    "collapse": (dict(n=21), RemeshParams(size_min=0.1, size_max=0.3, refine_angle=10.0)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bending_update_equals_a_rebuild_after_each_operation(case):
    kw, params = CASES[case]
    mesh = _sheet(**kw)
    bend = bending.IsotropicBending()
    assert _same(_update(bend, mesh), _rebuild(mesh))
    kinds = {"splits": 0, "flips": 0, "collapses": 0}
    for _ in range(3):
        new, _, st = remesh(mesh, params, frozen_verts=mesh.pinned)
        for k in kinds:
            kinds[k] += st[k]
        Q = _update(bend, new, st["vertex_map"])
        assert _same(Q, _rebuild(new)), case
        # Local: faces away from the operations kept their terms, and the changed ones
        # were computed again (a cache that reused everything, or nothing, fails here).
        if st["splits"] + st["flips"] + st["collapses"]:
            assert 0 < bend.last_reused < len(new.faces)
        mesh = new
    assert kinds["flips"] > 0 and kinds[case + "s"] > 0, kinds


def test_bending_update_follows_a_changed_clamp():
    """Pins changed, mesh not (a vertex held by the mouse, then the next remesh): the faces
    whose clamp flags changed are computed again."""
    mesh = _sheet(11, clamp=False)
    bend = bending.IsotropicBending()
    _update(bend, mesh)
    mesh.pinned = mesh.uv[:, 0] < 0.15                   # two rows: now a clamp
    identity = np.arange(len(mesh.uv))
    assert _same(_update(bend, mesh, identity), _rebuild(mesh))
    assert 0 < bend.last_reused < len(mesh.faces)


def _model_arrays(model):
    names = ("vert_uv", "vert_mass", "vert_pinned", "vert_pin_target", "face_verts",
             "face_Dm_inv", "face_rest_area", "face_grain", "edge_verts", "edge_faces",
             "edge_opp", "edge_rest_angle", "edge_bend_weight", "bend_ptr", "bend_col",
             "bend_val")
    out = {k: getattr(model, k).to_numpy() for k in names}
    out["x"], out["v"] = model.state.x.to_numpy(), model.state.v.to_numpy()
    return out


def test_refilled_model_equals_a_fresh_one_row_for_row():
    """A model that held a larger mesh and is refilled (active rows written, the rows the
    larger one left behind cleared) has every array equal to a model filled once, over the
    whole capacity, with the bending matrix updated through the remesh's vertex map."""
    big = _sheet(15)
    params = RemeshParams(size_min=0.1, size_max=0.3, refine_angle=10.0)
    small, _, st = remesh(big, params, frozen_verts=big.pinned)
    assert len(small.faces) < len(big.faces)
    refilled = ClothModel(big, Material(), capacity_factor=2.0)
    refilled.load(small, vertex_map=st["vertex_map"])
    # The same capacities, freshly allocated (zeros everywhere), then filled once.
    fresh = ClothModel(big, Material(), capacity_factor=2.0)
    fresh._allocate(len(big.uv), len(big.faces), len(build_edges(big.faces)[0]),
                    len(fresh.bend_pattern()[0]))
    fresh._filled = (fresh.v_cap, fresh.f_cap, fresh.e_cap, fresh.q_cap)
    assert (fresh.v_cap, fresh.q_cap) == (refilled.v_cap, refilled.q_cap)
    fresh.load(small)
    a, b = _model_arrays(refilled), _model_arrays(fresh)
    for k in a:
        if k == "bend_val":
            assert np.abs(a[k] - b[k]).max() <= 1e-12 * np.abs(b[k]).max(), k
        else:
            assert np.array_equal(a[k], b[k]), k
    assert np.array_equal(refilled.positions(), small.x)


def _slots(B):
    """The pattern's Taichi arrays, their rows that belong to it."""
    return {"ptr": B.ptr.to_numpy()[: B.n + 1], "col": B.col.to_numpy()[: B.nnz],
            "diag": B.diag.to_numpy()[: B.n], "bend": B.bend_slot.to_numpy()[: B.n_bend]}


def test_pattern_over_reused_arrays_equals_a_fresh_one():
    """After a split and after a collapse, the block pattern built into the last mesh's
    arrays (larger or smaller than needed) equals one built fresh; its sibling shares the
    pattern and has values of its own."""
    mesh = _sheet(9)
    model = ClothModel(mesh, Material(), capacity_factor=4.0)
    old = system_matrix.pattern_of(model)
    for case in ("split", "collapse"):
        kw, params = CASES[case]
        if case == "collapse":
            mesh = _sheet(**kw)
            model = ClothModel(mesh, Material(), capacity_factor=4.0)
        new_mesh, _, st = remesh(mesh, params, frozen_verts=mesh.pinned)
        assert st[case + "s"] > 0
        model.load(new_mesh, vertex_map=st["vertex_map"])
        reused = system_matrix.pattern_of(model, reuse=old)
        fresh = system_matrix.pattern_of(model)
        nf = model.n_faces
        assert reused.nnz == fresh.nnz and np.array_equal(reused.ptr_np, fresh.ptr_np)
        assert np.array_equal(reused.col_np, fresh.col_np)
        for k in ("ptr", "col", "diag", "bend"):
            assert np.array_equal(_slots(reused)[k], _slots(fresh)[k]), (case, k)
        assert np.array_equal(reused.face_slot.to_numpy()[:nf], fresh.face_slot.to_numpy()[:nf])
        twin = reused.sibling()
        assert twin.col is reused.col and twin.val is not reused.val
        old, mesh = reused, new_mesh


@pytest.mark.skipif(not linalg.HAVE_CHOLMOD, reason="the factor needs CHOLMOD")
def test_factor_over_a_reused_pattern_equals_a_fresh_one():
    """The factor preconditioner made over a pattern in reused arrays (its symbolic analysis
    deferred to the first refresh) uploads the same L as one made over a fresh pattern, and
    so does one made in the arrays of a larger mesh's factor (the last mesh's, after a
    remesh)."""
    from cloth.strain.factor_precond import FactorPreconditioner
    mesh = _sheet(9)
    model = ClothModel(mesh, Material(), capacity_factor=4.0)
    old = system_matrix.pattern_of(model)
    kw, params = CASES["split"]
    new_mesh, _, st = remesh(mesh, params, frozen_verts=mesh.pinned)
    model.load(new_mesh, vertex_map=st["vertex_map"])
    mats = [system_matrix.pattern_of(model, reuse=old), system_matrix.pattern_of(model)]
    # A symmetric positive definite matrix in the pattern: every block coupled, made
    # diagonally dominant.
    values = _spd_values(mats[1])
    # A factor of a larger mesh, whose arrays the third one takes (padded rows beyond n).
    big = system_matrix.pattern_of(ClothModel(_sheet(15), Material()))
    spare = FactorPreconditioner(big)
    spare.refresh(_spd_values(big))
    n = mats[1].n
    out = []
    for M, old_fp in ((mats[0], None), (mats[1], None), (mats[1], spare)):
        fp = FactorPreconditioner(M, spare=old_fp)
        assert fp._chol is None                          # analysis deferred
        fp.refresh(values)
        if old_fp is not None:
            assert fp.val is spare.val and fp.perm.shape[0] > n
        nb = 2 * (fp.blocks - n) + n
        out.append((fp.val.to_numpy()[:nb], fp.perm.to_numpy()[:n],
                    fp.ptr.to_numpy()[:2 * (n + 1)], fp.idx.to_numpy()[:nb]))
    for other in out[1:]:
        for k in (1, 2, 3):
            assert np.array_equal(out[0][k], other[k]), k
        assert np.abs(out[0][0] - other[0]).max() <= 1e-12 * np.abs(out[0][0]).max()


def _spd_values(B):
    """Block values of a symmetric positive definite matrix in B's pattern: every block
    coupled, made diagonally dominant."""
    R = B.to_scipy(ndarrays_ones(B)) * 0.01
    A = R + sp.identity(3 * B.n) * (abs(R).sum(axis=1).max() + 1.0)
    blocks = A.tobsr(blocksize=(3, 3))
    blocks.sort_indices()
    assert len(blocks.data) == B.nnz
    return blocks.data


def ndarrays_ones(B):
    """Block values of ones in B's pattern (as a Taichi array, for ``to_scipy``)."""
    import taichi as ti
    arr = ti.ndarray(system_matrix.mat3, max(B.nnz, 1))
    ndarrays.put_rows(arr, np.ones((B.nnz, 3, 3)))
    return arr


def test_vertex_data_is_carried_like_x_and_v():
    """transfer_vertex_data keeps the surviving vertices' rows and puts the edge's mean at
    every split vertex: data linear in material space is reproduced exactly, and v itself
    comes out as the remesh's own v."""
    mesh = _sheet(9)
    rng = np.random.default_rng(2)
    mesh.v = rng.standard_normal(mesh.x.shape)
    kw, params = CASES["split"]
    new, _, st = remesh(mesh, params, frozen_verts=mesh.pinned)
    assert st["splits"] > 0
    lin = lambda uv: np.c_[2 * uv[:, 0] - uv[:, 1] + 0.3, uv[:, 1] * 5.0, -uv[:, 0]]
    assert np.abs(transfer_vertex_data(lin(mesh.uv), st) - lin(new.uv)).max() < 1e-13
    assert np.array_equal(transfer_vertex_data(mesh.v, st), new.v)
    with pytest.raises(ValueError):
        transfer_vertex_data(mesh.v[:-1], st)


def test_limits_hold_after_every_remesh_with_deferral_and_without():
    """hanging (mapping) remeshed every frame: after each frame, its remesh applied or
    deferred, the method's own constraints hold to strain.tol, the material area is kept,
    nothing is inverted and the pins stay. A deferred remesh leaves the mesh as it was, and
    never more than defer_frames in a row; with defer_ops = 0 every remesh that changes the
    mesh is applied."""
    for defer_ops in (0.05, 0.0):
        sim, cfg = make_sim(cloth={"resolution": 13}, strain={"method": "mapping"},
                            remesh={"enabled": True, "size_min": 0.04, "size_max": 0.15,
                                    "defer_ops": defer_ops, "defer_frames": 2})
        tol = sim.strain.tol
        area0 = sim.model.rest_area.sum()
        pins = np.sort(sim.model.uv[sim.model.pinned], axis=0)
        applied = deferred = run = 0
        for _ in range(40):
            before = sim.model.faces.copy()
            sim.step_frame()
            st = sim.remesh_stats
            ops = st["splits"] + st["flips"] + st["collapses"]
            if st["applied"]:
                applied += 1
                run = 0
            else:
                assert np.array_equal(sim.model.faces, before)
                if st.get("deferred"):              # made and deferred, or deferred unmade
                    assert ops or not st["made"]
                    deferred += 1
                    run += 1
                    assert defer_ops > 0 and run <= 2
                else:
                    run = 0           # nothing to do: the deferral count starts again
            own = sim.own_violation()
            assert own.max() < tol, (defer_ops, sim.frame, own.max())
            assert abs(sim.model.rest_area.sum() - area0) < 1e-12 * area0
            assert signed_material_areas(sim.model.uv, sim.model.faces).min() > 0
            assert np.array_equal(np.sort(sim.model.uv[sim.model.pinned], axis=0), pins)
        assert applied > 0
        assert (deferred > 0) == (defer_ops > 0), (defer_ops, deferred)


def test_a_remesh_given_its_sizing_is_the_same_remesh():
    """The simulator computes the sizing once (to count the pending operations) and hands it
    to the remesh: the result must be the remesh that computes it itself."""
    mesh = _sheet(9, clamp=False)
    params = CASES["split"][1]
    edges = build_edges(mesh.faces)
    Mv = mesh_sizing(mesh, params, edges=edges)
    a, _, sa = remesh(mesh, params)
    b, _, sb = remesh(mesh, params, sizing=Mv, edges=edges)
    assert sa["splits"] > 0
    for k in ("uv", "x", "v", "faces", "pinned", "grain"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    # The count: every edge too long is split here (no cascade beyond them is needed on
    # this sheet's first pass), plus the edges failing the Delaunay test.
    n = pending_operations(mesh, Mv, edges=edges)
    assert sa["splits"] <= n <= sa["splits"] + sa["flips"]


def test_refinement_the_cloth_needs_now_is_not_deferred():
    """A remesh that would split many edges is made and applied in its frame, however few
    frames were deferred before it: here the sizing is made four times finer mid-run."""
    sim, _ = make_sim(cloth={"resolution": 13}, strain={"method": "mapping"},
                      remesh={"enabled": True, "size_min": 0.04, "size_max": 0.15,
                              "defer_frames": 4})
    made = []
    for _ in range(12):
        sim.step_frame()
        made.append(sim.remesh_stats.get("made", True))
    assert not all(made)                     # a settling cloth defers some unmade
    faces = sim.model.n_faces
    remesh_module, params = sim.remesher
    params.size_max, params.size_min = 0.04, 0.01
    sim._remesh_deferred = 0                 # the deferral budget untouched
    sim.step_frame()
    st = sim.remesh_stats
    assert st["applied"] and st["splits"] > 0.05 * faces and sim.model.n_faces > faces


def test_scalar_csr_written_down_equals_the_sorted_one():
    """The factor's scalar pattern of a remeshed cloth's block pattern, written down from the
    block rows, is the one sorting every entry gives (rows, columns and value sources)."""
    sim, _ = make_sim(cloth={"resolution": 13}, strain={"method": "mapping"},
                      remesh={"enabled": True, "size_min": 0.04, "size_max": 0.15})
    for _ in range(3):
        sim.step_frame()
    metric = sim.strain.system_metric()
    ptr, col, n = metric.ptr_np.astype(np.int64), metric.col_np.astype(np.int64), metric.n
    order, indices, indptr, r_idx, c_idx = linalg.scalar_csr(ptr, col, n)
    sorted_order = np.lexsort((c_idx, r_idx))
    assert np.array_equal(order, sorted_order)
    assert np.array_equal(indices, c_idx[sorted_order])
    # Unsorted block rows take the sort: the same matrix either way.
    swap = np.arange(len(col))
    first = np.flatnonzero(np.diff(ptr) >= 2)[0]
    swap[[ptr[first], ptr[first] + 1]] = swap[[ptr[first] + 1, ptr[first]]]
    o2, i2, p2, r2, c2 = linalg.scalar_csr(ptr, col[swap], n)
    val = np.random.default_rng(0).normal(size=(len(col), 3, 3))
    A = sp.csr_matrix((val.ravel()[order], indices, indptr), shape=(3 * n, 3 * n))
    B = sp.csr_matrix((val[swap].ravel()[o2], i2, p2), shape=(3 * n, 3 * n))
    assert abs(A - B).max() == 0 and np.all(np.diff(i2[p2[0]:p2[1]]) > 0)


@pytest.mark.skipif(not linalg.HAVE_CHOLMOD, reason="the factor needs CHOLMOD")
def test_a_lasting_mesh_gets_its_factor_before_its_first_solve():
    """hanging remeshed with deferral: the mesh before each applied remesh lasted several
    solves, so the first solve on the new mesh already uses a factor (made before it); where
    the last mesh lasted fewer (every remesh applied: a mesh per solve) the factor waits for
    FIRST_AFTER solves."""
    from cloth.strain.factor_precond import FIRST_AFTER, LASTING_SOLVES
    for defer_ops in (0.05, 0.0):
        sim, _ = make_sim(cloth={"resolution": 13}, strain={"method": "mapping"},
                          remesh={"enabled": True, "size_min": 0.04, "size_max": 0.15,
                                  "defer_ops": defer_ops})
        seen = {True: 0, False: 0}
        after_remesh = False
        for _ in range(30):
            sim.step_frame()
            pc = sim.strain._pc
            if after_remesh and pc is not None and pc.solves == 1:
                lasting = sim.strain._last_pattern_solves >= LASTING_SOLVES
                assert pc.ready == lasting
                assert pc.first_after == (0 if lasting else FIRST_AFTER)
                seen[lasting] += 1
            after_remesh = bool(sim.remesh_stats.get("applied"))
        assert seen[defer_ops > 0] > 0, (defer_ops, seen)


def test_rows_in_and_out_of_arrays_with_spare_capacity():
    """ndarrays.put_rows / get_rows move the first n rows of every kind of array the solvers
    keep (1-D scalars, 2-D scalars such as the constraint values, vectors) and leave the spare
    capacity alone: get_rows reads what to_numpy would, without copying the whole array."""
    import taichi as ti
    rng = np.random.default_rng(5)
    for shape, make in (((40,), lambda: ti.ndarray(float, 40)),
                        ((40, 8), lambda: ti.ndarray(float, (40, 8))),
                        ((40, 3), lambda: ti.Vector.ndarray(3, float, 40))):
        arr = make()
        full = rng.standard_normal(shape)
        arr.from_numpy(full)
        rows = rng.standard_normal((7,) + shape[1:])
        ndarrays.put_rows(arr, rows)
        np.testing.assert_array_equal(ndarrays.get_rows(arr, 7), rows)
        np.testing.assert_array_equal(arr.to_numpy()[7:], full[7:])      # spare rows kept
        assert ndarrays.get_rows(arr, 0).shape == (0,) + shape[1:]
        # Each read is the caller's own copy (the reads share a buffer inside): a later read
        # of changed rows leaves an earlier one as it was.
        before = ndarrays.get_rows(arr, 7)
        ndarrays.put_rows(arr, 2 * rows)
        np.testing.assert_array_equal(before, rows)
        np.testing.assert_array_equal(ndarrays.get_rows(arr, 7), 2 * rows)
