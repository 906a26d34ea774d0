"""The primal-dual active-set (PDAS) Newton step of the exact strain solve (settings
``strain.solve = "exact"``): here for the host loop of ``direct.py`` with exact linear solves
(cloth with seams, Vulkan); ``al.pdas_resolves`` is the same step in the kernels with PCG.

Why: the default Newton model puts every constraint within ``active_margin`` (1e-2 strain) of
its band into the Newton matrix. That keeps the line search from running into constraints the
step switches on, but the matrix is then 2.4-6.6x stiffer than the merit's Hessian, the inner
loop converges linearly and the projection stops 0.6-4 mm from its minimiser; the shortfall
acts as damping (docs/history/motion.md). The active-set step instead solves the Newton step of
the merit with its constraints *linearised*,

    min_d  -r.d + 1/2 d^T H0 d + sum_i (mu/2) max(0, t_i + J_i d)^2,   t = g + lambda / mu,

which is piecewise quadratic: guess the set A of constraints the step leaves active, solve
(H0 + mu J_A^T J_A) d = -W(x - x_hat) - mu J_A^T t_A (+ the seams' and friction's terms of r),
predict the set again from t + J d > 0 and re-solve until it stops changing (a few solves,
each re-using the last factorisation). With the margin 0 the matrix is the Hessian of the
merit wherever the set is right, so the Newton loop converges fast and the KKT stop is honest.
Measured with host prototypes (hanging resolution 9, frame 6; `git log --
benchmarks/al_variants.py` finds them):
0.001-0.09 mm from a tight solve, against 1.8-4.1 mm for the margin model.

H0 is the kernels' Newton matrix with margin 0 (``al.newton_matrix``): it holds the
Gauss-Newton terms mu grad g grad g^T of the constraints active at x (lambda + mu g > 0) and
their curvature. Those Gauss-Newton terms are replaced by the predicted set's; the curvature
(which is only ever added with weight max(lambda + mu g, 0)) stays as it is.
"""
import numpy as np

# At most this many solves per Newton step while the predicted set keeps changing (the
# kernels' limit, al.PDAS_SOLVES: the prototype needed 2-3; a step whose set has not settled
# is still a descent direction for the line search, since each solve's matrix is positive
# definite).
from .al import PDAS_SOLVES as MAX_RESOLVES  # noqa: E402


class LinearisedConstraints:
    """The projection's inequality constraints linearised at the current x, face by face:
    the gradients (nf, K, 9) with pinned vertices' columns zero, t = g + lambda / mu (nf, K),
    and per contact slot the normal and t (the contact constraint d - n.x has gradient -n; a
    slot without a contact has n = 0 and d = NO_CONTACT, so it never activates)."""

    def __init__(self, lim, K, mu):
        ws, m = lim._ws, lim.model
        nv, nf = m.n_verts, m.n_faces
        self.mu = mu
        faces = m.faces[:nf].astype(np.int64)
        self.faces = faces
        grad = ws.grad.to_numpy()[:nf, :K]
        G = np.empty((nf, K, 9))
        # Constraints come in bound pairs sharing one gradient, the upper bound's sign first
        # (al.pair_grad).
        G[:, 0::2], G[:, 1::2] = grad[:, 0::2], -grad[:, 0::2]
        free = ~m.pinned[:nv]
        G *= np.repeat(free[faces], 3, axis=1)[:, None, :]
        self.G = G
        self.t = ws.g.to_numpy()[:nf, :K] + ws.lam.to_numpy()[:nf, :K] / mu
        c = ws.contact.to_numpy()[:nv]                           # (nv, slots, 4): n, d
        x = ws.x.to_numpy()[:nv]
        self.normal = c[..., :3] * free[:, None, None]
        self.t_c = c[..., 3] - np.einsum("vjk,vk->vj", c[..., :3], x) \
            + ws.lam_c.to_numpy()[:nv] / mu

    def face_steps(self, d):
        """The step d (nv, 3) gathered per face as (nf, 9)."""
        return d[self.faces].reshape(len(self.faces), 9)

    def predict(self, d):
        """The constraints active after the linearised step d (nv, 3): (faces' (nf, K),
        contacts' (nv, slots))."""
        face = self.t + np.einsum("fkj,fj->fk", self.G, self.face_steps(d)) > 0.0
        contact = self.t_c - np.einsum("vjk,vk->vj", self.normal, d) > 0.0
        return face, contact

    def now(self):
        """The constraints active at x itself (t > 0), as ``predict`` gives them."""
        return self.t > 0.0, self.t_c > 0.0

    def gauss_newton(self, active, face_slot, w_diag, nnz):
        """mu J_A^T J_A in the Newton matrix's block pattern (nnz, 3, 3), and mu J_A^T t_A
        (nv, 3), for the active set ``active`` = (faces', contacts')."""
        face, contact = active
        mu, nf = self.mu, len(self.faces)
        Ga = self.G * face[:, :, None]
        Hf = mu * np.einsum("fki,fkj->fij", Ga, self.G).reshape(nf, 3, 3, 3, 3)
        blocks = np.zeros((nnz, 3, 3))
        # Block (a, b) of face f is Hf[f, a, :, b, :] and lands in face_slot[f, 3 a + b].
        np.add.at(blocks, face_slot[:nf].reshape(-1),
                  Hf.transpose(0, 1, 3, 2, 4).reshape(-1, 3, 3))
        nv = len(w_diag)
        force = np.zeros((nv, 3))
        np.add.at(force, self.faces.reshape(-1),
                  (mu * np.einsum("fk,fkj->fj", self.t * face, Ga)).reshape(-1, 3))
        na = self.normal * contact[..., None]
        blocks[w_diag] += mu * np.einsum("vji,vjk->vik", na, self.normal)
        force -= mu * np.einsum("vj,vjk->vk", self.t_c * contact, na)
        return blocks, force


def step(lc, H0, r0, solve, face_slot, w_diag):
    """The active-set Newton step. ``H0`` (nnz, 3, 3) and ``r0`` (nv, 3): the kernels' Newton
    matrix (margin 0) and residual -grad L_A at x; ``solve(values, rhs)`` solves a matrix in
    that pattern. Returns (d (nv, 3), solves, whether the predicted set settled)."""
    nnz = len(H0)
    now = lc.now()
    H_now, f_now = lc.gauss_newton(now, face_slot, w_diag, nnz)
    base, r_base = H0 - H_now, r0 + f_now          # W, curvature, seams, friction; -W(x - x_hat)
    active, d, settled = now, None, False
    for k in range(MAX_RESOLVES):
        H_a, f_a = (H_now, f_now) if k == 0 else lc.gauss_newton(active, face_slot, w_diag,
                                                                nnz)
        d = solve(base + H_a, r_base - f_a)
        if k == 0:
            d_now = d
        predicted = lc.predict(d)
        if _same(predicted, active):
            settled = True
            break
        active = predicted
    # The first solve is the Newton step of the merit itself (the set active at x), a descent
    # direction; a re-solved step need not be one (it minimises the linearised model, whose
    # gradient at d = 0 is the merit's only for the set active at x). Measured on hanging at
    # resolution 25 (svd): without this fallback the line search met ascent directions once
    # the penalty had grown, and took no step.
    if not np.sum(r0 * d) > 0.0:
        d, settled = d_now, False
    return d, k + 1, settled


def _same(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b))

