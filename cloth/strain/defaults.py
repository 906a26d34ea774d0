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
