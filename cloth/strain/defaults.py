"""Strain-solver defaults the settings need without importing the solver (which creates Taichi
types at import: ``cloth.backend.init`` must come before those, and the settings are read
before it)."""

# The AL's outer-round budget per projection, the one default (settings strain.iters too): a
# cap for solves that stall, since converged solves stop at tol (2-8 rounds on hanging). 50
# was too tight: svd on hanging with remeshing ran out once in 300 frames (violation 1.3e-3);
# that solve, continued, converged 84 rounds later, and with 100 all 300 frames pass
# (docs/remesh/remesh_limits.md).
AL_ROUNDS = 100

# How a projection decides it is done (settings strain.stop; cloth/strain/solver.py STOPS): "kkt"
# also asks for stationarity, "violation" only for feasibility. "violation" stays the default
# while the default Newton steps cannot reach stationarity reliably: under "kkt" the PCG path's
# svd projection of a stretched 8 x 8 sheet ran its 100 rounds without reaching 1 cm/s
# (tests/test_strain_solver.py), and its Newton step underestimates the distance to the
# minimiser anyway (docs/speed/motion.md).
STOP = "violation"
# The KKT stop's stationarity tolerance as a velocity (m/s; settings strain.kkt_velocity): the
# Newton step at the answer moves no vertex by more than this x h (1 cm/s: 0.33 mm a step at
# 30 frames a second, against edges of 3-4 cm).
KKT_VELOCITY = 1e-2

# Closure of the mapping family's feasible set at isotropy (METHOD 3.3 "the feasible set is not
# closed there"). The paper's c_ij = |e_i . v_j| depends on the principal frame V, which is
# arbitrary at eta1 = eta2 and turns by ~45 degrees under tiny changes of F near it, while the
# projection drives stretched regions exactly there: a near-isotropic stretch with V at 45
# degrees is the largest stretch the constraints allow (sqrt 2 eps). Measured on the tshirt
# scene (mapping +-5 %, the first projection that failed, t = 0.1 s): the worst faces ended at
# eta = (1.072, 1.063), V at 45 degrees, and the solve did not converge in 50 or 200 rounds
# (violation 6.5e-3); svd and warp-weft from the same state converged in 8-9 rounds. Loom
# blends c_ij towards the isotropic value 1/sqrt 2 (the permissive end of the closure) with the
# weight w = D^2 / (D^2 + iso^2), D = eta1^2 - eta2^2; w c^2 keeps c~ continuous at D = 0 and
# w dc (dc ~ 1/D) bounded. With iso = 0.01 (triangles whose principal stretches differ by less
# than ~0.5 % strain) the same solve converged in 13 rounds, with 0.03 in 7. iso = 0 restores
# the paper's constraint exactly (``strain.isotropy = 0``).
MAPPING_ISO = 0.01
