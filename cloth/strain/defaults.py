"""Strain-solver defaults the settings need without importing the solver (which creates Taichi
types at import: ``cloth.backend.init`` must come before those, and the settings are read
before it)."""

# The AL's outer-round budget per projection, the one default (settings strain.iters too): a
# cap for solves that stall, since converged solves stop at tol (2-8 rounds on hanging). 50
# was too tight: svd on hanging with remeshing ran out once in 300 frames (violation 1.3e-3);
# that solve, continued, converged 84 rounds later, and with 100 all 300 frames pass
# (docs/remesh/remesh_limits.md).
AL_ROUNDS = 100
